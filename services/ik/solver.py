"""Strict hierarchy of equality and inequality systems (section 2 of the footstep paper, after
Kanoun et al. 2009), each level a QP in the freedom left by the levels above.

Level k, with the increment dq = dq* + Z_k y over the solution dq* of the levels above (Z_k a basis of
the directions that keep every higher equality at its achieved value), solves::

    min_{y, w}  1/2 ||A_k (dq* + Z_k y) - b_k||^2 + 1/2 ||w||^2 + mu_k/2 ||y||^2
    s.t.        lb <= dq* + Z_k y <= ub                                   (level 0: hard limits)
                l_i' <= C_i (dq* + Z_k y) <= u_i'          for every higher inequality level i
                l_k <= C_k (dq* + Z_k y) - w <= u_k

with b_k = -lambda F (eq. 2) and [l_k, u_k] = lambda [lower - F, upper - F] (eq. 4). After the level,
its equalities are held at their achieved values (Z_{k+1} = Z_k N, N an orthonormal basis of
ker A_k Z_k from a pivoted QR) and the slacks of its inequalities are fixed at the optimum ([l', u']
widened to contain the achieved C_k dq), so a lower level can never change what a higher level
achieved.

Exactness and speed: the unconstrained minimizer (damped least squares) is computed first; when it
meets every constraint it *is* the optimum of the strictly convex QP and nothing else runs.
Otherwise the QP is solved on a working set of rows (``services.ik.qp.WorkingSetQP``): each
working-set QP is tried as its KKT system, kept when its multipliers prove it optimal, else solved
by proxsuite; rows violated by the solution are added until none is (the optimum of a relaxation
that meets every row is the optimum).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.blas import single_thread_blas_here
from services.ik.dofs import UNBOUNDED, bounded_dofs, near_limit_mask
from services.ik.kinematics import compute_kinematics
from services.ik.level import Level
from services.ik.linalg import damped_least_squares, kernel, metric_orthonormal, restrict
from services.ik.qp import BIG, WorkingSetQP

if TYPE_CHECKING:
    from services.ik.run import IKResult


@dataclass(frozen=True)
class SolverConfig:
    """Numerical settings of :class:`HierarchicalSolver`.

    Attributes:
        rank_tol: a direction of a level's Jacobian (in the freedom left to it) whose pivot is below
            ``rank_tol * max(1, largest pivot)`` counts as singular: it is not locked for the levels
            below (its use by the level is governed by the damping).
        feasibility_tol: constraint violation accepted at the unconstrained minimizer and at a QP
            solution before rows are added to the working set [row units: rad, m per IK time unit].
        qp_eps_abs: proxsuite absolute tolerance.
        qp_max_iter: proxsuite iteration cap.
        qp_preconditioner: let proxsuite equilibrate the QP (slower; these QPs are small and scaled).
        max_qp_rounds: working-set growth rounds per level (each round adds the violated rows).
        qp_kkt_shortcut: try each working-set QP as its equality-constrained KKT system first and
            keep it when its multipliers prove it optimal (see ``WorkingSetQP``); False: always
            proxsuite.
        always_qp: solve every level with proxsuite even when the unconstrained minimizer is feasible
            (for tests comparing both paths; slower).
        qp_method: ``"working_set"`` (KKT guesses, then proxsuite) or ``"dual_active_set"``
            (Goldfarb-Idnani, ``services.ik.active_set``: the same optimum, bitwise reproducible
            from run to run, and faster on these small QPs); see ``services.ik.qp.WorkingSetQP``.
    """

    rank_tol: float = 1e-6
    feasibility_tol: float = 1e-8
    qp_eps_abs: float = 1e-9
    qp_max_iter: int = 10_000
    qp_preconditioner: bool = False
    max_qp_rounds: int = 8
    qp_kkt_shortcut: bool = True
    always_qp: bool = False
    qp_method: str = "working_set"


@dataclass(frozen=True)
class LevelReport:
    """What one level achieved in the last :meth:`HierarchicalSolver.solve`.

    Attributes:
        name: the level's name.
        value: task value of the level at q (eqs. 5-6: root sum of squares of its tasks' values).
        task_values: value of each task at q.
        residual: least-squares residual of the level's linear systems at the returned dq,
            sqrt(||A dq - b||^2 + ||violation of lo <= C dq <= hi||^2): 0 when the level is met, its
            least-squares optimum when the level is infeasible.
        freedom: dimension of the freedom left to the level by the levels above.
        rank: rank of the level's equality Jacobian in that freedom.
        used_qp: proxsuite was called (some constraint was active).
    """

    name: str
    value: float
    task_values: tuple[float, ...]
    residual: float
    freedom: int
    rank: int
    used_qp: bool


class _System:
    """One level's linearized systems: equalities A dq = b and inequalities lo <= C dq <= hi."""

    __slots__ = ("A", "C", "b", "hi", "lo", "task_values", "value")

    def __init__(self, A_rows, b_rows, C_rows, lo_rows, hi_rows, task_values, empty):
        if not A_rows:
            self.A, self.b = empty
        elif len(A_rows) == 1:
            self.A, self.b = A_rows[0], b_rows[0]
        else:
            self.A, self.b = np.concatenate(A_rows), np.concatenate(b_rows)
        if not C_rows:
            self.C, self.lo = empty
            self.hi = self.lo
        elif len(C_rows) == 1:
            self.C, self.lo, self.hi = C_rows[0], lo_rows[0], hi_rows[0]
        else:
            self.C, self.lo, self.hi = (
                np.concatenate(C_rows),
                np.concatenate(lo_rows),
                np.concatenate(hi_rows),
            )
        self.task_values = task_values
        self.value = math.sqrt(sum(v * v for v in task_values))


class HierarchicalSolver:
    """Prioritized equality/inequality IK on any pinocchio model (free-flyer robots, and models with
    virtual joints prepended such as the footstep planner's chain of footprints).

    Args:
        model: the kinematic model (not modified).
        q_lower, q_upper: hard joint position limits (nq) [rad or m]; default the model's. Only
            coordinates of vector-space joints (revolute, prismatic) with a finite limit are bounded.
        dq_max: hard bound on |dq| per velocity coordinate (scalar or nv) [unit per IK time unit]:
            with ``alpha`` the time step of the integration it is a joint velocity limit [rad/s].
        config: numerical settings.
        limit_gain: in (0, 1]: the fraction of the distance to a position limit one step may
            cover (eq. 4 with lambda = limit_gain / alpha; 1: up to the limit).
    """

    def __init__(
        self,
        model: pin.Model,
        q_lower: np.ndarray | None = None,
        q_upper: np.ndarray | None = None,
        dq_max: float | np.ndarray | None = None,
        config: SolverConfig | None = None,
        limit_gain: float = 1.0,
    ) -> None:
        if not 0.0 < limit_gain <= 1.0:
            raise InvalidRequestError(f"limit_gain must be in (0, 1], got {limit_gain}")
        self.limit_gain = float(limit_gain)
        self.model = model
        self.data = model.createData()
        self.config = config or SolverConfig()
        self.q_lower = np.array(model.lowerPositionLimit if q_lower is None else q_lower, dtype=float)
        self.q_upper = np.array(model.upperPositionLimit if q_upper is None else q_upper, dtype=float)
        if self.q_lower.shape != (model.nq,) or self.q_upper.shape != (model.nq,):
            raise InvalidRequestError(f"q_lower and q_upper need {model.nq} values")
        self.bound_q_idx, self.bound_v_idx = bounded_dofs(model, self.q_lower, self.q_upper)
        if np.any(self.q_lower[self.bound_q_idx] > self.q_upper[self.bound_q_idx]):
            raise InvalidRequestError("q_lower is above q_upper for some joint")
        if dq_max is None:
            self.dq_max = np.full(model.nv, np.inf)
        else:
            self.dq_max = np.broadcast_to(np.asarray(dq_max, dtype=float), (model.nv,)).copy()
            if np.any(self.dq_max <= 0.0):
                raise InvalidRequestError("dq_max must be positive")
        finite_velocity = np.flatnonzero(self.dq_max < UNBOUNDED)
        # Coordinates with a hard bound on dq (position limits and/or velocity limits).
        self.box_v_idx = np.union1d(self.bound_v_idx, finite_velocity).astype(int)
        self._box_pos_of_bound = np.searchsorted(self.box_v_idx, self.bound_v_idx)
        self._box_rows = np.eye(model.nv)[self.box_v_idx]
        self._q_lower_bound = np.clip(self.q_lower[self.bound_q_idx], -BIG, BIG)
        self._q_upper_bound = np.clip(self.q_upper[self.bound_q_idx], -BIG, BIG)
        self._box_v_max = np.minimum(self.dq_max[self.box_v_idx], BIG)
        self._box_v_min = -self._box_v_max
        # dq bounds of the box before the position limits are applied (copied at each step)
        n_box = self.box_v_idx.shape[0]
        self._box_unbounded = (np.full(n_box, -BIG), np.full(n_box, BIG))
        self._only_position_box = finite_velocity.shape[0] == 0
        self._empty = (np.zeros((0, model.nv)), np.zeros(0))
        cfg = self.config
        self._qp = WorkingSetQP(
            cfg.qp_eps_abs,
            cfg.qp_max_iter,
            cfg.max_qp_rounds,
            cfg.feasibility_tol,
            cfg.qp_preconditioner,
            cfg.qp_kkt_shortcut,
            cfg.qp_method,
        )
        self._last: tuple | None = None

    # ------------------------------------------------------------------ evaluation

    def evaluate(self, levels: Sequence[Level], q: np.ndarray) -> list[_System]:
        """Kinematics once at q, then every task's value and Jacobian, stacked per level."""
        compute_kinematics(self.model, self.data, q, any(level.needs_com for level in levels))
        data = self.data
        systems = []
        for level in levels:
            A_rows, b_rows, C_rows, lo_rows, hi_rows, values = [], [], [], [], [], []
            for task in level.tasks:
                F, J = task.compute(q, data)
                gain = task.gain
                if task.lower is None:
                    norm = math.sqrt(F.dot(F))
                    values.append(norm)
                    A_rows.append(J)
                    max_step = task.max_step
                    if max_step is not None and gain * norm > max_step:
                        gain = max_step / norm
                    b_rows.append(-gain * F)
                else:
                    values.append(task.value_of(F))
                    if F.shape[0]:
                        C_rows.append(J)
                        lo_rows.append(gain * (task.lower - F))
                        hi_rows.append(gain * (task.upper - F))
            systems.append(_System(A_rows, b_rows, C_rows, lo_rows, hi_rows, values, self._empty))
        return systems

    # ------------------------------------------------------------------ solve

    def solve(self, levels: Sequence[Level], q: np.ndarray, alpha: float = 1.0) -> np.ndarray:
        """One step of the prioritized systems (eq. 7, dq = solve({T}, q)) at configuration q.

        Returns dq (nv), to be integrated as ``pin.integrate(model, q, alpha * dq)``; the hard joint
        limits hold for that step. An infeasible level is met in the least-squares sense; the
        per-level outcome is in :attr:`last_report`.
        """
        q = self.check_q(q)
        if alpha <= 0.0:
            raise InvalidRequestError(f"alpha must be positive, got {alpha}")
        return self.solve_systems(levels, self.evaluate(levels, q), q, alpha)

    def hard_bounds(self, q: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray]:
        """Bounds (lb, ub) on dq[box_v_idx]: q (+) alpha dq moves at most ``limit_gain`` of the way
        to each position limit (eq. 4 form; 1: up to the limit), within the velocity limits (a q
        outside its limits is brought back at most at the velocity limit)."""
        q_b = q[self.bound_q_idx]
        gain = self.limit_gain / alpha
        lb_pos = gain * (self._q_lower_bound - q_b)
        ub_pos = gain * (self._q_upper_bound - q_b)
        if self._only_position_box:
            return lb_pos, ub_pos
        lb, ub = self._box_unbounded[0].copy(), self._box_unbounded[1].copy()
        lb[self._box_pos_of_bound] = lb_pos
        ub[self._box_pos_of_bound] = ub_pos
        # np.clip(., -v_max, v_max) by two ufuncs (the same values: the bounds are nonzero)
        v_min, v_max = self._box_v_min, self._box_v_max
        return np.minimum(np.maximum(lb, v_min), v_max), np.minimum(np.maximum(ub, v_min), v_max)

    def solve_systems(
        self, levels: Sequence[Level], systems: Sequence[_System], q: np.ndarray, alpha: float
    ) -> np.ndarray:
        """Solve already evaluated systems (see :meth:`evaluate`); used by ``run``."""
        single_thread_blas_here()  # (thread-local; see services.ik.blas)
        nv = self.model.nv
        cfg = self.config
        tol = cfg.feasibility_tol
        dq = np.zeros(nv)
        moved = False
        box = self.box_v_idx
        n_box = box.shape[0]
        hard = self.hard_bounds(q, alpha)
        # Every inequality of level 0 and of the levels above, slacks fixed, in one stack:
        # K_lo <= K dq <= K_hi (the first n_box rows are the hard bounds on dq[box]).
        K, (K_lo, K_hi) = self._box_rows, hard
        K_lo_t, K_hi_t = K_lo - tol, K_hi + tol
        Z: np.ndarray | None = None  # basis of the freedom left; None: the identity
        Z_orthonormal = True
        info: list[tuple[int, np.ndarray | None, bool]] = []
        last_k = len(levels) - 1
        for k, (level, system) in enumerate(zip(levels, systems, strict=True)):
            A, C = system.A, system.C
            m, p = A.shape[0], C.shape[0]
            freedom = nv if Z is None else Z.shape[1]
            used_qp = False
            M = None
            if freedom and (m or p):
                # Basis of this level's increment: selection (S, S_l), then the metric (eq. 4).
                selected = self._selection(level, q)
                Z_level = Z if selected is None else restrict(Z, selected, nv, cfg.rank_tol)
                if level.weights is not None:
                    if level.weights.shape != (nv,):
                        raise InvalidRequestError(f"level {level.name!r}: weights needs {nv} values")
                    Z_level = metric_orthonormal(Z_level, nv, np.sqrt(level.weights))
                elif not Z_orthonormal:
                    Z_level = metric_orthonormal(Z_level, nv, None)
                r = nv if Z_level is None else Z_level.shape[1]
                e = None
                y = None
                candidate = dq
                if r and m:
                    e = system.b - A.dot(dq) if moved else system.b
                    M = A if Z_level is None else A.dot(Z_level)
                    # Levenberg-Marquardt-like: more damping while the level is far from met
                    mu = level.damping + level.error_damping * float(e.dot(e))
                    y = damped_least_squares(M, e, mu)
                    candidate = dq + (y if Z_level is None else Z_level.dot(y))
                if r:
                    violated = 0
                    if candidate is not dq:  # (dq itself meets every row above)
                        values = K.dot(candidate)
                        violated = np.count_nonzero((values < K_lo_t) | (values > K_hi_t))
                    if not violated and p:
                        values = C.dot(candidate)
                        violated = np.count_nonzero((values < system.lo - tol) | (values > system.hi + tol))
                    if violated or cfg.always_qp:
                        used_qp = True
                        damping = mu if M is not None else level.damping
                        y = self._solve_qp(M, e, r, damping, Z_level, dq, y, K, K_lo, K_hi, system, k)
                        candidate = dq + (y if Z_level is None else Z_level.dot(y))
                        # absorb the QP's tolerance: dq stays feasible for the levels below
                        values = K.dot(candidate)
                        K_lo, K_hi = np.minimum(K_lo, values), np.maximum(K_hi, values)
                        K_lo_t, K_hi_t = K_lo - tol, K_hi + tol
                if candidate is not dq:
                    dq = candidate
                    moved = True
                if k != last_k and m:
                    # Hold the level's equalities at their achieved values: Z <- Z N, N = ker A Z.
                    if selected is None and M is not None:
                        Z, _ = kernel(M, cfg.rank_tol, Z_level)
                        Z_orthonormal = level.weights is None
                    else:  # after a selection: the kernel over the unrestricted freedom
                        Z, _ = kernel(A if Z is None else A.dot(Z), cfg.rank_tol, Z)
            if p:
                # Fix the slacks at the optimum: bounds widened to contain the achieved C dq.
                achieved = C.dot(dq)
                lo, hi = np.minimum(system.lo, achieved), np.maximum(system.hi, achieved)
                K = np.concatenate((K, C))
                K_lo, K_hi = np.concatenate((K_lo, lo)), np.concatenate((K_hi, hi))
                K_lo_t, K_hi_t = K_lo - tol, K_hi + tol
            info.append((freedom, M, used_qp))
        # The levels meet the hard bounds to the feasibility tolerance; clip that last 1e-8 so
        # that the integrated step never crosses a limit.
        if n_box:
            dq[box] = np.clip(dq.take(box), *hard)
        self._last = (tuple(levels), tuple(systems), dq, info)
        return dq

    def _solve_qp(self, M, e, r, damping, Z_level, dq, y_free, K, K_lo, K_hi, system, k=None) -> np.ndarray:
        """The level's QP (module docstring) in its variable y (``k``: the level's index, the key of
        its warm start with ``qp_method="dual_active_set"``)."""
        base = K.dot(dq)
        blocks, lows, highs = [K if Z_level is None else K.dot(Z_level)], [K_lo - base], [K_hi - base]
        first_slack_row = K.shape[0]
        if system.C.shape[0]:
            base = system.C.dot(dq)
            blocks.append(system.C if Z_level is None else system.C.dot(Z_level))
            lows.append(system.lo - base)
            highs.append(system.hi - base)
        if M is not None:
            # H = damping I + M^T M, the damping added on the diagonal in place (the same sums)
            H = M.T.dot(M)
            H.flat[:: r + 1] += damping
            g = -M.T.dot(e)
        else:
            H = np.eye(r) * damping
            g = np.zeros(r)
        if y_free is None:
            y_free = np.zeros(r)
        D = np.concatenate(blocks)
        lows_all = np.maximum(np.concatenate(lows), -BIG)
        highs_all = np.minimum(np.concatenate(highs), BIG)
        # Rows this level cannot move (coordinates held by the levels above) are met at y = 0 by
        # construction; left in, they make a degenerate QP that proxsuite may call infeasible.
        movable = np.einsum("ij,ij->i", D, D) > 1e-24
        if np.count_nonzero(movable) != movable.shape[0]:
            first_slack_row = int(np.count_nonzero(movable[:first_slack_row]))
            D, lows_all, highs_all = D[movable], lows_all[movable], highs_all[movable]
        return self._qp.solve(H, g, D, lows_all, highs_all, first_slack_row, y_free, key=k)

    def reset(self) -> None:
        """Forget what earlier solves leave for the next ones (the QP warm starts of
        ``qp_method="dual_active_set"``): the solves that follow depend on their own data only."""
        self._qp.reset()
        self._last = None

    @property
    def last_report(self) -> tuple[LevelReport, ...]:
        """Per-level outcome of the last solve (computed on demand)."""
        if self._last is None:
            return ()
        levels, systems, dq, info = self._last
        reports = []
        for level, system, (freedom, M, used_qp) in zip(levels, systems, info, strict=True):
            rank = 0 if M is None else kernel(M, self.config.rank_tol)[1]
            reports.append(
                LevelReport(
                    name=level.name,
                    value=system.value,
                    task_values=tuple(system.task_values),
                    residual=_residual(system, dq),
                    freedom=freedom,
                    rank=rank,
                    used_qp=used_qp,
                )
            )
        return tuple(reports)

    def run(
        self,
        levels: Sequence[Level],
        q0: np.ndarray,
        alpha: float = 1.0,
        max_iters: int = 100,
        time_budget_s: float = math.inf,
        tol: float = 1e-4,
        **options: float,
    ) -> IKResult:
        """Iterate q <- q (+) alpha solve(levels, q) from q0; see :func:`services.ik.run.run`."""
        from services.ik.run import run  # the loop module builds on this one

        return run(self, levels, q0, alpha, max_iters, time_budget_s, tol, **options)

    # ------------------------------------------------------------------ helpers

    def check_q(self, q: np.ndarray) -> np.ndarray:
        """q as a float array of the model's size, or InvalidRequestError."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.model.nq,) or not np.all(np.isfinite(q)):
            raise InvalidRequestError(f"q must be {self.model.nq} finite numbers, got shape {q.shape}")
        return q

    def _selection(self, level: Level, q: np.ndarray) -> np.ndarray | None:
        if level.selection is None and level.lock_near_limits_rad is None:
            return None
        mask = np.ones(self.model.nv, dtype=bool)
        if level.selection is not None:
            if level.selection.shape != (self.model.nv,):
                raise InvalidRequestError(f"level {level.name!r}: selection needs {self.model.nv} booleans")
            mask &= level.selection
        if level.lock_near_limits_rad is not None:
            mask &= near_limit_mask(self.model, q, level.lock_near_limits_rad, self.q_lower, self.q_upper)
        return mask


def _residual(system: _System, dq: np.ndarray) -> float:
    total = 0.0
    if system.A.shape[0]:
        res = system.A @ dq - system.b
        total += float(res @ res)
    if system.C.shape[0]:
        y = system.C @ dq
        viol = np.maximum(np.maximum(y - system.hi, system.lo - y), 0.0)
        total += float(viol @ viol)
    return math.sqrt(total)
