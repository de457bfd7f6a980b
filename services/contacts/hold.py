"""Held contacts kept in place at every sample of a timed segment, not only at its postures (§3.3 of
Escande et al.: the motion between two contact sets keeps the held contacts).

The interpolation generates n postures that match the held contacts (within the posture generator's
tolerance) and times a cubic spline through them, joint by joint. Between two postures the spline
does not keep a held spot on its surface: measured on the chair egress, a hand on the table went
1.7 mm into it in the middle of a foot's swing. Under position control that is not a small error: the
loop floor - stance leg - body - arm - table is rigid, the motors push against the table with all
their torque (the wrist, then the shoulder and elbow at their effort limits, the hand at 300 N while
the plan needed 103-120 N), the stance sole's centre of pressure ran to its heel and the robot fell
(services/contacts/README.md, session 8).

Here every sample is corrected by a few Gauss-Newton steps on the held spots' frame errors (6-D, the
free flyer included: the smallest change of the whole configuration), each spot held on the geodesic
between its poses at the segment's first and last samples (both on their surfaces: at the start the
measured or planned posture, at the end the witness).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

HOLD_TOL = 1e-5  # frame error [m / rad] below which a sample is left as it is
HOLD_ITERS = 3
DAMPING = 1e-8


def hold_spots(
    model: pin.Model,
    frames: Sequence[str],
    samples: np.ndarray,
    bound_idx: np.ndarray,
    q_lower: np.ndarray,
    q_upper: np.ndarray,
) -> tuple[np.ndarray, float]:
    """``samples`` (N x nq) with the frames ``frames`` held on the geodesic between their poses at the
    first and last samples (both kept as they are); joints ``bound_idx`` clipped to their limits.
    Returns (the corrected samples, the largest frame error [m or rad] found before correcting)."""
    out = np.array(samples, dtype=float, copy=True)
    if not frames or len(out) < 3:
        return out, 0.0
    data = model.createData()
    ids = [model.getFrameId(f) for f in frames]

    def poses(q: np.ndarray) -> list[pin.SE3]:
        pin.framesForwardKinematics(model, data, q)
        return [pin.SE3(data.oMf[i]) for i in ids]

    start, end = poses(out[0]), poses(out[-1])
    deltas = [pin.log6(a.actInv(b)) for a, b in zip(start, end, strict=True)]
    worst = 0.0
    n = len(out)
    for k in range(1, n - 1):
        s = k / (n - 1)
        targets = [a * pin.exp6(d * s) for a, d in zip(start, deltas, strict=True)]
        q = out[k]
        for it in range(HOLD_ITERS):
            pin.framesForwardKinematics(model, data, q)
            errors = [pin.log6(t.actInv(data.oMf[i])).vector for t, i in zip(targets, ids, strict=True)]
            error = np.concatenate(errors)
            size = float(np.abs(error).max())
            if it == 0:
                worst = max(worst, size)
            if size < HOLD_TOL:
                break
            pin.computeJointJacobians(model, data, q)
            J = np.vstack([pin.getFrameJacobian(model, data, i, pin.LOCAL) for i in ids])
            # the log's Jacobian is the identity to first order for these small errors
            dq = -J.T.dot(np.linalg.solve(J.dot(J.T) + DAMPING * np.eye(J.shape[0]), error))
            q = pin.integrate(model, q, dq)
            q[bound_idx] = q[bound_idx].clip(q_lower[bound_idx], q_upper[bound_idx])
        out[k] = q
    return out, worst
