"""Messages of the ``footsteps`` service: footstep planning as inverse kinematics (Kanoun, Laumond,
Yoshida, ``000_49c4a782ba599e49.txt``): where to put the feet, and the final whole-body posture, so
that the hand reaches a point, the gaze stays on a point and the posture stays comfortable.

World frame, z up, flat ground at z = 0; poses on the ground are (x [m], y [m], yaw [rad]).
Configurations follow the pinocchio layout of the request's model
(``q = [x, y, z, qx, qy, qz, qw, joints...]``, joint order ``PlanReply.joint_names``); they travel as
raw float64 bytes (binary frames of ``services.bus.codec``).

A request typed by hand needs only the tasks::

    humanoid call footsteps/plan '{"tasks": [{"kind": "reach", "target": [1.5, -0.2, 0.8]},
                                   {"kind": "posture"}], "disks": [{"x": 0.8, "y": 0.0, "radius": 0.2}]}'

(``q_start`` omitted: half-sitting with the mid-feet frame on the world origin.)
"""

from __future__ import annotations

from typing import Annotated

import msgspec
import numpy as np
from msgspec import Meta

from services.bus.limits import (
    MAX_OBSTACLES,
    MAX_TASKS,
    Budget,
    Coord,
    Damping,
    Fraction,
    Gain,
    Iterations,
    Margin,
    Name,
    Point3,
    PolishIterations,
    Size,
    StepCount,
    Tolerance,
)
from services.bus.schemas.common import Footstep, Sphere
from services.bus.schemas.navigation import ObstacleMsg
from services.bus.spec import EndpointSpec

#: Where Algorithm 1 stopped (``details["reason"]`` of ``footsteps/plan``'s ``infeasible`` and ``timeout``
#: replies; sub-reasons across processes).
REASON_SOLVED = "solved"  # every task met (never in an error)
REASON_STALLED = "stalled"  # no task improves even with an extra footstep (lines 17-18, section 6.1)
REASON_MAX_STEPS = "max_steps"  # the step cap max_steps was reached
REASON_STEP_CAP = "step_cap"  # the other start foot already needs fewer steps
REASON_MAX_ITERATIONS = "max_iterations"  # the iteration cap max_iterations was reached
REASON_TIME_BUDGET = "time_budget"  # the time budget ran out (a ``timeout`` reply)


