"""The ZMP reference of a walk on the sampling grid (input of the preview control of Kajita et al. 2003).

During a single support the reference stays at a fixed point of the support sole (its centre, shifted by
an optional offset in the sole frame). During a double support it moves from the old support point to
the new one along the straight segment between them, which lies inside the convex hull of the two
soles, with a 5th-order smoothstep in time (zero velocity and acceleration at both ends). The initial
double support (after the standing lead-in) starts from the initial ZMP (by default the middle of the
starting soles) and the final double support ends between the final soles, where the reference stays
during the final hold.
"""

from __future__ import annotations

import math

import numpy as np

from services.model.ground import smoothstep5
from services.walking.footsteps import FootstepSequence, Side, SolePose, other_side
from services.walking.timing import Schedule

__all__ = ["smoothstep5", "support_point", "zmp_reference"]


def support_point(pose: SolePose, side: Side, offset_m: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """ZMP target [m] of a support sole: the sole centre shifted by ``offset_m`` = (forward, inward) in
    the sole frame (inward is -y for the left sole, +y for the right sole)."""
    fwd, inward = offset_m
    dy = -inward if side == "left" else inward
    c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
    return np.array([pose.x_m + c * fwd - s * dy, pose.y_m + s * fwd + c * dy])


def _mid_point(left: SolePose, right: SolePose, offset_m: tuple[float, float]) -> np.ndarray:
    return 0.5 * (support_point(left, "left", offset_m) + support_point(right, "right", offset_m))


def zmp_reference(
    seq: FootstepSequence,
    schedule: Schedule,
    *,
    offset_m: tuple[float, float] = (0.0, 0.0),
    initial_zmp_m: np.ndarray | None = None,
) -> np.ndarray:
    """ZMP reference (n_samples, 2) [m] in the world frame for ``seq`` laid out by ``schedule``.

    Args:
        seq: the footsteps (validated by the caller).
        schedule: the phases, from :func:`services.walking.timing.build_schedule` on ``seq``.
        offset_m: (forward, inward) shift [m] of the ZMP target inside each support sole.
        initial_zmp_m: (x, y) [m] where the reference starts (e.g. the ground projection of the
            initial CoM); default: the middle of the starting soles.
    """
    stances = seq.stances()
    steps = seq.steps
    start = (
        _mid_point(seq.left_start, seq.right_start, offset_m)
        if initial_zmp_m is None
        else np.asarray(initial_zmp_m, dtype=float)[:2]
    )

    def stance_point(i: int) -> np.ndarray:
        """Support point during the swing of step i."""
        side = other_side(steps[i].side)
        left, right = stances[i]
        return support_point(left if side == "left" else right, side, offset_m)

    final_mid = _mid_point(*stances[-1], offset_m)
    out = np.empty((schedule.n_samples, 2))
    for seg in schedule.segments:
        sl = slice(seg.start, seg.stop)
        if seg.role == "swing":
            out[sl] = stance_point(seg.step_index)
            continue
        if seg.role == "hold":
            out[sl] = final_mid
            continue
        if seg.role == "start":
            out[sl] = start
            continue
        if seg.role == "initial":
            a, b = start, stance_point(0)
        elif seg.role == "transfer":
            a, b = stance_point(seg.step_index), stance_point(seg.step_index + 1)
        else:  # "final"
            a, b = stance_point(seg.step_index), final_mid
        s = smoothstep5(np.arange(seg.n) / seg.n)[:, None]
        out[sl] = a + s * (b - a)
    out[-1] = final_mid  # the closing sample ends the final transfer (or the hold)
    return out
