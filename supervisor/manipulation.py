"""Manipulation actions: ``reach``, ``grasp``, ``open``, ``put``.

"Hand reaching to a position in 3D ... gripper opening and closing" (Fig. 11 of
``001_771c0ce3779b0683.txt``): ``reaching/reach`` plans the whole-body motions (support polygon
reshaping, stepping when needed), ``sim/gripper`` closes and opens the hands.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable

import numpy as np

from services.errors import (
    HumanoidError,
    InfeasibleError,
    InvalidRequestError,
    NotFoundError,
    NotGraspedError,
    RequestTimeoutError,
    WorldOutcomeError,
)
from supervisor.body import Body, Progress
from supervisor.calls import ServiceCaller
from supervisor.config import SupervisorConfig
from supervisor.memory import Memory
from supervisor.perceive import Eyes
from supervisor.planners import Planners
from supervisor.report import ActionReport
from supervisor.scene_map import box_estimate, is_obstacle, ray_entry
from supervisor.script import Step, parse_point


class ManipulationActions:
    """The manipulation actions (a part of :class:`supervisor.actions.Actions`)."""

    bus: ServiceCaller
    body: Body
    memory: Memory
    eyes: Eyes
    planners: Planners
    config: SupervisorConfig
    progress: Progress
    last_reach: tuple[str, str] | None
    do_look_at: Callable[[Step], ActionReport]
    _back_off: Callable[[str, list[str]], None]

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
        if not self.config.upright_hand:
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
        here = robot.grasp_position(q, hand)
        if here[2] >= height_m - 0.03:
            return
        x, y, yaw = self.body.base_xy_yaw(q)
        forward = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        ahead = float(np.dot(here[:2] - (x, y), forward[:2]))
        point = here + forward * max(0.0, self.config.raise_ahead_m - ahead)
        point[2] = height_m
        self._move_hand(hand, point, what, allowed=allowed, stepping=False, yaw_rad=yaw)

    def _grasp_point(self, hand: str, target: str, yaw_rad: float) -> np.ndarray:
        """Where the grasp frame goes for ``target``: its centre (perception), moved so that the object
        ends against the fixed finger without being pushed (services.model held_object_offset)."""
        point = parse_point(target, 3, "reach target")
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
        allowed = [target, *self._support(target)] if parse_point(target, 3, "reach target") is None else []
        above = point + np.array([0.0, 0.0, self.config.approach_m])
        if self._last_steps(hand, above, point, f"step up to {target}"):
            if parse_point(target, 3, "reach target") is None:
                # Nearer now: localize it again before the hand comes down (a grasp closed on nothing
                # when the ball had been localized a few centimetres off from farther away).
                self.eyes.look_at(self.memory.get(target).position_m, f"look at {target}")
                with contextlib.suppress(NotFoundError):
                    self.eyes.locate(target)
            yaw = self._heading()
            point = self._grasp_point(hand, target, yaw)
            above = point + np.array([0.0, 0.0, self.config.approach_m])
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

    def _last_steps(
        self, hand: str, target_m: np.ndarray, gaze_m: np.ndarray, what: str, allowed: list[str] | None = None
    ) -> int:
        """The last steps of the approach, planned by footsteps/plan for the hand at ``target_m`` and the
        gaze on ``gaze_m`` (paper 000 §7: the fine-tuner of the end of the locomotion) and walked; the
        steps taken (0: none needed, or the planner found none: reaching steps then if it must)."""
        if not self.config.last_steps:
            return 0
        # Upright first: the walk is planned from the posture the robot will be in when it starts
        # (after a failed reach the chest leans toward the target; a walk planned from there and
        # played after straightening starts 0.25 rad away from the chest's position).
        self.body.straighten()
        try:
            plan, found = self.planners.last_steps(hand, target_m, gaze_m)
        except (InfeasibleError, RequestTimeoutError) as exc:  # none found, or none within its budget
            self.progress(f"{what}: footsteps/plan found no steps ({exc.message}); reaching will step")
            return 0
        if plan is None:
            self.progress(f"{what}: {found}: no step needed")
            return 0
        self.progress(f"{what}: {found}; {plan.describe()}")
        self.body.execute(plan.q, what=what, allowed_contacts=allowed or [], progress=self.progress)
        return plan.n_steps

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
        forward, side, height = self.config.carry_m
        lateral = -side if hand == "right" else side
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([x + c * forward - s * lateral, y + s * forward + c * lateral, height])

    def _lift_and_carry(self, hand: str, allowed: list[str], what: str) -> None:
        """Raise the hand by ``lift_m``, then bring it to the carry point (no stepping)."""
        q = self.body.q()
        robot = self.body.robot
        here = robot.grasp_position(q, hand)
        yaw = self._heading()
        up = here + np.array([0.0, 0.0, self.config.lift_m])
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
            raise NotGraspedError(
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
            raise NotGraspedError(f"{obj} slipped out of the {hand} hand while lifting it", {"hand": hand})
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
        """Put the held object on a place: look at the place, step up to it (footsteps/plan), bring the
        object above it, lower it until it touches the place (a guarded move: perception's estimate of
        a table's height is rough), open the hand, withdraw it. Lowered down to ``put_lowest_m``
        without touching: raise it, localize the place again from here and try once more."""
        obj = step.args[0]
        place = step.kwargs.get("on")
        if not place:
            raise InvalidRequestError("put needs a place: `put OBJECT on=PLACE`")
        held = self.body.held()
        hand = next((side for side, name in held.items() if name == obj), None)
        if hand is None:
            holding = ", ".join(f"{n} in the {s} hand" for s, n in held.items()) or "nothing"
            raise NotGraspedError(f"cannot put {obj}: the robot holds {holding}", {"object": obj})
        allowed = [obj]
        for attempt in (1, 2):
            # Look at the place (again, on the second attempt: from nearer, with the object above it).
            self.do_look_at(Step(step.line, "look_at", (place,)))
            point = self._put_point(place)
            if attempt == 1:
                self._last_steps(hand, point, point, f"step up to {place}", allowed=allowed)
            yaw = self._heading()
            self._raise_hand(hand, float(point[2]), f"raise {obj}", allowed=allowed)
            self._move_hand(
                hand, point, f"bring {obj} above {place}", allowed=allowed, stepping=True, yaw_rad=yaw
            )
            low = point.copy()
            low[2] = max(self.config.put_lowest_m, point[2] - self.config.put_depth_m)
            plan = self.planners.reach(
                hand, low, yaw_rad=yaw if self.config.upright_hand else None, allow_stepping=False
            )
            what = f"lower {obj} onto {place}"
            self.progress(f"{what}: {plan.describe()}, until it touches")
            executed = self.body.execute(
                plan.q, what=what, allowed_contacts=allowed, progress=self.progress, touch=place
            )
            if executed.touched:
                break
            if attempt == 2:
                raise NotFoundError(
                    f"lowered {obj} down to {low[2]:.2f} m twice without touching {place}: it is not "
                    f"where perception saw it, even seen again from here",
                    {"object": place, "reason": "no_surface"},
                )
            self.progress(
                f"lowered {obj} down to {low[2]:.2f} m without touching {place}: raising it and "
                f"localizing {place} again"
            )
            self._move_hand(hand, point, f"raise {obj} again", allowed=allowed, stepping=False, yaw_rad=yaw)
        robot = self.body.robot
        at = robot.grasp_position(executed.q, hand)
        reply = self.body.gripper(hand, "open")
        self.memory.holding.pop(hand, None)
        if reply.released != obj:
            raise NotGraspedError(
                f"opening the {hand} hand released {reply.released or 'nothing'}, not {obj}"
            )
        self.progress(f"released {obj} on {place}: withdrawing the {hand} hand")
        note = ""
        try:
            self._lift_and_carry(hand, [place, obj], f"withdraw from {place}")
        except WorldOutcomeError as exc:  # the object is on the place: the put is done, the withdrawal is not
            note = f" (withdrawing the hand stopped: {exc.message})"
            touched = [c.other for c in exc.details.get("collisions", [])]
            with contextlib.suppress(HumanoidError):
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
        ahead = min(dist, max(0.0, face) + self.config.put_inside_m)
        xy = np.array([x, y]) + u * ahead
        top = min(box.top_z_m, self.config.put_highest_m)
        return np.array([xy[0], xy[1], top + self.config.put_height_m])
