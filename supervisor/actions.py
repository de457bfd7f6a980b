"""The supervisor's actions: each a sequence of service calls that returns an :class:`ActionReport`.

The generic action commands of the ball-fetching experiment (Fig. 11 of ``001_771c0ce3779b0683.txt``,
"Experiments"): "detection and localization of a learned object, locomotion to a location, and hand
reaching to a position in 3D, with other simple tasks like turning on the spot and gripper opening and
closing". Object positions come only from ``perception/locate`` (kept in :class:`Memory`); the robot's
state from its proprioception (``sim/state``); planners' trajectories are played by ``sim/execute``
(:class:`Body`), where a fall or a collision becomes the failure reason ``fell`` / ``collision``.

Failures are raised as typed bus errors (from the services) or :class:`ActionError` (world outcomes);
the runner turns both into failed reports and applies the retry policy; the remedies are here too.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from services.errors import (
    HumanoidError,
    InfeasibleError,
    InvalidRequestError,
    NotFoundError,
    UnavailableError,
)
from supervisor.body import Body, Progress
from supervisor.calls import ServiceCaller
from supervisor.health import HealthMonitor
from supervisor.memory import Memory
from supervisor.perceive import Eyes
from supervisor.planners import Planners
from supervisor.report import ActionError, ActionReport
from supervisor.runner import Action, Remedy
from supervisor.scene_map import box_estimate, boxes, distance_to_box, is_obstacle, ray_entry
from supervisor.script import Step
from supervisor.stand_up import stand_up

#: A contact farther than this from every mapped box [m] hit something the map lacks.
MAPPED_MARGIN_M = 0.1
#: Bodies of the robot stand this far from an object's face after ``goto OBJECT`` by default [m].
DEFAULT_GOTO_DISTANCE_M = 0.4
#: How long ``wait_service`` waits for a restarted service's liveliness token [s].
WAIT_SERVICE_S = 30.0


@dataclass(frozen=True)
class ActionOptions:
    """Tunables of the actions.

    clearance_m: before turning or walking away, the robot steps back until the objects seen are this
        far from its mid-feet point [m];
    back_off_m: after a collision, the touching hand moves this far back and up [m];
    far_m, near_m: an object farther than far_m is first approached to near_m and localized again [m]
        (near_face_m from a free face of it when there is no walk to the pose near_m short of it, and
        not at all when there is none to a face either);
    put_height_m: the object is brought this high above the estimated top of the place, then lowered
        until it touches [m];
    put_highest_m, put_lowest_m: bounds of a place's top height: the estimate is capped at the first,
        the object is lowered down to the second at most [m]; put_depth_m: and at most this far [m];
    put_inside_m: the release point is this far inside the place's near face [m];
    approach_m: the hand first goes this far above a reach or put point, then down [m];
    lift_m: a grasped object (or an emptied hand) is raised by this first [m];
    carry_m: (forward, lateral, height) of the carry point in front of the chest [m];
    raise_ahead_m: a hand below the approach height is first raised at least this far ahead of the
        mid-feet point [m];
    upright_hand: also ask reaching for the grasp frame upright along the heading (fingers down, jaws
        sideways); off by default: on hrp2_like the planner then often fails its joint-speed or
        end-effector criteria, while position-only reaches grasp the ball.
    """

    back_off_m: float = 0.08
    clearance_m: float = 0.6
    far_m: float = 2.2
    near_m: float = 1.8
    near_face_m: float = 1.0
    put_height_m: float = 0.12
    put_highest_m: float = 0.95
    put_lowest_m: float = 0.4
    put_depth_m: float = 0.35
    put_inside_m: float = 0.15
    approach_m: float = 0.12
    lift_m: float = 0.1
    carry_m: tuple[float, float, float] = (0.25, 0.22, 0.85)
    raise_ahead_m: float = 0.2
    upright_hand: bool = False


def _parse_point(text: str, n: int, what: str) -> tuple[float, ...] | None:
    """'x,y,z' -> floats, or None if ``text`` is a name."""
    if not any(c.isdigit() for c in text) or "," not in text:
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise InvalidRequestError(
            f"{what} {text!r}: expected {n} comma-separated numbers or an object name"
        ) from None
    if len(values) != n:
        raise InvalidRequestError(f"{what} {text!r}: expected {n} numbers, got {len(values)}")
    return values


def _arm_link(link: str) -> bool:
    """Whether a robot link (or ``held:<object>``) of a collision report is an arm, a hand or held."""
    upper = link.upper()
    return link.startswith("held:") or any(part in upper for part in ("ARM", "HAND", "GRIPPER", "WRIST"))


class Actions:
    """The action table and remedies over the services (see the module docstring)."""

    def __init__(
        self,
        bus: ServiceCaller,
        health: HealthMonitor,
        *,
        stop: threading.Event | None = None,
        progress: Progress | None = None,
        options: ActionOptions | None = None,
    ) -> None:
        self.bus = bus
        self.health = health
        self.stop = stop or threading.Event()
        self.progress: Progress = progress or (lambda _text: None)
        self.options = options or ActionOptions()
        self.memory = Memory()
        self.body = Body(bus, self.stop)
        self.eyes = Eyes(bus, self.body, self.memory)
        self.planners = Planners(bus, self.body, self.memory)
        self.last_reach: tuple[str, str] | None = None  # (hand, target) of the last reach

    # The tables the runner uses ---------------------------------------------------------------------
    def table(self) -> dict[str, Action]:
        names = ("detect", "localize", "goto", "turn", "reach", "grasp", "open", "put", "look_at")
        table = {name: self._timed(getattr(self, f"do_{name}")) for name in names}
        table["stand_up"] = self._timed(lambda step: stand_up(self.bus, self.body, self.progress, step.args))
        return table

    def remedies(self) -> dict[str, Remedy]:
        return {"relocalize": self.relocalize, "replan": self.replan, "wait_service": self.wait_service}

    def _timed(self, fn: Callable[[Step], ActionReport]) -> Callable[[Step], ActionReport]:
        """Run an action and fill in its sim time from proprioception."""

        def run(step: Step) -> ActionReport:
            start = self.body.state().sim_time_s
            report = fn(step)
            end = self.body.state().sim_time_s
            return ActionReport(
                report.action,
                report.args,
                ok=report.ok,
                reason=report.reason,
                message=report.message,
                details=report.details,
                sim_time_s=end - start,
            )

        return run

    # Perception ---------------------------------------------------------------------------------------
    def do_detect(self, step: Step) -> ActionReport:
        """Is the object in view now (no motion)? not_found otherwise."""
        name = step.args[0]
        sighting = self.eyes.locate(name)
        return self._ok(step, f"sees {sighting.describe()}", sighting)

    def do_localize(self, step: Step) -> ActionReport:
        """Find the object, looking around (head scan, then turning on the spot) when not in view."""
        name = step.args[0]
        sighting, views = self.eyes.localize(name, turn=self._turn_rad, progress=self.progress)
        return self._ok(step, f"{sighting.describe()} ({views} view(s))", sighting, views=views)

    def do_look_at(self, step: Step) -> ActionReport:
        """Turn the head (and the body if the head cannot) toward a localized object, then see it again."""
        name = step.args[0]
        if name not in self.memory.sightings:
            self.eyes.localize(name, turn=self._turn_rad, progress=self.progress)
        target = self.memory.get(name).position_m
        q = self.body.q()
        x, y, yaw = self.body.base_xy_yaw(q)
        bearing = math.remainder(math.atan2(target[1] - y, target[0] - x) - yaw, 2 * math.pi)
        (pan_lo, pan_hi), _ = self.body.head_limits()
        if not pan_lo <= bearing <= pan_hi:
            turn = bearing - math.copysign(min(abs(pan_lo), abs(pan_hi)) * 0.5, bearing)
            self._turn_rad(turn, f"turn toward {name}")
        self.eyes.look_at(target, f"look at {name}")
        try:
            sighting = self.eyes.locate(name)
        except NotFoundError as exc:
            # Not where it was seen (or half out of one image): look around for it.
            self.progress(
                f"{name} not where it was seen ({exc.details.get('reason', 'not found')}): looking around"
            )
            sighting, _views = self.eyes.localize(name, turn=self._turn_rad, progress=self.progress)
        return self._ok(step, f"looking at {sighting.describe()}", sighting)

    # Locomotion ---------------------------------------------------------------------------------------
    def do_goto(self, step: Step) -> ActionReport:
        """Walk in front of an object (``distance`` from its face, facing it) or to a pose 'x,y,yaw_deg'."""
        target = step.args[0]
        distance = float(step.kwargs.get("distance", DEFAULT_GOTO_DISTANCE_M))
        pose = _parse_point(target, 3, "goto target")
        self.body.straighten()
        self._survey(exclude={target})
        self._make_room(f"room to walk to {target}")
        if pose is None:
            sighting = self.memory.get(target)
            if not is_obstacle(sighting):
                raise InvalidRequestError(
                    f"{target} is small ({sighting.size_m[0]:.2f} m): walk to what it is on, or reach it"
                )
            self._approach(target)
            plan = self._goto_object(target, distance)
            what = f"walk to {target}"
        else:
            plan = self.planners.goto_pose(pose[0], pose[1], math.radians(pose[2]))
            what = f"walk to ({pose[0]:.2f}, {pose[1]:.2f})"
        self.progress(f"{what}: {plan.describe()}")
        executed = self.body.execute(plan.q, what=what, progress=self.progress)
        x, y, yaw = self.body.base_xy_yaw(executed.q)
        return ActionReport(
            "goto",
            step.args,
            message=f"at ({x:.2f}, {y:.2f}) facing {math.degrees(yaw):.0f} deg after {plan.describe()}",
            details={"pose": [x, y, yaw], "steps": plan.n_steps, "planned_goal": plan.goal},
        )

    def _goto_object(self, target: str, distance: float):
        """navigation/goto in front of ``target``; when no place to stand is free at ``distance`` (the
        map's box is a rough estimate), a little farther (reaching steps the rest of the way)."""
        for extra in (0.0, 0.15, 0.3):
            try:
                return self.planners.goto_object(target, distance + extra)
            except InfeasibleError as exc:
                if exc.details.get("reason") != "no_free_approach_pose" or extra >= 0.3:
                    raise
                self.progress(f"no place to stand {distance + extra:.2f} m from {target}: trying farther")
        raise AssertionError("unreachable")

    def _make_room(self, what: str) -> None:
        """Step back when an object seen is closer than ``clearance_m`` to the robot: turning on the spot
        would sweep the arms into it, and navigation does not start from inside an obstacle's margin."""
        x, y, _yaw = self.body.base_xy_yaw()
        near = [(distance_to_box(box, x, y), box.name) for box in boxes(self.memory)]
        if not near:
            return
        distance, name = min(near)
        if distance >= self.options.clearance_m:
            return
        back = min(self.options.clearance_m - distance + 0.05, 0.45)
        plan = self.planners.step_back(back)
        self.progress(f"{what}: stepping back {back:.2f} m from {name} ({plan.describe()})")
        self.body.execute(plan.q, what=f"step back from {name}", progress=self.progress)

    def _approach(self, name: str) -> None:
        """Far objects are seen roughly (a table 3 m away: its silhouette is a thin top on thin legs):
        walk to ``near_m`` short of the middle of its map box first (the middle of its silhouette can be
        a leg), facing it, and localize it again from there."""
        centre = np.asarray(box_estimate(self.memory.get(name)).center_m[:2])
        x, y, _yaw = self.body.base_xy_yaw()
        to = centre - (x, y)
        dist = float(np.linalg.norm(to))
        if dist <= self.options.far_m:
            return
        u = to / dist
        stop = centre - u * self.options.near_m
        what = f"approach {name}"
        try:
            plan = self.planners.goto_pose(float(stop[0]), float(stop[1]), math.atan2(u[1], u[0]))
        except InfeasibleError as exc:
            self.progress(f"{what}: no walk to {self.options.near_m:.1f} m short of it: {exc.message}")
            try:
                plan = self.planners.goto_object(name, self.options.near_face_m)
            except InfeasibleError as again:
                # Only a closer look is lost: the walk to the object itself plans with what is known.
                self.progress(f"{what}: none to a free face of it either ({again.message}): going on")
                return
        self.progress(
            f"{what} (seen {dist:.1f} m away: will look again from {self.options.near_m:.1f} m): "
            f"{plan.describe()}"
        )
        self.body.execute(plan.q, what=what, progress=self.progress)
        self.body.straighten()
        self.eyes.localize(name, turn=self._turn_rad, progress=self.progress)
        self.eyes.look_at(self.memory.get(name).position_m, f"look at {name}")
        self.eyes.locate(name)
        self._survey(exclude={name})
        self._make_room(f"room to walk to {name}")  # seen nearer now than from afar

    def _survey(self, exclude: set[str]) -> None:
        """Put the big objects in view on the map (not ``exclude``, not what the hands hold)."""
        self.eyes.survey(self.progress, exclude={*exclude, *self.memory.holding.values()})

    def do_turn(self, step: Step) -> ActionReport:
        """Turn on the spot by ``angle_deg`` (positive = left)."""
        try:
            angle = math.radians(float(step.args[0]))
        except ValueError:
            raise InvalidRequestError(f"turn angle {step.args[0]!r} is not a number of degrees") from None
        steps = self._turn_rad(angle, f"turn {step.args[0]} deg")
        _x, _y, yaw = self.body.base_xy_yaw()
        return ActionReport(
            "turn",
            step.args,
            message=f"now facing {math.degrees(yaw):.0f} deg ({steps} steps)",
            details={"yaw": yaw},
        )

    def _turn_rad(self, angle_rad: float, what: str) -> int:
        """Turn on the spot (walking/plan of a turn-in-place footstep sequence); the steps taken."""
        if abs(angle_rad) < math.radians(2.0):
            return 0
        self.body.straighten()
        self._make_room(f"room to {what}")
        plan = self.planners.turn(angle_rad)
        self.progress(f"{what}: {plan.describe()}")
        self.body.execute(plan.q, what=what, progress=self.progress)
        return plan.n_steps

    # Manipulation -------------------------------------------------------------------------------------
    def _heading(self) -> float:
        return self.body.base_xy_yaw()[2]

    def _move_hand(
        self,
        hand: str,
        point: np.ndarray,
        what: str,
        *,
        allowed: list[str],
        stepping: bool,
        yaw_rad: float | None,
    ) -> int:
        """Plan (reaching/reach) and execute a motion of the ``hand`` grasp frame to ``point``; the steps
        taken."""
        if not self.options.upright_hand:
            yaw_rad = None
        plan = self.planners.reach(hand, point, yaw_rad=yaw_rad, allow_stepping=stepping)
        self.progress(f"{what}: {plan.describe()}")
        self.body.execute(plan.q, what=what, allowed_contacts=allowed, progress=self.progress, hold_s=0.1)
        return plan.n_steps

    def _raise_hand(self, hand: str, height_m: float, what: str, *, allowed: list[str]) -> None:
        """Raise the hand in front of the body to ``height_m`` before moving it forward: the reaching
        planner moves the hand on a straight line, which from a hanging arm would sweep the front of the
        object's support (a box, a table). Nothing to do if the hand is already that high."""
        q = self.body.q()
        robot = self.body.robot
        here = robot.frame_pose(q, robot.frames.grasp(hand)).translation
        if here[2] >= height_m - 0.03:
            return
        x, y, yaw = self.body.base_xy_yaw(q)
        forward = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        ahead = float(np.dot(here[:2] - (x, y), forward[:2]))
        point = here + forward * max(0.0, self.options.raise_ahead_m - ahead)
        point[2] = height_m
        self._move_hand(hand, point, what, allowed=allowed, stepping=False, yaw_rad=yaw)

    def _grasp_point(self, hand: str, target: str, yaw_rad: float) -> np.ndarray:
        """Where the grasp frame goes for ``target``: its centre (perception), moved so that the object
        ends against the fixed finger without being pushed (services.model held_object_offset)."""
        point = _parse_point(target, 3, "reach target")
        if point is not None:
            return np.asarray(point, dtype=float)
        sighting = self.memory.get(target)
        radius = float(np.clip(max(sighting.size_m) / 2.0, 0.01, 0.06))
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        R_world_hand = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return sighting.position_m - R_world_hand @ self.body.robot.held_object_offset(hand, radius)

    def do_reach(self, step: Step) -> ActionReport:
        """Reach a hand to an object or 'x,y,z' from above (stepping when out of reach), gripper open.

        Two motions of ``reaching/reach``: to ``approach_m`` above the target (the support polygon may
        be reshaped: steps), then straight down onto it with the object as an allowed contact. The grasp
        frame is upright (fingers down, jaws closing sideways) along the robot's heading, so that the
        jaws straddle the object on the way down and no arm link sweeps the object's support.
        """
        hand, target = step.args
        if hand not in self.body.held():
            self.body.gripper(hand, "open")
        yaw = self._heading()
        point = self._grasp_point(hand, target, yaw)
        allowed = [target, *self._support(target)] if _parse_point(target, 3, "reach target") is None else []
        above = point + np.array([0.0, 0.0, self.options.approach_m])
        self._raise_hand(hand, float(above[2]), f"raise the {hand} hand", allowed=[])
        steps = self._move_hand(hand, above, f"reach above {target}", allowed=[], stepping=True, yaw_rad=yaw)
        yaw = self._heading()  # the steps may have turned the robot
        point = self._grasp_point(hand, target, yaw)
        self._move_hand(
            hand, point, f"lower the {hand} hand onto {target}", allowed=allowed, stepping=False, yaw_rad=yaw
        )
        self.last_reach = (hand, target)
        return ActionReport(
            "reach",
            step.args,
            message=f"{hand} hand at {target}" + (f" after {steps} steps" if steps else ""),
            details={"target": point.tolist(), "stepped": steps > 0, "steps": steps},
        )

    def _support(self, name: str) -> list[str]:
        """The object ``name`` rests on, among those seen (the big one under it), if any: the hand may
        brush it while closing on ``name`` (the last centimetres of a grasp are in contact anyway)."""
        sighting = self.memory.sightings.get(name)
        if sighting is None:
            return []
        best, best_d = [], math.inf
        for other in self.memory.sightings.values():
            if other.name == name or not is_obstacle(other):
                continue
            box = box_estimate(other)
            d = float(np.linalg.norm(np.asarray(box.center_m[:2]) - sighting.position_m[:2]))
            if d < max(box.size_m[:2]) and d < best_d and box.top_z_m > sighting.position_m[2] - 0.4:
                best, best_d = [other.name], d
        return best

    def _carry_point(self, hand: str) -> np.ndarray:
        """In front of the chest, on the hand's side, where a held object is carried [m] (world)."""
        x, y, yaw = self.body.base_xy_yaw()
        forward, side, height = self.options.carry_m
        lateral = -side if hand == "right" else side
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([x + c * forward - s * lateral, y + s * forward + c * lateral, height])

    def _lift_and_carry(self, hand: str, allowed: list[str], what: str) -> None:
        """Raise the hand by ``lift_m``, then bring it to the carry point (no stepping)."""
        q = self.body.q()
        robot = self.body.robot
        here = robot.frame_pose(q, robot.frames.grasp(hand)).translation
        yaw = self._heading()
        up = here + np.array([0.0, 0.0, self.options.lift_m])
        self._move_hand(hand, up, f"{what}: lift", allowed=allowed, stepping=False, yaw_rad=yaw)
        self._move_hand(
            hand, self._carry_point(hand), f"{what}: carry", allowed=allowed, stepping=False, yaw_rad=yaw
        )

    def do_grasp(self, step: Step) -> ActionReport:
        """Close the hand; ``not_grasped`` if nothing is held. Lifts what it holds and carries it."""
        hand = step.args[0]
        reply = self.body.gripper(hand, "close")
        if reply.outcome != "grasped" or not reply.held:
            self.body.gripper(hand, "open")  # ready for another reach
            aimed = f" at {self.last_reach[1]}" if self.last_reach else ""
            raise ActionError(
                "not_grasped",
                f"the {hand} hand closed{aimed} on nothing (finger at {reply.finger_q:.3f}); "
                "the object may have moved or been localized badly",
                {"hand": hand, "finger_q": reply.finger_q},
            )
        obj = reply.held
        support = self._support(obj)
        self.memory.holding[hand] = obj
        self.memory.forget(obj)  # it moves with the hand now
        self.progress(f"holding {obj}: lifting it")
        self._lift_and_carry(hand, [obj, *support], f"take {obj}")
        if self.body.held().get(hand) != obj:
            self.memory.holding.pop(hand, None)
            raise ActionError(
                "not_grasped", f"{obj} slipped out of the {hand} hand while lifting it", {"hand": hand}
            )
        return ActionReport(
            "grasp", step.args, message=f"holding {obj}", details={"object": obj, "hand": hand}
        )

    def do_open(self, step: Step) -> ActionReport:
        hand = step.args[0]
        reply = self.body.gripper(hand, "open")
        self.memory.holding.pop(hand, None)
        released = f", released {reply.released}" if reply.released else ""
        return ActionReport(
            "open", step.args, message=f"{hand} hand open{released}", details={"released": reply.released}
        )

    def do_put(self, step: Step) -> ActionReport:
        """Put the held object on a place: look at the place, bring the object above it, lower it until
        it touches the place (a guarded move: perception's estimate of a table's height is rough), open
        the hand, withdraw it."""
        obj = step.args[0]
        place = step.kwargs.get("on")
        if not place:
            raise InvalidRequestError("put needs a place: `put OBJECT on=PLACE`")
        held = self.body.held()
        hand = next((side for side, name in held.items() if name == obj), None)
        if hand is None:
            holding = ", ".join(f"{n} in the {s} hand" for s, n in held.items()) or "nothing"
            raise ActionError("not_grasped", f"cannot put {obj}: the robot holds {holding}", {"object": obj})
        self.do_look_at(Step(step.line, "look_at", (place,)))
        point = self._put_point(place)
        yaw = self._heading()
        allowed = [obj]
        self._raise_hand(hand, float(point[2]), f"raise {obj}", allowed=allowed)
        self._move_hand(
            hand, point, f"bring {obj} above {place}", allowed=allowed, stepping=True, yaw_rad=yaw
        )
        low = point.copy()
        low[2] = max(self.options.put_lowest_m, point[2] - self.options.put_depth_m)
        plan = self.planners.reach(
            hand, low, yaw_rad=yaw if self.options.upright_hand else None, allow_stepping=False
        )
        what = f"lower {obj} onto {place}"
        self.progress(f"{what}: {plan.describe()}, until it touches")
        executed = self.body.execute(
            plan.q, what=what, allowed_contacts=allowed, progress=self.progress, touch=place
        )
        if not executed.touched:
            raise ActionError(
                "not_found",
                f"lowered {obj} down to {low[2]:.2f} m without touching {place}: it is not "
                f"where perception saw it; localize it again",
                {"object": place, "reason": "no_surface"},
            )
        robot = self.body.robot
        at = robot.frame_pose(executed.q, robot.frames.grasp(hand)).translation
        reply = self.body.gripper(hand, "open")
        self.memory.holding.pop(hand, None)
        if reply.released != obj:
            raise ActionError(
                "not_grasped", f"opening the {hand} hand released {reply.released or 'nothing'}, not {obj}"
            )
        self.progress(f"released {obj} on {place}: withdrawing the {hand} hand")
        note = ""
        try:
            self._lift_and_carry(hand, [place, obj], f"withdraw from {place}")
        except ActionError as exc:  # the object is on the place: the put is done, the withdrawal is not
            note = f" (withdrawing the hand stopped: {exc.message})"
            touched = [str(c["other"]) for c in exc.details.get("collisions", [])]
            with contextlib.suppress(ActionError, HumanoidError):
                self._back_off(hand, sorted({*touched, place, obj}))
        return ActionReport(
            "put",
            step.args,
            message=f"{obj} put on {place} at ({at[0]:.2f}, {at[1]:.2f}, {at[2]:.2f}) m{note}",
            details={"point": at.tolist(), "on": place, "hand": hand},
        )

    def _put_point(self, place: str) -> np.ndarray:
        """Where the object goes before being lowered: inside the place's near face (as the map
        estimates it), above the highest its top can be (capped: a rough silhouette overestimates)."""
        box = box_estimate(self.memory.get(place))
        x, y, _ = self.body.base_xy_yaw()
        centre = np.array(box.center_m[:2])
        to_centre = centre - (x, y)
        dist = float(np.linalg.norm(to_centre))
        u = to_centre / max(dist, 1e-6)
        face = min(dist, ray_entry(box, np.array([x, y]), u))
        ahead = min(dist, max(0.0, face) + self.options.put_inside_m)
        xy = np.array([x, y]) + u * ahead
        top = min(box.top_z_m, self.options.put_highest_m)
        return np.array([xy[0], xy[1], top + self.options.put_height_m])

    # Remedies -----------------------------------------------------------------------------------------
    def relocalize(self, step: Step, report: ActionReport) -> None:
        """Localize the step's object again (for a missed grasp: the reached object, then reach again)."""
        if step.action == "grasp":
            if self.last_reach is None:
                return
            hand, target = self.last_reach
            if _parse_point(target, 3, "target") is None:
                self.eyes.localize(target, turn=self._turn_rad, progress=self.progress)
            self.progress(f"reaching {target} again")
            self.do_reach(Step(step.line, "reach", (hand, target)))
            return
        target = {"reach": 1, "goto": 0, "look_at": 0, "detect": 0, "localize": 0}.get(step.action)
        if target is None or target >= len(step.args):
            return
        name = step.args[target]
        if _parse_point(name, 3, "target") is None and name not in self.memory.holding.values():
            self.eyes.localize(name, turn=self._turn_rad, progress=self.progress)

    def replan(self, step: Step, report: ActionReport) -> None:
        """After a collision: free the robot (a leg or the body touched, or the robot stopped with a foot
        up: play the end of the stopped motion backward, :meth:`Body.back_out`; a hand: move it back and
        up, the touched objects allowed), map what was hit if the map lacks it, refresh the goal's
        position; the retry then plans again from the state the robot is in now (planners are stateless
        and the actions plan from ``sim/state``)."""
        if self.body.state().fallen:
            raise ActionError("fell", "the robot fell: it cannot replan from the ground")
        collisions = report.details.get("collisions") or []
        touched = sorted({str(c["other"]) for c in collisions})
        links = " ".join(str(c["robot_link"]).upper() for c in collisions)
        if self.body.interrupted is not None and (
            any(not _arm_link(str(c["robot_link"])) for c in collisions) or not self.body.standing()
        ):
            self.body.back_out(self.progress)  # a leg or the body hit it, or a foot is up: undo the end
        for hand, tag in (("right", "RARM"), ("left", "LARM")):
            if tag in links or ("held:" in links.lower() and hand in self.body.held()):
                self._back_off(hand, touched)
        self._map_what_was_hit([c["position"] for c in collisions])
        self.relocalize(step, report)

    def _map_what_was_hit(self, contacts: list[list[float]]) -> None:
        """A contact off every mapped box (by more than ``MAPPED_MARGIN_M``) hit something the map
        lacks: look at the first such contact point and put what is in view on the map."""
        mapped = boxes(self.memory)
        for point in contacts:
            if all(distance_to_box(box, point[0], point[1]) > MAPPED_MARGIN_M for box in mapped):
                self.eyes.look_at(np.asarray(point, dtype=float), "look at what was hit")
                self._survey(exclude=set())
                return

    def _back_off(self, hand: str, touched: list[str]) -> None:
        """Move ``hand`` back and up out of contact with ``touched`` (no stepping)."""
        q = self.body.q()
        robot = self.body.robot
        here = robot.frame_pose(q, robot.frames.grasp(hand)).translation
        _x, _y, yaw = self.body.base_xy_yaw(q)
        back = -self.options.back_off_m * np.array([math.cos(yaw), math.sin(yaw), -1.0])
        self.progress(f"backing the {hand} hand off {', '.join(touched)}")
        held = list(self.body.held().values())
        self._move_hand(
            hand,
            here + back,
            f"back the {hand} hand off",
            allowed=touched + held,
            stepping=False,
            yaw_rad=yaw,
        )

    def wait_service(self, step: Step, report: ActionReport) -> None:
        """Wait for the failed service's liveliness token (the launcher restarts dead services)."""
        service = str(report.details.get("service", ""))
        if not service:
            return
        self.progress(f"waiting for service {service} to come back")
        started = time.monotonic()
        if not self.health.wait_alive(service, WAIT_SERVICE_S, self.stop):
            raise UnavailableError(
                f"service {service!r} did not come back within {WAIT_SERVICE_S:.0f} s; "
                "is `humanoid up` running?",
                {"service": service},
            )
        self.progress(f"service {service} is back after {time.monotonic() - started:.1f} s")

    # Helpers ------------------------------------------------------------------------------------------
    def _ok(self, step: Step, message: str, sighting, **details) -> ActionReport:
        return ActionReport(
            step.action,
            step.args,
            message=message,
            details={
                "object": sighting.name,
                "position": sighting.position_m.tolist(),
                "confidence": sighting.confidence,
                **details,
            },
        )
