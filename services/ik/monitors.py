"""Monitors of task execution: task value functions (eqs. 5-6 of the footstep paper) and the
manipulability measure (eq. 5 of the reaching paper)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.kinematics import frame_id, frame_jacobian, joint_id
from services.ik.task import Task


def task_value(task: Task, q: np.ndarray, data: pin.Data) -> float:
    """V(q) of one task on kinematics already in ``data``: ||F(q)|| for an equality (eq. 5),
    sqrt(sum_j max(0, g_j(q))^2) for an inequality (eq. 6). Zero means satisfied."""
    return task.value_of(task.compute_error(q, data))


def manipulability(jacobian: np.ndarray) -> float:
    """w = sqrt(det(J J^T)) (eq. 5 of the reaching paper, Yoshikawa's measure)."""
    gram = jacobian @ jacobian.T
    return float(np.sqrt(max(np.linalg.det(gram), 0.0)))


class ArmManipulability:
    """Manipulability of the translation of ``frame_name`` by the joints from ``first_joint`` to the
    frame (the arm): the reaching paper tracks it and reshapes the support polygon when it drops
    below a threshold (1.5e-4 on HRP-2)."""

    def __init__(self, model: pin.Model, frame_name: str, first_joint: str) -> None:
        self.model = model
        self.frame_id = frame_id(model, frame_name)
        first = joint_id(model, first_joint)
        chain = list(model.supports[model.frames[self.frame_id].parentJoint])
        if first not in chain:
            raise InvalidRequestError(f"joint {first_joint!r} does not move frame {frame_name!r}")
        joints = chain[chain.index(first) :]
        self.v_idx = np.concatenate(
            [np.arange(model.joints[j].idx_v, model.joints[j].idx_v + model.joints[j].nv) for j in joints]
        )

    def __call__(self, data: pin.Data) -> float:
        """w on kinematics already in ``data`` (``compute_kinematics``)."""
        return manipulability(frame_jacobian(self.model, data, self.frame_id)[:3, self.v_idx])


def level_values(tasks: Sequence[Task], errors: Sequence[np.ndarray]) -> float:
    """Value of a level: the root sum of squares of its tasks' values."""
    return float(np.sqrt(sum(t.value_of(e) ** 2 for t, e in zip(tasks, errors, strict=True))))