class Task(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A desired task (section 4 of the paper); the order of ``PlanRequest.tasks`` is the priority order.

    ``reach``: the grasp frame of ``hand`` at ``target``; ``gaze``: the gaze axis through ``target``
    (OG x OB = 0, section 4.3); ``posture``: q - q_rest = 0 over the actuated joints (eq. 14);
    ``orient``: the grasp frame of ``hand`` at the world ``orientation`` (a grasp's wrist yaw).
    """

    kind: Name  # "reach", "gaze", "posture" or "orient"
    target: Point3 | None = None  # reach/gaze: [x, y, z] world [m]
    hand: Name = "right"  # reach: "left" or "right"
    tolerance: Tolerance | None = None  # solved below this value: [m] reach/gaze, [rad] posture; None: 2 mm,
    #                                 5 mm, and for the posture none (an objective, never required)
    # minimum value decrease per iteration of eq. (15) [m or rad]; None: default
    epsilon: Tolerance | None = None
    q_rest: np.ndarray | None = None  # posture: (nq,) float64 rest configuration; None: half-sitting
    # orient: the hand's grasp frame at this world orientation [qx, qy, qz, qw] (log3 error [rad])
    orientation: Annotated[list[Coord], Meta(min_length=4, max_length=4)] | None = None
    # orient: hold only the tilt of ``orientation`` (e.g. fingers down); the yaw about the vertical is the
    # IK's (the gripper's rows against hand_obstacles turn the jaws clear of a neighbour: q_final's yaw)
    free_yaw: bool = False


class Disk(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A disk on the ground that no footprint may enter (section 4.1): centre (x, y), radius [m]."""

    x: Coord
    y: Coord
    radius: Size


class Options(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Numerical settings of the planner (``services.footsteps.request.PlannerOptions``); None keeps
    the planner's default.

    Algorithm 1's numerics where they differ from eqs. (2)/(15) of the paper (the planner's README,
    "paper vs here"), each with a switch back to the paper's form: ``saturation`` false (the desired
    rates lambda F unsaturated: eq. 2), ``dq_cap`` false (no per-coordinate bound, the 0.25 default of
    ``dq_max``), ``damping`` = ``error_damping`` = 0 (the undamped least squares of eq. 7),
    ``epsilon_rule`` false (the stall test with epsilon_i as written in eq. 15, not
    min(epsilon_i, relative_epsilon alpha lambda V_i)), ``polish_iterations`` = 0.
    """

    gain: Gain | None = None  # lambda of eqs. (2), (4), (11), (13)
    alpha: Fraction | None = None  # integration step of q <- q + alpha dq, in (0, 1]
    dq_max: Tolerance | None = None  # bound on |alpha dq| per coordinate per iteration [rad or m]
    com_margin_m: Margin | None = None  # CoM projection kept this far inside the support polygon [m]
    overlap_margin_m: Margin | None = None  # gap between the footprints of a support polygon [m]
    disk_margin_m: Margin | None = None  # gap between a footprint and a disk [m]
    collision_margin_m: Margin | None = None  # gap between capsules (eq. 12) [m]
    self_collision: bool | None = None  # eq. (13) on/off
    arm_obstacle_margin_m: Margin | None = None  # gap between the reaching arm and hand_obstacles [m]
    joint_margin_rad: Margin | None = None  # joint limits kept this far inside the range [rad]
    step_region_scale: Fraction | None = None  # step bounds shrunk towards their middle, in (0, 1]
    max_rate_m: Gain | None = None  # saturation of the reach/gaze desired rate [m per IK time]
    max_rate_rad: Gain | None = None  # saturation of the posture desired rate [rad per IK time]
    saturation: bool | None = None  # false: no saturation of the desired rates (eq. 2 as written)
    dq_cap: bool | None = None  # false: no per-coordinate bound dq_max (the paper has none)
    damping: Damping | None = None  # LM mu_0 of every level (0 with error_damping 0: eq. 7 undamped)
    error_damping: Damping | None = None  # LM growth of mu with the level's squared residual
    relative_epsilon: Gain | None = None  # eq. (15) stall test with min(eps_i, this alpha lambda V_i)
    epsilon_rule: bool | None = None  # false: eq. (15) with epsilon_i as written (relative_epsilon off)
    polish_iterations: PolishIterations | None = None  # iterations without new steps after a stall


class PlanRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """What to plan. The planner is stateless: plan from the robot's measured configuration."""

    tasks: Annotated[list[Task], Meta(max_length=MAX_TASKS)]  # highest priority first
    model: Name = "hrp2_like"  # services.model.load_robot name: hrp2_like or talos
    q_start: np.ndarray | None = None  # (nq,) float64, both soles flat on the ground; None: half-sitting
    disks: Annotated[list[Disk], Meta(max_length=MAX_OBSTACLES)] = []
    # boxes on the floor (e.g. the supervisor's map, as for navigation/goto): each covered by disks of
    # its footprint rectangle (services.footsteps.geometry.disks_covering), obstacles like ``disks``
    boxes: Annotated[list[ObstacleMsg], Meta(max_length=MAX_OBSTACLES)] = []
    # spheres above the ground that the reaching arm's capsules (gripper, forearm, upper arm) keep out of
    # in the final posture (the gripper not out of the one the hand's target lies in or above: the object)
    hand_obstacles: Annotated[list[Sphere], Meta(max_length=MAX_OBSTACLES)] = []
    front_foot: Name = "auto"  # foot of the last step, "left"/"right"; "auto": both solved, the one with
    #                           fewer steps kept (section 5.2: this is the choice of the start foot)
    initial_steps: StepCount = 0  # initial guess of the number of steps (section 5.1)
    max_steps: StepCount = 20  # Algorithm 1 never grows the chain beyond this many steps
    max_iterations: Iterations = 2000  # IK iterations per front-foot choice
    time_budget_s: Budget = 10.0  # wall-clock budget; past it: infeasible with the residuals reached [s]
    options: Options | None = None
    trace: bool = False  # also return the task values at every iteration (Fig. 10)


class Residual(msgspec.Struct, kw_only=True, frozen=True):
    """A task's final value (eqs. 5-6: [m] reach/gaze, [rad] posture) against its tolerance (None: an
    objective, never required)."""

    name: str  # e.g. "reach:right", "gaze", "posture"
    value: float
    tolerance: float | None
    solved: bool


class Alternative(msgspec.Struct, kw_only=True, frozen=True):
    """A front-foot choice that was solved (section 5.2)."""

    front_foot: str
    solved: bool
    steps: int
    posture_residual_rad: float  # ||q - q_rest|| over the actuated joints [rad]


class PlanReply(msgspec.Struct, kw_only=True, frozen=True):
    """The plan: footsteps in walking order, the final whole-body configuration, residuals."""

    model: str  # robot model the configuration belongs to
    joint_names: list[str]  # actuated joints in q order (after the 7 base coordinates)
    footsteps: list[Footstep]  # walking order; footprints that never moved are discarded (section 5.1)
    left_start: list[float]  # [x, y, yaw] of the left sole before the first step
    right_start: list[float]  # [x, y, yaw] of the right sole before the first step
    q_final: np.ndarray  # (nq,) float64 final configuration: the robot on the last footprints
    residuals: list[Residual]  # every task, in priority order
    iterations: int  # IK iterations of the retained front-foot choice
    steps_added_at: list[int]  # iterations after which Algorithm 1 added a footstep
    solve_time_s: float  # wall time of the planning (both front-foot choices) [s]
    front_foot: str  # front-foot choice retained ("left" or "right")
    chain_steps: int  # steps of the virtual chain before the null steps were discarded
    alternatives: list[Alternative]  # every front-foot choice solved
    task_values: np.ndarray | None = None  # (iterations + 1, n_tasks) float64 values per iteration (trace)


PLAN = EndpointSpec(
    "footsteps",
    "plan",
    PlanRequest,
    PlanReply,
    "footstep planning as inverse kinematics: footsteps and final posture for hand/gaze/posture tasks",
)
