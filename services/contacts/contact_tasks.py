"""IK tasks of a *floating* contact (§2.5-2.6 of Escande et al.): the spot's frame lies on the
surface's plane with its inner normal along the surface's outer normal (plane-plane contact, §2.1),
while its position (x, y) and rotation theta on the surface are left to the posture generator inside a
convex search volume C_i. A fixed contact is an ordinary ``FramePoseTask`` on the spot frame.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from services.contacts.environment import Surface
from services.contacts.volumes import SearchVolume
from services.ik import Task
from services.ik.kinematics import frame_id, frame_jacobian, skew


class OnPlaneTask(Task):
    """Equality, 3 rows: the spot frame's origin at height 0 over the surface's plane and its z axis
    along the surface normal, F = (z_local, (R_S^T z_F)_x, (R_S^T z_F)_y)."""

    def __init__(
        self,
        model: pin.Model,
        spot_frame: str,
        surface: Surface,
        gain: float = 1.0,
        max_step: float | None = 0.1,
    ) -> None:
        super().__init__(f"on_plane[{spot_frame}@{surface.name}]", gain, max_step=max_step)
        self.model = model
        self.fid = frame_id(model, spot_frame)
        self.R_S = surface.T_world_surface.rotation.copy()
        self.o_S = surface.T_world_surface.translation.copy()

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        T = data.oMf[self.fid]
        J = frame_jacobian(self.model, data, self.fid)
        n_S = self.R_S[:, 2]
        z_F = T.rotation[:, 2]
        tilt = self.R_S.T.dot(z_F)
        F = np.array([n_S.dot(T.translation - self.o_S), tilt[0], tilt[1]])
        # d z_F = omega x z_F = -[z_F]x omega
        d_tilt = -self.R_S.T.dot(skew(z_F)).dot(J[3:])
        return F, np.vstack((n_S.dot(J[:3]), d_tilt[:2]))


class InVolumeTask(Task):
    """Inequality, 3 rows: (x, y, theta) of the spot frame in the surface's frame within the box
    ``volume`` (theta measured from ``theta_ref`` + wrapped, so a volume may straddle +-pi)."""

    def __init__(
        self, model: pin.Model, spot_frame: str, surface: Surface, volume: SearchVolume, gain: float = 1.0
    ) -> None:
        super().__init__(
            f"in_volume[{spot_frame}@{surface.name}]",
            gain,
            lower=np.array(volume.lower),
            upper=np.array(volume.upper),
        )
        self.model = model
        self.fid = frame_id(model, spot_frame)
        self.R_S = surface.T_world_surface.rotation.copy()
        self.o_S = surface.T_world_surface.translation.copy()
        self.theta_mid = 0.5 * (volume.lower[2] + volume.upper[2])

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        T = data.oMf[self.fid]
        J = frame_jacobian(self.model, data, self.fid)
        local = self.R_S.T.dot(T.translation - self.o_S)
        a = self.R_S.T.dot(T.rotation[:, 0])
        theta = math.atan2(a[1], a[0])
        # unwrap around the volume's middle so that the bounds compare with a continuous angle
        theta = self.theta_mid + (theta - self.theta_mid + math.pi) % (2.0 * math.pi) - math.pi
        da = -self.R_S.T.dot(skew(T.rotation[:, 0])).dot(J[3:])
        r2 = max(a[0] * a[0] + a[1] * a[1], 1e-9)
        d_theta = (a[0] * da[1] - a[1] * da[0]) / r2
        d_xy = self.R_S.T[:2].dot(J[:3])
        return np.array([local[0], local[1], theta]), np.vstack((d_xy, d_theta))
