"""Messages of the ``navigation`` service: two-stage walking plans with smooth reshaping of a carried bar.

World frame: z up, flat floor at z = 0, positions [m], angles [rad]. Configurations follow the pinocchio
layout of the robot model the service runs (``GotoReply.model``): ``q = [x, y, z, qx, qy, qz, qw,
joints...]``. The planner is stateless: the scene's obstacles (from perception or the supervisor's map,
not the sim's ground truth) and the robot's current configuration come with every request.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec
import numpy as np
from msgspec import Meta

from services.bus.limits import MAX_OBSTACLES, Angle, Budget, Coord, Name, Point3, PositiveSize, Seed, Size
from services.bus.schemas.rectangle import Rectangle
from services.bus.spec import EndpointSpec

#: ``details["reason"]`` of ``navigation/goto``'s ``infeasible`` replies (sub-reasons across processes).
REASON_NO_PATH_WITHIN_BUDGET = "no_path_within_budget"  # stage 1 found no path in time_budget_s
REASON_NO_FREE_APPROACH_POSE = "no_free_approach_pose"  # no place to stand goal_distance_m from the object
REASON_GOAL_ENCLOSED = "goal_enclosed"
REASON_BODY_COLLISION = "body_collision"  # stage 2: the body (not the bar) meets an obstacle
REASON_ZMP_OUTSIDE_SUPPORT = "zmp_outside_support"
REASON_START_IN_COLLISION = "start_in_collision"  # the robot's footprint at the start meets an obstacle
REASON_GOAL_IN_COLLISION = "goal_in_collision"  # the goal pose puts the footprint into an obstacle
REASON_NO_COLLISION_FREE_RESHAPING = "no_collision_free_reshaping"  # stage 2 could not reshape clear
REASON_BAR_OUT_OF_REACH = "bar_out_of_reach"  # the bar cannot be held from the pick-up pose
REASON_FOOTSTEP_BOUNDS = "footstep_bounds"  # footsteps along the path leave the step bounds
REASON_LIFT_TOO_HIGH = "lift_too_high"  # a bar key frame would lift it above the arms' reach
REASON_NO_COLLISION_FREE_SAMPLE = "no_collision_free_sample"  # no bar key frame clear of the obstacles


class ObstacleMsg(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """An obstacle: ``kind`` ``box`` (vertical-axis box: ``size`` = full extents [sx, sy, sz], ``yaw``) or
    ``cylinder`` (vertical: ``radius``, ``height``); ``center`` = [x, y, z] of its middle [m]."""

    name: Name
    kind: Name = "box"
    center: Point3  # [x, y, z] [m]
    size: Annotated[list[Size], Meta(max_length=3)] = []  # box: [sx, sy, sz] full extents [m]
    yaw: Angle = 0.0  # box: rotation about z [rad]
    radius: Size = 0.0  # cylinder [m]
    height: Size = 0.0  # cylinder [m]

    @property
    def footprint(self) -> Rectangle:
        """Its floor projection (world [m, rad]): a box's x and y extents turned by its yaw; a cylinder's
        bounding square (side 2 ``radius``). The caller checked ``center`` and ``size`` have their length."""
        centre = (float(self.center[0]), float(self.center[1]))
        if self.kind == "cylinder":
            return Rectangle(centre, (2.0 * float(self.radius), 2.0 * float(self.radius)), 0.0)
        return Rectangle(centre, (float(self.size[0]), float(self.size[1])), float(self.yaw))


class CarriedBarMsg(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A bar held in both hands (as in the starting configuration): the paper's 1.8 m, 2.4 cm, 0.5 kg."""

    length_m: PositiveSize = 1.8
    radius_m: PositiveSize = 0.012
    mass_kg: Annotated[float, Meta(gt=0.0, le=20.0)] = 0.5


class GotoRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Walk from ``q_start`` to a goal among ``obstacles``.

    The goal is ``goal_pose`` = [x, y, theta] of the base (mid-feet point, heading), or ``goal_object``:
    stand in front of that obstacle, facing it, ``goal_distance_m`` from its face to the base (on side
    ``goal_side`` "-x", "+x", "-y", "+y" of a box, "" = the free side nearest the start). Exactly one of
    the two. ``bounds`` = [xmin, xmax, ymin, ymax] [m] of the floor the base may use (empty: the box
    around start, goal and obstacles grown by 1.5 m).
    """

    q_start: np.ndarray  # (nq,) the robot's current configuration, standing on flat ground
    obstacles: Annotated[list[ObstacleMsg], Meta(max_length=MAX_OBSTACLES)] = []
    goal_pose: Annotated[list[Coord], Meta(max_length=3)] = []  # [x, y, theta] [m, m, rad]
    goal_object: Name = ""  # name of an obstacle to stand in front of
    goal_distance_m: Size = 0.4
    goal_side: Name = ""
    bounds: Annotated[list[Coord], Meta(max_length=4)] = []  # [xmin, xmax, ymin, ymax] [m]
    carried: CarriedBarMsg | None = None  # a bar held in both hands; None: nothing carried
    carry_height_m: Size | None = None  # bar centre height while walking [m]; None: as held at the start
    turning_radius_m: Annotated[float, Meta(gt=0.0, le=5.0)] = 0.5  # minimum turning radius of the path [m]
    time_budget_s: Budget = 1.0  # stage-1 search budget [s] (each search; cut to what total_budget_s leaves)
    # wall-clock budget of the whole goto [s] (<= 60): path searches, footsteps, stage 2 and replans;
    # None: the service's goto_budget_s. Past it: ``timeout`` naming the stage reached (``details.stage``).
    total_budget_s: Budget | None = None
    max_iterations: Annotated[int, Meta(ge=1, le=50)] = 5  # whole-body solutions of the reshaping loop
    seed: Seed = 1  # OMPL seed (same request, same plan)
    double_support_s: Annotated[float, Meta(gt=0.0, le=5.0)] = 0.3  # between two steps of the walk [s]
    straight_walks: bool = True  # a near goal whose path is a detour (or none found) may be walked straight
    # smooth reshaping of a carried bar (Fig. 2): "sample" a random collision-free pose near the collision
    # (the paper's), or "lift" its height only
    reshape_mode: Literal["sample", "lift"] = "sample"
    reshape_seed: Seed = 0  # seed of the reshaping's random sampling (same request, same plan)


class LiftSegment(msgspec.Struct, kw_only=True, frozen=True):
    """One reshaping of the bar: nominal until ``t_anticipate_s``, lifted to ``height_m`` from
    ``t_collide_s`` to ``t_collide_end_s``, nominal again from ``t_regain_s`` (times from the start of
    the trajectory [s])."""

    t_anticipate_s: float
    t_collide_s: float
    t_collide_end_s: float
    t_regain_s: float
    height_m: float  # bar centre height while lifted [m]
    obstacles: list[str]


class ReshapingReport(msgspec.Struct, kw_only=True, frozen=True):
    """What stage 2 did: whole-body solutions computed (1: the first one was collision-free), segments
    lifted, and the bar's height (n,) [m] on the trajectory's grid: ``bar_height_nominal_m`` before
    reshaping (task space), ``bar_height_before_m`` realised by the first whole-body solution,
    ``bar_height_planned_m`` the reshaped task-space profile, ``bar_height_m`` realised by the returned
    trajectory (empty arrays when nothing is carried)."""

    iterations: int
    segments: list[LiftSegment]
    min_clearance_m: (
        float | None
    )  # smallest distance of any part (robot, bar) to any obstacle [m]; None: none
    zmp_margin_m: float  # smallest distance of the multibody ZMP inside the support polygon [m]
    hand_error_m: float  # largest distance between the bar's planned and realised pose [m]
    collisions_per_iteration: list[int]  # collision events found by each whole-body solution's check
    bar_height_nominal_m: np.ndarray
    bar_height_before_m: np.ndarray
    bar_height_planned_m: np.ndarray
    bar_height_m: np.ndarray


class GotoReply(msgspec.Struct, kw_only=True, frozen=True):
    """The plan. Path samples every <= 2 cm (``path_xy_m`` (N, 2), ``path_theta_rad`` (N,),
    ``path_s_m`` (N,) arc length, ``path_forward`` (N,) 1 where walking forward; ``path_curve``
    "straight" when a near goal was walked straight, stepping sideways and turning, instead of along a
    car-like detour); footsteps (start soles
    [x, y, yaw], then ``step_sides`` and ``step_poses`` (K, 3)); the whole-body trajectory ``q`` (T, nq)
    every ``dt_s`` (send it to ``sim/execute``) with its CoM (T, 3) and multibody ZMP (T, 2)."""

    model: str  # robot model of q
    goal: list[float]  # [x, y, theta] reached by the base (the approach pose of an object goal)
    path_xy_m: np.ndarray
    path_theta_rad: np.ndarray
    path_s_m: np.ndarray
    path_forward: np.ndarray  # (N,) uint8
    path_curve: str  # "dubins", "reeds_shepp" or "straight"; "escape+" first: a way out of the start first
    left_start: list[float]
    right_start: list[float]
    step_sides: list[str]
    step_poses: np.ndarray  # (K, 3) [x, y, yaw] of each landing
    dt_s: float
    q: np.ndarray  # (T, nq)
    com_m: np.ndarray  # (T, 3)
    zmp_m: np.ndarray  # (T, 2) multibody ZMP (without the carried bar)
    duration_s: float
    reshaping: ReshapingReport
    timings_s: dict[str, float]  # path_s, footsteps_s, stage2_s, total_s
    replans: int = 0  # times stage 2 sent stage 1 back for a path with a larger margin (body too close)


GOTO = EndpointSpec(
    "navigation",
    "goto",
    GotoRequest,
    GotoReply,
    "walk to a pose or in front of an object: car-like path, footsteps, 5 ms whole-body trajectory, "
    "smooth reshaping of a carried bar",
)
