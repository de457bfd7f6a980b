"""The iteration loop: q <- q (+) alpha solve({T}, q) until the tasks are solved (Algorithm 1 of the
footstep paper without the step insertion, which belongs to the footstep planner)."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.level import Level
from services.ik.solver import HierarchicalSolver

REASONS = ("converged", "stagnated", "max_iters", "time_budget")


@dataclass(frozen=True)
class IKResult:
    """Outcome of :func:`run`.

    Attributes:
        q: final configuration (nq).
        iterations: integration steps taken.
        converged: every level with a finite tolerance is at or below it.
        reason: one of ``converged``, ``stagnated`` (no required level improves any more, or the
            step vanished: a local minimum, or an infeasible level at its least-squares optimum),
            ``max_iters``, ``time_budget``.
        level_names: names of the levels, in priority order.
        values: (iterations + 1) x n_levels task values of the levels (eqs. 5-6) at each iterate,
            the curves of Fig. 10 of the footstep paper.
        task_names: names of every task, level by level.
        task_values: (iterations + 1) x n_tasks values of each task.
        residuals: values of the levels at ``q`` (the last row of ``values``).
        wall_time_s: time spent in the loop [s].
    """

    q: np.ndarray
    iterations: int
    converged: bool
    reason: str
    level_names: tuple[str, ...]
    values: np.ndarray
    task_names: tuple[str, ...]
    task_values: np.ndarray
    residuals: np.ndarray
    wall_time_s: float


def run(
    solver: HierarchicalSolver,
    levels: Sequence[Level],
    q0: np.ndarray,
    alpha: float = 1.0,
    max_iters: int = 100,
    time_budget_s: float = math.inf,
    tol: float = 1e-4,
    step_tol: float = 1e-9,
    stagnation_ratio: float = 1e-3,
    patience: int = 5,
) -> IKResult:
    """Iterate the prioritized IK from ``q0``.

    Args:
        solver: the solver (its model and hard limits).
        levels: priority levels, highest first.
        q0: initial configuration (nq).
        alpha: integration step of q <- q (+) alpha dq (1 with gains 1: Gauss-Newton steps).
        max_iters: iteration budget.
        time_budget_s: wall-time budget [s], checked before each step.
        tol: value (eqs. 5-6) under which a level is solved, unless the level sets its own ``tol``.
        step_tol: stagnation when the largest coordinate of alpha dq falls below it.
        stagnation_ratio, patience: stagnation when, during ``patience`` consecutive iterations, no
            unsolved required level decreases its value by more than ``stagnation_ratio`` of it
            (the value-decrease test of eq. (15)).
    """
    if max_iters < 0:
        raise InvalidRequestError(f"max_iters must be >= 0, got {max_iters}")
    if alpha <= 0.0:
        raise InvalidRequestError(f"alpha must be positive, got {alpha}")
    if not levels:
        raise InvalidRequestError("give at least one level")
    model = solver.model
    q = solver.check_q(q0).copy()
    tolerances = [tol if level.tol is None else level.tol for level in levels]
    required = [k for k, t in enumerate(tolerances) if math.isfinite(t)]
    values_history: list[list[float]] = []
    task_history: list[list[float]] = []
    bound_q = solver.bound_q_idx
    lower, upper = solver.q_lower[bound_q], solver.q_upper[bound_q]
    start = time.perf_counter()
    iterations = 0
    stalled = 0
    systems = solver.evaluate(levels, q)
    while True:
        values = [s.value for s in systems]
        values_history.append(values)
        task_history.append([v for s in systems for v in s.task_values])
        unsolved = [k for k in required if values[k] > tolerances[k]]
        if not unsolved:
            reason = "converged"
            break
        if iterations:
            previous = values_history[-2]
            improving = any(previous[k] - values[k] > stagnation_ratio * previous[k] for k in unsolved)
            stalled = 0 if improving else stalled + 1
            if stalled >= patience:
                reason = "stagnated"
                break
        if iterations >= max_iters:
            reason = "max_iters"
            break
        if time.perf_counter() - start > time_budget_s:
            reason = "time_budget"
            break
        step = solver.solve_systems(levels, systems, q, alpha)
        if alpha != 1.0:
            step = alpha * step
        q = pin.integrate(model, q, step)
        # (the rounding of q + dq when dq brings a joint exactly onto its limit)
        q[bound_q] = q.take(bound_q).clip(lower, upper)
        iterations += 1
        systems = solver.evaluate(levels, q)
        if np.abs(step).max() < step_tol:
            values_history.append([s.value for s in systems])
            task_history.append([v for s in systems for v in s.task_values])
            solved = all(values_history[-1][k] <= tolerances[k] for k in required)
            reason = "converged" if solved else "stagnated"
            break
    values_array = np.array(values_history)
    return IKResult(
        q=q,
        iterations=iterations,
        converged=reason == "converged",
        reason=reason,
        level_names=tuple(level.name for level in levels),
        values=values_array,
        task_names=tuple(task.name for level in levels for task in level.tasks),
        task_values=np.array(task_history),
        residuals=values_array[-1].copy(),
        wall_time_s=time.perf_counter() - start,
    )
