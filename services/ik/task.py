"""The task abstraction of the prioritized IK (section 2.1 of the footstep paper).

A task is a differentiable vector function F(q) with its Jacobian dF/dq (nv columns, tangent space).
Used as an *equality* it asks F(q) = 0 and contributes the linear system of eq. (2)::

    J dq = -lambda F

Used as an *inequality* it asks lower <= F(q) <= upper and contributes the ordinary differential
inequality of eq. (4) on both sides::

    lambda (lower - F) <= J dq <= lambda (upper - F)

``upper = 0, lower = -inf`` is exactly eq. (4) with G = F (G <= 0 satisfied). Tasks that are
inequalities by nature (support polygon, self-collision, joint limits, ...) set those bounds
themselves; any other task becomes an inequality by passing ``lower``/``upper`` (e.g. a hand kept in
a box around a point).

Tasks never compute kinematics: the solver fills ``data`` once per iteration (joint Jacobians, frame
placements, and the CoM Jacobian when a task sets ``needs_com``), tasks only read it.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError


class Task(ABC):
    """Base class of every IK task.

    Attributes:
        name: label used in value histories and reports.
        gain: lambda of eqs. (2)/(4) [1/IK time unit]; 1 with an integration step alpha = 1 is a
            Gauss-Newton step.
        max_step: equality tasks only: the largest task-space step ||lambda F|| asked by eq. (2) in
            one iteration (task units, e.g. [m]); a larger one is scaled down to it. Far from the
            goal this keeps the linearization valid (a hand 0.5 m away moves 0.2 m per step
            instead of swinging the whole body through a step the linear model cannot predict);
            the task value (eq. 5) keeps the true error. ``None``: no limit.
        lower, upper: inequality bounds on F (scalar or per row), ``None`` for an equality task.
        needs_com: the solver must compute the centre-of-mass Jacobian for this task.
    """

    needs_com: bool = False

    def __init__(
        self,
        name: str,
        gain: float = 1.0,
        lower: float | np.ndarray | None = None,
        upper: float | np.ndarray | None = None,
        max_step: float | None = None,
    ) -> None:
        if not math.isfinite(gain) or gain <= 0.0:
            raise InvalidRequestError(f"task {name!r}: gain must be a positive finite number, got {gain}")
        if max_step is not None and not max_step > 0.0:
            raise InvalidRequestError(f"task {name!r}: max_step must be positive, got {max_step}")
        self.name = name
        self.gain = float(gain)
        self.max_step = None if max_step is None else float(max_step)
        if lower is None and upper is None:
            self.lower: float | np.ndarray | None = None
            self.upper: float | np.ndarray | None = None
        else:
            self.lower = -np.inf if lower is None else _as_bound(lower)
            self.upper = np.inf if upper is None else _as_bound(upper)
            if (
                self.lower > self.upper
                if isinstance(self.lower, float) and isinstance(self.upper, float)
                else np.any(np.asarray(self.lower) > np.asarray(self.upper))
            ):
                raise InvalidRequestError(f"task {name!r}: lower bound above upper bound")

    @property
    def kind(self) -> str:
        """``"equality"`` (eq. 2) or ``"inequality"`` (eq. 4)."""
        return "equality" if self.lower is None else "inequality"

    @property
    def is_equality(self) -> bool:
        return self.lower is None

    @abstractmethod
    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        """Task value F(q) (or G(q) for an inequality), shape (m,)."""

    @abstractmethod
    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        """dF/dq in the tangent space, shape (m, nv)."""

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """Value and Jacobian together; tasks whose two halves share work override this."""
        return self.compute_error(q, data), self.compute_jacobian(q, data)

    def bounds(self, m: int) -> tuple[np.ndarray, np.ndarray]:
        """Inequality bounds broadcast to ``m`` rows (only for inequality tasks)."""
        if self.lower is None or self.upper is None:
            raise InvalidRequestError(f"task {self.name!r} is an equality task and has no bounds")
        lower = np.broadcast_to(np.asarray(self.lower, dtype=float), (m,))
        upper = np.broadcast_to(np.asarray(self.upper, dtype=float), (m,))
        return lower, upper

    def value_of(self, error: np.ndarray) -> float:
        """Task value function of a computed error: eq. (5) ||F|| for an equality, eq. (6)
        sqrt(sum max(0, violation)^2) for an inequality (0 when satisfied)."""
        if self.lower is None:
            return math.sqrt(error.dot(error))
        # scalar or per-row bounds broadcast against the error
        if isinstance(self.lower, float) and self.lower == -math.inf:
            # G <= upper only (eq. 4 as written): lower - error = -inf never counts (finite errors)
            violation = np.maximum(error - self.upper, 0.0)
        else:
            violation = np.maximum(np.maximum(error - self.upper, self.lower - error), 0.0)
        return math.sqrt(violation.dot(violation))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, kind={self.kind}, gain={self.gain})"


def _as_bound(value: float | np.ndarray) -> float | np.ndarray:
    array = np.asarray(value, dtype=float)
    return float(array) if array.ndim == 0 else array.copy()
