"""A priority level of the hierarchy: tasks solved together, with the level options of the reaching
paper (weighted pseudo-inverse, selection matrix)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from services.errors import InvalidRequestError
from services.ik.task import Task


@dataclass(frozen=True)
class Level:
    """Tasks of one priority stage, solved as one least-squares problem (equalities) with slacked
    inequalities, in the freedom left by every level above.

    Attributes:
        tasks: the level's tasks (equalities and inequalities may be mixed).
        name: label for histories and reports (default: the task names).
        damping: mu_0 of the regularization mu ||dq_k||^2_W of this level's increment (in [unit^2]
            of the tasks): damps singular directions and picks the minimum-norm solution among equals.
        error_damping: the damping grows with the level's squared residual e (the right-hand side
            of eq. 2 not yet met), mu = damping + error_damping ||e||^2, Levenberg-Marquardt style
            (Sugihara 2011): long, nearly singular steps far from a goal (an arm stretched toward
            an unreachable point) are damped, steps near the goal are Gauss-Newton.
        weights: per velocity coordinate weights W_i (nv); the level's increment then minimizes
            sum sqrt(W_i) dq_i^2, the weighted pseudo-inverse of eq. (4) of the reaching paper with
            W_i = m_i / M (``services.ik.dofs.link_mass_weights``): lighter links move first.
        selection: boolean mask over nv, the selection matrix S of the reaching paper: this level's
            increment only moves the True coordinates (lower levels may still move the others).
        lock_near_limits_rad: S_l of the reaching paper: coordinates closer than this to a joint
            limit are left out of this level's increment (recomputed at every iteration).
        tol: value (eqs. 5-6) under which the level counts as solved in ``run``; ``None`` uses the
            run's ``tol``; ``math.inf`` makes the level an objective that never blocks convergence
            (a rest posture).
    """

    tasks: tuple[Task, ...]
    name: str = ""
    damping: float = 1e-3
    error_damping: float = 0.1
    weights: np.ndarray | None = field(default=None, repr=False)
    selection: np.ndarray | None = field(default=None, repr=False)
    lock_near_limits_rad: float | None = None
    tol: float | None = None

    def __post_init__(self) -> None:
        tasks = tuple(self.tasks) if isinstance(self.tasks, Sequence) else (self.tasks,)
        if not tasks or not all(isinstance(t, Task) for t in tasks):
            raise InvalidRequestError(f"level {self.name!r}: tasks must be a non-empty sequence of Task")
        object.__setattr__(self, "tasks", tasks)
        if not self.name:
            object.__setattr__(self, "name", "+".join(t.name for t in tasks))
        if not math.isfinite(self.damping) or self.damping < 0.0:
            raise InvalidRequestError(f"level {self.name!r}: damping must be >= 0, got {self.damping}")
        if not math.isfinite(self.error_damping) or self.error_damping < 0.0:
            raise InvalidRequestError(
                f"level {self.name!r}: error_damping must be >= 0, got {self.error_damping}"
            )
        if self.weights is not None:
            weights = np.asarray(self.weights, dtype=float)
            if weights.ndim != 1 or np.any(weights <= 0.0) or not np.all(np.isfinite(weights)):
                raise InvalidRequestError(
                    f"level {self.name!r}: weights must be a vector of positive numbers"
                )
            object.__setattr__(self, "weights", weights)
        if self.selection is not None:
            object.__setattr__(self, "selection", np.asarray(self.selection, dtype=bool))
        if self.tol is not None and self.tol < 0.0:
            raise InvalidRequestError(f"level {self.name!r}: tol must be >= 0, got {self.tol}")
        object.__setattr__(self, "_needs_com", any(t.needs_com for t in tasks))

    @property
    def needs_com(self) -> bool:
        """Some task of the level reads the centre of mass (the solver then computes it)."""
        return self._needs_com
