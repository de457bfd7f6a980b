"""The walking pattern: footsteps + timing -> CoM, ZMP, sole and waist trajectories on the 5 ms grid.

The first stage of Kajita et al. 2003: a ZMP reference inside the support polygons
(:mod:`services.walking.zmp_reference`), the cart-table preview control for the horizontal CoM
(:mod:`services.walking.preview_control`), the CoM at constant height, swing-foot trajectories
(:mod:`services.walking.swing`) and the waist yaw following the feet (the mean of the two sole yaws).
The whole-body stage (:mod:`services.walking.wholebody`) turns a :class:`WalkPattern` into joint
trajectories.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from services.errors import InvalidRequestError
from services.walking.footsteps import (
    FootstepBounds,
    FootstepSequence,
    SolePose,
    validate_footsteps,
    wrap_angle,
)
from services.walking.preview_control import PreviewGains, preview_gains, settle_at_end, simulate
from services.walking.swing import swing_trajectory
from services.walking.timing import LEFT, PHASE_NAMES, RIGHT, Schedule, WalkTiming, build_schedule
from services.walking.zmp_reference import smoothstep5, zmp_reference


@dataclass(frozen=True)
class PatternOptions:
    """Options of the pattern generator.

    ``com_height_m`` is z_c of the cart-table [m] (default: the height of ``initial_com_m`` given to
    :func:`plan_pattern`); when both are given and differ, the CoM height moves from the initial one
    to ``com_height_m`` during the first standing segment. ``zmp_offset_m`` is (forward, inward) [m] of
    the ZMP target in each support sole. ``q_e`` and ``r`` are the preview-control weights (Kajita 2003:
    1 and 1e-6).
    """

    com_height_m: float | None = None
    step_height_m: float = 0.05
    preview_horizon_s: float = 1.6
    q_e: float = 1.0
    r: float = 1e-6
    zmp_offset_m: tuple[float, float] = (0.0, 0.0)
    swing_horizontal_delay_ratio: float = 0.1


@dataclass(frozen=True)
class WalkPattern:
    """A walk on the grid ``times_s`` (n samples, world frame, flat ground z = ``ground_z_m``).

    Sole arrays are (n, 4) = (x [m], y [m], z [m], yaw [rad]) with continuous (unwrapped) yaw, and their
    time derivatives. ``phase`` is DOUBLE / LEFT / RIGHT (LEFT: the left sole supports).
    """

    times_s: np.ndarray
    com_m: np.ndarray  # (n, 3)
    com_vel_m_s: np.ndarray  # (n, 3)
    com_acc_m_s2: np.ndarray  # (n, 3)
    zmp_ref_m: np.ndarray  # (n, 2) reference given to the preview control
    zmp_planned_m: np.ndarray  # (n, 2) ZMP of the cart-table CoM motion
    left_sole: np.ndarray  # (n, 4)
    right_sole: np.ndarray  # (n, 4)
    left_sole_vel: np.ndarray  # (n, 4)
    right_sole_vel: np.ndarray  # (n, 4)
    waist_yaw_rad: np.ndarray  # (n,)
    waist_yaw_rate_rad_s: np.ndarray  # (n,)
    phase: np.ndarray  # (n,) int8
    footsteps: FootstepSequence
    timing: WalkTiming
    options: PatternOptions
    schedule: Schedule = field(repr=False)
    gains: PreviewGains = field(repr=False)
    ground_z_m: float = 0.0  # height of the flat ground (and of the soles on it) [m]

    @property
    def dt_s(self) -> float:
        """Sampling period [s]."""
        return self.timing.dt_s

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.times_s.shape[0])

    @property
    def duration_s(self) -> float:
        """Duration [s]."""
        return float(self.times_s[-1])

    @property
    def com_height_m(self) -> float:
        """z_c of the cart-table model [m]."""
        return self.gains.com_height_m

    def sole(self, side: str) -> np.ndarray:
        """(n, 4) sole trajectory of ``side`` ("left" or "right")."""
        if side == "left":
            return self.left_sole
        if side == "right":
            return self.right_sole
        raise InvalidRequestError(f"side must be 'left' or 'right', got {side!r}")

    def sole_transform(self, side: str, k: int) -> np.ndarray:
        """T_world_<side>_sole at sample ``k``: 4x4 homogeneous pose (flat: yaw only)."""
        x, y, z, yaw = self.sole(side)[k]
        c, s = math.cos(yaw), math.sin(yaw)
        T = np.eye(4)
        T[:2, :2] = [[c, -s], [s, c]]
        T[:3, 3] = [x, y, z]
        return T

    def phase_names(self) -> list[str]:
        """Support phase of every sample as "double" / "left" / "right"."""
        return [PHASE_NAMES[int(p)] for p in self.phase]


def _resolve_com(
    seq: FootstepSequence, options: PatternOptions, initial_com_m: np.ndarray | None, ground_z_m: float
) -> tuple[np.ndarray, float]:
    """(initial CoM (3,) [m], z_c [m] above the ground)."""
    if initial_com_m is not None:
        c0 = np.asarray(initial_com_m, dtype=float).reshape(-1)
        if c0.shape != (3,) or not np.all(np.isfinite(c0)):
            raise InvalidRequestError(f"initial_com_m must be 3 finite numbers [m], got {initial_com_m!r}")
    else:
        c0 = None
    z_c = (
        options.com_height_m
        if options.com_height_m is not None
        else (None if c0 is None else c0[2] - ground_z_m)
    )
    if z_c is None:
        raise InvalidRequestError("give the CoM height: options.com_height_m or initial_com_m")
    if not (math.isfinite(z_c) and z_c > 0):
        raise InvalidRequestError(f"the CoM height must be > 0 m, got {z_c}")
    if c0 is None:
        mid = 0.5 * (seq.left_start.as_array()[:2] + seq.right_start.as_array()[:2])
        c0 = np.array([mid[0], mid[1], ground_z_m + z_c])
    return c0, float(z_c)


def _sole_trajectories(
    seq: FootstepSequence, schedule: Schedule, options: PatternOptions, ground_z_m: float
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per side: (pose (n, 4), velocity (n, 4)) with continuous yaw."""
    n = schedule.n_samples
    dt = schedule.dt_s
    left0 = seq.left_start
    # Right start yaw chosen within pi of the left one so that the mean yaw is the waist yaw.
    right0 = seq.right_start
    right0 = SolePose(right0.x_m, right0.y_m, left0.yaw_rad + wrap_angle(right0.yaw_rad - left0.yaw_rad))
    current = {"left": left0, "right": right0}
    out = {}
    for side in ("left", "right"):
        pose = np.empty((n, 4))
        pose[:] = [current[side].x_m, current[side].y_m, ground_z_m, current[side].yaw_rad]
        out[side] = (pose, np.zeros((n, 4)))
    for seg in schedule.segments:
        if seg.role != "swing":
            continue
        step = seq.steps[seg.step_index]
        start = current[step.side]
        end = SolePose(
            step.pose.x_m, step.pose.y_m, start.yaw_rad + wrap_angle(step.pose.yaw_rad - start.yaw_rad)
        )
        traj = swing_trajectory(
            start,
            end,
            seg.n * dt,
            np.arange(seg.n) * dt,
            step_height_m=options.step_height_m,
            horizontal_delay_ratio=options.swing_horizontal_delay_ratio,
            ground_z_m=ground_z_m,
        )
        pose, vel = out[step.side]
        pose[seg.start : seg.stop] = traj.pose
        vel[seg.start : seg.stop] = traj.vel
        pose[seg.stop :] = [end.x_m, end.y_m, ground_z_m, end.yaw_rad]
        current[step.side] = end
    return out


