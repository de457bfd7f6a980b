"""Requests to the planners, from the robot's current state and the supervisor's map; plans back.

Every plan starts at the configuration ``sim/state`` reports now (the planners are stateless and
``sim/execute`` wants the first sample near the current joints). The planners:

* ``navigation/goto``: walk in front of an object (from the map of perception's sightings) or to a pose;
* ``walking/goal``: a short walk to a pose relative to the robot (or in the world), a turn on the spot, a
  step back: the walking planner makes the footsteps within the robot's bounds and checks them against
  the map's boxes;
* ``footsteps/plan``: the last steps before a reach or a put (footstep planning as inverse kinematics,
  the paper's "fine-tuner" that "reshapes the last few steps precisely according to the tasks"),
  walked by ``walking/plan``;
* ``reaching/reach``: whole-body reaching with support polygon reshaping (stepping when needed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import msgspec
import numpy as np
from scipy.spatial.transform import Rotation

from services.bus.schemas import footsteps as fs_msg
from services.bus.schemas import navigation as nav_msg
from services.bus.schemas import reaching as reach_msg
from services.bus.schemas import walking as walk_msg
from services.bus.schemas.common import Sphere
from services.errors import InfeasibleError
from supervisor.body import Body
from supervisor.calls import ServiceCaller
from supervisor.config import SupervisorConfig
from supervisor.memory import Memory
from supervisor.scene_map import obstacles


def spheres(pairs: list[tuple[np.ndarray, float]] | None) -> list[Sphere]:
    """(centre [m] world, radius [m]) pairs as the planners' ``hand_obstacles`` spheres."""
    return [Sphere(center=[float(v) for v in centre], radius=float(radius)) for centre, radius in pairs or []]


@dataclass(frozen=True)
class LastSteps:
    """What ``footsteps/plan`` decided for the end of an approach: the walk of its footsteps (None: no
    step needed), a line saying what it found, and its final whole-body posture ``q_final`` (the robot
    on the last footprints with the hand at the target, paper 000 §7) with that posture's grasp-frame
    orientation ``hand_quat`` ([qx, qy, qz, qw], world)."""

    walk: Plan | None
    found: str
    q_final: np.ndarray = field(repr=False)
    hand_quat: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class Plan:
    """A whole-body trajectory to execute: ``q`` (N, nq) every ``dt_s``; ``n_steps`` footsteps taken;
    ``goal`` what the planner aimed at; ``planner`` who planned it."""

    q: np.ndarray = field(repr=False)
    dt_s: float
    n_steps: int
    planner: str
    goal: list[float] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return (self.q.shape[0] - 1) * self.dt_s

    def describe(self) -> str:
        steps = f", {self.n_steps} steps" if self.n_steps else ""
        return f"{self.duration_s:.1f} s motion{steps} ({self.planner})"


