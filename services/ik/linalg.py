"""Small dense linear algebra for the hierarchy, straight on LAPACK (these matrices have tens of
rows: the Python overhead of each call matters more than the flops)."""

from __future__ import annotations

import numpy as np
import scipy.linalg.lapack as lapack


def damped_least_squares(M: np.ndarray, e: np.ndarray, damping: float) -> np.ndarray:
    """y = argmin ||M y - e||^2 + damping ||y||^2, by the normal equations of the smaller side
    (M^T (M M^T + damping I)^-1 e when M is wide), with a least-squares fallback when they are
    singular (no damping and a rank-deficient M)."""
    m, r = M.shape
    if m < r:
        normal = M.dot(M.T)
        normal.flat[:: m + 1] += damping
        chol, info = lapack.dpotrf(normal)
        if info == 0:
            return M.T.dot(lapack.dpotrs(chol, e)[0])
    else:
        normal = M.T.dot(M)
        normal.flat[:: r + 1] += damping
        chol, info = lapack.dpotrf(normal)
        if info == 0:
            return lapack.dpotrs(chol, M.T.dot(e))[0]
    return np.linalg.lstsq(M, e, rcond=None)[0]


def kernel(M: np.ndarray, rank_tol: float, Z: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Z N with N an orthonormal basis of ker M (N itself when Z is None), and the rank of M.

    Pivoted QR M^T P = Q R: the rank k counts the pivots above ``rank_tol * max(1, |R_00|)``
    (they are non-increasing) and ker M = span Q[:, k:]. Z Q is formed by applying the Householder
    reflectors to Z (no explicit Q)."""
    m, r = M.shape
    qr, _, tau, _, _ = lapack.dgeqp3(M.T)
    kk = min(m, r)
    threshold = rank_tol * max(1.0, abs(qr[0, 0]))
    if abs(qr[kk - 1, kk - 1]) > threshold:
        rank = kk
    else:
        rank = int(np.count_nonzero(np.abs(np.diagonal(qr)) > threshold))
    if rank == 0:
        return (np.eye(r) if Z is None else Z), 0
    if Z is None:
        basis = np.zeros((r, r), order="F")
        basis[:, :kk] = qr[:, :kk]
        Q = lapack.dorgqr(basis, tau[:kk], lwork=64 * r, overwrite_a=1)[0]
        return Q[:, rank:], rank
    ZQ = lapack.dormqr("R", "N", qr[:, :kk], tau[:kk], Z, lwork=64 * Z.shape[0])[0]
    return ZQ[:, rank:], rank


def restrict(Z: np.ndarray | None, selected: np.ndarray, nv: int, rank_tol: float) -> np.ndarray:
    """Basis of {Z y : (Z y)_i = 0 for the unselected i}: a selection matrix S on a level."""
    if Z is None:
        return np.eye(nv)[:, selected]
    locked_rows = Z[~selected]
    if locked_rows.shape[0] == 0:
        return Z
    return kernel(locked_rows, rank_tol, Z)[0]


def metric_orthonormal(Z: np.ndarray | None, nv: int, metric: np.ndarray | None) -> np.ndarray:
    """Z L^-T with Z^T W Z = L L^T: a basis of span Z orthonormal in the metric W = diag(metric)
    (identity when None), so that ||y|| is the W-norm of the increment Z y."""
    if Z is None:
        return np.diag(1.0 / np.sqrt(metric)) if metric is not None else np.eye(nv)
    G = Z.T.dot(Z * metric[:, None]) if metric is not None else Z.T.dot(Z)
    chol, info = lapack.dpotrf(G, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError("level basis is rank deficient (metric Cholesky failed)")
    return lapack.dtrtrs(chol, Z.T, lower=1)[0].T