def plan_pattern(
    footsteps: FootstepSequence,
    timing: WalkTiming | None = None,
    options: PatternOptions | None = None,
    *,
    initial_com_m: np.ndarray | None = None,
    bounds: FootstepBounds | None = None,
    ground_z_m: float = 0.0,
) -> WalkPattern:
    """Plan the CoM / ZMP / sole / waist trajectories of a walk (first stage of Kajita 2003).

    Args:
        footsteps: the sole landings; validated against ``bounds`` (default :class:`FootstepBounds`).
        timing: phase durations and the sampling period (default :class:`WalkTiming`).
        options: see :class:`PatternOptions`.
        initial_com_m: the CoM of the robot's starting configuration [m] (world); the CoM starts there
            at rest and the ZMP reference starts below it. Default: above the middle of the soles.
        ground_z_m: height of the flat ground [m]: the soles stay at this height, the swing foot
            rises from it and ``com_height_m`` (z_c) is measured from it. :func:`plan_walk` passes the
            height of the starting soles, so that a robot measured standing a millimetre above z = 0
            (a collision margin) is not asked to push its feet into the floor.

    Raises:
        InvalidRequestError: malformed input (overlapping feet, a zero duration, no CoM height...).
        InfeasibleError: a step outside the bounds (the message names the step).
    """
    timing = timing or WalkTiming()
    options = options or PatternOptions()
    bounds = bounds or FootstepBounds()
    validate_footsteps(footsteps, bounds)
    if not (math.isfinite(options.step_height_m) and options.step_height_m >= 0):
        raise InvalidRequestError(f"step_height_m must be >= 0 m, got {options.step_height_m}")
    if not math.isfinite(ground_z_m):
        raise InvalidRequestError(f"ground_z_m must be a finite height [m], got {ground_z_m}")
    c0, z_c = _resolve_com(footsteps, options, initial_com_m, ground_z_m)

    schedule = build_schedule([s.side for s in footsteps.steps], timing)
    zmp_ref = zmp_reference(footsteps, schedule, offset_m=options.zmp_offset_m, initial_zmp_m=c0[:2])
    gains = preview_gains(timing.dt_s, z_c, options.preview_horizon_s, options.q_e, options.r)
    x0 = np.zeros((3, 2))
    x0[0] = c0[:2]
    res = simulate(gains, zmp_ref, x0)
    # End exactly at rest between the final soles, blended over the last weight transfer and the final
    # hold together: the CoM's residual spread over both, a shorter hold keeps the planned ZMP margins
    # (blended over a 0.2 s hold alone, the ZMP of a 10-step walk swung to 18 mm of the polygon's edge).
    final = next(seg for seg in reversed(schedule.segments) if seg.role in ("final", "initial"))
    res = settle_at_end(res, schedule.n_samples - final.start, timing.dt_s, z_c, zmp_ref[-1])

    n = schedule.n_samples
    com = np.empty((n, 3))
    com_vel = np.zeros((n, 3))
    com_acc = np.zeros((n, 3))
    com[:, :2], com_vel[:, :2], com_acc[:, :2] = res.com_m, res.com_vel_m_s, res.com_acc_m_s2
    com_z_m = ground_z_m + z_c
    com[:, 2] = com_z_m
    if abs(c0[2] - com_z_m) > 1e-9:
        # Height change during the first double-support segment (quintic, zero vel/acc at both ends).
        seg = schedule.segments[0]
        T = seg.n * timing.dt_s
        tau = np.arange(seg.n) / seg.n
        s = smoothstep5(tau)
        ds = 30 * tau**2 * (1 - tau) ** 2 / T
        dds = 60 * tau * (1 - tau) * (1 - 2 * tau) / T**2
        dz = com_z_m - c0[2]
        com[: seg.n, 2] = c0[2] + s * dz
        com_vel[: seg.n, 2] = ds * dz
        com_acc[: seg.n, 2] = dds * dz

    soles = _sole_trajectories(footsteps, schedule, options, ground_z_m)
    left, left_vel = soles["left"]
    right, right_vel = soles["right"]
    waist_yaw = 0.5 * (left[:, 3] + right[:, 3])
    waist_rate = 0.5 * (left_vel[:, 3] + right_vel[:, 3])

    times = schedule.times_s
    arrays = (
        com,
        com_vel,
        com_acc,
        zmp_ref,
        res.zmp_m,
        left,
        right,
        left_vel,
        right_vel,
        waist_yaw,
        waist_rate,
        schedule.phase,
        times,
    )
    for a in arrays:
        a.setflags(write=False)
    return WalkPattern(
        times_s=times,
        com_m=com,
        com_vel_m_s=com_vel,
        com_acc_m_s2=com_acc,
        zmp_ref_m=zmp_ref,
        zmp_planned_m=res.zmp_m,
        left_sole=left,
        right_sole=right,
        left_sole_vel=left_vel,
        right_sole_vel=right_vel,
        waist_yaw_rad=waist_yaw,
        waist_yaw_rate_rad_s=waist_rate,
        phase=schedule.phase,
        footsteps=footsteps,
        timing=timing,
        options=options,
        schedule=schedule,
        gains=gains,
        ground_z_m=float(ground_z_m),
    )


__all__ = ["LEFT", "RIGHT", "PatternOptions", "WalkPattern", "plan_pattern"]
