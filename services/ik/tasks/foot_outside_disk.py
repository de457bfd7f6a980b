"""A foot kept out of a disk on the ground (section 4.1 of the footstep paper, after eqs. 12-13)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.kinematics import frame_id, frame_jacobian
from services.ik.task import Task


class FootOutsideDiskTask(Task):
    """The sole rectangle of ``sole_frame`` (``sole_size_m`` = length along the sole x, width along
    y [m], centred on the frame) stays ``margin_m`` away from the ground disk of centre
    ``center_world_xy`` and radius ``radius_m``.

    The footprint is the sole rectangle placed at the sole's ground position and yaw. B is the
    projection of the disk centre c on the footprint (the closest footprint point, or the closest
    edge point when c is under the sole) and s the signed distance from c to the footprint (negative
    inside). As in the paper, the relative velocity between c and B is bounded with eq. (13):
    G = radius + margin - s <= 0, dG = n^T dB with n the footprint's outward normal at B and B held
    fixed in the footprint (the rotation of n adds nothing because c - B is parallel to n).
    """

    def __init__(
        self,
        model: pin.Model,
        sole_frame: str,
        sole_size_m: tuple[float, float],
        center_world_xy: Sequence[float],
        radius_m: float,
        margin_m: float = 0.0,
        gain: float = 1.0,
        name: str | None = None,
    ) -> None:
        super().__init__(name or f"outside_disk:{sole_frame}", gain, lower=-np.inf, upper=0.0)
        if len(sole_size_m) != 2 or min(sole_size_m) <= 0.0:
            raise InvalidRequestError(f"task {self.name!r}: sole_size_m must be (length, width) > 0 [m]")
        if radius_m < 0.0:
            raise InvalidRequestError(f"task {self.name!r}: radius_m must be >= 0, got {radius_m}")
        self.model = model
        self.frame_id = frame_id(model, sole_frame)
        self.half_size = 0.5 * np.array(sole_size_m, dtype=float)
        self.center_world_xy = np.array(center_world_xy, dtype=float).reshape(2)
        self.clearance_m = float(radius_m) + float(margin_m)

    def _footprint(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray, float]:
        """Planar footprint pose: (origin xy [m], 2x2 rotation by the yaw, yaw [rad])."""
        T = data.oMf[self.frame_id]
        yaw = float(np.arctan2(T.rotation[1, 0], T.rotation[0, 0]))
        c, s = np.cos(yaw), np.sin(yaw)
        return T.translation[:2].copy(), np.array([[c, -s], [s, c]]), yaw

    def _closest(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray, float]:
        """(B in footprint coordinates, outward unit normal at B in world xy, signed distance [m])."""
        origin, R_yaw, _ = self._footprint(data)
        c_local = R_yaw.T @ (self.center_world_xy - origin)
        h = self.half_size
        B_local = np.clip(c_local, -h, h)
        offset = c_local - B_local
        outside = float(np.linalg.norm(offset))
        if outside > 1e-9:
            n_local, signed = offset / outside, outside
        else:
            # c under the sole: nearest edge, negative distance.
            gaps = np.array([h[0] - c_local[0], c_local[0] + h[0], h[1] - c_local[1], c_local[1] + h[1]])
            k = int(np.argmin(gaps))
            n_local = _EDGE_NORMALS[k]
            B_local = c_local + gaps[k] * n_local
            signed = -float(gaps[k])
        return B_local, R_yaw @ n_local, signed

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return np.array([self.clearance_m - self._closest(data)[2]])

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        B_local, n_world, signed = self._closest(data)
        _, R_yaw, _ = self._footprint(data)
        R = data.oMf[self.frame_id].rotation
        J = frame_jacobian(self.model, data, self.frame_id)
        # Exact yaw rate of the sole x axis r projected on the ground, d atan2(r_y, r_x), tilt included.
        r = R[:, 0]
        J_yaw = J[5] - r[2] * (r[0] * J[3] + r[1] * J[4]) / (r[0] ** 2 + r[1] ** 2)
        lever = R_yaw @ B_local
        J_B = J[:2] + np.outer([-lever[1], lever[0]], J_yaw)
        return np.array([self.clearance_m - signed]), (n_world @ J_B)[None, :]


_EDGE_NORMALS = (np.array([1.0, 0.0]), np.array([-1.0, 0.0]), np.array([0.0, 1.0]), np.array([0.0, -1.0]))
