"""C2 interpolation of free-flyer configurations between IK knots (knots -> the 5 ms grid)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicSpline


def spline_configurations(t_knots_s: np.ndarray, Q: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Clamped cubic spline (zero velocity at both ends) of configurations ``Q`` (k, nq) given at
    ``t_knots_s`` (k,), evaluated at ``t_s`` (n,): base position, base roll/pitch/unwrapped yaw and the
    joints are splined, the quaternion is rebuilt from the angles. Returns (n, nq)."""
    if Q.shape[0] == 1:
        return np.repeat(Q, t_s.shape[0], axis=0)
    rpy = np.array(
        [pin.rpy.matrixToRpy(pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()) for q in Q]
    )
    rpy[:, 2] = np.unwrap(rpy[:, 2])
    values = np.column_stack([Q[:, :3], rpy, Q[:, 7:]])
    S = CubicSpline(t_knots_s, values, bc_type="clamped")(t_s)
    out = np.empty((t_s.shape[0], Q.shape[1]))
    out[:, :3] = S[:, :3]
    roll, pitch, yaw = S[:, 3] / 2, S[:, 4] / 2, S[:, 5] / 2
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    # R = Rz(yaw) Ry(pitch) Rx(roll) as a quaternion (x, y, z, w)
    out[:, 3] = sr * cp * cy - cr * sp * sy
    out[:, 4] = cr * sp * cy + sr * cp * sy
    out[:, 5] = cr * cp * sy - sr * sp * cy
    out[:, 6] = cr * cp * cy + sr * sp * sy
    out[:, 7:] = S[:, 6:]
    return out
