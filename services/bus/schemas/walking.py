"""Messages of the ``walking`` service: footsteps in, a 5 ms whole-body walk out (ZMP preview control,
Kajita et al. 2003, on the prioritized IK).

The planner is stateless: the request carries the robot model name, its starting configuration and the
footsteps. World frame, z up, flat ground; poses on the ground are ``[x, y, yaw]`` ([m], [m], [rad]).
Configurations follow the pinocchio layout of the model (``q = [x, y, z, qx, qy, qz, qw, joints...]``,
joint order ``PlanReply.joint_names``): ``PlanReply.q`` goes to ``sim/execute`` as it is.

A request typed by hand only needs the steps::

    humanoid call walking/plan '{"first_side": "right", "steps": [{"pose": [0.2, -0.095, 0]},
                                  {"pose": [0.2, 0.095, 0]}]}'

(``q_start`` omitted: half-sitting with the mid-feet frame on the world origin, the soles where the
model puts them, e.g. y = +-0.095 m for ``hrp2_like``).
"""

from __future__ import annotations

from typing import Annotated

import msgspec
import numpy as np
from msgspec import Meta

from services.bus.limits import (
    MAX_OBSTACLES,
    MAX_STEPS,
    Angle,
    Budget,
    Coord,
    Margin,
    Name,
    Phase,
    Point3,
    Pose2,
    Size,
    Tolerance,
)
from services.bus.schemas.navigation import ObstacleMsg
from services.bus.spec import EndpointSpec


