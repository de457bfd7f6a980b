"""Stage 2 of the two-stage planner: the dynamic whole-body motion along the footsteps, its 3D collision
check, and the smooth reshaping loop (Figures 1 and 2 of `001_771c0ce3779b0683.txt`).

"In the second stage, this output path is given as inputs to the dynamic pattern generator of the
humanoid robot that transforms it into a dynamically executable motion. [...] If the generated dynamic
motion induces unpredicted collisions due to deviation from the geometrically and kinematically planned
path, then the planner goes back to the first stage to 'reshape' the previous path" ("Two-stage Planning
Method"). :func:`plan_motion`:

1. the walking pattern (ZMP preview control, ``services.walking``) of the footsteps; the whole-body IK
   tracks it with the caller's upper-body task: both hands on the bar (:class:`HandOnBarTask`), the bar
   carried with the walk at its nominal height (:func:`nominal_bar_trajectory`);
2. the motion (robot and bar) is checked against the scene in 3D (:class:`MotionChecker`);
3. for each collision of the bar or the arms: the colliding times and, around them, the anticipating and
   regaining times where the part comes within ``target_clearance_m`` (Figure 2 (a)); the bar's height
   is key-framed over the obstacle (its top + the bar's radius + the clearance) and interpolated by
   quintics (b), resampled at 5 ms (c) and enforced by the whole-body IK (d) (:mod:`reshaping`);
4. repeat until no part comes closer than ``required_clearance_m`` or ``max_iterations`` whole-body
   solutions are spent: then InfeasibleError names the obstacle and the part.

The reshaped motion is the walking planner's output, so its multibody ZMP is checked by the walking
package (second preview stage when it leaves the polygon); :func:`plan_motion` checks it once more with
the bar's mass on the left hand (``zmp_margin_m``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from services import budget
from services.bus.schemas.navigation import (
    REASON_BAR_OUT_OF_REACH,
    REASON_BODY_COLLISION,
    REASON_NO_COLLISION_FREE_RESHAPING,
    REASON_ZMP_OUTSIDE_SUPPORT,
)
from services.collision.carried import BarGrip, CarriedBar
from services.collision.motion import RESHAPABLE_GROUPS, CollisionEvent, MotionCheck, MotionChecker
from services.collision.obstacles import Scene
from services.errors import InfeasibleError, InvalidRequestError
from services.ik import Level
from services.navigation.bar_sampling import ArmReach, BarPoseSampler, SampleStats
from services.navigation.carry import (
    BarTrajectory,
    HandOnBarTask,
    bar_poses,
    grip_from_configuration,
    hands_on_bar,
    nominal_bar_trajectory,
)
from services.navigation.keyframes import next_windows
from services.navigation.reshaping import ReshapeOptions, ReshapeWindow, reshaped_trajectory
from services.walking.footsteps import FootstepSequence
from services.walking.pattern import WalkPattern
from services.walking.timing import WalkTiming
from services.walking.two_stage import SupportSamples, robot_pattern
from services.walking.wholebody import WholeBodyOptions, WholeBodyPlanner, WholeBodyResult
from services.walking.zmp_reference import smoothstep5

CARRY_COM_LOWERING_M = 0.03
"""Holding the bar ahead moves the pelvis back (the CoM stays above the feet), so a 0.2 m step stretches
the front knee nearly straight (hrp2_like: 0.17 rad) and it snaps at 4.6 rad/s, above its 4 rad/s limit;
walking 3 cm lower keeps it bent (0.56 rad at -2 cm, 3.6 rad/s)."""


@dataclass(frozen=True)
class Stage2Options:
    """Options of :func:`plan_motion`.

    - ``timing``: the walk's phase durations (``services.walking.timing.WalkTiming``);
    - ``carry_height_m`` [m]: height of the bar's centre while walking; the bar moves there from its
      starting height during the standing start (None: keep the starting height);
    - ``reshape``: :class:`ReshapeOptions`;
    - ``wholebody``: ``services.walking.wholebody.WholeBodyOptions``;
    - ``min_zmp_margin_m`` [m]: the multibody ZMP (bar included) must stay this far inside the support
      polygon (0: inside);
    - ``check_stride``: check every ``check_stride``-th sample (1: every 5 ms);
    - ``com_lowering_m`` [m]: the walk's CoM height is the starting one minus this (lowered during the
      standing start); None: :data:`CARRY_COM_LOWERING_M` when a bar is carried, else 0.
    """

    timing: WalkTiming = field(default_factory=WalkTiming)
    carry_height_m: float | None = None
    reshape: ReshapeOptions = field(default_factory=ReshapeOptions)
    wholebody: WholeBodyOptions = field(default_factory=WholeBodyOptions)
    min_zmp_margin_m: float = 0.0
    check_stride: int = 1
    com_lowering_m: float | None = None

    def __post_init__(self) -> None:
        if self.carry_height_m is not None and not (
            math.isfinite(self.carry_height_m) and self.carry_height_m > 0
        ):
            raise InvalidRequestError(f"carry_height_m must be > 0 m or None, got {self.carry_height_m}")
        if self.com_lowering_m is not None and not (0.0 <= self.com_lowering_m <= 0.15):
            raise InvalidRequestError(
                f"com_lowering_m must be within 0 and 0.15 m, got {self.com_lowering_m}"
            )
        if self.check_stride < 1:
            raise InvalidRequestError(f"check_stride must be >= 1, got {self.check_stride}")


@dataclass(frozen=True)
class ReshapeIteration:
    """One whole-body solution of the loop: its smallest clearance [m], the events found (closer than the
    required clearance) and the windows it was solved with; ``rejected``: why the whole-body IK could not
    follow these windows (mode ``"sample"``: they are sampled again), else empty."""

    index: int
    min_clearance_m: float
    events: tuple[CollisionEvent, ...]
    windows: tuple[ReshapeWindow, ...]
    wall_time_s: float
    rejected: str = ""


@dataclass(frozen=True, eq=False)
class WholeBodyMotion:
    """The stage-2 result on the 5 ms grid.

    ``q`` (n, nq) the whole-body trajectory, ``wholebody`` the walking package's result (pattern, CoM,
    multibody ZMP without the bar), ``check`` the final 3D check, ``windows`` the lift windows applied,
    ``iterations`` the loop's history. Bar (None fields when nothing is carried): ``bar_height_nominal_m``
    (n,) before reshaping, ``bar_height_planned_m`` (n,) the reshaped task-space profile, ``bar_centre_m``
    (n, 3) where the hands really hold it (left hand, rigid), ``bar_height_first_m`` (n,) that height in
    the first, unreshaped, whole-body solution (whose 3D check is ``first_check``); ``hand_error_m`` the
    largest distance between the bar's planned and realised centre or between the hands [m].
    ``zmp_margin_m`` is the smallest distance [m] of the multibody ZMP (bar's mass included) inside the
    support polygon (< 0: outside). ``bar_axis`` (n, 3) the bar's realised axis (``bar_centre_first_m``,
    ``bar_axis_first`` (n, 3): centre [m] and axis in the first solution), ``bar_planned`` the
    reshaped task-space trajectory (key frames interpolated at 5 ms), ``sampling`` what each random
    sampling did (mode ``"sample"``), ``mode`` the reshaping mode.
    """

    times_s: np.ndarray
    q: np.ndarray
    wholebody: WholeBodyResult
    check: MotionCheck
    windows: tuple[ReshapeWindow, ...]
    iterations: tuple[ReshapeIteration, ...]
    zmp_margin_m: float
    wall_time_s: float
    bar_height_nominal_m: np.ndarray | None = None
    bar_height_planned_m: np.ndarray | None = None
    bar_height_first_m: np.ndarray | None = None
    bar_centre_m: np.ndarray | None = None
    hand_error_m: float = 0.0
    first_check: MotionCheck | None = None
    bar_axis: np.ndarray | None = None
    bar_centre_first_m: np.ndarray | None = None
    bar_axis_first: np.ndarray | None = None
    bar_planned: BarTrajectory | None = None
    sampling: tuple[SampleStats, ...] = ()
    mode: str = "sample"

    @property
    def pattern(self) -> WalkPattern:
        return self.wholebody.pattern

    @property
    def reshaped(self) -> bool:
        """True when at least one lift window was applied."""
        return bool(self.windows)

    def report(self) -> dict[str, Any]:
        """Plain-data summary of the reshaping (for replies, benchmarks and logs)."""
        return {
            "iterations": len(self.iterations),
            "segments_lifted": [
                {
                    "t_anticipate_s": w.t_anticipate_s,
                    "t_collide_s": w.t_collide_s,
                    "t_collide_end_s": w.t_collide_end_s,
                    "t_regain_s": w.t_regain_s,
                    "height_m": w.height_m,
                    "obstacles": list(w.obstacles),
                }
                for w in self.windows
            ],
            "mode": self.mode,
            "key_frames": [
                [{"key_frame": name, "t_s": t_s, **offset.__dict__} for name, t_s, offset in w.key_frames()]
                for w in self.windows
            ],
            "samples": [s.__dict__ for s in self.sampling],
            "min_clearance_m": self.check.min_clearance_m,
            "zmp_margin_m": self.zmp_margin_m,
            "hand_error_m": self.hand_error_m,
            "wall_time_s": self.wall_time_s,
            "history": [
                {
                    "iteration": it.index,
                    "min_clearance_m": it.min_clearance_m,
                    "collisions": [
                        {
                            "part": e.group,
                            "link": e.link,
                            "obstacle": e.obstacle,
                            "t_start_s": e.t_start_s,
                            "t_end_s": e.t_end_s,
                            "min_distance_m": e.min_distance_m,
                        }
                        for e in it.events
                    ],
                }
                for it in self.iterations
            ],
        }


def _with_bar_mass(model: pin.Model, grip: BarGrip) -> pin.Model:
    """A copy of ``model`` with the bar's mass (a uniform rod) on the left hand's joint."""
    out = pin.Model(model)
    frame = out.frames[out.getFrameId(grip.grasp_frames["left"])]
    T_joint_bar = frame.placement * grip.T_left_grasp_bar
    bar = grip.bar
    ixx = 0.5 * bar.mass_kg * bar.radius_m**2
    iyy = bar.mass_kg * (3.0 * bar.radius_m**2 + bar.length_m**2) / 12.0
    inertia_bar = pin.Inertia(bar.mass_kg, np.zeros(3), np.diag([ixx, iyy, iyy]))
    out.appendBodyToJoint(frame.parentJoint, inertia_bar, T_joint_bar)
    return out


def _nominal_heights(pattern: WalkPattern, start_height_m: float, carry_height_m: float | None) -> np.ndarray:
    """Bar height (n,) [m]: from the starting height to the carry height during the standing start
    (quintic), then constant."""
    h = np.full(pattern.n_samples, start_height_m)
    if carry_height_m is None or abs(carry_height_m - start_height_m) < 1e-9:
        return h
    first = pattern.schedule.segments[0]
    n = max(first.n, 1)
    s = np.ones(pattern.n_samples)
    s[:n] = smoothstep5(np.arange(n) / n)
    return start_height_m + s * (carry_height_m - start_height_m)


def _check_hands(
    robot: Any,
    grip: BarGrip,
    q: np.ndarray,
    trajectory: BarTrajectory,
    options: ReshapeOptions,
    windows: list[ReshapeWindow],
) -> tuple[np.ndarray, np.ndarray, float]:
    """The bar's realised centre (n, 3) [m], axis (n, 3) along the motion ``q`` (n, nq) and the hands'
    largest error [m] from its planned ``trajectory``; InfeasibleError (``bar_out_of_reach``) when that
    error is above ``max_hand_error_m``."""
    centre, axis, grip_err = bar_poses(robot, grip, q)
    hand_error = float(max(np.abs(centre - trajectory.centre_m).max(), grip_err.max()))
    if hand_error > options.max_hand_error_m:
        worst = max(windows, key=lambda w: w.offset.displacement_m(0.5 * grip.bar.length_m), default=None)
        raise InfeasibleError(
            f"the arms do not hold the bar where the reshaped motion puts it: "
            f"{1e3 * hand_error:.0f} mm off (at most {1e3 * options.max_hand_error_m:.0f} mm)"
            + (
                f" while moving it to {worst.height_m:.2f} m (roll {math.degrees(worst.offset.roll_rad):.0f}"
                f" deg, yaw {math.degrees(worst.offset.yaw_rad):.0f} deg) near {list(worst.obstacles)}"
                if worst
                else ""
            )
            + ": lower max_bar_height_m, or go around the obstacle",
            {
                "reason": REASON_BAR_OUT_OF_REACH,
                "hand_error_m": hand_error,
                "obstacles": sorted({o for w in windows for o in w.obstacles}),
            },
        )
    return centre, axis, hand_error


def plan_motion(
    robot: Any,
    scene: Scene,
    footsteps: FootstepSequence,
    q_start: np.ndarray,
    bar: CarriedBar | None = None,
    options: Stage2Options | None = None,
) -> WholeBodyMotion:
    """The dynamic whole-body motion walking ``footsteps`` from ``q_start`` (soles on the footsteps'
    start), holding ``bar`` in both hands as at ``q_start`` (None: nothing carried), reshaped until it
    clears the scene's obstacles in 3D.

    Raises InfeasibleError (``details["reason"]``): ``body_collision`` (the waist, chest, head or legs
    meet an obstacle: not something the bar's reshaping can fix), ``lift_too_high`` (clearing the
    obstacle needs the bar above ``max_bar_height_m``), ``bar_out_of_reach`` (the arms do not follow the
    bar's reshaped motion within ``max_hand_error_m``), ``no_collision_free_reshaping`` (the iteration
    budget is spent), ``zmp_outside_support``; the walking package's errors for the footsteps.
    """
    options = options or Stage2Options()
    rs = options.reshape
    t_wall = time.perf_counter()
    q_start = robot.check_q(q_start)
    lowering = options.com_lowering_m
    if lowering is None:
        lowering = CARRY_COM_LOWERING_M if bar is not None else 0.0
    pattern = robot_pattern(robot, footsteps, q_start, options.timing, com_lowering_m=lowering)
    planner = WholeBodyPlanner(robot, options.wholebody)
    grip = grip_from_configuration(robot, q_start, bar) if bar is not None else None
    checker = MotionChecker(robot, scene, grip)
    times = pattern.times_s

    nominal = first_heights = first_check = nominal_bar = sampler = None
    first_pose: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
    stats: list[SampleStats] = []
    extra: list[Level] = []
    update = None
    tasks: dict[str, HandOnBarTask] = {}
    if grip is not None:
        nominal = _nominal_heights(pattern, float(grip.centre_world_m[2]), options.carry_height_m)
        tasks = hands_on_bar(planner.model, grip)
        extra = [Level((tasks["left"], tasks["right"]), name="hands_on_bar")]
        nominal_bar = nominal_bar_trajectory(pattern, grip, nominal)
        if rs.mode == "sample":
            reach = ArmReach(
                robot, planner.model, grip, planner.reduce_q, planner.expand_q, rs.sampling.ik_iterations
            )
            rng = np.random.default_rng(rs.sampling.seed)
            sampler = BarPoseSampler(scene, grip, rs, reach, rng, checker)

    windows: list[ReshapeWindow] = []
    history: list[ReshapeIteration] = []
    last: tuple | None = None  # the last checked motion's (events, check, windows, centre, q)
    rejected: list[ReshapeWindow] = []
    for iteration in range(rs.max_iterations):
        budget.check(
            f"navigation's stage 2, reshaping iteration {iteration + 1} of {rs.max_iterations}",
            {"iterations_done": iteration},
        )
        t_it = time.perf_counter()
        trajectory: BarTrajectory | None = None
        if nominal_bar is not None:
            trajectory = reshaped_trajectory(nominal_bar, windows)

            def update(k: int, t_s: float, com_ref: np.ndarray, traj: BarTrajectory = trajectory) -> None:
                for side, task in tasks.items():
                    task.set_target(traj.held_point(grip, side, k), traj.axis[k])

        try:
            result = planner.solve(pattern, q_start, extra_levels=extra, update_extra=update)
            centre = hand_error = bar_axis = None
            if grip is not None and trajectory is not None:
                centre, bar_axis, hand_error = _check_hands(robot, grip, result.q, trajectory, rs, windows)
        except InfeasibleError as error:
            # "an IK solver is applied to ensure the geometric constraints": the arms cannot follow the
            # sampled configuration (too fast, too far): sample other ones
            if last is None or rs.mode != "sample" or iteration == rs.max_iterations - 1:
                raise
            rejected.extend(w for w in windows if w not in last[2])
            history.append(
                ReshapeIteration(
                    iteration, math.nan, (), tuple(windows), time.perf_counter() - t_it, error.message
                )
            )
            windows, sampled = next_windows(*last, nominal_bar, scene, grip, rs, sampler, rejected=rejected)
            stats.extend(sampled)
            continue
        check = checker.check(
            result.q, pattern.dt_s, release_m=rs.required_clearance_m, stride=options.check_stride
        )
        events = check.events(rs.required_clearance_m)
        if centre is not None and iteration == 0:
            first_heights = centre[:, 2].copy()
            first_pose = (centre, bar_axis)
        if iteration == 0:
            first_check = check
        history.append(
            ReshapeIteration(
                iteration, check.min_clearance_m, tuple(events), tuple(windows), time.perf_counter() - t_it
            )
        )
        if not events:
            break
        blocking = [e for e in events if e.group not in RESHAPABLE_GROUPS or grip is None]
        if blocking:
            e = min(blocking, key=lambda e: e.min_distance_m)
            raise InfeasibleError(
                f"the robot's {e.link} ({e.group}) comes {1e3 * e.min_distance_m:.0f} mm from "
                f"{e.obstacle!r} at t={e.t_min_s:.2f} s (at least {1e3 * rs.required_clearance_m:.0f} mm "
                f"needed); reshaping the carried object cannot fix that: plan the path with a larger "
                f"footprint margin or farther from {e.obstacle!r}",
                {
                    "reason": REASON_BODY_COLLISION,
                    "obstacle": e.obstacle,
                    "link": e.link,
                    "part": e.group,
                    "t_s": e.t_min_s,
                    "distance_m": e.min_distance_m,
                },
            )
        if iteration == rs.max_iterations - 1 or nominal_bar is None or centre is None or grip is None:
            break  # budget spent (without a grip every event was blocking: raised above)
        # Figure 2 (a)-(b): the key frames of the next solution (keyframes.py, bar_sampling.py)
        last = (events, check, windows, centre, result.q)
        windows, sampled = next_windows(*last, nominal_bar, scene, grip, rs, sampler, rejected=rejected)
        stats.extend(sampled)
    if events:
        e = min(events, key=lambda e: e.min_distance_m)
        raise InfeasibleError(
            f"no collision-free reshaping within {rs.max_iterations} whole-body solutions: the {e.link} "
            f"({e.group}) still comes {1e3 * e.min_distance_m:.0f} mm from {e.obstacle!r} at "
            f"t={e.t_min_s:.2f} s: go around {e.obstacle!r} or allow more iterations",
            {
                "reason": REASON_NO_COLLISION_FREE_RESHAPING,
                "obstacle": e.obstacle,
                "link": e.link,
                "distance_m": e.min_distance_m,
                "iterations": rs.max_iterations,
            },
        )
    zmp_model = _with_bar_mass(robot.model, grip) if grip is not None else robot.model
    _, dist = SupportSamples.of_pattern(pattern, robot.sole_size_m).zmp_distance(zmp_model, result.q)
    zmp_margin = float(-dist.max())
    if zmp_margin < options.min_zmp_margin_m:
        k = int(np.argmax(dist))
        raise InfeasibleError(
            f"the multibody ZMP (carried bar included) leaves the support polygon by "
            f"{1e3 * dist[k]:.1f} mm at t={times[k]:.2f} s (margin needed "
            f"{1e3 * options.min_zmp_margin_m:.0f} mm): walk more slowly",
            {"reason": REASON_ZMP_OUTSIDE_SUPPORT, "t_s": float(times[k]), "outside_m": float(dist[k])},
        )
    return WholeBodyMotion(
        times_s=times,
        q=result.q,
        wholebody=result,
        check=check,
        windows=tuple(windows),
        iterations=tuple(history),
        zmp_margin_m=zmp_margin,
        wall_time_s=time.perf_counter() - t_wall,
        bar_height_nominal_m=nominal,
        bar_height_planned_m=None if trajectory is None else trajectory.centre_m[:, 2].copy(),
        bar_height_first_m=first_heights,
        bar_centre_m=centre,
        hand_error_m=0.0 if hand_error is None else hand_error,
        first_check=first_check,
        bar_axis=bar_axis,
        bar_centre_first_m=first_pose[0],
        bar_axis_first=first_pose[1],
        bar_planned=trajectory,
        sampling=tuple(stats),
        mode=rs.mode,
    )
