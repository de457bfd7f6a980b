"""Requests to the planners, from the robot's current state and the supervisor's map; plans back.

Every plan starts at the configuration ``sim/state`` reports now (the planners are stateless and
``sim/execute`` wants the first sample near the current joints). The planners:

* ``navigation/goto``: walk in front of an object (from the map of perception's sightings) or to a pose;
* ``walking/plan``: a footstep sequence (a turn on the spot from ``turn_in_place``) to a whole body walk;
* ``reaching/reach``: whole-body reaching with support polygon reshaping (stepping when needed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import msgspec
import numpy as np

from services.bus.schemas import navigation as nav_msg
from services.bus.schemas import reaching as reach_msg
from services.bus.schemas import walking as walk_msg
from services.errors import InfeasibleError
from services.walking.footsteps import (
    Footstep,
    FootstepLimits,
    SolePose,
    fit_to_bounds,
    footsteps_along_mid_poses,
    turn_in_place,
)
from supervisor.body import Body
from supervisor.calls import ServiceCaller
from supervisor.memory import Memory
from supervisor.scene_map import boxes, distance_to_box, obstacles

PLAN_TIMEOUT_S = 120.0
#: Largest yaw of one pair of turning steps [rad]: the opening foot's bound is pi/4 (footstep paper §5).
TURN_PER_PAIR_RAD = 0.98 * math.pi / 4
#: Double support between turning steps [s]: with walking's default 0.1 s the simulated robot fell in
#: about half of the 60-90 deg turns (tilting over during a weight transfer); 0.3 s turned every time.
TURN_DOUBLE_SUPPORT_S = 0.3
#: A goal nearer than this [m] whose car-like path is longer than ``DETOUR_FACTOR`` times the straight
#: line plus ``DETOUR_SLACK_M`` is walked straight (sideways and turning as needed): navigation's
#: forward-preferring Dubins curves loop around to shift the robot sideways by half a metre.
SHORT_WALK_M = 1.5
DETOUR_FACTOR = 1.5
DETOUR_SLACK_M = 0.5
#: When navigation finds no path in its default budget: the second search's budget [s] and turning
#: radius [m] (the first one's is navigation's default, 0.5 m).
RETRY_BUDGET_S = 4.0
RETRY_TURNING_RADIUS_M = 0.3
#: The straight walk keeps the base this far from every mapped obstacle [m] (or as far as its start or
#: its goal is).
SHORT_WALK_CLEARANCE_M = 0.35


@dataclass(frozen=True)
class Plan:
    """A whole-body trajectory to execute: ``q`` (N, nq) every ``dt_s``; ``n_steps`` footsteps taken;
    ``goal`` what the planner aimed at; ``planner`` who planned it; ``plan_s`` its planning time [s]."""

    q: np.ndarray = field(repr=False)
    dt_s: float
    n_steps: int
    planner: str
    goal: list[float] = field(default_factory=list)
    plan_s: float = 0.0

    @property
    def duration_s(self) -> float:
        return (self.q.shape[0] - 1) * self.dt_s

    def describe(self) -> str:
        steps = f", {self.n_steps} steps" if self.n_steps else ""
        return f"{self.duration_s:.1f} s motion{steps} ({self.planner})"


class Planners:
    """Builds planner requests from the robot's state and the map; returns :class:`Plan` objects."""

    def __init__(self, bus: ServiceCaller, body: Body, memory: Memory) -> None:
        self.bus = bus
        self.body = body
        self.memory = memory

    def _walk(
        self,
        request: walk_msg.PlanRequest,
        *,
        planner: str = "walking/plan",
        goal: list[float] | None = None,
        plan_s: float = 0.0,
    ) -> Plan:
        """``walking/plan`` of ``request`` as a :class:`Plan`."""
        reply = self.bus.call(walk_msg.PLAN, request, PLAN_TIMEOUT_S)
        return Plan(
            q=np.asarray(reply.q, dtype=float),
            dt_s=float(reply.dt_s),
            n_steps=len(reply.steps),
            planner=planner,
            goal=goal or [],
            plan_s=plan_s,
        )

    # navigation -----------------------------------------------------------------------------------------
    def _goto(self, **goal: object) -> Plan:
        q = self.body.plan_q()
        request = nav_msg.GotoRequest(q_start=q, obstacles=obstacles(self.memory), **goal)  # type: ignore[arg-type]
        try:
            reply = self.bus.call(nav_msg.GOTO, request, PLAN_TIMEOUT_S)
        except InfeasibleError as exc:
            if exc.details.get("reason") != "no_path_within_budget":
                raise
            # No car-like path in the budget: a near goal is walked straight to if the line is clear,
            # else navigation searches again, longer and with the tighter turns a humanoid can make.
            for tried in exc.details.get("goals", []):
                straight = self._short_walk(q, [float(v) for v in tried], math.inf)
                if straight is not None:
                    return straight
            request = msgspec.structs.replace(
                request, time_budget_s=RETRY_BUDGET_S, turning_radius_m=RETRY_TURNING_RADIUS_M
            )
            reply = self.bus.call(nav_msg.GOTO, request, PLAN_TIMEOUT_S)
        goal_reached = [float(v) for v in reply.goal]
        path_m = float(np.asarray(reply.path_s_m)[-1]) if len(reply.path_s_m) else 0.0
        straight = self._short_walk(q, goal_reached, path_m)
        if straight is not None:
            return straight
        # navigation's path and footsteps, walked by walking/plan with the longer double support that
        # keeps the simulated robot up (see TURN_DOUBLE_SUPPORT_S), not navigation's own whole-body walk:
        # with it the fetch benchmark failed more often (one walk failed a joint speed check). A held
        # object is carried by the arm keeping its posture (walking's lowest level): a hand task in the
        # walk frame made the planner move the arms at up to 1.5x their speed limits.
        walk = walk_msg.PlanRequest(
            steps=[
                walk_msg.Step(pose=[float(v) for v in pose], side=side)
                for side, pose in zip(reply.step_sides, np.asarray(reply.step_poses), strict=True)
            ],
            model=self.body.robot.name,
            q_start=q,
            left_start=list(reply.left_start),
            right_start=list(reply.right_start),
            double_support_s=TURN_DOUBLE_SUPPORT_S,
        )
        return self._walk(
            walk,
            planner="navigation/goto + walking/plan",
            goal=goal_reached,
            plan_s=float(reply.timings_s.get("total_s", 0.0)),
        )

    def _short_walk(self, q: np.ndarray, goal: list[float], path_m: float) -> Plan | None:
        """The straight walk to a near ``goal`` (x, y, yaw) when navigation's path of ``path_m`` [m] is a
        detour (see ``SHORT_WALK_M``) and the straight line keeps clear of the mapped obstacles; None
        otherwise (navigation's path is walked)."""
        x0, y0, _yaw = self.body.robot.mid_feet_pose(q)
        straight_m = math.hypot(goal[0] - x0, goal[1] - y0)
        if straight_m > SHORT_WALK_M or path_m <= DETOUR_FACTOR * straight_m + DETOUR_SLACK_M:
            return None
        for box in boxes(self.memory):
            ends = (distance_to_box(box, goal[0], goal[1]), distance_to_box(box, x0, y0))
            need = min(SHORT_WALK_CLEARANCE_M, *ends) - 0.02
            for t in np.linspace(0.0, 1.0, max(2, math.ceil(straight_m / 0.05) + 1)):
                x, y = x0 + t * (goal[0] - x0), y0 + t * (goal[1] - y0)
                if distance_to_box(box, x, y) < need:
                    return None
        try:
            return self.walk_to(
                goal[0], goal[1], goal[2], planner=f"walking/plan, straight ({path_m:.1f} m path)", q=q
            )
        except InfeasibleError:  # e.g. turning much while side-stepping crosses the feet: navigation's way
            return None

    def walk_to(
        self,
        x_m: float,
        y_m: float,
        yaw_rad: float,
        *,
        planner: str = "walking/plan",
        q: np.ndarray | None = None,
    ) -> Plan:
        """Walk straight to the base pose (x, y [m], yaw [rad]) of the mid-feet frame, stepping forward,
        sideways and turning together (or, when that crosses the feet, walking there and then turning on
        the spot), steps as long as the robot's footstep bounds allow, the feet side by side at the end.
        No obstacle check: for short walks on free floor. ``q``: the configuration to start from
        (default: :meth:`Body.plan_q`)."""
        q = self.body.plan_q() if q is None else q
        robot = self.body.robot
        soles = self._soles(q)
        x0, y0, yaw0 = robot.mid_feet_pose(q)
        c, s = math.cos(yaw0), math.sin(yaw0)
        dx, dy = c * (x_m - x0) + s * (y_m - y0), -s * (x_m - x0) + c * (y_m - y0)
        dyaw = math.remainder(yaw_rad - yaw0, 2.0 * math.pi)
        first = "left" if (dy if abs(dy) > 0.02 else dyaw) > 0 else "right"  # lead with the foot on the way

        def fractions(n: int) -> list[float]:  # n steps, the last one bringing the feet side by side
            return [min(k, n - 1) / (n - 1) for k in range(1, n + 1)]

        def along(poses: list[tuple[float, float, float]]):
            left, right = soles["left"], soles["right"]
            return footsteps_along_mid_poses(poses, first, left_start=left, right_start=right)

        def together(n: int):
            return along([(f * dx, f * dy, f * dyaw) for f in fractions(n)])

        def turn_last(n: int):  # walk there, then turn on the spot: no turning while side-stepping
            m = max(2, n // 2)
            walk = [(f * dx, f * dy, 0.0) for f in fractions(m)]
            return along(walk + [(dx, dy, f * dyaw) for f in fractions(max(2, n - m))])

        limits = FootstepLimits.from_robot(robot)
        try:
            sequence = fit_to_bounds(together, 2, limits, "a straight walk")
        except InfeasibleError:  # turning while stepping sideways can cross the feet
            sequence = fit_to_bounds(turn_last, 4, limits, "a straight walk, then a turn")
        request = walk_msg.PlanRequest(
            steps=[
                walk_msg.Step(pose=[st.pose.x_m, st.pose.y_m, st.pose.yaw_rad], side=st.side)
                for st in sequence.steps
            ],
            model=robot.name,
            q_start=q,
            double_support_s=TURN_DOUBLE_SUPPORT_S,
        )
        return self._walk(request, planner=planner, goal=[x_m, y_m, yaw_rad])

    def goto_object(self, name: str, distance_m: float) -> Plan:
        """Stand ``distance_m`` in front of ``name``'s face (as the map estimates it), facing it."""
        return self._goto(goal_object=name, goal_distance_m=distance_m)

    def goto_pose(self, x_m: float, y_m: float, yaw_rad: float) -> Plan:
        return self._goto(goal_pose=[x_m, y_m, math.remainder(yaw_rad, 2 * math.pi)])

    # walking ----------------------------------------------------------------------------------------------
    def turn(self, angle_rad: float) -> Plan:
        """Turn on the spot by ``angle_rad`` (> 0: left): ``turn_in_place`` footsteps from the soles where
        they are now (squared up first when one foot is ahead of the other, as after a reaching step),
        planned by ``walking/plan``; a held object is carried (the arm keeps its posture, walking's
        lowest level)."""
        q = self.body.plan_q()
        robot = self.body.robot
        soles = self._soles(q)
        limits = FootstepLimits.from_robot(robot)
        first = square_up(soles, limits)
        if first is not None:
            soles[first.side] = first.pose
        n_pairs = max(1, math.ceil(abs(angle_rad) / TURN_PER_PAIR_RAD))
        sequence = turn_in_place(
            angle_rad,
            2 * n_pairs,
            left_start=soles["left"],
            right_start=soles["right"],
            sole_size_m=tuple(robot.sole_size_m),
            limits=limits,
        )
        steps = [*([first] if first is not None else []), *sequence.steps]
        request = walk_msg.PlanRequest(
            steps=[walk_msg.Step(pose=[s.pose.x_m, s.pose.y_m, s.pose.yaw_rad], side=s.side) for s in steps],
            model=robot.name,
            q_start=q,
            double_support_s=TURN_DOUBLE_SUPPORT_S,
        )
        return self._walk(request)

    # reaching -------------------------------------------------------------------------------------------
    def reach(
        self,
        hand: str,
        target_m: np.ndarray,
        *,
        yaw_rad: float | None = None,
        allow_stepping: bool = True,
        gaze: bool = True,
    ) -> Plan:
        """``reaching/reach``: the ``hand`` grasp frame to ``target_m`` [m], from above: the grasp frame
        upright (fingers down, jaws closing sideways) turned by ``yaw_rad`` (None: position only)."""
        orientation = None
        if yaw_rad is not None:
            orientation = [0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0)]
        q = self.body.plan_q()
        request = reach_msg.ReachRequest(
            hand=hand,
            target=[float(v) for v in target_m],
            q_start=q,
            orientation=orientation,
            gaze=gaze,
            allow_stepping=allow_stepping,
        )
        reply = self.bus.call(reach_msg.REACH, request, PLAN_TIMEOUT_S)
        return Plan(
            q=np.asarray(reply.q, dtype=float),
            dt_s=float(reply.dt_s),
            n_steps=len(reply.footsteps),
            planner="reaching/reach",
            goal=[float(v) for v in target_m],
            plan_s=float(reply.planning_time_s),
        )

    def step_back(self, distance_m: float) -> Plan:
        """Walk straight back by ``distance_m`` [m] (:meth:`walk_to`: a staggered stance is evened out on
        the way, steps within the bounds): room to turn on the spot or to start a path away from an
        object."""
        q = self.body.plan_q()
        x, y, yaw = self.body.robot.mid_feet_pose(q)
        return self.walk_to(x - distance_m * math.cos(yaw), y - distance_m * math.sin(yaw), yaw, q=q)

    def _soles(self, q: np.ndarray) -> dict[str, SolePose]:
        """The sole poses (x, y, yaw) on the ground at ``q``."""
        soles = {}
        for side in ("left", "right"):
            T = self.body.robot.sole_pose(q, side)
            yaw = math.atan2(T.rotation[1, 0], T.rotation[0, 0])
            soles[side] = SolePose(float(T.translation[0]), float(T.translation[1]), yaw)
        return soles


