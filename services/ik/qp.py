"""A level's QP on proxsuite, solved on a growing working set of constraint rows."""

from __future__ import annotations

import numpy as np
import scipy.linalg.lapack as lapack
from proxsuite import proxqp

from services.errors import InvalidRequestError
from services.ik.active_set import ActiveSetError, solve_dual_active_set

BIG = 1e20  # proxsuite's "no bound"
QP_METHODS = ("working_set", "dual_active_set")


class WorkingSetQP:
    """Solves, for one level with variable y (r) and slacks w on its own inequality rows::

        min  1/2 y^T H y + g^T y + 1/2 ||w||^2
        s.t. lo_i <= D_i y <= hi_i            (rows i <  first_slack_row: hard bounds, levels above)
             lo_i <= D_i y - w_i <= hi_i      (rows i >= first_slack_row: the level's inequalities)

    The QP is solved on a working set: the rows violated by a start point, then every row violated
    by the last solution, until none is. Each QP of the sequence is a relaxation of the full one, so
    the first solution that violates no row is the full QP's optimum. After ``max_rounds`` rounds
    the full QP is solved at once.

    Each working-set QP is first tried as an equality-constrained problem with its rows on the
    bound they crossed (a small KKT system): if its multipliers have the right signs (and the
    slacks the right sides), the KKT conditions of the inequality QP hold, so it is that QP's
    optimum (H is positive definite). Otherwise proxsuite solves it; QP objects are kept per
    dimension and warm-started from their previous solution.

    ``method="dual_active_set"`` solves the QP instead by the dual active-set method of Goldfarb
    and Idnani (:mod:`services.ik.active_set`): the same optimum (to the feasibility tolerance),
    computed by a fixed sequence of dense operations, hence bitwise reproducible (proxsuite's
    results vary from run to run at the 1e-15 level); the working set above remains the fallback
    for degenerate data.
    """

    def __init__(
        self,
        eps_abs: float,
        max_iter: int,
        max_rounds: int,
        tol: float,
        preconditioner: bool = False,
        kkt_shortcut: bool = True,
        method: str = "working_set",
    ) -> None:
        if method not in QP_METHODS:
            raise InvalidRequestError(f"qp method must be one of {list(QP_METHODS)}, got {method!r}")
        self.method = method
        self.eps_abs = eps_abs
        self.max_iter = max_iter
        self.max_rounds = max_rounds
        self.tol = tol
        self.preconditioner = preconditioner
        self.kkt_shortcut = kkt_shortcut
        self._cache: dict[tuple[int, int], proxqp.dense.QP] = {}
        self.calls = 0
        self.cold_restarts = 0
        self.failures = 0
        self.kkt_solves = 0
        self.full_solves = 0
        self.active_set_solves = 0
        self.active_set_failures = 0
        self.active_set_iterations = 0
        # per QP key: (rows, first slack row, active rows, signs) of the last solution, a guess
        self._active: dict[object, tuple[int, int, np.ndarray, np.ndarray]] = {}

    def reset(self) -> None:
        """Forget the active sets of earlier solves (the warm starts of ``dual_active_set``): the
        solves that follow then depend on their own data only."""
        self._active.clear()

    def solve(
        self,
        H: np.ndarray,
        g: np.ndarray,
        D: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        first_slack_row: int,
        y_start: np.ndarray,
        key: object = None,
    ) -> np.ndarray:
        """The QP's optimum y. ``key`` names the QP (e.g. a level of the hierarchy): with
        ``dual_active_set``, the active set of the last solve with the same key and row layout
        starts this one (same optimum, fewer iterations when the QPs follow each other closely)."""
        r = H.shape[0]
        tol = self.tol
        if self.method == "dual_active_set":
            m = D.shape[0]
            last = self._active.get(key) if key is not None else None
            guess = last[2:] if last is not None and last[:2] == (m, first_slack_row) else None
            try:
                solution = solve_dual_active_set(H, g, D, lo, hi, first_slack_row, tol, guess=guess)
            except ActiveSetError:
                self.active_set_failures += 1  # degenerate data: the working set below
            else:
                self.active_set_solves += 1
                self.active_set_iterations += solution.iterations
                if key is not None:
                    self._active[key] = (m, first_slack_row, solution.rows, solution.signs)
                return solution.y
        values = D.dot(y_start)
        working = (values < lo - tol) | (values > hi + tol)
        upper = values > hi  # the side of each working row: the bound it crossed
        y = y_start
        for round_ in range(self.max_rounds + 1):
            full = round_ == self.max_rounds
            if full:
                # The working set keeps growing: solve the full QP once (every row, by proxsuite).
                self.full_solves += 1
                working[:] = True
            rows = np.flatnonzero(working)
            y_kkt = (
                self._kkt(H, g, D, lo, hi, rows, upper[rows], first_slack_row)
                if self.kkt_shortcut and not full
                else None
            )
            if y_kkt is not None:
                self.kkt_solves += 1
                y = y_kkt
                values = D.dot(y)
                violated = (values < lo - tol) | (values > hi + tol)
                new = violated & ~working
                if not new.any():
                    break
                upper[new] = values[new] > hi[new]
                working |= new
                continue
            slack_rows = rows[rows >= first_slack_row]
            n_slack = slack_rows.shape[0]
            n = r + n_slack
            H_qp = np.zeros((n, n))
            H_qp[:r, :r] = H
            H_qp.flat[r * (n + 1) :: n + 1] = 1.0
            g_qp = np.zeros(n)
            g_qp[:r] = g
            C_qp = np.zeros((rows.shape[0], n))
            C_qp[:, :r] = D[rows]
            C_qp[np.arange(rows.shape[0] - n_slack, rows.shape[0]), np.arange(r, n)] = -1.0
            y = self._proxsuite(H_qp, g_qp, C_qp, lo[rows], hi[rows])[:r]
            values = D.dot(y)
            violated = (values < lo - tol) | (values > hi + tol)
            new = violated & ~working
            if full or not new.any():
                break
            upper[new] = values[new] > hi[new]
            working |= new
        hard_violation = max(
            float((values[:first_slack_row] - hi[:first_slack_row]).max(initial=0.0)),
            float((lo[:first_slack_row] - values[:first_slack_row]).max(initial=0.0)),
        )
        if hard_violation > 100.0 * tol:
            # proxsuite failed (should not happen: the QP is feasible at y = 0); keep the levels
            # above intact rather than cross a limit: this level makes no progress this step.
            self.failures += 1
            return np.zeros(r)
        return y

    @staticmethod
    def _kkt(H, g, D, lo, hi, rows, upper, first_slack_row) -> np.ndarray | None:
        """The working-set QP's optimum if the guess "every working row on the bound it crossed"
        satisfies the KKT conditions, else None."""
        bounds = np.where(upper, hi[rows], lo[rows])
        slack = rows >= first_slack_row
        H_eq, g_eq = H, g
        if slack.any():
            # an active slack row is the least-squares term 1/2 (D_i y - bound_i)^2
            D_s, b_s = D[rows[slack]], bounds[slack]
            H_eq = H + D_s.T.dot(D_s)
            g_eq = g - D_s.T.dot(b_s)
        chol, info = lapack.dpotrf(H_eq)
        if info != 0:
            return None
        hard = ~slack
        if hard.any():
            E, f = D[rows[hard]], bounds[hard]
            # y = -H^-1 (g + E^T lam), E y = f  =>  (E H^-1 E^T) lam = -f - E H^-1 g
            H_inv_Et = lapack.dpotrs(chol, E.T)[0]
            H_inv_g = lapack.dpotrs(chol, g_eq)[0]
            schur = E.dot(H_inv_Et)
            schur_chol, info = lapack.dpotrf(schur)
            if info != 0:
                return None  # dependent rows: let proxsuite sort it out
            lam = lapack.dpotrs(schur_chol, -f - E.dot(H_inv_g))[0]
            # multipliers: >= 0 on an upper bound, <= 0 on a lower bound
            if np.any(np.where(upper[hard], lam, -lam) < -1e-12 * (1.0 + np.abs(lam).max())):
                return None
            y = -(H_inv_g + H_inv_Et.dot(lam))
        else:
            y = -lapack.dpotrs(chol, g_eq)[0]
        if slack.any():
            # each slack on the side of the bound it relaxes
            w = D[rows[slack]].dot(y) - bounds[slack]
            if np.any(np.where(upper[slack], w, -w) < 0.0):
                return None
        return y

    def _proxsuite(self, H, g, C, lo, hi) -> np.ndarray:
        self.calls += 1
        key = (H.shape[0], C.shape[0])
        qp = self._cache.get(key)
        if qp is not None:
            # Same dimensions as an earlier QP: update it and warm-start from its solution.
            qp.settings.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            qp.update(H, g, None, None, C, lo, hi, update_preconditioner=self.preconditioner)
            qp.solve()
            if qp.results.info.status == proxqp.QPSolverOutput.PROXQP_SOLVED:
                return np.array(qp.results.x)
            # A warm start from an unrelated problem can mislead the infeasibility detection
            # (these QPs are feasible by construction): solve again from scratch.
            self.cold_restarts += 1
        qp = proxqp.dense.QP(key[0], 0, key[1])
        qp.settings.eps_abs = self.eps_abs
        qp.settings.eps_rel = 0.0
        # These QPs are feasible by construction (y = 0 meets every hard row): with proxsuite's
        # default infeasibility thresholds (1e-4) a few percent of them come back "infeasible".
        qp.settings.eps_primal_inf = 1e-14
        qp.settings.eps_dual_inf = 1e-14
        qp.settings.max_iter = self.max_iter
        qp.settings.verbose = False
        qp.init(H, g, None, None, C, lo, hi, compute_preconditioner=self.preconditioner)
        qp.solve()
        self._cache[key] = qp
        return np.array(qp.results.x)