class Step(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """One footstep: foot ``side`` lands with its sole at ``pose`` = [x, y, yaw] ([m], [m], [rad])."""

    pose: Pose2
    side: Name = ""  # "left" or "right"; "" alternates, starting with PlanRequest.first_side


class HandTask(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Keep a hand (its grasp frame) at its starting pose in ``frame``, or move it along waypoints.

    ``frame``: "walk" (moves with the walk: origin on the ground below the planned CoM, x along the
    waist yaw; a carried object) or "world". With ``times_s`` / ``positions_m`` the hand position
    follows a C2 spline from its starting position (t = 0) through the waypoints ([s] from the start of
    the walk, strictly increasing, > 0; [x, y, z] [m] in ``frame``) and stays at the last one.
    """

    side: Name  # "left" or "right"
    frame: Name = "walk"
    times_s: Annotated[list[Phase], Meta(max_length=MAX_STEPS)] = []
    positions_m: Annotated[list[Point3], Meta(max_length=MAX_STEPS)] = []
    keep_orientation: bool = True  # also hold the starting orientation (in frame)


class GazeTask(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Look at ``point_m`` = [x, y, z] [m] in ``frame`` ("world" or "walk"), blended in over ``blend_s``."""

    point_m: Point3
    frame: Name = "world"
    blend_s: Phase = 1.0


class PlanRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Footsteps, timing and options of one walk.

    ``left_start`` / ``right_start``: the soles before the first step ([x, y, yaw]); omitted (null):
    measured on ``q_start``. ``q_start`` omitted: the model's half-sitting standing on the starting
    soles' mid-feet frame (the soles must then be as far apart as in half-sitting). When both are
    given they must agree within 5 mm.
    """

    steps: Annotated[list[Step], Meta(max_length=MAX_STEPS)]
    first_side: Name = "right"  # foot that moves first when steps[0].side is ""
    model: Name = "hrp2_like"  # services.model.load_robot name: hrp2_like or talos
    q_start: np.ndarray | None = None  # (nq,) starting configuration, pinocchio layout
    left_start: Pose2 | None = None  # [x, y, yaw] of the left sole before the first step
    right_start: Pose2 | None = None  # [x, y, yaw] of the right sole before the first step
    # timing [s]
    single_support_s: Phase = 0.7
    double_support_s: Phase = 0.3  # between two steps (0.1 is fragile in the sim: see the README)
    initial_double_support_s: Phase = 0.8  # first weight transfer onto the first stance foot
    final_double_support_s: Phase = 0.5  # last weight transfer back between the feet
    initial_hold_s: Phase = 0.6  # standing still before the first transfer (preview lead-in)
    stop_at_end: bool = True  # stand still final_hold_s at the end (else end with the last transfer)
    final_hold_s: Phase = 0.2  # (the pattern comes to rest over the last transfer and this hold)
    # pattern options
    # swing apex [m]; None: the robot's parameter
    step_height_m: Annotated[float, Meta(gt=0.0, le=0.5)] | None = None
    # cart-table z_c above the ground [m]; None: CoM of q_start
    com_height_m: Annotated[float, Meta(gt=0.0, le=3.0)] | None = None
    preview_horizon_s: Annotated[float, Meta(gt=0.0, le=5.0)] = 1.6  # preview control horizon [s]
    zmp_margin_m: Margin = 0.010  # multibody ZMP inside the support polygon by this much [m]
    max_corrections: Annotated[int, Meta(ge=0, le=20)] = 2  # passes of the second preview stage at most
    # upper body (below feet > CoM > waist/chest orientation, above the rest posture)
    hands: Annotated[list[HandTask], Meta(max_length=2)] = []
    gaze: GazeTask | None = None
    hand_tolerance_m: Tolerance = 0.01  # a hand farther than this from its target: infeasible [m]
    gaze_tolerance_m: Tolerance = 0.02  # target point farther than this from the gaze axis: infeasible [m]
    # wall-clock planning budget [s] (<= 60); None: the service's time_budget_s. Past it: ``timeout``
    # with the stage reached (``details.stage``, ``knots_done``, ``knots``).
    time_budget_s: Budget | None = None


class StepTiming(msgspec.Struct, kw_only=True, frozen=True):
    """When step ``index`` (foot ``side``) lifts off and lands [s], and its landing pose [x, y, yaw]."""

    index: int
    side: str
    lift_off_s: float
    touch_down_s: float
    pose: list[float]


class PlanFigures(msgspec.Struct, kw_only=True, frozen=True):
    """How good the walk is (deterministic figures: no wall-clock times in a planner reply)."""

    duration_s: float  # time of the last sample [s]
    n_samples: int
    min_zmp_margin_m: float  # smallest distance of the multibody ZMP inside the polygon [m] (< 0: out)
    worst_zmp_outside_m: float  # largest distance outside the polygon [m] (0: always inside)
    second_stage_passes: int  # passes of the second preview stage (0: the first stage sufficed)
    second_stage_acted: bool  # second_stage_passes > 0
    min_zmp_margin_first_pass_m: float  # min_zmp_margin_m before any correction [m]
    max_zmp_error_m: float  # largest |ZMP reference - multibody ZMP| of the final pass [m]
    max_sole_error_m: float  # sole position error left by the IK knots + spline, every sample [m]
    max_com_error_m: float  # CoM error of the joint trajectory w.r.t. the CoM reference [m]
    task_errors: dict[str, float] = {}  # upper-body task -> largest error [m] ([rad] for *_rotation)


class PlanReply(msgspec.Struct, kw_only=True, frozen=True):
    """The whole-body walk on a 5 ms grid (n samples). ``phase``: 0 double support, 1 left foot supports
    (right swings), 2 right foot supports. Sole arrays are (n, 4) = x, y, z [m], yaw [rad] (continuous)."""

    model: str
    joint_names: list[str]  # actuated joints in q order (after the 7 base coordinates)
    dt_s: float  # 0.005
    times_s: np.ndarray  # (n,) [s]
    q: np.ndarray  # (n, nq) base pose and every joint: send to sim/execute
    com_m: np.ndarray  # (n, 3) CoM of q [m]
    com_ref_m: np.ndarray  # (n, 3) CoM reference (cart-table + second-stage corrections) [m]
    zmp_ref_m: np.ndarray  # (n, 2) ZMP reference from the footsteps [m]
    zmp_planned_m: np.ndarray  # (n, 2) ZMP of the cart-table CoM motion (first stage) [m]
    zmp_multibody_m: np.ndarray  # (n, 2) ZMP of the whole-body motion (pinocchio centroidal) [m]
    zmp_margin_m: np.ndarray  # (n,) signed distance of the multibody ZMP inside its polygon [m]
    left_sole: np.ndarray  # (n, 4)
    right_sole: np.ndarray  # (n, 4)
    phase: np.ndarray  # (n,) int8 support phase
    steps: list[StepTiming]
    final_left_sole: list[float]  # [x, y, yaw] after the last step
    final_right_sole: list[float]
    figures: PlanFigures


PLAN = EndpointSpec(
    "walking",
    "plan",
    PlanRequest,
    PlanReply,
    "footsteps -> 5 ms whole-body walk (ZMP preview control + IK); infeasible names the step out of bounds",
)


# ------------------------------------------------------------------------------------------ walks to a goal

#: ``GoalRequest.kind`` values.
GOAL_KINDS = ("pose", "turn", "square", "settle")
#: ``details["reason"]`` of an ``infeasible`` reply of ``walking/goal`` (sub-reasons across processes).
REASON_BLOCKED = "blocked_by_obstacle"  # a step or the mid-feet path comes too near a box of the map
REASON_NO_ROOM_TO_TURN = "no_room_to_turn"  # a box nearer than turn_room_m to the mid-feet point
REASON_OUT_OF_BOUNDS = "out_of_bounds"  # no count of steps fits the robot's stepping bounds
REASON_ALREADY_SQUARE = "already_square"  # invalid_request: a `square` goal for a stance square already
REASON_ALREADY_SETTLED = "already_settled"  # invalid_request: a `settle` goal with both soles flat already
REASON_LEANING = "leaning"  # a `settle` goal: the robot is held up by something it touches


class GoalRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Walk to a goal relative to the stance now; the walking planner makes the footsteps itself (each as
    long as the robot's stepping bounds allow), checks them against ``obstacles`` and plans the walk.

    ``kind``:

    * ``"pose"``: the mid-feet frame to ``pose`` = [x, y, yaw] ([m], [m], [rad]) in ``frame``
      (``"robot"``: the mid-feet frame at ``q_start``, x forward, y left; ``"world"``), stepping
      forward, sideways and turning together (or there first, then turning on the spot), the feet side
      by side at the end. ``[-0.3, 0, 0]`` steps back 0.3 m; ``[0, 0, 0]`` squares a staggered stance.
    * ``"turn"``: turn on the spot by ``angle_rad`` (> 0: left), a staggered stance squared up first;
      needs no box nearer than ``turn_room_m`` to the mid-feet point. With ``back_m`` > 0: first
      straight back by ``back_m`` [m] (as ``"pose"`` [-back_m, 0, 0]), then the turn from there, one
      walk (no stand-still between them); the turn's room is checked where it starts.
    * ``"square"``: the one step that brings the rear foot beside the front one (``invalid_request``
      if the stance is already square).
    * ``"settle"``: from ``q_start`` as measured (a sole left up to a few cm up or tilted by a stopped
      motion), both soles back flat on the ground and the body over them, no step
      (:mod:`services.walking.settle`: the anchor is the sole on the ground; the other one comes down
      flat below where it is, the anchor and the CoM held; then the anchor turns flat and the CoM moves
      to the middle; the multibody ZMP checked, on the anchor alone while the other sole is in the
      air). ``invalid_request`` with reason ``already_settled`` when both soles are within 1 mm and
      0.005 rad of flat; ``infeasible`` with reason ``leaning`` when the CoM is outside the two soles
      laid flat (the robot is held up by something it touches), ``out_of_bounds`` when a sole would
      land on the other, is out of reach, or the ZMP check fails. The obstacles are not used (the
      sole comes down where it is).

    Obstacle test (``obstacles``: the map's boxes, ``kind`` "box"): the mid-feet path keeps
    ``clearance_m`` from every box (or as far as its start or its end is, if nearer), every landing sole
    ``sole_margin_m``; in 3D, the legs of the walk planned (their swept volume: a lifted foot brings
    its knee forward) keep ``leg_clearance_m`` from every box (or, from a box a leg starts nearer to,
    as far as it starts). Failures: ``infeasible`` with ``details.reason`` one of ``REASON_*``.
    """

    q_start: np.ndarray  # (nq,) the robot's configuration now, standing on both soles (settle: as measured)
    kind: Name = "pose"
    pose: Annotated[list[Coord], Meta(max_length=3)] = []  # kind "pose": [x, y, yaw] of the mid-feet frame
    frame: Name = "robot"  # kind "pose": "robot" or "world"
    angle_rad: Angle = 0.0  # kind "turn"
    back_m: Size = 0.0  # kind "turn": straight back by this much first [m], one walk with the turn
    model: Name = "hrp2_like"
    obstacles: Annotated[list[ObstacleMsg], Meta(max_length=MAX_OBSTACLES)] = []
    clearance_m: Size = 0.35
    sole_margin_m: Size = 0.03
    turn_room_m: Size = 0.3
    leg_clearance_m: Size = 0.02  # the legs' swept volume from the boxes (3D) [m]
    single_support_s: Phase = 0.7
    # The service's default 0.3 s; the supervisor asks for 0.2 s. At 0.1 s an earlier walking timing
    # tipped the simulated robot over in about half of the 60-90 deg turns, and session 9's fetch fell on
    # two of about 25 layouts (supervisor/config.py).
    double_support_s: Phase = 0.3
    time_budget_s: Budget | None = None  # as PlanRequest.time_budget_s [s]


GOAL = EndpointSpec(
    "walking",
    "goal",
    GoalRequest,
    PlanReply,
    "walk to a pose relative to the robot (or in the world), turn on the spot, square the stance: the "
    "planner makes the footsteps within the bounds, checks them against the map's boxes, plans the walk",
)