#: Feet further apart than this along the heading [m], or turned apart by more [rad], are squared up
#: before a turn on the spot (whose steps are made for a square stance).
SQUARE_DX_M = 0.02
SQUARE_DYAW_RAD = math.radians(3.0)


def square_up(soles: dict[str, SolePose], limits: FootstepLimits) -> Footstep | None:
    """The step that brings the rear foot beside the front one (parallel, at their current lateral
    distance kept within the bounds), or None when the stance is already square.

    After a reaching step one foot is up to 0.22 m ahead, while ``turn_in_place`` makes its steps for
    a square stance, turning about its mid-feet point."""
    yaw = math.atan2(
        math.sin(soles["left"].yaw_rad) + math.sin(soles["right"].yaw_rad),
        math.cos(soles["left"].yaw_rad) + math.cos(soles["right"].yaw_rad),
    )
    c, s = math.cos(yaw), math.sin(yaw)
    ahead = {side: c * p.x_m + s * p.y_m for side, p in soles.items()}
    dyaw = abs(math.remainder(soles["left"].yaw_rad - soles["right"].yaw_rad, 2 * math.pi))
    if abs(ahead["left"] - ahead["right"]) <= SQUARE_DX_M and dyaw <= SQUARE_DYAW_RAD:
        return None
    front = max(soles, key=lambda side: ahead[side])
    rear = "left" if front == "right" else "right"
    f = soles[front]
    cf, sf = math.cos(f.yaw_rad), math.sin(f.yaw_rad)
    dx, dy = soles[rear].x_m - f.x_m, soles[rear].y_m - f.y_m
    lateral = abs(-sf * dx + cf * dy)  # the rear foot's distance to the side in the front foot's frame
    lateral = min(max(lateral, limits.dy_min_m + 0.02), limits.dy_max_m - 0.02)
    sign = 1.0 if rear == "left" else -1.0  # the left foot is on the +y side
    pose = SolePose(f.x_m - sign * lateral * sf, f.y_m + sign * lateral * cf, f.yaw_rad)
    return Footstep(side=rear, pose=pose)  # type: ignore[arg-type]
