"""Gaze direction task with two rows: the direction to the target, seen from the head, on the gaze axis.

Task (iv) of the reaching paper ("gaze direction"). ``services.ik.GazeTask`` writes the same goal as
u x (B - O) = 0, three rows of rank two: its third singular value is proportional to the error itself,
so the rank the hierarchy detects flips as the error crosses the rank threshold, and with it the
null space left to the levels below (the posture jumps). Here the error has exactly two rows.

With O and R the origin and orientation of the gaze frame, B the target, d = B - O, n = d / |d| and
m = R^T n (the target direction in the gaze frame), F = (m_y, m_z) for a gaze along the frame's x axis:
zero when the x axis points at B (and also when it points exactly away: start facing the target's
half-space). With w and v_O the angular velocity and the velocity of O in world axes,
dm = R^T ([n]x w - (I - n n^T) v_O / |d|).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik import Task
from services.ik.kinematics import frame_id, frame_jacobian, skew


class GazeDirectionTask(Task):
    """Point the x axis of ``frame_name`` at ``target_world_m`` [m]; F (2,) is dimensionless."""

    def __init__(
        self,
        model: pin.Model,
        frame_name: str,
        target_world_m: Sequence[float] | np.ndarray,
        gain: float = 1.0,
        max_step: float | None = None,
        name: str = "gaze",
    ) -> None:
        super().__init__(name, gain, max_step=max_step)
        self.model = model
        self.frame_id = frame_id(model, frame_name)
        self.set_target(target_world_m)

    def set_target(self, target_world_m: Sequence[float] | np.ndarray) -> None:
        """New point to look at [m], world frame."""
        target = np.asarray(target_world_m, dtype=float).reshape(-1)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise InvalidRequestError(
                f"task {self.name!r}: target must be 3 finite numbers, got {target_world_m!r}"
            )
        self.target_world_m = target

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        T = data.oMf[self.frame_id]
        d = self.target_world_m - T.translation
        distance = float(np.linalg.norm(d))
        if distance < 1e-6:
            raise InvalidRequestError(f"task {self.name!r}: the target is at the gaze frame's origin")
        n = d / distance
        J = frame_jacobian(self.model, data, self.frame_id)
        Rt = T.rotation.T
        dm = Rt @ (skew(n) @ J[3:] - (np.eye(3) - np.outer(n, n)) @ J[:3] / distance)
        return (Rt @ n)[1:], dm[1:]
