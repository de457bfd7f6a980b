"""Posture task q - q_rest = 0 on a subset of joints (eq. 14 of the footstep paper)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.kinematics import joint_id
from services.ik.task import Task


class PostureTask(Task):
    """Joints ``joint_names`` (default: every 1-dof-per-coordinate joint, i.e. all actuated joints of
    a free-flyer robot) at their value in ``q_rest``.

    F = q (-) q_rest on the selected velocity coordinates (pin.difference, so unbounded revolute or
    spherical joints are handled), J = the matching rows of its derivative (identity rows for
    vector-space joints, computed once).
    """

    def __init__(
        self,
        model: pin.Model,
        q_rest: np.ndarray,
        joint_names: Sequence[str] | None = None,
        gain: float = 1.0,
        lower: float | np.ndarray | None = None,
        upper: float | np.ndarray | None = None,
        max_step: float | None = None,
        name: str = "posture",
    ) -> None:
        super().__init__(name, gain, lower, upper, max_step)
        self.model = model
        # (the model's per-joint index vectors: cheaper to read than the joint models)
        idx_qs, nqs, idx_vs, nvs = model.idx_qs, model.nqs, model.idx_vs, model.nvs
        if joint_names is None:
            ids = [j for j in range(1, model.njoints) if nqs[j] == nvs[j]]
        else:
            ids = [joint_id(model, n) for n in joint_names]
        if not ids:
            raise InvalidRequestError(f"task {name!r}: no joint selected")
        self.vector_space = all(nqs[j] == nvs[j] for j in ids)
        self.q_idx = np.array([i for j in ids for i in range(idx_qs[j], idx_qs[j] + nqs[j])], dtype=int)
        self.v_idx = np.array([i for j in ids for i in range(idx_vs[j], idx_vs[j] + nvs[j])], dtype=int)
        self.jacobian = np.zeros((self.v_idx.shape[0], model.nv))
        self.jacobian[np.arange(self.v_idx.shape[0]), self.v_idx] = 1.0
        self.set_rest(q_rest)

    def set_rest(self, q_rest: np.ndarray) -> None:
        """New rest configuration (nq)."""
        q_rest = np.asarray(q_rest, dtype=float)
        if q_rest.shape != (self.model.nq,):
            raise InvalidRequestError(
                f"task {self.name!r}: q_rest needs {self.model.nq} values, got {q_rest.shape}"
            )
        self.q_rest = q_rest.copy()
        self._rest_values = q_rest[self.q_idx]

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        if self.vector_space:
            return q[self.q_idx] - self._rest_values
        return pin.difference(self.model, self.q_rest, q)[self.v_idx]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        if self.vector_space:
            return self.jacobian
        return pin.dDifference(self.model, self.q_rest, q, pin.ArgumentPosition.ARG1)[self.v_idx]
