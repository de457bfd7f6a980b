"""Swing-foot trajectories: the sole stays flat, leaves and lands with zero velocity and acceleration.

Horizontal position and yaw follow the quintic smoothstep s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 (zero
velocity and acceleration at both ends) over the central part of the swing: it starts after
``horizontal_delay_ratio`` of the swing and ends as much before touchdown, so that the foot lifts before
it moves and lands vertically. The height is h(tau) = 64 step_height tau^3 (1 - tau)^3 over the whole
swing: peak ``step_height_m`` at mid-swing, and zero velocity and acceleration at lift-off and touchdown.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.errors import InvalidRequestError
from services.model.ground import SolePose, smoothstep5_derivatives, wrap_angle


@dataclass(frozen=True)
class SwingTrajectory:
    """Sole pose of a swinging foot on n samples: x, y, z [m], yaw [rad] and their time derivatives."""

    pose: np.ndarray  # (n, 4): x, y, z, yaw
    vel: np.ndarray  # (n, 4) [m/s, rad/s]
    acc: np.ndarray  # (n, 4) [m/s^2, rad/s^2]


def _bump(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """64 tau^3 (1 - tau)^3 (peak 1 at 1/2) and its first two derivatives with respect to tau."""
    t = np.clip(tau, 0.0, 1.0)
    u = 1 - t
    h = 64 * t**3 * u**3
    dh = 192 * t * t * u * u * (u - t)
    ddh = 192 * (2 * t * u * u * (1 - 2 * t) - 2 * t * t * u * (1 - 2 * t) - 2 * t * t * u * u)
    return h, dh, ddh


def swing_trajectory(
    start: SolePose,
    end: SolePose,
    duration_s: float,
    times_s: np.ndarray,
    *,
    step_height_m: float,
    horizontal_delay_ratio: float = 0.1,
    ground_z_m: float = 0.0,
) -> SwingTrajectory:
    """Swing from ``start`` to ``end`` (sole poses on the ground) in ``duration_s`` [s], evaluated at
    ``times_s`` [s] measured from lift-off (values outside [0, duration] clamp to the ends).

    The yaw goes the short way round. ``horizontal_delay_ratio`` in [0, 0.5) is the fraction of the swing
    at each end during which the foot only moves vertically.
    """
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise InvalidRequestError(f"swing duration must be > 0 s, got {duration_s}")
    if not 0.0 <= horizontal_delay_ratio < 0.5:
        raise InvalidRequestError(f"horizontal_delay_ratio must be in [0, 0.5), got {horizontal_delay_ratio}")
    if not (np.isfinite(step_height_m) and step_height_m >= 0):
        raise InvalidRequestError(f"step_height_m must be >= 0 m, got {step_height_m}")
    times = np.asarray(times_s, dtype=float)
    tau = times / duration_s
    r = horizontal_delay_ratio
    span = 1.0 - 2.0 * r
    s, ds, dds = smoothstep5_derivatives((tau - r) / span)
    inside = (tau > r) & (tau < 1 - r)
    ds = np.where(inside, ds, 0.0) / (span * duration_s)
    dds = np.where(inside, dds, 0.0) / (span * duration_s) ** 2
    h, dh, ddh = _bump(tau)
    in_swing = (tau > 0) & (tau < 1)
    dh = np.where(in_swing, dh, 0.0) / duration_s
    ddh = np.where(in_swing, ddh, 0.0) / duration_s**2

    delta = np.array([end.x_m - start.x_m, end.y_m - start.y_m, wrap_angle(end.yaw_rad - start.yaw_rad)])
    n = times.shape[0]
    pose = np.empty((n, 4))
    vel = np.empty((n, 4))
    acc = np.empty((n, 4))
    pose[:, [0, 1, 3]] = start.as_array() + s[:, None] * delta
    vel[:, [0, 1, 3]] = ds[:, None] * delta
    acc[:, [0, 1, 3]] = dds[:, None] * delta
    pose[:, 2] = ground_z_m + step_height_m * h
    vel[:, 2] = step_height_m * dh
    acc[:, 2] = step_height_m * ddh
    return SwingTrajectory(pose, vel, acc)