class Planners:
    """Builds planner requests from the robot's state and the map; returns :class:`Plan` objects."""

    def __init__(
        self, bus: ServiceCaller, body: Body, memory: Memory, config: SupervisorConfig | None = None
    ) -> None:
        self.bus = bus
        self.body = body
        self.memory = memory
        self.config = config or SupervisorConfig()

    # navigation -----------------------------------------------------------------------------------------
    def _goto(self, **goal: object) -> Plan:
        """``navigation/goto`` from the configuration to plan from, with the map's boxes: the reply's
        whole-body motion is executed as navigation's stage 2 checked and reshaped it (each walk planned
        once). A near goal whose car-like path is a detour is walked straight by navigation itself."""
        q = self.body.plan_q()
        request = nav_msg.GotoRequest(
            q_start=q,
            obstacles=obstacles(self.memory),
            double_support_s=self.config.walk_double_support_s,
            **goal,  # type: ignore[arg-type]
        )
        try:
            reply = self.bus.call(nav_msg.GOTO, request, self.config.plan_timeout_s)
        except InfeasibleError as exc:
            if exc.details.get("reason") != nav_msg.REASON_NO_PATH_WITHIN_BUDGET:
                raise
            # No car-like path in the budget (and no straight walk): search again, longer and with the
            # tighter turns a humanoid can make.
            request = msgspec.structs.replace(
                request,
                time_budget_s=self.config.retry_budget_s,
                turning_radius_m=self.config.retry_turning_radius_m,
            )
            reply = self.bus.call(nav_msg.GOTO, request, self.config.plan_timeout_s)
        path_m = float(np.asarray(reply.path_s_m)[-1]) if len(reply.path_s_m) else 0.0
        how = "straight" if reply.path_curve == "straight" else f"{path_m:.1f} m {reply.path_curve} path"
        return Plan(
            q=np.asarray(reply.q, dtype=float),
            dt_s=float(reply.dt_s),
            n_steps=len(reply.step_sides),
            planner=f"navigation/goto, {how}",
            goal=[float(v) for v in reply.goal],
        )

    def walk_goal(self, request: walk_msg.GoalRequest) -> Plan:
        """``walking/goal`` of ``request`` with the map's boxes as its obstacles, as a :class:`Plan`."""
        request = msgspec.structs.replace(
            request,
            model=self.body.robot.name,
            obstacles=obstacles(self.memory),
            double_support_s=self.config.walk_double_support_s,
        )
        reply = self.bus.call(walk_msg.GOAL, request, self.config.plan_timeout_s)
        goal = {"pose": list(request.pose), "turn": [request.angle_rad]}.get(request.kind, [])
        return Plan(
            q=np.asarray(reply.q, dtype=float),
            dt_s=float(reply.dt_s),
            n_steps=len(reply.steps),
            planner="walking/goal",
            goal=goal,
        )

    def walk(self, forward_m: float, left_m: float, yaw_rad: float) -> Plan:
        """Walk by (forward, left) [m] and turn by ``yaw_rad`` relative to the robot's stance now (the
        mid-feet frame), checked against the map (``walking/goal``)."""
        return self.walk_goal(
            walk_msg.GoalRequest(q_start=self.body.plan_q(), kind="pose", pose=[forward_m, left_m, yaw_rad])
        )

    def square(self) -> Plan:
        """Square the stance: the rear foot stepped beside the front one (``walking/goal`` ``kind:
        square``, one step checked against the map); ``invalid_request`` when it is square already."""
        return self.walk_goal(walk_msg.GoalRequest(q_start=self.body.plan_q(), kind="square"))

    def goto_object(self, name: str, distance_m: float) -> Plan:
        """Stand ``distance_m`` in front of ``name``'s face (as the map estimates it), facing it."""
        return self._goto(goal_object=name, goal_distance_m=distance_m)

    def goto_pose(self, x_m: float, y_m: float, yaw_rad: float) -> Plan:
        return self._goto(goal_pose=[x_m, y_m, math.remainder(yaw_rad, 2 * math.pi)])

    # walking ----------------------------------------------------------------------------------------------
    def turn(self, angle_rad: float, *, back_m: float = 0.0) -> Plan:
        """Turn on the spot by ``angle_rad`` (> 0: left) with ``walking/goal`` (a staggered stance, as after
        a reaching step, is squared up first; no box of the map nearer than its turning room), after
        stepping straight back by ``back_m`` [m] in the same walk when > 0; a held object is carried
        (the arm keeps its posture, walking's lowest level)."""
        return self.walk_goal(
            walk_msg.GoalRequest(q_start=self.body.plan_q(), kind="turn", angle_rad=angle_rad, back_m=back_m)
        )

    # footsteps ----------------------------------------------------------------------------------------
    def last_steps(
        self,
        hand: str,
        target_m: np.ndarray,
        gaze_m: np.ndarray,
        hand_obstacles: list[tuple[np.ndarray, float]] | None = None,
        orientation: list[float] | None = None,
        step_region_scale: float | None = None,
        free_yaw: bool = False,
    ) -> LastSteps:
        """``footsteps/plan`` for the last steps before the ``hand`` reaches ``target_m`` [m] (tasks, by
        priority: the hand at the target, the gaze on ``gaze_m``, the rest posture; the map's boxes, which
        no footprint may enter; ``hand_obstacles``, (centre [m] world, radius [m]) spheres the arm keeps
        out of; ``orientation``, the hand's world orientation [qx, qy, qz, qw] as a task below the
        reach (with ``free_yaw`` only its tilt, e.g. fingers down: the planner turns the jaws clear of
        ``hand_obstacles``, and ``LastSteps.hand_quat`` has the yaw it chose);
        ``step_region_scale``, footsteps/plan's option (None: its default); paper 000 §7), then
        ``walking/plan`` of its footsteps. Returns the
        walk (None when no step is needed), what the planner found and its final posture with the
        hand's orientation in it (:class:`LastSteps`). Raises the planners' typed errors
        (``infeasible`` when the tasks cannot be met)."""
        q = self.body.plan_q()
        c = self.config
        orient = (
            []
            if orientation is None
            else [fs_msg.Task(kind="orient", orientation=orientation, hand=hand, free_yaw=free_yaw)]
        )
        options = None if step_region_scale is None else fs_msg.Options(step_region_scale=step_region_scale)
        request = fs_msg.PlanRequest(
            tasks=[
                fs_msg.Task(kind="reach", target=[float(v) for v in target_m], hand=hand),
                *orient,
                fs_msg.Task(kind="gaze", target=[float(v) for v in gaze_m]),
                fs_msg.Task(kind="posture"),
            ],
            model=self.body.robot.name,
            q_start=q,
            boxes=obstacles(self.memory),  # the footstep service covers each box by disks (paper 000 §4.1)
            hand_obstacles=spheres(hand_obstacles),
            max_steps=c.last_steps_max,
            time_budget_s=c.last_steps_budget_s,
            options=options,
        )
        reply = self.bus.call(fs_msg.PLAN, request, c.plan_timeout_s)
        found = (
            f"footsteps/plan: {len(reply.footsteps)} step(s) ({reply.front_foot} foot in front), "
            f"{reply.iterations} iterations in {reply.solve_time_s:.1f} s"
        )
        q_final = np.asarray(reply.q_final, dtype=float)
        robot = self.body.robot
        hand_rotation = robot.frame_pose(q_final, robot.grasp_frame(hand)).rotation
        hand_quat = [float(v) for v in Rotation.from_matrix(hand_rotation).as_quat()]
        if not reply.footsteps:
            return LastSteps(None, found, q_final, hand_quat)
        walk = walk_msg.PlanRequest(
            steps=[walk_msg.Step(pose=[f.x, f.y, f.yaw], side=f.side) for f in reply.footsteps],
            model=self.body.robot.name,
            q_start=q,
            left_start=list(reply.left_start),
            right_start=list(reply.right_start),
            double_support_s=c.walk_double_support_s,
        )
        try:
            walked = self.bus.call(walk_msg.PLAN, walk, c.plan_timeout_s)
        except InfeasibleError as exc:
            steps = ", ".join(
                f"{f.side} ({f.x:.2f}, {f.y:.2f}, {math.degrees(f.yaw):.0f} deg)" for f in reply.footsteps
            )
            raise InfeasibleError(f"walking/plan of {found} [{steps}]: {exc.message}", exc.details) from exc
        plan = Plan(
            q=np.asarray(walked.q, dtype=float),
            dt_s=float(walked.dt_s),
            n_steps=len(walked.steps),
            planner="footsteps/plan + walking/plan",
            goal=[float(v) for v in target_m],
        )
        return LastSteps(plan, found, q_final, hand_quat)

    # reaching -------------------------------------------------------------------------------------------
    def reach(
        self,
        hand: str,
        target_m: np.ndarray,
        *,
        yaw_rad: float | None = None,
        allow_stepping: bool = True,
        gaze: bool = True,
        orientation: list[float] | None = None,
        ee_error_threshold_m: float | None = None,
        q_start: np.ndarray | None = None,
        posture: np.ndarray | None = None,
        timing: dict[str, float] | None = None,
        hand_obstacles: list[tuple[np.ndarray, float]] | None = None,
    ) -> Plan:
        """``reaching/reach``: the ``hand`` grasp frame to ``target_m`` [m], from above: the grasp frame
        upright (fingers down, jaws closing sideways) turned by ``yaw_rad`` (None: position only), or
        at ``orientation`` ([qx, qy, qz, qw] in the world) when given; ``ee_error_threshold_m``: the
        lag of the hand behind its reference [m] reaching accepts (None: its default); ``q_start``: the
        configuration to plan from, standing (None: the robot's now); ``posture``: the whole-body posture
        (nq,) the motion goes to with the hand (footsteps/plan's final posture), None: reaching's own;
        ``timing``: the request's timing fields (``SupervisorConfig.arm_timing``; None or empty:
        reaching's default); ``hand_obstacles``: (centre [m] world, radius [m]) spheres the whole arm,
        gripper and wrist included, keeps its clearance from over the motion (a ball beside the one to
        grasp; the gripper not from the one the target lies in or above; reaching refuses a motion
        that cannot: ``infeasible``, ``details.reason`` ``hand_obstacle``)."""
        if orientation is None and yaw_rad is not None:
            orientation = [0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0)]
        q = self.body.plan_q() if q_start is None else q_start
        request = reach_msg.ReachRequest(
            hand=hand,
            target=[float(v) for v in target_m],
            q_start=q,
            orientation=orientation,
            gaze=gaze,
            allow_stepping=allow_stepping,
            ee_error_threshold_m=ee_error_threshold_m,
            posture=None if posture is None else np.ascontiguousarray(posture, dtype=float),
            hand_obstacles=spheres(hand_obstacles),
            **(timing or {}),
        )
        reply = self.bus.call(reach_msg.REACH, request, self.config.plan_timeout_s)
        return Plan(
            q=np.asarray(reply.q, dtype=float),
            dt_s=float(reply.dt_s),
            n_steps=len(reply.footsteps),
            planner="reaching/reach",
            goal=[float(v) for v in target_m],
        )

    def step_back(self, distance_m: float) -> Plan:
        """Walk straight back by ``distance_m`` [m] (``walking/goal``: a staggered stance is evened out
        on the way, steps within the bounds, checked against the map): room to turn on the spot or to
        start a path away from an object."""
        return self.walk(-distance_m, 0.0, 0.0)
