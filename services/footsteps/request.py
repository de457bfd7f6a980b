"""Request and result of the footstep planner (plain frozen dataclasses, mapped 1:1 by the bus adapter).

Units: metres, radians, seconds; world frame z up, ground z = 0. Configurations are in the pinocchio
order of ``services.model.load_robot(robot).model`` (free-flyer [x, y, z, qx, qy, qz, qw] in the world,
then the actuated joints).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from services.errors import InvalidRequestError
from services.ik.hand_obstacles import SphereObstacle, check_spheres
from services.walking.footsteps import Footstep, FootstepSequence, SolePose

TaskKind = Literal["reach", "gaze", "posture", "orient"]
TASK_KINDS: tuple[str, ...] = ("reach", "gaze", "posture", "orient")
FOOT_CHOICES: tuple[str, ...] = ("auto", "left", "right")

# Default task tolerance (value under which the task is "solved", eqs. 5-6) and eq. (15)'s minimum
# value decrease per iteration epsilon_i, per task kind: [m] for reach and gaze (OG x OB is in m for a
# unit optical axis), [rad] (norm over the joints) for the posture, [rad] (rotation angle) for orient.
# The posture is by default an *objective* (infinite tolerance): never required for success, never
# "solved", so Algorithm 1 keeps adding steps for it while a step helps (section 4.3, Fig. 10).
DEFAULT_TOLERANCE = {"reach": 2e-3, "gaze": 5e-3, "posture": math.inf, "orient": 0.05}
DEFAULT_EPSILON = {"reach": 5e-3, "gaze": 5e-3, "posture": 0.05, "orient": 0.02}


@dataclass(frozen=True)
class FootstepTask:
    """One desired task (section 4): ``reach`` puts the ``hand`` grasp frame at ``target_m``; ``gaze``
    keeps the gaze axis through ``target_m`` (OG x OB = 0, section 4.3); ``posture`` is eq. (14),
    q - q_rest = 0 over the actuated joints (``q_rest``: a full robot configuration, default the
    half-sitting); ``orient`` turns the ``hand`` grasp frame to the world ``orientation`` [qx, qy, qz,
    qw] (a grasp's wrist yaw, fingers down, chosen clear of a neighbouring object), log3 error [rad];
    with ``free_yaw`` only its tilt (the rotations about the horizontal axes: e.g. fingers down), the yaw
    about the vertical left to the IK: the gripper's rows against ``hand_obstacles`` (level 0) turn
    the jaws clear of a neighbour, and the chosen yaw is ``q_final``'s. ``tolerance`` and ``epsilon``
    default per kind (see ``DEFAULT_TOLERANCE`` and ``DEFAULT_EPSILON``)."""

    kind: str
    target_m: tuple[float, float, float] | None = None
    hand: str = "right"
    tolerance: float | None = None
    epsilon: float | None = None
    q_rest: tuple[float, ...] | None = None
    orientation: tuple[float, float, float, float] | None = None
    free_yaw: bool = False

    @property
    def name(self) -> str:
        """Label in residuals and histories, e.g. ``reach:right``, ``orient:right``."""
        return f"{self.kind}:{self.hand}" if self.kind in ("reach", "orient") else self.kind

    def tol(self) -> float:
        return DEFAULT_TOLERANCE[self.kind] if self.tolerance is None else float(self.tolerance)

    def eps(self) -> float:
        return DEFAULT_EPSILON[self.kind] if self.epsilon is None else float(self.epsilon)

    def validate(self, where: str) -> None:
        """InvalidRequestError naming the field at fault."""
        if self.kind not in TASK_KINDS:
            raise InvalidRequestError(f"{where}.kind: {self.kind!r} is not one of {list(TASK_KINDS)}")
        target_ok = self.target_m is not None and len(self.target_m) == 3
        if self.kind in ("reach", "gaze") and not (
            target_ok and all(math.isfinite(v) for v in self.target_m)
        ):
            raise InvalidRequestError(f"{where}.target_m: a {self.kind} task needs 3 finite numbers [m]")
        if self.kind == "orient":
            quat = self.orientation
            if quat is None or len(quat) != 4 or not all(math.isfinite(v) for v in quat):
                raise InvalidRequestError(f"{where}.orientation: an orient task needs [qx, qy, qz, qw]")
            if not math.isclose(math.sqrt(sum(v * v for v in quat)), 1.0, abs_tol=1e-3):
                raise InvalidRequestError(f"{where}.orientation: {list(quat)} is not a unit quaternion")
        if self.free_yaw and self.kind != "orient":
            raise InvalidRequestError(f"{where}.free_yaw: only an orient task has a yaw to free")
        if self.kind in ("reach", "orient") and self.hand not in ("left", "right"):
            raise InvalidRequestError(f"{where}.hand: must be 'left' or 'right', got {self.hand!r}")
        for attr in ("tolerance", "epsilon"):
            value = getattr(self, attr)
            if value is not None and not (value > 0.0 and (math.isfinite(value) or attr == "tolerance")):
                raise InvalidRequestError(f"{where}.{attr}: must be a positive number, got {value!r}")


@dataclass(frozen=True)
class DiskObstacle:
    """A disk on the ground that no footprint may enter (section 4.1) [m]."""

    x_m: float
    y_m: float
    radius_m: float


@dataclass(frozen=True)
class PlannerOptions:
    """Numerical settings of the planner.

    Attributes:
        gain: lambda of eqs. (2), (4), (11), (13) for every task and constraint.
        alpha: integration step of q~ <- q~ + alpha dq (Algorithm 1 line 6).
        dq_max: bound on |alpha dq| per coordinate per iteration [rad or m]: keeps each step of the
            linearization small (a joint velocity limit of the IK time).
        com_margin_m: d of eq. (11), the CoM projection kept this far inside the support polygon.
        overlap_margin_m: gap kept between the inner corner of a foot and the other foot's half-plane
            (Fig. 5).
        disk_margin_m: gap kept between a footprint and a disk obstacle.
        collision_margin_m: d of eq. (12) between capsules; ``self_collision`` turns eq. (13) on/off.
        arm_obstacle_margin_m: d of eq. (12) between the reaching arm's capsules and the request's
            ``hand_obstacles`` (``arm_obstacles.py``).
        joint_margin_rad: joint limits are kept this far inside the model's range.
        step_region_scale: the relative step bounds of section 3.3 (the robot's, e.g. HRP-2's
            -0.22 < dx < 0.22 m, 0.07 < dy < 0.25 m, -0.1 < dtheta < pi/4 rad) shrunk towards their
            middle by this factor (1: the paper's bounds); below 1 keeps the steps away from the
            corners of the region, which a dynamic walk executes less easily.
        max_rate_m, max_rate_rad: saturation of the desired rate lambda F of the reach and gaze tasks
            [m per IK time] and of the posture task [rad per IK time] (norms); ``math.inf``: eq. (2)
            as written.
        damping, error_damping: Levenberg-Marquardt regularization of every level's increment,
            mu = damping + error_damping ||e||^2 (``services.ik.Level``); 0, 0: the undamped
            least squares of eq. (7).
        relative_epsilon: the stall test of eq. (15) uses min(epsilon_i, relative_epsilon alpha lambda
            V_i) (the paper asks epsilon_i < lambda V_i); ``math.inf``: epsilon_i as written.
        polish_iterations: iterations without new steps after Algorithm 1 stops on a stall (the
            level-0 equalities settle); 0: Algorithm 1 as written.
        hand_floor: keep the corners of both hands' collision boxes ``hand_floor_margin_m`` [m] above
            the floor, a constraint in the form of eq. (13) (``services.footsteps.hand_floor``; an
            extension: the paper's §3.2 has no ground under the hand, and §4.2's reach of an object on
            the floor put the gripper into it).
    """

    gain: float = 1.0
    alpha: float = 0.7
    dq_max: float = 0.25
    com_margin_m: float = 0.03
    overlap_margin_m: float = 0.01
    disk_margin_m: float = 0.01
    collision_margin_m: float = 0.01
    self_collision: bool = True
    arm_obstacle_margin_m: float = 0.02
    joint_margin_rad: float = 0.02
    max_rate_m: float = 0.1
    step_region_scale: float = 1.0
    max_rate_rad: float = 0.5
    damping: float = 1e-3
    error_damping: float = 0.1
    relative_epsilon: float = 0.3
    polish_iterations: int = 30
    hand_floor: bool = True
    hand_floor_margin_m: float = 0.01


@dataclass(frozen=True)
class FootstepPlanRequest:
    """What to plan: tasks in priority order (first = highest), disks, and the algorithm's options.

    Attributes:
        robot: a name accepted by ``services.model.load_robot``.
        q_start: the robot standing with both soles flat on the ground (world free-flyer); default the
            half-sitting with the mid-feet frame at the origin.
        tasks: desired tasks, highest priority first.
        disks: disk obstacles on the ground.
        hand_obstacles: spheres the reaching arm, gripper included, keeps out of in the final posture
            (level 0, ``arm_obstacles.py``; the gripper not out of the one a reach target lies in or
            above: the object it closes on).
        front_foot: the foot that makes the last step; "auto" solves for both and keeps the solution
            with fewer steps, ties broken by the posture residual (section 5.2). With a root insertion
            per added step, the two choices give the two possible first stepping feet at any count.
        initial_steps: initial guess of the number of steps (Algorithm 1 starts from the folded chain
            with that many footprints; they are held at their place with decreasing priority).
        max_steps: Algorithm 1 never grows the chain beyond this many steps.
        max_iterations: cap on IK iterations per front-foot choice.
        time_budget_s: wall-clock budget of the whole request; past it the planner stops and reports
            the goal infeasible with the residuals reached.
        options: numerical settings.
        record_trace: keep the per-iteration values and chain states (for the figures).
    """

    tasks: tuple[FootstepTask, ...]
    robot: str = "hrp2_like"
    q_start: tuple[float, ...] | None = None
    disks: tuple[DiskObstacle, ...] = ()
    hand_obstacles: tuple[SphereObstacle, ...] = ()
    front_foot: str = "auto"
    initial_steps: int = 0
    max_steps: int = 20
    max_iterations: int = 2000
    time_budget_s: float = 10.0
    options: PlannerOptions = field(default_factory=PlannerOptions)
    record_trace: bool = False

    def validate(self) -> None:
        """InvalidRequestError naming the field at fault."""
        if not self.tasks:
            raise InvalidRequestError("tasks: give at least one task (reach, gaze or posture)")
        for i, task in enumerate(self.tasks):
            task.validate(f"tasks[{i}]")
        names = [t.name for t in self.tasks]
        if len(set(names)) != len(names):
            raise InvalidRequestError(f"tasks: each task may appear once, got {names}")
        for i, disk in enumerate(self.disks):
            if not all(math.isfinite(v) for v in (disk.x_m, disk.y_m, disk.radius_m)) or disk.radius_m <= 0:
                raise InvalidRequestError(f"disks[{i}]: needs finite x_m, y_m and radius_m > 0, got {disk}")
        check_spheres(self.hand_obstacles)
        if self.front_foot not in FOOT_CHOICES:
            raise InvalidRequestError(f"front_foot: {self.front_foot!r} is not one of {list(FOOT_CHOICES)}")
        if not 0 <= self.initial_steps <= self.max_steps:
            raise InvalidRequestError(
                f"initial_steps must be in 0..max_steps ({self.max_steps}), got {self.initial_steps}"
            )
        if self.max_iterations < 1:
            raise InvalidRequestError(f"max_iterations must be >= 1, got {self.max_iterations}")
        if not (math.isfinite(self.time_budget_s) and self.time_budget_s > 0):
            raise InvalidRequestError(f"time_budget_s must be positive, got {self.time_budget_s}")
        o = self.options
        if not (0 < o.alpha <= 1 and o.gain > 0 and o.dq_max > 0):
            raise InvalidRequestError(f"options: need 0 < alpha <= 1, gain > 0, dq_max > 0, got {o}")
        numerics_ok = o.damping >= 0 and o.error_damping >= 0 and o.relative_epsilon > 0
        if not (numerics_ok and o.polish_iterations >= 0):
            raise InvalidRequestError(
                "options: need damping >= 0, error_damping >= 0, relative_epsilon > 0, "
                f"polish_iterations >= 0, got {o.damping}, {o.error_damping}, {o.relative_epsilon}, "
                f"{o.polish_iterations}"
            )
        if not (math.isfinite(o.hand_floor_margin_m) and o.hand_floor_margin_m >= 0):
            raise InvalidRequestError(
                f"options.hand_floor_margin_m must be >= 0 m, got {o.hand_floor_margin_m}"
            )
        if not 0 < o.step_region_scale <= 1:
            raise InvalidRequestError(
                f"options.step_region_scale must be in (0, 1], got {o.step_region_scale}"
            )


@dataclass(frozen=True)
class PlannedFootstep:
    """One landing, in walking order: ``side`` foot's sole at (x, y, yaw) in the world [m, rad]."""

    side: str
    x_m: float
    y_m: float
    yaw_rad: float


@dataclass(frozen=True)
class TaskResidual:
    """Final value of a task (eqs. 5-6) against its tolerance."""

    name: str
    value: float
    tolerance: float
    solved: bool


@dataclass(frozen=True)
class PlanTrace:
    """What the figures draw, one entry per evaluated configuration (iteration 0 = start).

    ``values[k][i]`` is task i's value at iteration k; ``footprints[k]`` the world footprints
    (side, x, y, yaw) of the chain F_0..F_{p-1} then the front foot; ``q_robot[k]`` the robot's
    world configuration; ``steps_added_at`` the iterations after which a footstep was inserted.
    """

    task_names: tuple[str, ...]
    values: tuple[tuple[float, ...], ...]
    footprints: tuple[tuple[tuple[str, float, float, float], ...], ...]
    q_robot: tuple[tuple[float, ...], ...]
    steps_added_at: tuple[int, ...]


@dataclass(frozen=True)
class FootstepPlanResult:
    """The plan: footsteps in walking order (null steps discarded), the final whole-body
    configuration, per-task residuals, iterations, when steps were added and the solve time.

    Attributes:
        footsteps: landings in walking order.
        left_start, right_start: initial sole footprints (x, y, yaw) [m, rad].
        q_final: the robot's final configuration (world free-flyer).
        residuals: every task's final value, in priority order.
        iterations: IK iterations of the retained front-foot choice.
        steps_added_at: iterations after which Algorithm 1 added a footstep (retained choice).
        solve_time_s: wall-clock time of the whole request (both front-foot choices) [s].
        front_foot: front-foot choice retained ("left" or "right").
        chain_steps: steps of the virtual chain before the null ones were discarded.
        alternatives: (front_foot, solved, steps, posture residual [rad]) of every choice tried.
        trace: per-iteration record of the retained choice (``record_trace``), else None.
    """

    footsteps: tuple[PlannedFootstep, ...]
    left_start: tuple[float, float, float]
    right_start: tuple[float, float, float]
    q_final: tuple[float, ...]
    residuals: tuple[TaskResidual, ...]
    iterations: int
    steps_added_at: tuple[int, ...]
    solve_time_s: float
    front_foot: str
    chain_steps: int
    alternatives: tuple[tuple[str, bool, int, float], ...] = ()
    trace: PlanTrace | None = None

    @property
    def n_steps(self) -> int:
        return len(self.footsteps)

    def footstep_sequence(self) -> FootstepSequence:
        """The plan as a ``services.walking`` footstep sequence (for the pattern generator)."""
        return FootstepSequence(
            SolePose(*self.left_start),
            SolePose(*self.right_start),
            tuple(Footstep(s.side, SolePose(s.x_m, s.y_m, s.yaw_rad)) for s in self.footsteps),  # type: ignore[arg-type]
        )

    def residual(self, name: str) -> TaskResidual:
        """The residual of task ``name`` (e.g. ``reach:right``)."""
        for r in self.residuals:
            if r.name == name:
                return r
        raise InvalidRequestError(f"no task {name!r}; tasks are {[r.name for r in self.residuals]}")

    def summary(self) -> dict[str, Any]:
        """Small plain-data summary (for logs and the benchmark)."""
        return {
            "steps": self.n_steps,
            "front_foot": self.front_foot,
            "iterations": self.iterations,
            "steps_added_at": list(self.steps_added_at),
            "solve_time_s": self.solve_time_s,
            "residuals": {r.name: r.value for r in self.residuals},
        }
