"""Cart-table model and ZMP preview control (Kajita et al., ICRA 2003, "Biped walking pattern generation
by using preview control of zero-moment point", reference 7 of the reaching paper 001).

Discrete cart-table model with the CoM jerk as input (Kajita 2003, eq. (9)-(10)), per horizontal axis:

    x_{k+1} = A x_k + B u_k,    p_k = C x_k,        x = (c, c', c'') [m, m/s, m/s^2], u = c''' [m/s^3]
    A = [[1, T, T^2/2], [0, 1, T], [0, 0, 1]],  B = [T^3/6, T^2/2, T],  C = [1, 0, -z_c/g]

The preview controller with integral action (Kajita 2003, eq. (11)-(14), after Katayama et al.) minimises
sum Qe e_k^2 + dx_k^T Qx dx_k + R du_k^2 (e = p - p_ref) and applies

    u_k = -Gi sum_{i<=k} (p_i - p_ref_i) - Gx x_k - sum_{j=1..N} Gd(j) p_ref_{k+j}

with the gains from the discrete algebraic Riccati equation of the augmented (incremental) system.

The time loop is run without a Python loop: the future-reference term is one correlation of the
reference with Gd, and the closed loop z_{k+1} = M z_k + w_k (z = (x, sum e)) is diagonalised so that each
mode is a first-order recursive filter (scipy.signal.lfilter). :func:`simulate_loop` is the plain
per-sample loop, kept as the readable reference the fast path is tested against.

The same controller is the second stage of Kajita 2003 (section IV-B): fed with the error between the
desired ZMP and the multibody ZMP of the first-stage motion, it gives the CoM correction
(:func:`second_stage_correction`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal

from services.errors import InvalidRequestError

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class PreviewGains:
    """Preview-control gains for one (dt, z_c, horizon, weights). Arrays are read-only."""

    dt_s: float
    com_height_m: float
    horizon_s: float
    q_e: float
    r: float
    A: np.ndarray  # (3, 3)
    B: np.ndarray  # (3,)
    C: np.ndarray  # (3,)
    Gi: float  # integral gain
    Gx: np.ndarray  # (3,) state feedback gain
    Gd: np.ndarray  # (N,) preview gains for p_ref_{k+1} .. p_ref_{k+N}
    M: np.ndarray  # (4, 4) closed loop on z = (x, sum e)
    eigvals: np.ndarray  # (4,) of M (complex)
    V: np.ndarray  # (4, 4) eigenvectors of M (complex)
    V_inv: np.ndarray  # (4, 4)

    @property
    def n_preview(self) -> int:
        """Number of preview samples N."""
        return int(self.Gd.shape[0])


@dataclass(frozen=True)
class PreviewResult:
    """Cart-table trajectories on the grid, (n, d) with d the number of axes (1 or 2)."""

    com_m: np.ndarray  # c [m]
    com_vel_m_s: np.ndarray  # c' [m/s]
    com_acc_m_s2: np.ndarray  # c'' [m/s^2]
    zmp_m: np.ndarray  # p = c - z_c/g c'' [m], the ZMP the cart-table realises
    jerk_m_s3: np.ndarray  # u [m/s^3]


@functools.lru_cache(maxsize=64)
def preview_gains(
    dt_s: float = 0.005,
    com_height_m: float = 0.8,
    horizon_s: float = 1.6,
    q_e: float = 1.0,
    r: float = 1e-6,
    gravity_m_s2: float = GRAVITY_M_S2,
) -> PreviewGains:
    """Gains of Kajita 2003 eq. (12)-(14) (Qx = 0), cached per arguments.

    Args:
        dt_s: sampling period T [s].
        com_height_m: height z_c of the CoM above the ground [m].
        horizon_s: preview horizon [s] (N = round(horizon / T) samples).
        q_e: weight on the ZMP tracking error; r: weight on the jerk increments (Kajita: 1, 1e-6).
    """
    for name, value in (
        ("dt_s", dt_s),
        ("com_height_m", com_height_m),
        ("horizon_s", horizon_s),
        ("q_e", q_e),
        ("r", r),
    ):
        if not (np.isfinite(value) and value > 0):
            raise InvalidRequestError(f"preview control: {name} must be > 0, got {value}")
    T = dt_s
    A = np.array([[1.0, T, T * T / 2], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
    B = np.array([T**3 / 6, T * T / 2, T])
    C = np.array([1.0, 0.0, -com_height_m / gravity_m_s2])
    n_prev = max(1, round(horizon_s / T))

    # Augmented incremental system (Kajita 2003 eq. (11)): state (e_k, dx_k), input du_k.
    At = np.zeros((4, 4))
    At[0, 0] = 1.0
    At[0, 1:] = C @ A
    At[1:, 1:] = A
    Bt = np.concatenate([[C @ B], B])[:, None]
    Qt = np.zeros((4, 4))
    Qt[0, 0] = q_e
    Rm = np.array([[r]])
    P = scipy.linalg.solve_discrete_are(At, Bt, Qt, Rm)
    S = (Rm + Bt.T @ P @ Bt)[0, 0]
    K = (Bt.T @ P @ At) / S  # (1, 4) = [Gi, Gx]
    Gi = float(K[0, 0])
    Gx = K[0, 1:].copy()

    # Preview gains (Kajita 2003 eq. (14)): Gd(1) = -Gi, X_1 = -Ac^T P I,
    # Gd(j) = (R + B^T P B)^-1 B^T X_{j-1}, X_j = Ac^T X_{j-1}.
    Ac = At - Bt @ K
    I_t = np.array([1.0, 0.0, 0.0, 0.0])
    X = -Ac.T @ P @ I_t
    Gd = np.empty(n_prev)
    Gd[0] = -Gi
    for j in range(1, n_prev):
        Gd[j] = (Bt[:, 0] @ X) / S
        X = Ac.T @ X

    # Closed loop on z = (x, sum e): see the module docstring.
    ABG = A - np.outer(B, Gx)
    M = np.zeros((4, 4))
    M[:3, :3] = ABG
    M[:3, 3] = -B * Gi
    M[3, :3] = C @ ABG
    M[3, 3] = 1.0 - (C @ B) * Gi
    eigvals, V = np.linalg.eig(M)
    V_inv = np.linalg.inv(V)
    for arr in (A, B, C, Gx, Gd, M, eigvals, V, V_inv):
        arr.setflags(write=False)
    return PreviewGains(dt_s, com_height_m, horizon_s, q_e, r, A, B, C, Gi, Gx, Gd, M, eigvals, V, V_inv)


def _as_2d(zmp_ref_m: np.ndarray) -> tuple[np.ndarray, bool]:
    ref = np.asarray(zmp_ref_m, dtype=float)
    squeeze = ref.ndim == 1
    ref = ref[:, None] if squeeze else ref
    if ref.ndim != 2 or ref.shape[0] < 1:
        raise InvalidRequestError(f"ZMP reference must be (n,) or (n, d), got shape {ref.shape}")
    if not np.all(np.isfinite(ref)):
        raise InvalidRequestError("ZMP reference has non-finite values")
    return ref, squeeze


def _initial_state(x0: np.ndarray | None, ref: np.ndarray) -> np.ndarray:
    """(3, d) initial state: by default at rest on the first reference point."""
    d = ref.shape[1]
    if x0 is None:
        X0 = np.zeros((3, d))
        X0[0] = ref[0]
        return X0
    X0 = np.array(x0, dtype=float).reshape(3, -1)
    if X0.shape[1] != d:
        raise InvalidRequestError(f"initial state must be (3,) or (3, {d}), got {np.shape(x0)}")
    return X0


def _relative_to_start(ref: np.ndarray, X0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ref, X0, origin) expressed relative to the first reference point ``origin`` = ref[0].

    The controller of Kajita 2003 eq. (13) is not translation invariant with a finite preview window:
    its gains satisfy Gx[0] + sum_j Gd(j) != 0 (about 270 of 72000 for HRP-2's 0.8 m and 1.6 s), so
    at a constant offset d the integral term sum e must hold -(Gx[0] + sum Gd) d / Gi to stay at rest.
    Starting it at 0 far from the origin kicks the CoM: the ZMP swung 0.36 m for a walk starting at
    x = 2.9 m. Working relative to the start makes every walk behave as if it started at the origin,
    where that state is the rest state.
    """
    origin = ref[0].copy()
    X0 = X0.copy()
    X0[0] -= origin
    return ref - origin, X0, origin


