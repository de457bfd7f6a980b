"""Requests to the planners, from the robot's current state and the supervisor's map; plans back.

Every plan starts at the configuration ``sim/state`` reports now (the planners are stateless and
``sim/execute`` wants the first sample near the current joints). The planners:

* ``navigation/goto``: walk in front of an object (from the map of perception's sightings) or to a pose;
* ``walking/goal``: a short walk to a pose relative to the robot (or in the world), a turn on the spot, a
  step back: the walking planner makes the footsteps within the robot's bounds and checks them against
  the map's boxes;
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
from supervisor.body import Body
from supervisor.calls import ServiceCaller
from supervisor.memory import Memory
from supervisor.scene_map import obstacles

PLAN_TIMEOUT_S = 120.0
#: Double support between steps of navigation's path walked by ``walking/plan`` [s]: with walking's
#: former default 0.1 s the simulated robot fell in about half of the 60-90 deg turns; 0.3 s held.
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
        detour (see ``SHORT_WALK_M``) and ``walking/goal`` finds the line clear of the map's boxes; None
        otherwise (navigation's path is walked)."""
        x0, y0, _yaw = self.body.robot.mid_feet_pose(q)
        straight_m = math.hypot(goal[0] - x0, goal[1] - y0)
        if straight_m > SHORT_WALK_M or path_m <= DETOUR_FACTOR * straight_m + DETOUR_SLACK_M:
            return None
        try:
            return self.walk_goal(
                walk_msg.GoalRequest(q_start=q, kind="pose", pose=list(goal), frame="world"),
                planner=f"walking/goal, straight ({path_m:.1f} m path)",
            )
        except InfeasibleError:  # blocked by the map, or out of the bounds: navigation's way
            return None

    def walk_goal(self, request: walk_msg.GoalRequest, *, planner: str = "walking/goal") -> Plan:
        """``walking/goal`` of ``request`` with the map's boxes as its obstacles, as a :class:`Plan`."""
        request = msgspec.structs.replace(
            request, model=self.body.robot.name, obstacles=obstacles(self.memory)
        )
        reply = self.bus.call(walk_msg.GOAL, request, PLAN_TIMEOUT_S)
        goal = list(request.pose) if request.kind == "pose" else [request.angle_rad]
        return Plan(
            q=np.asarray(reply.q, dtype=float),
            dt_s=float(reply.dt_s),
            n_steps=len(reply.steps),
            planner=planner,
            goal=goal,
        )

    def walk(self, forward_m: float, left_m: float, yaw_rad: float) -> Plan:
        """Walk by (forward, left) [m] and turn by ``yaw_rad`` relative to the robot's stance now (the
        mid-feet frame), checked against the map (``walking/goal``)."""
        return self.walk_goal(
            walk_msg.GoalRequest(q_start=self.body.plan_q(), kind="pose", pose=[forward_m, left_m, yaw_rad])
        )

    def goto_object(self, name: str, distance_m: float) -> Plan:
        """Stand ``distance_m`` in front of ``name``'s face (as the map estimates it), facing it."""
        return self._goto(goal_object=name, goal_distance_m=distance_m)

    def goto_pose(self, x_m: float, y_m: float, yaw_rad: float) -> Plan:
        return self._goto(goal_pose=[x_m, y_m, math.remainder(yaw_rad, 2 * math.pi)])

    # walking ----------------------------------------------------------------------------------------------
    def turn(self, angle_rad: float) -> Plan:
        """Turn on the spot by ``angle_rad`` (> 0: left) with ``walking/goal`` (a staggered stance, as after
        a reaching step, is squared up first; no box of the map nearer than its turning room); a held
        object is carried (the arm keeps its posture, walking's lowest level)."""
        return self.walk_goal(
            walk_msg.GoalRequest(q_start=self.body.plan_q(), kind="turn", angle_rad=angle_rad)
        )

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
        """Walk straight back by ``distance_m`` [m] (``walking/goal``: a staggered stance is evened out
        on the way, steps within the bounds, checked against the map): room to turn on the spot or to
        start a path away from an object."""
        return self.walk(-distance_m, 0.0, 0.0)
