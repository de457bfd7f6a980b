"""Frame orientation task: the rotation error log3(R R_target^T) = 0 on selected world axes."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.kinematics import frame_id, frame_jacobian
from services.ik.task import Task
from services.ik.tasks._mask import axis_rows


class FrameOrientationTask(Task):
    """Orientation of frame ``frame_name`` equal to ``R_world_target`` (3x3 rotation).

    F = log3(R_world_frame R_world_target^T) [rad], the rotation vector that brings the target onto
    the frame, expressed in world axes so that ``mask`` selects rotations about world x, y, z (e.g.
    ``(True, True, False)`` leaves the yaw free). With the world angular velocity w = J_w dq,
    dF = Jlog3(R_e) R_e^T w (left perturbation of R_e = R R_target^T).
    """

    def __init__(
        self,
        model: pin.Model,
        frame_name: str,
        R_world_target: np.ndarray,
        mask: Sequence[bool] = (True, True, True),
        gain: float = 1.0,
        lower: float | np.ndarray | None = None,
        upper: float | np.ndarray | None = None,
        max_step: float | None = None,
        name: str | None = None,
    ) -> None:
        super().__init__(name or f"orientation:{frame_name}", gain, lower, upper, max_step)
        self.model = model
        self.frame_id = frame_id(model, frame_name)
        self.rows = axis_rows(mask, 3, self.name)
        self.set_target(R_world_target)

    def set_target(self, R_world_target: np.ndarray) -> None:
        """New target rotation (3x3, orthonormal, det +1) in the world frame."""
        self.R_world_target = rotation_matrix(R_world_target, f"task {self.name!r}: target")

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        # R_e^T = R_target R^T; log3(R_e) = -log3(R_e^T) and Jlog3(R_e) R_e^T = Jlog3(R_e^T).
        R_eT = self.R_world_target.dot(data.oMf[self.frame_id].rotation.T)
        J_angular = frame_jacobian(self.model, data, self.frame_id)[3:]
        return -pin.log3(R_eT)[self.rows], pin.Jlog3(R_eT)[self.rows].dot(J_angular)


_EYE3 = np.eye(3)
#: ``np.allclose(R @ R.T, I, atol=1e-6)``'s tolerance element by element (its rtol 1e-5 times |I|): the
#: same test without allclose's Python overhead (~60 us), which was a fifth of a walk's whole-body solve
#: (a target set at every knot).
_ORTHONORMAL_TOL = 1e-6 + 1e-5 * _EYE3


def rotation_matrix(value: np.ndarray, what: str) -> np.ndarray:
    """A copy of ``value`` as a 3x3 rotation matrix, or InvalidRequestError naming ``what`` (not
    orthonormal within 1e-6, a reflection, non-finite)."""
    R = np.array(value, dtype=float)
    if R.shape != (3, 3) or not (np.abs(R @ R.T - _EYE3) <= _ORTHONORMAL_TOL).all():  # False for NaN
        raise InvalidRequestError(f"{what} must be a 3x3 rotation matrix (orthonormal, det +1)")
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    if a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) < 0.0:  # a reflection
        raise InvalidRequestError(f"{what} must be a 3x3 rotation matrix (orthonormal, det +1)")
    return R
