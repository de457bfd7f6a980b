"""Manipulation actions: ``reach``, ``grasp``, ``open`` (``put`` is in ``put.py``; it uses the hand
motions of this module).

"Hand reaching to a position in 3D ... gripper opening and closing" (Fig. 11 of
``001_771c0ce3779b0683.txt``): ``reaching/reach`` plans the whole-body motions (support polygon
reshaping, stepping when needed), ``sim/gripper`` closes and opens the hands.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from services.bus.schemas import walking as walk_msg
from services.bus.schemas.reaching import CRITERION_HAND_OBSTACLE, REASON_HAND_OBSTACLE
from services.bus.schemas.supervisor import REASON_NO_CLEAR_WAY, REASON_OUT_OF_REACH
from services.errors import (
    CollisionError,
    HumanoidError,
    InfeasibleError,
    InvalidRequestError,
    NotFoundError,
    NotGraspedError,
    RequestTimeoutError,
)
from supervisor.parts import ActionParts
from supervisor.planners import LastSteps, Plan
from supervisor.report import ActionReport
from supervisor.scene_map import BoxEstimate, box_estimate, is_obstacle, neighbours, ray_entry, sphere_radius
from supervisor.script import EITHER_HAND, Step, parse_point


def turns_clear_of(
    point: np.ndarray,
    robot_xy: tuple[float, float],
    felt: list[np.ndarray],
    clear_deg: float,
    turns_deg: tuple[float, ...],
) -> list[float]:
    """The turns [rad] about ``point`` (smallest first, each of ``turns_deg`` both ways) of a stance at
    ``robot_xy`` after which the direction from the robot to ``point`` is at least ``clear_deg`` off
    the direction from ``point`` to every ``felt`` point (world [m]); [] when it already is (no turn
    needed) or none is. A hand reaching ``point`` points along that direction, its fingers past it."""

    def clear(direction: float) -> bool:
        return all(
            abs(math.remainder(math.atan2(f[1] - point[1], f[0] - point[0]) - direction, 2 * math.pi))
            >= math.radians(clear_deg)
            for f in felt
        )

    bearing = math.atan2(point[1] - robot_xy[1], point[0] - robot_xy[0])
    if clear(bearing):
        return []
    turns = sorted((math.radians(d) * sign for d in turns_deg for sign in (1.0, -1.0)), key=abs)
    return [t for t in turns if clear(bearing + t)]


def jaws_clear_of(
    point: np.ndarray, felt: list[np.ndarray], heading_rad: float, turns_deg: tuple[float, ...]
) -> float:
    """The yaw [rad] (world) of a fingers-down hand at ``point`` [m] whose jaws stay clearest of the
    ``felt`` points [m]: the jaws close along the hand's y axis, its fingers are thin plates across
    it, so a neighbour along the hand's x axis (ahead of or behind the plates) is clear of them. Among
    ``heading_rad`` turned by each of ``turns_deg`` [deg] (both ways; 0 included), the one whose
    largest angle between a felt point's direction from ``point`` and the x axis line is smallest,
    the least turned among equals."""
    candidates = sorted({0.0, *(math.radians(d) * sign for d in turns_deg for sign in (1.0, -1.0))}, key=abs)

    def worst(yaw: float) -> float:
        return max(
            abs(math.remainder(math.atan2(f[1] - point[1], f[0] - point[0]) - yaw, math.pi)) for f in felt
        )

    best = min(candidates, key=lambda turn: (round(worst(heading_rad + turn), 6), abs(turn)))
    return math.remainder(heading_rad + best, math.tau)


def grasp_point(
    centre_m: np.ndarray, R_world_hand: np.ndarray, held_offset_m: np.ndarray, clearance_m: float
) -> np.ndarray:
    """Where the grasp frame goes [m] (world) so that an object centred at ``centre_m`` [m] (world) ends
    where a held one is (``held_offset_m`` [m], grasp frame: against the fixed finger), but
    ``clearance_m`` [m] off that finger toward the jaws' middle (never past it), with the grasp frame
    turned by ``R_world_hand`` (3, 3): the orientation the hand has when it comes down (fetch seed 46:
    lowered against the fixed finger, the ball seen 1.5 mm smaller than it is was rolled 2.2 cm away)."""
    offset = np.array(held_offset_m, dtype=float)
    offset[1] = math.copysign(max(0.0, abs(offset[1]) - clearance_m), offset[1])
    return np.asarray(centre_m, dtype=float) - np.asarray(R_world_hand, dtype=float) @ offset


def hand_in_the_way(
    point: np.ndarray,
    radius_m: float,
    robot_xy: tuple[float, float],
    beside: list[tuple[np.ndarray, float]],
    way_deg: tuple[float, float],
    gap_m: float,
) -> dict[str, list[tuple[float, np.ndarray]]]:
    """For each hand, the spheres ``beside`` (centre [m] world, radius [m]) in its way to an object of
    ``radius_m`` centred at ``point`` [m] (world), as (surface gap [m], centre), smallest gap first: those
    on that hand's side of the approach (the direction from ``robot_xy`` to ``point``; the right hand's
    side is to the right), between ``way_deg`` = (low, high) [deg] off it, with a gap under ``gap_m``;
    a hand with none is left out. The hand comes down onto the object from its own side, its gripper
    turned with the arm, and its moving finger sweeps that side (fetch seed 6: the right gripper on the
    purple ball 3.1 cm from the orange one, 34 deg right of the approach; seed 37: 1.6 cm, 58 deg)."""
    bearing = math.atan2(point[1] - robot_xy[1], point[0] - robot_xy[0])
    low, high = (math.radians(a) for a in way_deg)
    way: dict[str, list[tuple[float, np.ndarray]]] = {}
    for centre, radius in beside:
        off = math.remainder(math.atan2(centre[1] - point[1], centre[0] - point[0]) - bearing, math.tau)
        gap = float(np.linalg.norm(np.asarray(centre[:2]) - point[:2])) - radius - radius_m
        if low <= abs(off) <= high and gap < gap_m:
            way.setdefault("right" if off < 0 else "left", []).append((gap, np.asarray(centre, dtype=float)))
    return {hand: sorted(spheres, key=lambda s: s[0]) for hand, spheres in way.items()}


def choose_hand(
    in_the_way: dict[str, list[tuple[float, np.ndarray]]], default: str = "right"
) -> tuple[str, str]:
    """The hand to reach with, given :func:`hand_in_the_way`, and why (empty: the ``default``):
    ``default`` unless something is in its way and nothing in the other's (a real stack picks the arm
    by feasibility)."""
    other = "left" if default == "right" else "right"
    if default in in_the_way and other not in in_the_way:
        gap = in_the_way[default][0][0]
        return (
            other,
            f"something {100 * gap:.1f} cm from it on the {default} hand's side, none on the {other}'s",
        )
    return default, ""


def raise_parts(
    here_m: np.ndarray, point_m: np.ndarray, box: BoxEstimate | None, margin_m: float
) -> list[np.ndarray]:
    """The hand's raise from ``here_m`` to ``point_m`` [m] (world) as one straight motion, or as two (up
    to ``point_m``'s height where the hand is, then forward) when the straight line comes over the
    footprint of ``box`` (the map's box of the object's support; None: none known) less than
    ``margin_m`` [m] above its top: the wrist, near the hand, would sweep into its side or edge (layout
    ball_far_side). Not when the line ends before the box: the hand's posture after the raise is
    what the reach above starts from, and an arm raised another way came down onto the ball another
    way (fetch seed 37's left hand: closed on nothing after the two motions, grasped after one)."""
    if box is None:
        return [point_m]
    way = np.asarray(point_m[:2], dtype=float) - here_m[:2]
    length = float(np.linalg.norm(way))
    if length < 1e-6:
        return [point_m]
    entry = ray_entry(box, np.asarray(here_m[:2], dtype=float), way / length)
    if entry >= length:
        return [point_m]
    z_over_edge = here_m[2] + (point_m[2] - here_m[2]) * entry / length
    if z_over_edge >= box.top_z_m + margin_m:
        return [point_m]
    up = np.array(here_m, dtype=float)
    up[2] = point_m[2]
    return [up, point_m]


def refused_for_spheres(details: dict[str, Any]) -> bool:
    """Whether a ``reaching/reach`` refusal with ``hand_obstacles`` (its ``details``) is because of the
    spheres: ``reason`` ``hand_obstacle`` (no motion keeps the arm clear of them) or the criterion
    ``hand_obstacle`` (one came within its clearance, or a criterion failed while its rows held the
    arm off: ``held_back``); not when another criterion failed as it would without them."""
    reason, criterion = details.get("reason"), details.get("criterion")
    return reason == REASON_HAND_OBSTACLE or criterion == CRITERION_HAND_OBSTACLE


def yaw_of(R_world_hand: np.ndarray) -> float:
    """The yaw [rad] (world, about the vertical) of a grasp frame turned by ``R_world_hand`` (3, 3): the
    direction of its x axis on the ground (fingers down: the jaws' line is its y axis)."""
    R = np.asarray(R_world_hand, dtype=float)
    return math.atan2(R[1, 0], R[0, 0])


class ManipulationActions(ActionParts):
    """The manipulation actions (a part of :class:`supervisor.actions.Actions`)."""

    last_reach: tuple[str, str] | None
    do_look_at: Callable[[Step], ActionReport]
    _back_off: Callable[[str, list[str]], None]
    _goto_object: Callable[[str, float], Plan]
    _make_room: Callable[[str], None]

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
        yaw_rad: float | None = None,
        upright: bool = False,
        orientation: list[float] | None = None,
        lag_m: float | None = None,
        beside: list[tuple[np.ndarray, float]] | None = None,
    ) -> int:
        """Plan (reaching/reach) and execute a motion of the ``hand`` grasp frame to ``point``; the steps
        taken. ``upright``: the grasp frame upright along ``yaw_rad`` (fingers down), position only when
        reaching refuses that (or ``config.upright_hand`` is off); ``orientation``: the grasp frame at
        that world quaternion [qx, qy, qz, qw] (as the hand is turned now: footsteps/plan's final
        posture, or fingers down), position only when reaching refuses it; else position only.
        ``lag_m``: with ``orientation``, the hand's lag behind its reference reaching accepts [m].
        ``beside``: (centre [m] world, radius [m]) spheres the whole arm keeps clear of in the motions
        with an orientation (:meth:`_reach_clear`); never in a position-only one (reaching would turn
        the hand clear of them, and the grasp point is for the hand as it was asked for: seeds 6 and
        12 closed on nothing). Reaching's default timing (the guarded motions near objects;
        :meth:`_arm_motion` for the unguarded ones)."""
        if orientation is not None and not (upright and self.config.upright_hand):
            try:
                plan = self._reach_clear(
                    hand,
                    point,
                    what,
                    beside,
                    orientation=orientation,
                    allow_stepping=stepping,
                    ee_error_threshold_m=lag_m,
                )
            except InfeasibleError as exc:
                self.progress(f"{what}: keeping the hand's orientation refused ({exc.message})")
            else:
                return self._play(plan, what + " (keeping the hand's orientation)", allowed)
        if upright and self.config.upright_hand and yaw_rad is not None:
            try:
                plan = self._reach_clear(hand, point, what, beside, yaw_rad=yaw_rad, allow_stepping=stepping)
            except InfeasibleError as exc:
                steps = self._turn_hand_on_the_way(hand, point, what, allowed, yaw_rad, exc)
                if steps is not None:
                    return steps
            else:
                return self._play(plan, what, allowed)
        plan = self.planners.reach(hand, point, yaw_rad=None, allow_stepping=stepping)
        return self._play(plan, what, allowed)

    def _reach_clear(
        self,
        hand: str,
        point: np.ndarray,
        what: str,
        beside: list[tuple[np.ndarray, float]] | None,
        **request: Any,
    ) -> Plan:
        """``Planners.reach`` of ``hand`` to ``point`` with its ``request`` fields (an orientation: the
        hand's turn is the supervisor's, which the grasp point is for), the whole arm, gripper
        included, kept clear of the spheres ``beside`` (reaching's ``hand_obstacles``: the balls seen
        beside the object and the points felt near it; paper 000 eqs. 12-13). Refused because of them
        (:func:`refused_for_spheres`: ``infeasible`` for them, or for a criterion that failed while
        their rows held the arm off), it is planned as without them (the stance and the jaws' yaw were
        chosen clear of them already; the hand may then brush one); refused for any other reason, that
        refusal is the answer (planning it again without them would reach the same one)."""
        if not beside:
            return self.planners.reach(hand, point, **request)
        try:
            return self.planners.reach(hand, point, hand_obstacles=beside, **request)
        except InfeasibleError as exc:
            if not refused_for_spheres(exc.details):
                raise
            self.progress(f"{what}: clear of what is beside it refused ({exc.message}); as without it")
        return self.planners.reach(hand, point, **request)

    def _arm_motion(
        self, hand: str, point: np.ndarray, what: str, *, allowed: list[str], motion: str
    ) -> None:
        """An unguarded arm motion of the ``hand`` grasp frame to ``point`` [m] (world), position only,
        without stepping, timed as the config's ``motion`` (``config.arm_timing``: fast if configured
        so, else reaching's default)."""
        timing = self.config.arm_timing(motion)
        plan = self.planners.reach(hand, point, yaw_rad=None, allow_stepping=False, timing=timing)
        self._play(plan, what, allowed)

    def _play(self, plan: Plan, what: str, allowed: list[str]) -> int:
        self.progress(f"{what}: {plan.describe()}")
        self.body.execute(plan.q, what=what, allowed_contacts=allowed, progress=self.progress, hold_s=0.1)
        return plan.n_steps

    def _turn_hand_on_the_way(
        self,
        hand: str,
        point: np.ndarray,
        what: str,
        allowed: list[str],
        yaw_rad: float,
        refused: HumanoidError,
    ) -> int | None:
        """Fingers down at ``point`` in several motions when one was refused (the wrist turning too
        fast for reaching's criteria in one motion's time): k - 1 motions along the straight line to
        ``point``, each turning the hand by at most ``turn_piece_deg`` (a slerp of the hand's
        orientation now and the upright one), then to ``point``, upright; no stepping. None when
        reaching refuses one (the caller then goes on, position only, from where the hand is)."""
        robot = self.body.robot
        q = self.body.q()
        here = robot.frame_pose(q, robot.grasp_frame(hand))
        rotations = Rotation.from_matrix(
            np.stack([here.rotation, Rotation.from_euler("z", yaw_rad).as_matrix()])
        )
        angle = float((rotations[0].inv() * rotations[1]).magnitude())
        k = max(2, math.ceil(math.degrees(angle) / self.config.turn_piece_deg))
        slerp = Slerp([0.0, 1.0], rotations)
        start = np.asarray(here.translation, dtype=float)
        for i in range(1, k):
            f = i / k
            try:
                plan = self.planners.reach(
                    hand,
                    start + f * (point - start),
                    orientation=slerp(f).as_quat().tolist(),
                    allow_stepping=False,
                )
            except InfeasibleError as exc:
                self.progress(
                    f"{what}: fingers down refused ({refused.message}; in {k} motions of "
                    f"{math.degrees(angle) / k:.0f} deg, motion {i}: {exc.message}); any orientation then"
                )
                return None
            self._play(plan, f"{what}: turning the hand, {i} of {k}", allowed)
        try:
            last = self.planners.reach(hand, point, yaw_rad=yaw_rad, allow_stepping=False)
        except InfeasibleError as exc:
            self.progress(
                f"{what}: fingers down refused in the last of {k} motions ({exc.message}); any orientation"
            )
            return None
        return self._play(last, what, allowed)

    def _raise_hand(
        self, hand: str, height_m: float, what: str, *, allowed: list[str], support: str | None = None
    ) -> None:
        """Raise the hand in front of the body to ``height_m`` before moving it forward: the reaching
        planner moves the hand on a straight line, which from a hanging arm would sweep the front of the
        object's support (a box, a table). Nothing to do if the hand is already that high. When that
        line comes over the ``support``'s box on the map less than ``raise_box_margin_m`` above its
        top (a stance close to it: layout ball_far_side's 4 steps toward a ball 0.4 m deep swept the
        wrist into the box's side), the hand goes straight up first, then forward (:func:`raise_parts`)."""
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
        sighting = self.memory.sightings.get(support) if support else None
        box = box_estimate(sighting) if sighting is not None and is_obstacle(sighting) else None
        parts = raise_parts(here, point, box, self.config.raise_box_margin_m)
        for i, part in enumerate(parts):
            how = f"up first, clear of {support}" if i == 0 else "then forward"
            label = what if len(parts) == 1 else f"{what} ({how})"
            self._arm_motion(hand, part, label, allowed=allowed, motion="raise")

    def _grasp_point(
        self, hand: str, target: str, yaw_rad: float, R_world_hand: np.ndarray | None = None
    ) -> np.ndarray:
        """Where the grasp frame goes for ``target`` with the hand turned by ``yaw_rad`` [rad] (world;
        fingers down), or by ``R_world_hand`` (3, 3) when given (as it is turned now: the point follows
        the orientation actually executed): its centre (perception), moved so that the object ends
        near the fixed finger (``Robot.held_object_offset``), ``grasp_clearance_m`` off it
        (:func:`grasp_point`)."""
        point = parse_point(target, 3, "reach target")
        if point is not None:
            return np.asarray(point, dtype=float)
        sighting = self.memory.get(target)
        offset = self.body.robot.held_object_offset(hand, sphere_radius(sighting))
        R = Rotation.from_euler("z", yaw_rad).as_matrix() if R_world_hand is None else R_world_hand
        return grasp_point(sighting.position_m, R, offset, self.config.grasp_clearance_m)

    def _hand_rotation(self, hand: str) -> np.ndarray:
        """The ``hand`` grasp frame's world orientation now (3, 3)."""
        robot = self.body.robot
        return robot.frame_pose(self.body.q(), robot.grasp_frame(hand)).rotation

    def do_reach(self, step: Step) -> ActionReport:
        """Reach a hand to an object or 'x,y,z' from above (stepping when out of reach), gripper open.

        First the last steps, which footsteps/plan decides with the final posture for the hand on the
        target (paper 000 §7), then two motions of ``reaching/reach``: to ``approach_m`` above the
        target, the hand turned as in footsteps/plan's final posture and without stepping (the
        footstep planner decided the stance; "grasp" in ``last_steps_posture``), or (by default, or
        where reaching refuses that) position only with support polygon reshaping (steps) when
        needed; then straight down onto it with the object as an allowed contact, the hand keeping
        its orientation.
        """
        hand, target = step.args
        way = self._in_the_way(target)
        if hand == EITHER_HAND:  # the script names none: the one whose way is clear (the right by default)
            hand, why = choose_hand(way)
            if why:
                self.progress(f"reach {target}: the {hand} hand ({why})")
        # Something in both hands' ways (balls a few cm on either side): only a hand whose jaws straddle
        # the object, fingers down, its yaw clear of them, can take it; the hand as reaching turns it
        # would come down on one of them (layout balls_tight: three touches, then a dead end).
        tight = [centre for spheres in way.values() for _gap, centre in spheres] if len(way) == 2 else []
        self.last_reach = (hand, target)  # the reach under way (a remedy backs this hand off its target)
        if hand not in self.body.held():
            self.body.gripper(hand, "open")
        yaw = self._heading()
        point = self._grasp_point(hand, target, yaw)
        allowed = [target, *self._support(target)] if parse_point(target, 3, "reach target") is None else []
        # Something felt near it (a ball perception has no model of): fingers down, the jaws' yaw clear
        # of it (it can be beside the wrist: fetch seed 37). That hand is a task of the footstep IK
        # (paper 000 §4: the tasks decide where the feet go), the hand on the object, so that the
        # stance suits the posture: approach direction and wrist yaw chosen from the neighbours.
        near = self._felt_near(point) + tight
        turns = self.config.jaws_turns_deg
        if near and turns and parse_point(target, 3, "reach target") is None:
            self._where_it_was_aimed(target)
            point = self._grasp_point(hand, target, self._heading())
        keep_out = self._grasp_obstacles(target)
        beside = self._beside(target)  # what the arm keeps clear of in the motions with an orientation
        centre = self._centre(target, point)
        jaws = jaws_clear_of(centre, near, self._heading(), turns) if near and turns else None
        jaws_quat = None
        decided = None
        if jaws is not None and self.config.jaws_planned:
            decided, jaws = self._jaws_stance(hand, target, centre, near, jaws, keep_out)
            if decided is not None:
                jaws_quat = Rotation.from_euler("z", jaws).as_quat().tolist()
        if decided is None:
            # Planned without it (none found with it): walked around what the hand felt ahead of the
            # fingers first.
            jaws_quat = None
            point = self._grasp_point(hand, target, self._heading())  # (turned for the jaws above)
            self._clear_of_felt(point, f"step around {target}")
            if jaws is not None:
                jaws = jaws_clear_of(centre, near, self._heading(), turns)
        yaw = self._heading() if jaws is None else jaws
        point = self._grasp_point(hand, target, yaw)
        above = point + np.array([0.0, 0.0, self.config.approach_m])
        # The hand on the object (the paper's task) with the grasp's posture in ``last_steps_posture``:
        # its final posture is then the one the lowering ends in. Else above it: planned for the
        # object itself, the stance moved and the position-only lowering brought the wrist onto the
        # neighbouring ball in fetch seed 12, which it grasps without a retry when planned above.
        hand_at = point if "grasp" in self.config.last_steps_posture else above
        if decided is None:
            decided = self._last_steps(hand, hand_at, point, f"step up to {target}", hand_obstacles=keep_out)
        support = self._support(target)
        # Nothing found from here: nearer first (to the object itself when it rests on nothing known: a
        # ball on the floor; what refuses it then is its height or reach from near, not the step cap).
        toward = support[0] if support else None if parse_point(target, 3, "reach target") else target
        if decided is None and toward and self._walk_nearer(toward, point, f"step up to {target}"):
            decided = self._last_steps(hand, hand_at, point, f"step up to {target}", hand_obstacles=keep_out)
            walked = True
        else:
            walked = decided is not None and decided.walk is not None
        if walked:
            if parse_point(target, 3, "reach target") is None:
                # Nearer now: localize it again before the hand comes down (a grasp closed on nothing
                # when the ball had been localized a few centimetres off from farther away).
                self.eyes.look_at(self.memory.get(target).position_m, f"look at {target}")
                with contextlib.suppress(NotFoundError):
                    self.eyes.locate(target)
            yaw = self._heading() if jaws is None else jaws
            point = self._grasp_point(hand, target, yaw)
            above = point + np.array([0.0, 0.0, self.config.approach_m])
        self._raise_hand(
            hand,
            float(above[2]),
            f"raise the {hand} hand",
            allowed=[],
            support=support[0] if support else None,
        )
        # The hand above the object as footsteps/plan's final posture has it (paper 000 §7: the footstep
        # planner decided the stance and the posture together; reaching executes that hand pose), or,
        # with ``upright_hand``, fingers down: the jaws then straddle the object and no finger reaches
        # past it onto a neighbour the map does not show.
        final = self._final_hand(decided, target, "grasp", planned=jaws_quat is not None)
        # The jaws' hand (fingers down, its yaw clear of the neighbours) does not step: the hand's lag on
        # the way is no reason to refuse it (reaching's 4e-5 m is the paper's trigger for stepping; 0.2
        # mm refused it on seed 37, 0.06 mm on seed 6 from the stance planned without it)
        lag = self.config.jaws_lag_m if jaws is not None else None
        # ... and the whole final posture planned with it (reaching executes it: paper 000 §7)
        posture = decided.q_final if decided is not None and final is not None else None
        steps = self._as_planned(
            hand, above, f"reach above {target}", [], final, target, lag_m=lag, posture=posture, beside=beside
        )
        if steps is None and jaws is not None:
            steps = self._fingers_down(hand, above, f"reach above {target}", jaws, beside, lag_m=lag)
        if steps is None and tight:
            raise self._no_clear_way(hand, target, way, yaw)
        if steps is None:
            # From the stance planned for the jaws, no reaching steps (fetch seed 6: 8 steps into the box)
            try:
                steps = self._move_hand(
                    hand,
                    above,
                    f"reach above {target}",
                    allowed=[],
                    stepping=jaws_quat is None,
                    yaw_rad=yaw,
                    upright=True,
                )
            except InfeasibleError as exc:
                point_target = parse_point(target, 3, "reach target") is not None
                if support or point_target or not self._on_floor(target):
                    raise  # a support not mapped (yet): the retry's fresh look may map it
                raise self._out_of_reach(hand, target, above, exc) from None
        upright = None
        if jaws is not None or self.config.upright_hand:
            upright = Rotation.from_euler("z", self._heading() if jaws is None else jaws).as_quat().tolist()
        keep = next((quat for quat in (final, upright) if quat and self._hand_at(hand, quat)), None)
        jaws_kept = jaws is not None and keep is not None and (keep is upright or jaws_quat is not None)
        yaw = jaws if jaws_kept else self._heading()  # the steps may have turned it
        if parse_point(target, 3, "reach target") is None:
            self.memory.aimed[target] = self.memory.get(target)
        R_now = None
        if keep is not None:
            # The lowering keeps the orientation the reach above executed, and the point is for the hand
            # turned so (not as it was asked for: within 0.1 rad of it, ``_hand_at``).
            R_now = self._hand_rotation(hand)
            keep = Rotation.from_matrix(R_now).as_quat().tolist()
        point = self._grasp_point(hand, target, yaw, R_world_hand=R_now)
        self._move_hand(  # straight down, the hand turned as it is when it was reached above
            hand,
            point,
            f"lower the {hand} hand onto {target}",
            allowed=allowed,
            stepping=False,
            orientation=keep,
            lag_m=lag,
            beside=beside,
        )
        self.last_reach = (hand, target)
        return ActionReport(
            "reach",
            step.args,
            message=f"{hand} hand at {target}" + (f" after {steps} steps" if steps else ""),
            details={"target": point.tolist(), "stepped": steps > 0, "steps": steps},
        )

    def _out_of_reach(
        self, hand: str, target: str, above: np.ndarray, refused: InfeasibleError
    ) -> InfeasibleError:
        """The ``infeasible`` answer (final: no look again raises it) when reaching refused the hand
        ``above`` [m] (world) an object ``target`` that rests on nothing known (a ball on the floor),
        from as near as the robot came: its height and distance as the residuals, with reaching's
        criterion (a standing HRP-2 does not squat: layout ball_on_floor)."""
        x, y, _yaw = self.body.base_xy_yaw()
        centre = self.memory.get(target).position_m
        far = float(np.hypot(centre[0] - x, centre[1] - y))
        return InfeasibleError(
            f"{target} rests on nothing known, {centre[2]:.2f} m above the floor and {far:.2f} m from "
            f"the feet: the {hand} hand cannot reach {above[2]:.2f} m high above it ({refused.message})",
            {
                "reason": REASON_OUT_OF_REACH,
                "target": target,
                "hand": hand,
                "height_m": float(centre[2]),
                "hand_height_m": float(above[2]),
                "distance_m": far,
                "refused": refused.details,
            },
        )

    def _no_clear_way(
        self, hand: str, target: str, way: dict[str, list[tuple[float, np.ndarray]]], yaw_rad: float
    ) -> InfeasibleError:
        """The ``infeasible`` answer when something is in both hands' ``way`` to ``target`` and the
        jaws' approach (fingers down, its yaw ``yaw_rad`` [rad] clear of them) was refused: given before
        the hand comes down (not after touching them), with the clearances as residuals."""
        gaps = {side: [round(gap, 4) for gap, _centre in spheres] for side, spheres in way.items()}
        lowest = min(gap for spheres in gaps.values() for gap in spheres)
        return InfeasibleError(
            f"no clear way for a hand to {target}: something beside it on both sides (the nearest "
            f"{100 * lowest:.1f} cm away, under {100 * self.config.hand_way_gap_m:.1f} cm) and the "
            f"{hand} hand's jaws, fingers down at {math.degrees(yaw_rad):.0f} deg, refused by the planners",
            {
                "reason": REASON_NO_CLEAR_WAY,
                "target": target,
                "hand": hand,
                "gaps_m": gaps,
                "needed_gap_m": self.config.hand_way_gap_m,
                "jaws_yaw_rad": yaw_rad,
            },
        )

    def _jaws_stance(
        self,
        hand: str,
        target: str,
        centre: np.ndarray,
        near: list[np.ndarray],
        jaws: float,
        keep_out: list[tuple[np.ndarray, float]],
    ) -> tuple[LastSteps | None, float]:
        """The stance for the fingers-down hand above ``target`` at the jaws' yaw ``jaws`` [rad] (world),
        planned by footsteps/plan with that hand as a task (paper 000 §4: the tasks decide where the feet
        go), checked for what follows the grasp, and walked: (what it decided, the yaw it was planned
        for), or (None, ``jaws``) when no stance passed (the caller approaches as without it).

        The jaws' line is what keeps them clear of the ``near`` points, so the hand turned by half a
        turn is as clear (:func:`jaws_clear_of`); either hand is tried, ``jaws`` first. A stance is
        kept when what follows the grasp can be planned from its final posture (the hand above the
        object, as the lift leaves it: :meth:`_what_follows_refused`): on fetch seed 6 the stance for
        the jaws at -46 deg put the ball 57 deg to the right of the heading, the arm stretched
        sideways and the wrist turned, and the carry after the grasp was refused there
        (manipulability 5.4e-5, then a wrist joint at its limit); the hand at 134 deg was carried,
        but from that posture (the waist rolled 22 deg) no walk could start (the step back before
        the turn: an arm joint at ~100 rad/s).

        First (``jaws_free_yaw``) the yaw is left to the footstep IK, with the hand on the object (its
        fingers down within ``jaws_tilt_deg``), then the two fixed yaws."""
        felt = ", ".join(f"{math.degrees(math.atan2(f[1] - centre[1], f[0] - centre[0])):.0f}" for f in near)

        def check(planned: LastSteps) -> str | None:
            return self._what_follows_refused(hand, planned.q_final)

        if self.config.jaws_free_yaw:
            # The yaw the footstep IK chooses (reach8's free_yaw: only the fingers-down tilt is a task, the
            # gripper's rows against the spheres turn the jaws clear of them), planned with the hand on
            # the object: 12 cm above it the fingers are far from the neighbours and the rows do not act.
            # The grasp frame's origin (the jaws' middle) on the object's centre: the same point whatever
            # yaw the IK chooses (the grasp point of one yaw is up to twice the held offset's side off for
            # another: review s11 #11); the lowering then aims the held offset for the yaw executed.
            decided = self._last_steps(
                hand,
                centre,
                centre,
                f"step up to {target}, the jaws' yaw free (beside it at {felt} deg)",
                hand_obstacles=keep_out,
                orientation=Rotation.from_euler("z", jaws).as_quat().tolist(),
                step_region_scale=self.config.jaws_step_region_scale,
                free_yaw=True,
                check=lambda planned: self._fingers_not_down(hand, planned) or check(planned),
            )
            if decided is not None:
                chosen = yaw_of(Rotation.from_quat(decided.hand_quat).as_matrix())
                self.progress(f"step up to {target}: the jaws at {math.degrees(chosen):.0f} deg")
                return decided, chosen
        for yaw in (jaws, math.remainder(jaws + math.pi, math.tau)):
            quat = Rotation.from_euler("z", yaw).as_quat().tolist()
            point = self._grasp_point(hand, target, yaw)
            # planned above it: the posture reaching goes to first; the lowering keeps its orientation
            over = point + np.array([0.0, 0.0, self.config.approach_m])
            decided = self._last_steps(
                hand,
                over,
                point,
                f"step up to {target}, the jaws at {math.degrees(yaw):.0f} deg (felt at {felt} deg from it)",
                hand_obstacles=keep_out,
                orientation=quat,
                step_region_scale=self.config.jaws_step_region_scale,
                check=check,
            )
            if decided is not None:
                return decided, yaw
        return None, jaws

    def _fingers_not_down(self, hand: str, planned: LastSteps) -> str | None:
        """Why footsteps/plan's final posture ``planned`` does not have the ``hand``'s fingers down (its
        grasp frame's z axis more than ``jaws_tilt_deg`` off the vertical: the orientation is a task
        below the reach), or None."""
        z = Rotation.from_quat(planned.hand_quat).as_matrix()[:, 2]
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(z[2])))))
        if tilt <= self.config.jaws_tilt_deg:
            return None
        return f"the fingers {tilt:.0f} deg off down"

    def _what_follows_refused(self, hand: str, q_final: np.ndarray) -> str | None:
        """Why what follows a grasp from footsteps/plan's final posture ``q_final`` cannot be planned, or
        None when it can (dry runs: nothing is executed): reaching brings the ``hand`` to the carry
        point of that stance without stepping (what the grasp does after the lift:
        ``_lift_and_carry``), and, from that posture with the chest straightened (as before every
        walk), ``walking/goal`` steps back ``jaws_step_back_m`` (the turn that follows steps back from
        the object's support first)."""
        there = self._carry_point(hand, pose=self.body.robot.mid_feet_pose(q_final))  # at the planned stance
        try:
            timing = self.config.arm_timing("carry")  # as the carry will be asked for
            self.planners.reach(hand, there, allow_stepping=False, q_start=q_final, timing=timing)
        except (InfeasibleError, RequestTimeoutError) as exc:  # a dry run: refused, not failed
            return f"no carry from there ({exc.message})"
        robot = self.body.robot
        straight = np.array(q_final, dtype=float)
        for joint in robot.info.chest_joints:
            straight[robot.index(joint)] = robot.q_half_sitting[robot.index(joint)]
        back = self.config.jaws_step_back_m
        try:
            step_back = walk_msg.GoalRequest(q_start=straight, kind="pose", pose=[-back, 0.0, 0.0])
            self.planners.walk_goal(step_back)
        except (InfeasibleError, RequestTimeoutError) as exc:
            return f"no step back from there ({exc.message})"
        return None

    def _where_it_was_aimed(self, target: str) -> None:
        """Before choosing the jaws' yaw from what the hand felt beside ``target``: when the sighting of
        ``target`` the last lowering aimed at (localized from near just before it; ``Memory.aimed``) was
        more confident than the latest one and lies more than ``relocalized_jump_m`` from it, the
        latest is not kept (fetch seed 37: seen again from where the hand had backed off, the ball
        was put 0.13 m off and 0.12 m low, and the jaws were turned for a neighbour on the wrong
        side). Seen again (and kept) otherwise."""
        aimed = self.memory.aimed.get(target)
        latest = self.memory.get(target)
        jump = float(np.linalg.norm(latest.position_m - aimed.position_m)) if aimed is not None else 0.0
        if (
            aimed is not None
            and jump > self.config.relocalized_jump_m
            and aimed.confidence > latest.confidence
        ):
            self.progress(
                f"{target} seen again {jump:.2f} m from where the hand went down on it (confidence "
                f"{latest.confidence:.2f} against {aimed.confidence:.2f}): keeping that one"
            )
            self.memory.remember(aimed)

    def _centre(self, target: str, point: np.ndarray) -> np.ndarray:
        """The centre of the object ``target`` as perception saw it (``point`` for an 'x,y,z' target)."""
        if parse_point(target, 3, "reach target") is not None:
            return point
        return np.asarray(self.memory.get(target).position_m, dtype=float)

    def _grasp_obstacles(self, target: str) -> list[tuple[np.ndarray, float]]:
        """What the reaching arm (upper arm, forearm, gripper) keeps out of in footsteps/plan's final
        posture for a grasp of ``target``: the object itself (its sighting: centre, half its largest
        seen size), the balls seen within ``felt_radius_m`` of it (``scene_map.neighbours``) and
        what the hand felt near it (memory's felt points within ``felt_radius_m``, spheres of
        ``felt_obstacle_radius_m``: a ball beside it that perception has no model of), as (centre [m]
        world, radius [m]). The footstep IK then chooses the stance and the arm's posture clear of them
        (paper 000: obstacles as inequalities, eq. 13)."""
        if parse_point(target, 3, "reach target") is not None:
            return []
        sighting = self.memory.get(target)
        itself = (np.asarray(sighting.position_m, dtype=float), sphere_radius(sighting))
        return [itself, *self._beside(target)]

    def _beside(self, target: str) -> list[tuple[np.ndarray, float]]:
        """The spheres (centre [m] world, radius [m]) beside ``target`` a hand reaching it keeps clear
        of: the balls seen within ``felt_radius_m`` of it (``scene_map.neighbours``: perception reports
        every object a look sees, so they are known before a touch) and the points felt near it
        (spheres of ``felt_obstacle_radius_m``: a ball perception has no model of); none for a point."""
        if parse_point(target, 3, "reach target") is not None:
            return []
        sighting = self.memory.get(target)
        # the balls seen beside it (perception reports every object a look sees): known before a touch
        spheres = neighbours(self.memory, sighting.position_m, self.config.felt_radius_m, {target})
        r_felt = self.config.felt_obstacle_radius_m
        return spheres + [(f, r_felt) for f in self._felt_near(sighting.position_m)]

    def _felt_near(self, point: np.ndarray) -> list[np.ndarray]:
        """Memory's felt points within ``felt_radius_m`` of ``point`` (horizontally) [m]."""
        radius = self.config.felt_radius_m
        return [f for f in self.memory.felt if float(np.linalg.norm(f[:2] - point[:2])) < radius]

    def _fingers_down(
        self,
        hand: str,
        point: np.ndarray,
        what: str,
        yaw_rad: float,
        beside: list[tuple[np.ndarray, float]] | None = None,
        lag_m: float | None = None,
    ) -> int | None:
        """The ``hand`` above ``point`` fingers down, turned by ``yaw_rad`` (its jaws clear of what it
        felt: :func:`jaws_clear_of`), the arm clear of the spheres ``beside`` (:meth:`_reach_clear`),
        the hand's lag behind its reference up to ``lag_m`` [m] (None: reaching's default), without
        stepping (in two motions when one is refused); the steps taken (0), or None when reaching
        refuses it (the caller reaches as usual)."""
        try:
            plan = self._reach_clear(
                hand, point, what, beside, yaw_rad=yaw_rad, allow_stepping=False, ee_error_threshold_m=lag_m
            )
        except InfeasibleError as exc:
            return self._turn_hand_on_the_way(hand, point, what, [], yaw_rad, exc)
        return self._play(plan, f"{what} (fingers down, the jaws clear of what the hand felt)", [])

    def _clear_of_felt(self, point: np.ndarray, what: str) -> bool:
        """When a hand touched something unseen near ``point`` (memory's felt points, within
        ``felt_radius_m``): the fingers, which point from the robot over the object and past it, came
        down on it. Walk around ``point`` (``walking/goal``, checked against the map) by the smallest of
        ``felt_turns_deg`` that puts every such point at least ``felt_clear_deg`` off the direction
        from the robot to ``point``; the last steps are then planned from there. Whether it walked
        (nothing to do when none was felt near, none is ahead of the fingers, or no stance is free)."""
        c = self.config
        near = self._felt_near(point)
        if not near:
            return False
        self.body.straighten()  # the walk is planned from the posture it starts in
        x, y, yaw = self.body.base_xy_yaw()
        turns = turns_clear_of(point, (x, y), near, c.felt_clear_deg, c.felt_turns_deg)
        if not turns:
            bearing = math.atan2(point[1] - y, point[0] - x)
            # Which side of the approach they lie (+ left), for the transcript: a point beside the hand's
            # wrist (about +-90 deg) is touched whatever the turn (fetch seed 37).
            off = [
                math.remainder(math.atan2(f[1] - point[1], f[0] - point[0]) - bearing, math.tau) for f in near
            ]
            self.progress(
                f"{what}: {len(near)} point(s) felt near it, "
                + ", ".join(f"{math.degrees(a):+.0f}" for a in off)
                + " deg off the approach (+ left): no turn clears them"
            )
        for turn in turns:
            # The stance rotated about the point by ``turn``: same distance, same offset to the side.
            cos_t, sin_t = math.cos(turn), math.sin(turn)
            dx, dy = x - point[0], y - point[1]
            goal = [point[0] + cos_t * dx - sin_t * dy, point[1] + sin_t * dx + cos_t * dy, yaw + turn]
            try:
                plan = self.planners.walk_goal(
                    walk_msg.GoalRequest(q_start=self.body.plan_q(), kind="pose", pose=goal, frame="world")
                )
            except InfeasibleError as exc:
                self.progress(f"{what}: no walk {math.degrees(turn):+.0f} deg around it ({exc.message})")
                continue
            self.progress(
                f"{what}: the hand touched something unseen there; approaching {math.degrees(turn):+.0f} "
                f"deg around it ({plan.describe()})"
            )
            self.body.execute(plan.q, what=what, progress=self.progress)
            return True
        return False

    def _final_hand(
        self, decided: LastSteps | None, target: str, approach: str, planned: bool = False
    ) -> list[float] | None:
        """The grasp frame's world orientation in footsteps/plan's final posture ([qx, qy, qz, qw]), when
        it decided the last steps and ``approach`` ("grasp" or "put") is in ``last_steps_posture`` (or
        ``planned``: the orientation was one of its tasks), unless an approach to ``target`` in that
        orientation touched something before (``Memory.posture_touched``); else None."""
        wanted = planned or approach in self.config.last_steps_posture
        if decided is None or not wanted or not decided.hand_quat:
            return None
        if target in self.memory.posture_touched:
            self.progress(
                f"{target}: the hand as in footsteps/plan's final posture touched before: position only"
            )
            return None
        return decided.hand_quat

    def _as_planned(
        self,
        hand: str,
        point: np.ndarray,
        what: str,
        allowed: list[str],
        quat: list[float] | None,
        target: str,
        lag_m: float | None = None,
        posture: np.ndarray | None = None,
        beside: list[tuple[np.ndarray, float]] | None = None,
    ) -> int | None:
        """The ``hand`` to ``point`` turned as in footsteps/plan's final posture (``quat``), from the
        stance footsteps/plan decided: without stepping (paper 000 §7: the footstep planner decided
        where the feet go for this posture; reaching's stepping would walk away from that stance when
        its manipulability trigger fires on the way, paper 001 Fig. 4). The steps taken (0), or None
        when ``quat`` is None or reaching refuses it (the caller then reaches position only, stepping
        if it must: the object moved). ``lag_m``: the hand's lag behind its reference reaching accepts
        [m] (None: its default). ``posture``: footsteps/plan's whole final posture (nq,), which reaching
        then goes to with the hand (its joints, CoM and hand path; its gaze replaces reaching's) rather
        than to one its own IK finds (without it the planned hand was refused: the multibody ZMP 374-1609 mm
        out of the support polygon; with it the motion ends in the posture the footstep IK checked).
        ``beside``: spheres the arm keeps clear of (:meth:`_reach_clear`)."""
        if quat is None:
            return None
        try:
            plan = self._reach_clear(
                hand,
                point,
                what,
                beside,
                orientation=quat,
                allow_stepping=False,
                ee_error_threshold_m=lag_m,
                posture=posture,
            )
        except InfeasibleError as exc:
            self.progress(f"{what}: the hand as in footsteps/plan's final posture refused ({exc.message})")
            return None
        try:
            return self._play(plan, what + " (hand as in footsteps/plan's final posture)", allowed)
        except CollisionError:
            self.memory.posture_touched.add(target)  # the retry approaches it position only
            raise

    def _hand_at(self, hand: str, quat: list[float], tolerance_rad: float = 0.1) -> bool:
        """Whether the ``hand``'s grasp frame is within ``tolerance_rad`` of the world orientation
        ``quat`` [qx, qy, qz, qw] now (then the lowering keeps it)."""
        robot = self.body.robot
        R = robot.frame_pose(self.body.q(), robot.grasp_frame(hand)).rotation
        return float((Rotation.from_quat(quat).inv() * Rotation.from_matrix(R)).magnitude()) < tolerance_rad

    def _last_steps(
        self,
        hand: str,
        target_m: np.ndarray,
        gaze_m: np.ndarray,
        what: str,
        allowed: list[str] | None = None,
        hand_obstacles: list[tuple[np.ndarray, float]] | None = None,
        orientation: list[float] | None = None,
        step_region_scale: float | None = None,
        check: Callable[[LastSteps], str | None] | None = None,
        free_yaw: bool = False,
    ) -> LastSteps | None:
        """The last steps of the approach, planned by footsteps/plan for the hand at ``target_m`` (turned
        to the world ``orientation`` [qx, qy, qz, qw] if given) and the gaze on ``gaze_m`` (paper 000
        §7: the fine-tuner of the end of the locomotion), the arm out of ``hand_obstacles`` ((centre,
        radius) spheres [m]), with footsteps/plan's step region scaled by ``step_region_scale`` (None:
        its default), and walked unless ``check`` (given what was planned) says why not; what it
        decided (its final posture included), None when it found no steps or ``check`` refused them
        (reaching steps then if it must)."""
        if not self.config.last_steps:
            return None
        # Upright first: the walk is planned from the posture the robot will be in when it starts
        # (after a failed reach the chest leans toward the target; a walk planned from there and
        # played after straightening starts 0.25 rad away from the chest's position).
        self.body.straighten()
        try:
            decided = self.planners.last_steps(
                hand, target_m, gaze_m, hand_obstacles, orientation, step_region_scale, free_yaw=free_yaw
            )
        except (InfeasibleError, RequestTimeoutError) as exc:  # none found, or none within its budget
            self.progress(f"{what}: footsteps/plan found no steps ({exc.message}); reaching will step")
            return None
        refused = None if check is None else check(decided)
        if refused is not None:
            self.progress(f"{what}: {decided.found}; not taken: {refused}")
            return None
        if decided.walk is None:
            self.progress(f"{what}: {decided.found}: no step needed")
            return decided
        self.progress(f"{what}: {decided.found}; {decided.walk.describe()}")
        self.body.execute(decided.walk.q, what=what, allowed_contacts=allowed or [], progress=self.progress)
        return decided

    def _walk_nearer(self, name: str, point: np.ndarray, what: str) -> bool:
        """When footsteps/plan found no last steps to ``point`` [m] (world) and it lies farther than
        ``nearer_beyond_m`` from the mid-feet point: walk with navigation (checked against the map) to
        ``nearer_m`` short of it, facing it (or, when no such pose is free, in front of ``name``'s map
        box), rather than letting reaching, which does not know the map, walk there (fetch seed 13:
        a table seen 0.8 m nearer from 2 m than it was; footsteps/plan's 6 steps were refused by
        walking, reaching then walked 18 steps into the chair). True when it walked; the caller plans
        the last steps again from there."""
        x, y, _yaw = self.body.base_xy_yaw()
        to = np.asarray(point[:2], dtype=float) - (x, y)
        far = float(np.linalg.norm(to))
        if far <= self.config.nearer_beyond_m:
            return False
        self.body.straighten()
        self._make_room(f"room to walk nearer to {name}")
        u = to / far
        stop = np.asarray(point[:2], dtype=float) - u * self.config.nearer_m
        try:
            plan = self.planners.goto_pose(float(stop[0]), float(stop[1]), math.atan2(u[1], u[0]))
        except InfeasibleError as exc:
            self.progress(
                f"{what}: {far:.2f} m away; no walk to {self.config.nearer_m:.2f} m short of it "
                f"({exc.message})"
            )
            try:
                plan = self._goto_object(name, self.config.goto_distance_m)
            except InfeasibleError as again:
                self.progress(f"{what}: no walk nearer to {name} either ({again.message})")
                return False
        self.progress(f"{what}: {far:.2f} m away: walking nearer to {name} ({plan.describe()})")
        self.body.execute(plan.q, what=f"walk nearer to {name}", progress=self.progress)
        return True

    def _on_floor(self, name: str) -> bool:
        """Whether the object ``name`` as seen rests on the floor: its bottom (its centre less its radius
        as seen) within ``floor_margin_m`` of z = 0. Not when it floats higher on something the map does
        not hold (a table not seen yet, a footprint refused): that refusal is not final."""
        sighting = self.memory.sightings.get(name)
        if sighting is None:
            return False
        return float(sighting.position_m[2]) - sphere_radius(sighting) <= self.config.floor_margin_m

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

    def _carry_point(self, hand: str, pose: tuple[float, float, float] | None = None) -> np.ndarray:
        """In front of the chest, on the hand's side, where a held object is carried [m] (world), for the
        mid-feet ``pose`` (x [m], y [m], yaw [rad]; None: the robot's now)."""
        x, y, yaw = self.body.base_xy_yaw() if pose is None else pose
        forward, side, height = self.config.carry_m
        lateral = -side if hand == "right" else side
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([x + c * forward - s * lateral, y + s * forward + c * lateral, height])

    def _lift_and_carry(
        self,
        hand: str,
        allowed: list[str],
        what: str,
        *,
        up: np.ndarray | None = None,
        motions: tuple[str, str] = ("lift", "carry"),
    ) -> None:
        """Raise the hand to ``up`` [m] (world; None: ``lift_m`` straight above where it is), then bring
        it to the carry point (no stepping), the two timed as the config's ``motions`` (the grasp's
        "lift" and "carry"; the emptied hand after a put "withdraw" twice; a held object raised again
        after a put that touched nothing "raise" and "carry")."""
        if up is None:
            here = self.body.robot.grasp_position(self.body.q(), hand)
            up = here + np.array([0.0, 0.0, self.config.lift_m])
        lift, carry = motions
        self._arm_motion(hand, up, f"{what}: lift", allowed=allowed, motion=lift)
        self._arm_motion(hand, self._carry_point(hand), f"{what}: carry", allowed=allowed, motion=carry)

    def _in_the_way(self, target: str) -> dict[str, list[tuple[float, np.ndarray]]]:
        """What beside ``target`` on the map (balls seen, points felt: :meth:`_beside`) is in each hand's
        way from the robot's stance now (:func:`hand_in_the_way`); empty for a point."""
        if parse_point(target, 3, "reach target") is not None:
            return {}
        sighting = self.memory.get(target)
        x, y, _yaw = self.body.base_xy_yaw()
        c = self.config
        return hand_in_the_way(
            np.asarray(sighting.position_m, dtype=float),
            sphere_radius(sighting),
            (x, y),
            self._beside(target),
            c.hand_way_deg,
            c.hand_way_gap_m,
        )

    def do_grasp(self, step: Step) -> ActionReport:
        """Close the hand; ``not_grasped`` if nothing is held. Lifts what it holds and carries it."""
        hand = step.args[0]
        if hand == EITHER_HAND:
            if self.last_reach is None:
                raise InvalidRequestError("grasp: no hand has reached for anything yet; name the hand")
            hand = self.last_reach[0]  # the hand that reached
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
        """Open the hand; ``either`` (the console's "release it" naming no hand): the hand that holds
        something, else the one that reached last."""
        hand = step.args[0]
        if hand == EITHER_HAND:
            holding = sorted(self.memory.holding)
            if len(holding) > 1:
                raise InvalidRequestError("open: both hands hold something; name the hand to open")
            if holding:
                hand = holding[0]
            elif self.last_reach is not None:
                hand = self.last_reach[0]
            else:
                raise InvalidRequestError("open: no hand holds anything or has reached; name the hand")
        reply = self.body.gripper(hand, "open")
        self.memory.holding.pop(hand, None)
        released = f", released {reply.released}" if reply.released else ""
        return ActionReport(
            "open", step.args, message=f"{hand} hand open{released}", details={"released": reply.released}
        )
