"""Reference trajectories of the hand and of the gaze point, sampled on the 5 ms grid.

The reaching task of the paper is a desired velocity of the hand towards the target (Fig. 4). Here the
hand reference moves along a minimum-jerk profile s(t) from where the hand is to the target, expressed in
the *body frame* (origin at the planned CoM on the ground, x axis along the planned waist yaw): the hand
is carried along while the robot steps and turns towards the target, and completes its own motion
relative to the body. Without stepping the body frame is fixed and this is a straight minimum-jerk line
in the world. The gaze point is interpolated the same way, from straight ahead of the head to the target.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from services.walking.zmp_reference import smoothstep5


def minimum_jerk(times_s: np.ndarray, start_s: float, duration_s: float) -> np.ndarray:
    """Quintic 0 -> 1 profile over [start_s, start_s + duration_s] [s] (zero velocity and acceleration at
    both ends), 0 before and 1 after."""
    return smoothstep5((np.asarray(times_s, dtype=float) - start_s) / max(duration_s, 1e-9))


def rot_z(yaw_rad: float) -> np.ndarray:
    """Rotation about the world z axis (3, 3)."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _to_body(point_world: np.ndarray, body_xy: np.ndarray, body_yaw: float) -> np.ndarray:
    rel = np.array([point_world[0] - body_xy[0], point_world[1] - body_xy[1], point_world[2]])
    return rot_z(body_yaw).T @ rel


def body_frame_path(
    body_xy_m: np.ndarray,
    body_yaw_rad: np.ndarray,
    s: np.ndarray,
    p_start_world_m: np.ndarray,
    p_end_world_m: np.ndarray,
) -> np.ndarray:
    """(n, 3) world points [m] moving from ``p_start`` (at sample 0) to ``p_end`` (at the last sample)
    along the profile ``s`` (n,), linearly in the body frame (origin ``body_xy_m`` (n, 2) on the ground,
    yaw ``body_yaw_rad`` (n,))."""
    r0 = _to_body(p_start_world_m, body_xy_m[0], float(body_yaw_rad[0]))
    r1 = _to_body(p_end_world_m, body_xy_m[-1], float(body_yaw_rad[-1]))
    rel = (1.0 - s)[:, None] * r0 + s[:, None] * r1
    c, sn = np.cos(body_yaw_rad), np.sin(body_yaw_rad)
    out = np.empty((s.shape[0], 3))
    out[:, 0] = body_xy_m[:, 0] + c * rel[:, 0] - sn * rel[:, 1]
    out[:, 1] = body_xy_m[:, 1] + sn * rel[:, 0] + c * rel[:, 1]
    out[:, 2] = rel[:, 2]
    return out


def body_frame_rotations(
    body_yaw_rad: np.ndarray, s: np.ndarray, R_start_world: np.ndarray, R_end_world: np.ndarray
) -> np.ndarray:
    """(n, 3, 3) orientations from ``R_start`` to ``R_end``: geodesic (slerp) interpolation along ``s`` of
    the orientation relative to the body yaw, carried by the body's turn."""
    A = rot_z(float(body_yaw_rad[0])).T @ R_start_world
    B = rot_z(float(body_yaw_rad[-1])).T @ R_end_world
    log_AB = pin.log3(A.T @ B)
    out = np.empty((s.shape[0], 3, 3))
    for k in range(s.shape[0]):
        out[k] = rot_z(float(body_yaw_rad[k])) @ A @ pin.exp3(s[k] * log_AB)
    return out
