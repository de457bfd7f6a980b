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
from services.walking.footsteps import FootstepLimits, SolePose, turn_in_place
from supervisor.body import Body
from supervisor.calls import ServiceCaller
from supervisor.memory import Memory
from supervisor.scene_map import obstacles

PLAN_TIMEOUT_S = 120.0
#: Largest yaw of one pair of turning steps [rad]: the opening foot's bound is pi/4 (footstep paper §5).
TURN_PER_PAIR_RAD = 0.98 * math.pi / 4
#: Double support between turning steps [s]: with walking's default 0.1 s the simulated robot fell in
#: about half of the 60-90 deg turns (tilting over during a weight transfer); 0.3 s turned every time.
TURN_DOUBLE_SUPPORT_S = 0.3


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
        #: Walk navigation's footsteps with walking/plan (longer double support) instead of its own
        #: whole-body trajectory: with the latter the simulated robot fell at the end of some walks.
        self.retime_walks = True

    # frames -------------------------------------------------------------------------------------------
    def _local(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``q`` moved so that the mid-feet point is at the world origin, and the (x, y) offset [m].

        Every plan is requested in this robot-centred frame (translation only) and moved back: the
        planners are translation invariant in principle, but walking's multibody ZMP check was not
        (a 2-step walk planned from x = 2.9 m failed with the ZMP 73 mm out at t = 0.005 s, the same
        walk from the origin passed), which made every walk after the first one fail.
        """
        x, y, _yaw = self.body.robot.mid_feet_pose(q)
        offset = np.array([x, y])
        local = np.array(q, dtype=float)
        local[:2] -= offset
        return local, offset

    @staticmethod
    def _world(Q: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """A trajectory planned in the local frame of :meth:`_local`, back in the world frame."""
        Q = np.array(Q, dtype=float)
        Q[:, :2] += offset
        return Q

    def _walk(
        self,
        request: walk_msg.PlanRequest,
        offset: np.ndarray,
        *,
        planner: str = "walking/plan",
        goal: list[float] | None = None,
        plan_s: float = 0.0,
    ) -> Plan:
        """``walking/plan`` of ``request`` (in the local frame), as a world-frame :class:`Plan`."""
        reply = self.bus.call(walk_msg.PLAN, request, PLAN_TIMEOUT_S)
        return Plan(
            q=self._world(reply.q, offset),
            dt_s=float(reply.dt_s),
            n_steps=len(reply.steps),
            planner=planner,
            goal=goal or [],
            plan_s=plan_s,
        )

    # navigation -----------------------------------------------------------------------------------------
    def _goto(self, **goal: object) -> Plan:
        q, offset = self._local(self.body.plan_q())
        local_obstacles = [
            msgspec.structs.replace(o, center=[o.center[0] - offset[0], o.center[1] - offset[1], o.center[2]])
            for o in obstacles(self.memory)
        ]
        request = nav_msg.GotoRequest(q_start=q, obstacles=local_obstacles, **goal)  # type: ignore[arg-type]
        reply = self.bus.call(nav_msg.GOTO, request, PLAN_TIMEOUT_S)
        x, y, theta = reply.goal
        goal_world = [x + offset[0], y + offset[1], theta]
        if not self.retime_walks:
            return Plan(
                q=self._world(reply.q, offset),
                dt_s=float(reply.dt_s),
                n_steps=len(reply.step_sides),
                planner="navigation/goto",
                goal=goal_world,
                plan_s=float(reply.timings_s.get("total_s", 0.0)),
            )
        # navigation's path and footsteps, walked by walking/plan with the longer double support that
        # keeps the simulated robot up (see TURN_DOUBLE_SUPPORT_S). A held object is carried by the arm
        # keeping its posture (walking's lowest level): a hand task in the walk frame made the planner
        # move the arms at up to 1.5x their speed limits.
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
            offset,
            planner="navigation/goto + walking/plan",
            goal=goal_world,
            plan_s=float(reply.timings_s.get("total_s", 0.0)),
        )

    def goto_object(self, name: str, distance_m: float) -> Plan:
        """Stand ``distance_m`` in front of ``name``'s face (as the map estimates it), facing it."""
        return self._goto(goal_object=name, goal_distance_m=distance_m)

    def goto_pose(self, x_m: float, y_m: float, yaw_rad: float) -> Plan:
        _q, offset = self._local(self.body.plan_q())
        return self._goto(goal_pose=[x_m - offset[0], y_m - offset[1], math.remainder(yaw_rad, 2 * math.pi)])

    # walking ----------------------------------------------------------------------------------------------
    def turn(self, angle_rad: float) -> Plan:
        """Turn on the spot by ``angle_rad`` (> 0: left): ``turn_in_place`` footsteps from the soles where
        they are now, planned by ``walking/plan``; a held object is carried (the arm keeps its posture,
        walking's lowest level)."""
        q, offset = self._local(self.body.plan_q())
        robot = self.body.robot
        soles = {}
        for side in ("left", "right"):
            T = robot.sole_pose(q, side)
            soles[side] = SolePose(
                float(T.translation[0]),
                float(T.translation[1]),
                math.atan2(T.rotation[1, 0], T.rotation[0, 0]),
            )
        n_pairs = max(1, math.ceil(abs(angle_rad) / TURN_PER_PAIR_RAD))
        sequence = turn_in_place(
            angle_rad,
            2 * n_pairs,
            left_start=soles["left"],
            right_start=soles["right"],
            sole_size_m=tuple(robot.sole_size_m),
            limits=FootstepLimits.from_robot(robot),
        )
        request = walk_msg.PlanRequest(
            steps=[
                walk_msg.Step(pose=[s.pose.x_m, s.pose.y_m, s.pose.yaw_rad], side=s.side)
                for s in sequence.steps
            ],
            model=robot.name,
            q_start=q,
            double_support_s=TURN_DOUBLE_SUPPORT_S,
        )
        return self._walk(request, offset)

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
        q, offset = self._local(self.body.plan_q())
        request = reach_msg.ReachRequest(
            hand=hand,
            target=[float(target_m[0] - offset[0]), float(target_m[1] - offset[1]), float(target_m[2])],
            q_start=q,
            orientation=orientation,
            gaze=gaze,
            allow_stepping=allow_stepping,
        )
        reply = self.bus.call(reach_msg.REACH, request, PLAN_TIMEOUT_S)
        return Plan(
            q=self._world(reply.q, offset),
            dt_s=float(reply.dt_s),
            n_steps=len(reply.footsteps),
            planner="reaching/reach",
            goal=[float(v) for v in target_m],
            plan_s=float(reply.planning_time_s),
        )

    def step_back(self, distance_m: float, *, step_m: float = 0.15) -> Plan:
        """Walk straight back by ``distance_m`` [m] (pairs of steps of at most ``step_m``): room to turn
        on the spot or to start a path away from an object."""
        q, offset = self._local(self.body.plan_q())
        robot = self.body.robot
        soles = {}
        for side in ("left", "right"):
            T = robot.sole_pose(q, side)
            soles[side] = (
                float(T.translation[0]),
                float(T.translation[1]),
                math.atan2(T.rotation[1, 0], T.rotation[0, 0]),
            )
        yaw = robot.mid_feet_pose(q)[2]
        n_pairs = max(1, math.ceil(distance_m / step_m))
        steps = []
        for k in range(1, n_pairs + 1):
            back = distance_m * k / n_pairs
            for side in ("right", "left"):
                x, y, sole_yaw = soles[side]
                steps.append(
                    walk_msg.Step(
                        pose=[x - back * math.cos(yaw), y - back * math.sin(yaw), sole_yaw], side=side
                    )
                )
        request = walk_msg.PlanRequest(
            steps=steps,
            model=robot.name,
            q_start=q,
            double_support_s=TURN_DOUBLE_SUPPORT_S,
        )
        return self._walk(request, offset)
