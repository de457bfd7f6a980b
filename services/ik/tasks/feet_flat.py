"""Feet flat on the ground: sole height, roll and pitch (section 3.2 of the footstep paper)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.kinematics import frame_id, frame_jacobian
from services.ik.task import Task


class FeetFlatTask(Task):
    """For each sole frame: z = ``ground_height_m`` and its z axis vertical, leaving x, y and the
    yaw free (the front foot of the footstep chain "authorized to rotate around the vertical").

    Rows per frame: [p_z - h [m], (R e_z)_x, (R e_z)_y]; the last two are sin of the pitch and
    minus sin of the roll to first order. d(R e_z) = w x (R e_z) = -[R e_z]x w.
    """

    def __init__(
        self,
        model: pin.Model,
        sole_frames: Sequence[str],
        ground_height_m: float = 0.0,
        gain: float = 1.0,
        name: str = "feet_flat",
    ) -> None:
        super().__init__(name, gain)
        if len(sole_frames) == 0:
            raise InvalidRequestError(f"task {name!r}: give at least one sole frame")
        self.model = model
        self.frame_ids = [frame_id(model, f) for f in sole_frames]
        self.ground_height_m = float(ground_height_m)

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        m = len(self.frame_ids)
        F = np.empty(3 * m)
        J = np.empty((3 * m, self.model.nv))
        for k, fid in enumerate(self.frame_ids):
            T = data.oMf[fid]
            z = T.rotation[:, 2]
            J_frame = frame_jacobian(self.model, data, fid)
            F[3 * k] = T.translation[2] - self.ground_height_m
            F[3 * k + 1 : 3 * k + 3] = z[:2]
            J[3 * k] = J_frame[2]
            # rows x, y of -[z]x w = w x z: (w_y z_z - w_z z_y, w_z z_x - w_x z_z)
            J[3 * k + 1] = z[2] * J_frame[4] - z[1] * J_frame[5]
            J[3 * k + 2] = z[0] * J_frame[5] - z[2] * J_frame[3]
        return F, J
