"""A level's QP by the dual active-set method of Goldfarb and Idnani (1983): exact and deterministic.

The problem is the one of :class:`services.ik.qp.WorkingSetQP`, in the variable y (r) and slacks w
on the rows i >= ``first_slack_row``::

    min  1/2 y^T H y + g^T y + 1/2 ||w||^2
    s.t. lo_i <= D_i y <= hi_i              (i <  first_slack_row: hard rows)
         lo_i <= D_i y - w_i <= hi_i        (i >= first_slack_row: the level's own inequalities)

with H positive definite. Each two-sided row gives two inequalities n^T x >= b over x = (y, w):
n = (D_i, -e_i), b = lo_i (the lower side) and n = (-D_i, e_i), b = -hi_i (the upper side), without
the e_i on a hard row. The dual method starts from a dual feasible pair (the unconstrained minimizer
y = -H^-1 g, w = 0, or the minimizer with a guessed set of inequalities held as equalities when all
their multipliers are >= 0), then repeatedly takes the most violated inequality p and moves the
primal point and the multipliers along the directions that keep the active inequalities active and
their multipliers >= 0: a full step makes p active, a partial step drops the active inequality whose
multiplier reaches zero first. It stops when no inequality is violated by more than ``tol``: the KKT
conditions of the strictly convex QP then hold, so the result is its unique optimum, as from any
exact QP solver; and it is a fixed sequence of dense operations, bitwise reproducible (an iterative
solver's result differs from run to run at the 1e-15 level).

Range-space form: with H = L L^T and v = blockdiag(L, I)^-1 n, an active set A gives
S = V_A^T V_A (= N_A H_qp^-1 N_A^T, Cholesky factor L_S kept and extended by one row per addition);
adding p moves x along z = blockdiag(L, I)^-T (v_p - V_A r) and the multipliers along -r, with
r = S^-1 V_A^T v_p, and n_p^T z = ||v_p - V_A r||^2. The slacks enter v only as signed unit vectors,
so they are handled sparsely: S gains 1 on the diagonal of an active inequality on a slack row, and
a step changes only the slacks of p and of the active set.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import scipy.linalg.lapack as lapack


class ActiveSetError(RuntimeError):
    """The dual active-set iterations did not terminate (degenerate or inconsistent data)."""


class ActiveSetSolution(NamedTuple):
    """The optimum ``y``; the inequalities active there (``rows``, ``signs``: +1 on the lower bound,
    -1 on the upper one), a guess for a similar QP; the iterations (additions and drops)."""

    y: np.ndarray
    rows: np.ndarray
    signs: np.ndarray
    iterations: int


@np.errstate(divide="ignore", invalid="ignore")  # 0/0 and x/0 are handled where they arise
def solve_dual_active_set(
    H: np.ndarray,
    g: np.ndarray,
    D: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    first_slack_row: int,
    tol: float,
    max_iter: int | None = None,
    guess: tuple[np.ndarray, np.ndarray] | None = None,
) -> ActiveSetSolution:
    """The optimum of the QP of the module docstring (every row met to ``tol``).

    Args:
        guess: (rows, signs) of inequalities expected to be active, e.g. those of the same QP at the
            previous iteration of the IK. The method starts from them held as equalities, less those
            whose multiplier comes out negative (a dual feasible start, as the method requires): the
            optimum is the same, found in fewer iterations when the guess is good.

    Raises:
        ActiveSetError: dependent active inequalities that a partial step cannot resolve, hard rows
            that cannot all hold (not for the IK's QPs: they are feasible at y = 0), or the iteration
            cap (default 3 (rows + r) + 20).
    """
    r = H.shape[0]
    m = D.shape[0]
    chol, info = lapack.dpotrf(H, lower=1, clean=1)
    if info != 0:
        raise ActiveSetError("H is not positive definite")
    L_inv, info = lapack.dtrtri(chol, lower=1)  # (its upper triangle stays zero)
    if info != 0:
        raise ActiveSetError("H is singular")
    # Coordinates x = L^T y: the rows become W = D L^-T, v_p = L^-1 D_p = W_p, and a primal step
    # along H^-1 (n_p - N_A r) is a step along rho = v_p - V_A^T r.
    W = D.dot(L_inv.T)
    x = -L_inv.dot(g)  # the unconstrained minimizer, L^T (-H^-1 g)
    n_slack_rows = m - first_slack_row
    cap = min(m, r + n_slack_rows)  # at most as many independent normals as variables
    V = np.empty((cap, r))  # rows: y part of v = blockdiag(L, I)^-1 n of the active inequalities
    P = np.empty((cap, r))  # S^-1 V, S = V V^T + diag(active on a slack row)
    rows = np.empty(cap, dtype=int)
    signs = np.empty(cap)
    slack_a = np.zeros(cap, dtype=bool)
    u = np.empty(cap)  # multipliers (>= 0)
    q = 0
    n_slack_active = 0
    w = np.zeros(m) if n_slack_rows else None  # slack of each row (rows >= first_slack_row)
    masked = np.zeros(m)  # +inf on the active rows
    if guess is not None and guess[0].shape[0] and guess[0].shape[0] <= cap:
        g_rows, g_signs = guess
        for _ in range(4):  # drop the inequalities with a negative multiplier, re-solve
            start = _equality_point(W, x, lo, hi, g_rows, g_signs, g_rows >= first_slack_row)
            if start is None:
                break  # dependent guess: start from the unconstrained minimizer
            x_g, mult, P_g = start
            negative = mult < 0.0
            if negative.any():
                g_rows, g_signs = g_rows[~negative], g_signs[~negative]
                if not g_rows.shape[0]:
                    break
                continue
            q = g_rows.shape[0]
            x = x_g
            V[:q] = g_signs[:, None] * W[g_rows]
            P[:q] = P_g
            rows[:q], signs[:q], u[:q] = g_rows, g_signs, mult
            slack_a[:q] = g_rows >= first_slack_row
            n_slack_active = int(np.count_nonzero(slack_a[:q]))
            masked[g_rows] = math.inf
            if w is not None:
                # w = sum_j u_j (-sign_j e_row_j) over the active slack rows
                w[g_rows[slack_a[:q]]] = -(g_signs * mult)[slack_a[:q]]
            break
    max_iter = 3 * (m + r) + 20 if max_iter is None else max_iter
    iterations = 0
    while True:
        values = W.dot(x)
        if w is not None:
            values -= w
        viol = np.minimum(values - lo, hi - values)  # (bounds of +-1e20 are never violated)
        viol_free = viol + masked
        p = int(viol_free.argmin())
        if not viol_free.item(p) < -tol:
            if q and viol.min() < -tol:
                # only active rows are off (rounding in the updates): recompute from the set
                start = _equality_point(W, -L_inv.dot(g), lo, hi, rows[:q], signs[:q], slack_a[:q])
                if start is None:
                    raise ActiveSetError("dependent active inequalities")
                x = start[0]
            return ActiveSetSolution(L_inv.T.dot(x), rows[:q].copy(), signs[:q].copy(), iterations)
        value_p, lo_p, hi_p = values.item(p), lo.item(p), hi.item(p)
        sign_p = 1.0 if value_p - lo_p <= hi_p - value_p else -1.0
        b_p = lo_p if sign_p > 0.0 else -hi_p
        v_p = W[p] if sign_p > 0.0 else -W[p]
        p_slack = p >= first_slack_row
        S_pp = v_p.dot(v_p) + (1.0 if p_slack else 0.0)
        u_p = 0.0
        current = sign_p * value_p  # n_p^T x
        # Add p, dropping active inequalities whose multiplier would turn negative (partial steps).
        while True:
            iterations += 1
            if iterations > max_iter:
                raise ActiveSetError(f"no convergence in {max_iter} iterations")
            if q:
                step_r = P[:q].dot(v_p)  # r = S^-1 V_A v_p
                rho = v_p - step_r.dot(V[:q])
                zz = rho.dot(rho)
                if p_slack:
                    zz += 1.0
                if n_slack_active:
                    r_s = step_r[slack_a[:q]]
                    zz += r_s.dot(r_s)
                # partial step: the first active multiplier to reach zero
                ratios = u[:q] / step_r  # (under errstate: only the positive r_j count)
                ratios[step_r <= 1e-14] = math.inf
                k = int(ratios.argmin())
                t1 = ratios.item(k)
            else:
                rho = v_p
                zz = S_pp
                t1, k = math.inf, -1
            dependent = zz <= 1e-13 * S_pp  # n_p in the span of the active normals: z = 0
            t2 = math.inf if dependent else (b_p - current) / zz
            t = t1 if t1 < t2 else t2
            if not math.isfinite(t):
                raise ActiveSetError("the hard rows cannot all hold")
            if not dependent:
                x += t * rho
                current += t * zz  # n_p^T z = zz
                if w is not None:
                    if p_slack:
                        w[p] -= t * sign_p
                    if n_slack_active:
                        # z on w: -sign_p e_p + sum_j r_j sign_j e_row_j over the active slack rows
                        slack_j = np.flatnonzero(slack_a[:q])
                        w[rows[slack_j]] += t * step_r[slack_j] * signs[slack_j]
            if q:
                u[:q] -= t * step_r
            u_p += t
            if t == t2:
                if q >= cap:
                    raise ActiveSetError("more active inequalities than variables")
                # S_new^-1 V_new by the bordering formula (Schur complement zz, S^-1 s = r)
                scaled = rho / zz
                if q:
                    P[:q] -= step_r[:, None] * scaled
                P[q] = scaled
                V[q] = v_p
                rows[q], signs[q], slack_a[q], u[q] = p, sign_p, p_slack, u_p
                masked[p] = math.inf
                q += 1
                n_slack_active += p_slack
                break
            # drop inequality k and retry p from the new point
            masked[rows[k]] = 0.0
            n_slack_active -= bool(slack_a[k])
            q -= 1
            for array in (V, rows, signs, slack_a, u):
                array[k:q] = array[k + 1 : q + 1]  # (numpy copies overlapping slices correctly)
            if q:
                S = V[:q].dot(V[:q].T)
                S.flat[:: q + 1] += slack_a[:q]
                S_chol, info = lapack.dpotrf(S, lower=1)
                if info != 0:
                    raise ActiveSetError("dependent active inequalities")
                P[:q] = lapack.dpotrs(S_chol, V[:q], lower=1)[0]


def _equality_point(
    W: np.ndarray,
    x_free: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    rows: np.ndarray,
    signs: np.ndarray,
    slack: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The minimizer with the inequalities (rows, signs) held as equalities, from the unconstrained
    one ``x_free`` (coordinates x = L^T y): (x = x_free + V^T u, the multipliers u with
    S u = b - V x_free, S^-1 V); None when their normals are (nearly) dependent."""
    V = signs[:, None] * W[rows]
    S = V.dot(V.T)
    S.flat[:: rows.shape[0] + 1] += slack
    scale = S.diagonal().max()
    S_chol, info = lapack.dpotrf(S, lower=1)
    if info != 0 or S_chol.diagonal().min() ** 2 <= 1e-13 * scale:
        return None
    b = np.where(signs > 0.0, lo[rows], -hi[rows])
    mult = lapack.dpotrs(S_chol, b - V.dot(x_free), lower=1)[0]
    return x_free + V.T.dot(mult), mult, lapack.dpotrs(S_chol, V, lower=1)[0]


__all__ = ["ActiveSetError", "ActiveSetSolution", "solve_dual_active_set"]
