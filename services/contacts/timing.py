"""Timing a transition's discrete path so that its motion stays quasi-static (§3.3-4 of Escande et al.:
a statically stable path, then "a smooth trajectory" with "null speed at each contact change").

The postures of a path are generated one after the other and are not evenly spaced: one step may move
the CoM 5 cm and the next one 5 mm. A spline through them with evenly spaced knots then runs fast where
the postures are far apart, and the motion is not quasi-static there even though every posture is
statically stable. Played on the simulated robot, a swing of 12 s whose planned ZMP left the CoM by
12 cm for half a second tipped the robot over the toe of its stance sole
(``services/contacts/README.md``). Here:

* each interval between two postures gets the time its largest displacement needs at the quasi-static
  speed limits (base, joints), and the spline's knots are spaced by those times (a longer interval,
  a longer time);
* the whole segment is timed by the sinusoidal speed profile (null speed at both ends, §4), its
  duration twice the sum of those times (the profile's peak speed is twice its mean);
* the timed samples' dynamics are then checked: the horizontal distance between the multibody ZMP on
  the floor (the total contact wrench the motion needs, from the recursive Newton-Euler algorithm) and
  the CoM's projection. For a static posture it is zero; it grows with the accelerations as 1 / T^2. A
  segment whose largest distance exceeds ``zmp_shift_m`` is slowed down by the square root of the
  ratio (the accelerations and velocity products scale as 1 / T^2), so that the forces the motion
  needs stay those of the static equilibrium the posture generator certified, within that shift.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicSpline

ZMP_SLOWDOWNS = 3  # at most this many re-timings of a segment whose ZMP shift is too large


def sinusoidal_profile(n_samples: int) -> np.ndarray:
    """s(t) in [0, 1] with a sinusoidal speed (1 - cos), null at both ends (§4)."""
    t = np.linspace(0.0, 1.0, n_samples)
    return t - np.sin(2.0 * math.pi * t) / (2.0 * math.pi)


def interval_times(
    model: pin.Model,
    waypoints: np.ndarray,
    base_speed_m_s: float,
    joint_speed_m_s: np.ndarray,
) -> np.ndarray:
    """(len - 1,) times [s] of the intervals between consecutive waypoints at the mean speed limits: the
    base's translation at ``base_speed_m_s`` [m/s], each joint at ``joint_speed_m_s`` (nv - 6) [rad/s]."""
    d = np.array(
        [pin.difference(model, waypoints[k], waypoints[k + 1]) for k in range(len(waypoints) - 1)]
    ).reshape(-1, model.nv)
    base = np.linalg.norm(d[:, :3], axis=1) / base_speed_m_s
    joints = (np.abs(d[:, 6:]) / joint_speed_m_s).max(axis=1) if d.shape[1] > 6 else np.zeros(len(d))
    return np.maximum(base, joints)


def knots(times: np.ndarray) -> np.ndarray:
    """Spline parameters in [0, 1] of the waypoints, spaced by the intervals' ``times`` (evenly when
    they are all zero; an interval never gets less than 1 % of an even share, so the knots increase)."""
    n = len(times)
    total = float(np.sum(times))
    share = np.full(n, 1.0 / n) if total <= 0.0 else np.maximum(times / total, 0.01 / n)
    return np.concatenate([[0.0], np.cumsum(share / share.sum())])


def time_segment(
    model: pin.Model,
    waypoints: np.ndarray,
    duration_s: float,
    dt_s: float,
    u_knots: np.ndarray | None = None,
) -> np.ndarray:
    """Samples every ``dt_s`` [s] of a clamped cubic spline through the waypoints (tangent coordinates
    from the first) at the parameters ``u_knots`` (default: evenly spaced), timed by the sinusoidal
    profile over ``duration_s`` [s]; the last sample is the last waypoint."""
    base = waypoints[0]
    d = np.array([pin.difference(model, base, w) for w in waypoints])
    u_knots = np.linspace(0.0, 1.0, len(waypoints)) if u_knots is None else np.asarray(u_knots, float)
    spline = CubicSpline(u_knots, d, bc_type="clamped")
    n = max(2, round(duration_s / dt_s) + 1)
    return np.array([pin.integrate(model, base, v) for v in spline(sinusoidal_profile(n))])


def zmp_shift(
    model: pin.Model, q: np.ndarray, dt_s: float, every: int = 1, stencil_s: float = 0.05
) -> np.ndarray:
    """Horizontal distance [m] between the ZMP on the floor (z = 0, world) of the total contact wrench
    that the motion ``q`` (N x nq, every ``dt_s`` [s]) needs and the CoM's projection, at the samples
    ``q[::every]``; zero for a static posture. Velocities and accelerations by central differences over
    ``stencil_s`` [s] (the position-controlled joints do not follow a kink of one 5 ms sample, e.g. a
    joint clipped at its limit, whose acceleration over one sample does not shrink with a slower
    motion)."""
    data = model.createData()
    n = len(q)
    h = max(1, round(stencil_s / dt_s))
    out = []
    for i in range(0, n, max(1, every)):
        a, b = max(i - h, 0), min(i + h, n - 1)
        if b == a:
            out.append(0.0)
            continue
        v = pin.difference(model, q[a], q[b]) / ((b - a) * dt_s)
        acc = np.zeros(model.nv)
        if a == i - h and b == i + h:
            acc = (pin.difference(model, q[i], q[b]) - pin.difference(model, q[a], q[i])) / (h * dt_s) ** 2
        tau = pin.rnea(model, data, q[i], v, acc)
        pin.forwardKinematics(model, data, q[i])
        wrench = data.oMi[1].act(pin.Force(tau[:6]))  # world frame, about the origin
        force, moment = wrench.linear, wrench.angular
        if force[2] <= 1e-6:  # the motion needs the robot pulled down: no ZMP
            out.append(math.inf)
            continue
        zmp = np.array([-moment[1], moment[0]]) / force[2]
        com = pin.centerOfMass(model, data, q[i])
        out.append(float(np.linalg.norm(zmp - com[:2])))
    return np.array(out)
