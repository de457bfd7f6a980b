"""The multibody ZMP of a whole-body trajectory, from pinocchio's centroidal dynamics.

With h = (m c', L_c) the centroidal momentum (linear, angular about the CoM, world axes) and its rate
dh = (m c'', L_c'), the contact wrench on flat ground z = z_g balances gravity and dh. Its moment about
the point p = (p_x, p_y, z_g) has no horizontal component at the ZMP, which gives

    p_x = c_x - (c_z - z_g) m c''_x / (m (g + c''_z)) - L_c'_y / (m (g + c''_z))
    p_y = c_y - (c_z - z_g) m c''_y / (m (g + c''_z)) + L_c'_x / (m (g + c''_z))

(the cart-table ZMP p = c - z_c/g c'' of Kajita 2003 eq. (7) when L_c' = 0 and c''_z = 0). The
velocities and accelerations of q(t) are central finite differences on the Lie group
(pin.difference), the trajectory being at rest before its first and after its last sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services import budget
from services.errors import InfeasibleError, InvalidRequestError

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class MultibodyZmp:
    """Per-sample centroidal quantities of a trajectory and its ZMP."""

    zmp_m: np.ndarray  # (n, 2)
    com_m: np.ndarray  # (n, 3)
    com_acc_m_s2: np.ndarray  # (n, 3)
    angular_momentum_rate_n_m: np.ndarray  # (n, 3) dL/dt about the CoM, world axes [N m]


def finite_difference_velocities(
    model: pin.Model, qs: np.ndarray, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """(v (n, nv), a (n, nv)) of a configuration trajectory ``qs`` (n, nq) sampled at ``dt_s`` [s]:
    central differences, with the robot at rest before the first and after the last sample."""
    n = qs.shape[0]
    # d[k] = difference(q_k, q_{k+1}) / dt for k = 0..n-2; zero outside (at rest).
    d = np.zeros((n + 1, model.nv))
    for k in range(n - 1):
        d[k + 1] = pin.difference(model, qs[k], qs[k + 1]) / dt_s
    v = 0.5 * (d[:-1] + d[1:])
    a = (d[1:] - d[:-1]) / dt_s
    return v, a


def multibody_zmp(
    model: pin.Model,
    qs: np.ndarray,
    dt_s: float,
    *,
    ground_z_m: float = 0.0,
    gravity_m_s2: float = GRAVITY_M_S2,
    data: pin.Data | None = None,
) -> MultibodyZmp:
    """The ZMP (n, 2) [m] on the ground plane z = ``ground_z_m`` of the whole-body motion ``qs``
    (n, nq) of a free-flyer ``model``, from pin.computeCentroidalMomentumTimeVariation."""
    qs = np.asarray(qs, dtype=float)
    if qs.ndim != 2 or qs.shape[1] != model.nq:
        raise InvalidRequestError(f"qs must be (n, {model.nq}), got {qs.shape}")
    if not (np.isfinite(dt_s) and dt_s > 0):
        raise InvalidRequestError(f"dt_s must be > 0, got {dt_s}")
    data = data or model.createData()
    v, a = finite_difference_velocities(model, qs, dt_s)
    n = qs.shape[0]
    mass = sum(inertia.mass for inertia in model.inertias)
    com = np.empty((n, 3))
    dh = np.empty((n, 6))
    for k in range(n):
        if k % 1000 == 0:
            budget.check(f"the multibody ZMP of the walk, sample {k} of {n}")
        pin.computeCentroidalMomentumTimeVariation(model, data, qs[k], v[k], a[k])
        com[k] = data.com[0]
        dh[k, :3] = data.dhg.linear
        dh[k, 3:] = data.dhg.angular
    return zmp_from_centroidal(com, dh, mass, ground_z_m=ground_z_m, gravity_m_s2=gravity_m_s2)


def zmp_from_centroidal(
    com_m: np.ndarray,
    dh: np.ndarray,
    mass_kg: float,
    *,
    ground_z_m: float = 0.0,
    gravity_m_s2: float = GRAVITY_M_S2,
) -> MultibodyZmp:
    """ZMP from the CoM (n, 3) [m] and the centroidal momentum rate dh (n, 6) = (m c'' [N], dL/dt [N m])."""
    fz = dh[:, 2] + mass_kg * gravity_m_s2
    if np.any(fz <= 0):
        k = int(np.argmax(fz <= 0))
        raise InfeasibleError(
            f"the motion accelerates the CoM downwards faster than gravity at sample {k} (vertical contact "
            f"force {fz[k]:.1f} N <= 0): the feet would leave the ground and there is no ZMP; look for a "
            "jump in the trajectory (e.g. a task target far from the starting configuration)",
            {"sample": k, "vertical_force_n": float(fz[k])},
        )
    height = com_m[:, 2] - ground_z_m
    zmp = np.empty((com_m.shape[0], 2))
    zmp[:, 0] = com_m[:, 0] - (height * dh[:, 0] + dh[:, 4]) / fz
    zmp[:, 1] = com_m[:, 1] - (height * dh[:, 1] - dh[:, 3]) / fz
    return MultibodyZmp(zmp, com_m, dh[:, :3] / mass_kg, dh[:, 3:])