def _shifted(X: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """States (n, 3, d) of :func:`_relative_to_start` back in the caller's frame (positions only)."""
    X = X.copy()
    X[:, 0] += origin
    return X


def preview_term(gains: PreviewGains, ref: np.ndarray) -> np.ndarray:
    """f_k = sum_{j=1..N} Gd(j) p_ref_{k+j} for every k, the reference held at its last value beyond
    the end (the robot stops). ``ref`` (n, d) -> (n, d)."""
    n, N = ref.shape[0], gains.n_preview
    ext = np.concatenate([ref[1:], np.repeat(ref[-1:], N, axis=0)], axis=0)  # p_ref_{1 .. n-1+N}
    return np.stack([np.correlate(ext[:, a], gains.Gd, mode="valid")[:n] for a in range(ref.shape[1])], 1)


def _outputs(gains: PreviewGains, X: np.ndarray, U: np.ndarray, squeeze: bool) -> PreviewResult:
    """X (n, 3, d) states, U (n, d) jerks -> PreviewResult."""
    zmp = np.einsum("i,nid->nd", gains.C, X)
    parts = [X[:, 0], X[:, 1], X[:, 2], zmp, U]
    if squeeze:
        parts = [p[:, 0] for p in parts]
    return PreviewResult(*parts)


def simulate(gains: PreviewGains, zmp_ref_m: np.ndarray, x0: np.ndarray | None = None) -> PreviewResult:
    """Run the preview controller on a ZMP reference (n,) or (n, d) [m] sampled at ``gains.dt_s``.

    ``x0`` is the initial state (c, c', c'') per axis, (3,) or (3, d); default: at rest on ``zmp_ref[0]``.
    Returns the state and the realised ZMP at the n samples (sample k is the state before the k-th jerk).
    """
    ref, squeeze = _as_2d(zmp_ref_m)
    n, d = ref.shape
    ref, X0, origin = _relative_to_start(ref, _initial_state(x0, ref))
    f = preview_term(gains, ref)
    # Input of z_{k+1} = M z_k + w_k, per axis: w = [-B f_k ; -C B f_k - p_ref_{k+1}].
    ref_next = np.concatenate([ref[1:], ref[-1:]], axis=0)
    B, C = gains.B, gains.C
    W = np.empty((n, 4, d))
    W[:, :3] = -B[None, :, None] * f[:, None, :]
    W[:, 3] = -(C @ B) * f - ref_next
    Z0 = np.concatenate([X0, (C @ X0 - ref[0])[None]], axis=0)  # sum e includes sample 0
    # Modal decomposition: y = V^-1 z, y_{k+1} = lambda y_k + (V^-1 w)_k.
    Y_in = np.einsum("ij,njd->nid", gains.V_inv, W.astype(complex))
    Y0 = gains.V_inv @ Z0.astype(complex)
    Y = np.empty((n, 4, d), dtype=complex)
    Y[0] = Y0
    for i, lam in enumerate(gains.eigvals):
        for a in range(d):
            out, _ = scipy.signal.lfilter([1.0], [1.0, -lam], Y_in[: n - 1, i, a], zi=[lam * Y0[i, a]])
            Y[1:, i, a] = out
    Z = np.einsum("ij,njd->nid", gains.V, Y).real
    X = Z[:, :3]
    U = -gains.Gi * Z[:, 3] - np.einsum("i,nid->nd", gains.Gx, X) - f
    return _outputs(gains, _shifted(X, origin), U, squeeze)


def simulate_loop(gains: PreviewGains, zmp_ref_m: np.ndarray, x0: np.ndarray | None = None) -> PreviewResult:
    """Same as :func:`simulate`, as the plain per-sample loop of Kajita 2003 eq. (13) (slow; reference)."""
    ref, squeeze = _as_2d(zmp_ref_m)
    n, d = ref.shape
    ref, x, origin = _relative_to_start(ref, _initial_state(x0, ref))
    N = gains.n_preview
    ext = np.concatenate([ref, np.repeat(ref[-1:], N, axis=0)], axis=0)
    X = np.empty((n, 3, d))
    U = np.empty((n, d))
    e_sum = np.zeros(d)
    for k in range(n):
        X[k] = x
        e_sum += gains.C @ x - ref[k]
        u = -gains.Gi * e_sum - gains.Gx @ x - gains.Gd @ ext[k + 1 : k + 1 + N]
        U[k] = u
        x = gains.A @ x + np.outer(gains.B, u)
    return _outputs(gains, _shifted(X, origin), U, squeeze)


def settle_at_end(
    result: PreviewResult,
    n_blend: int,
    dt_s: float,
    com_height_m: float,
    target_m: np.ndarray | None = None,
    gravity_m_s2: float = GRAVITY_M_S2,
) -> PreviewResult:
    """Make a preview-control trajectory end exactly at rest on ``target_m`` (default: where it ends).

    With a finite horizon the CoM is still creeping at the end (about 1 mm/s after a 1 s hold); a robot
    that stops there would jerk. Over the last ``n_blend`` samples a quintic offset d(t) with zero value,
    velocity and acceleration at its start, and d = target - c, d' = -c', d'' = -c'' at the end, is
    added to the CoM; the ZMP and jerk are recomputed from it (p = c - z_c/g c'').
    """
    n = result.com_m.shape[0]
    n_blend = int(min(max(n_blend, 2), n - 1))
    squeeze = result.com_m.ndim == 1
    c, v, a = (
        np.array(x, dtype=float).reshape(n, -1)
        for x in (result.com_m, result.com_vel_m_s, result.com_acc_m_s2)
    )
    end = c[-1] if target_m is None else np.asarray(target_m, dtype=float).reshape(-1)
    T = (n_blend - 1) * dt_s
    # Quintic d(tau) on [0, T] with d(0)=d'(0)=d''(0)=0 and prescribed d(T), d'(T), d''(T).
    d1, v1, a1 = end - c[-1], -v[-1], -a[-1]
    c3 = 10 * d1 / T**3 - 4 * v1 / T**2 + a1 / (2 * T)
    c4 = -15 * d1 / T**4 + 7 * v1 / T**3 - a1 / T**2
    c5 = 6 * d1 / T**5 - 3 * v1 / T**4 + a1 / (2 * T**3)
    tau = (np.arange(n_blend) * dt_s)[:, None]
    sl = slice(n - n_blend, n)
    c[sl] += c3 * tau**3 + c4 * tau**4 + c5 * tau**5
    v[sl] += 3 * c3 * tau**2 + 4 * c4 * tau**3 + 5 * c5 * tau**4
    a[sl] += 6 * c3 * tau + 12 * c4 * tau**2 + 20 * c5 * tau**3
    zmp = c - com_height_m / gravity_m_s2 * a
    jerk = np.zeros_like(a)
    jerk[:-1] = np.diff(a, axis=0) / dt_s
    parts = [c, v, a, zmp, jerk]
    if squeeze:
        parts = [x[:, 0] for x in parts]
    return PreviewResult(*parts)


def second_stage_correction(
    gains: PreviewGains, zmp_target_m: np.ndarray, zmp_multibody_m: np.ndarray
) -> PreviewResult:
    """CoM correction of the second preview stage (Kajita 2003, section IV-B, Fig. 9).

    The error dp = p_target - p_multibody between the desired ZMP and the ZMP of the multibody motion
    is the reference of the same preview controller starting at rest at zero; the resulting ``com_m``
    (and its derivatives) is the correction dc to add to the first-stage CoM, so that the cart-table
    ZMP moves by about dp and the multibody ZMP comes back onto the target.
    """
    target = np.asarray(zmp_target_m, dtype=float)
    mb = np.asarray(zmp_multibody_m, dtype=float)
    if target.shape != mb.shape:
        raise InvalidRequestError(f"ZMP target {target.shape} and multibody ZMP {mb.shape} differ in shape")
    err = target - mb
    return simulate(gains, err, np.zeros((3, *err.shape[1:])))
