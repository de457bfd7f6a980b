"""The walking package's public two-stage API (Kajita et al. 2003), the one every planner that walks
or steps goes through (walking, navigation's stage 2, reaching's support polygon reshaping):

1. :func:`robot_pattern`: the first stage, the ZMP preview-control pattern of footsteps for a robot
   standing at ``q_start`` (its CoM, the height of its soles, its step height and stepping bounds);
2. :func:`correct_multibody_zmp`: the second stage, the loop around any whole-body tracker of such a
   pattern: the multibody ZMP of the tracked motion (:mod:`services.walking.multibody_zmp`) is checked
   against the support polygon (:func:`services.walking.support_polygon.distances_to_support`); where
   it comes closer than the margin to the edge, the error dp = p_ref - p_multibody goes through the same
   preview controller (Kajita 2003, section IV-B), whose CoM output, brought to rest at the end, offsets
   the CoM reference of the next tracking pass.

:func:`services.walking.wholebody.plan_walk` is both in one call; :func:`executable_walk` is the same
with the pattern's CoM height and timing derived so that the joints stay within their speed limits.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from services.errors import InfeasibleError, InvalidRequestError
from services.model.ground import SIDES, FootstepBounds, FootstepSequence
from services.walking.multibody_zmp import MultibodyZmp, multibody_zmp
from services.walking.pattern import PatternOptions, WalkPattern, plan_pattern
from services.walking.preview_control import PreviewGains, second_stage_correction, settle_at_end
from services.walking.support_polygon import distances_to_support
from services.walking.timing import WalkTiming


def robot_pattern(
    robot: Any,
    footsteps: FootstepSequence,
    q_start: np.ndarray,
    timing: WalkTiming | None = None,
    options: PatternOptions | None = None,
    *,
    com_lowering_m: float = 0.0,
) -> WalkPattern:
    """The first stage for a ``services.model`` robot standing at ``q_start``: the pattern of
    ``footsteps`` (validated against the robot's bounds), the CoM starting at the CoM of ``q_start``, the
    ground at the height of its soles, the step height from the robot's parameters unless ``options``
    says otherwise. ``com_lowering_m`` > 0 [m]: the walk's CoM height is the starting one minus this
    (reached during the standing start), unless ``options.com_height_m`` is given."""
    if options is None:
        options = PatternOptions(step_height_m=float(robot.params.step_height_m))
    q_start = robot.check_q(q_start)
    data = robot.new_data()
    ground_z_m = 0.5 * sum(float(robot.sole_pose(q_start, side, data).translation[2]) for side in SIDES)
    com_m = robot.com(q_start, data)
    if com_lowering_m > 0.0 and options.com_height_m is None:
        options = dataclasses.replace(options, com_height_m=float(com_m[2]) - ground_z_m - com_lowering_m)
    return plan_pattern(
        footsteps,
        timing or WalkTiming(),
        options,
        initial_com_m=com_m,
        bounds=FootstepBounds.from_robot(robot),
        ground_z_m=ground_z_m,
    )


@dataclass(frozen=True)
class SupportSamples:
    """The support of a motion on its sampling grid (n samples): phase codes (n,), the left and right
    sole trajectories (n, 4) = (x, y, z, yaw) [m, rad], the sole size (length, width) [m], the period
    [s], the ground height [m] and the reference ZMP (n, 2) [m] the second stage brings the multibody
    ZMP back to."""

    phase: np.ndarray
    left_sole: np.ndarray
    right_sole: np.ndarray
    sole_size_m: tuple[float, float]
    dt_s: float
    zmp_ref_m: np.ndarray
    ground_z_m: float = 0.0

    @staticmethod
    def of_pattern(pattern: WalkPattern, sole_size_m: tuple[float, float]) -> SupportSamples:
        """The support of a walking pattern."""
        return SupportSamples(
            pattern.phase,
            pattern.left_sole,
            pattern.right_sole,
            (float(sole_size_m[0]), float(sole_size_m[1])),
            pattern.dt_s,
            pattern.zmp_ref_m,
            pattern.ground_z_m,
        )

    def zmp_distance(self, model: Any, q: np.ndarray) -> tuple[MultibodyZmp, np.ndarray]:
        """The multibody ZMP of the motion ``q`` (n, nq) of pinocchio ``model`` and its signed distance
        (n,) [m] to the support polygon of each sample (< 0 inside)."""
        mb = multibody_zmp(model, q, self.dt_s, ground_z_m=self.ground_z_m)
        dist = distances_to_support(mb.zmp_m, self.phase, self.left_sole, self.right_sole, *self.sole_size_m)
        return mb, dist


@dataclass(frozen=True, eq=False)
class ZmpCorrection:
    """The outcome of :func:`correct_multibody_zmp`: the motion kept ``q`` (n, nq), its multibody ZMP and
    distance to the support (n,) [m], the CoM offset (n, 2) [m] it was tracked with, the number of
    corrections applied and one record per pass (``pass``, ``worst_outside_mm``, ``min_margin_mm``,
    ``max_zmp_error_mm``, ``max_zmp_error_walking_mm`` where the window is 1)."""

    q: np.ndarray
    zmp: MultibodyZmp
    distance_m: np.ndarray
    com_offset_m: np.ndarray
    corrections: int
    history: tuple[dict[str, float], ...]


def correct_multibody_zmp(
    model: Any,
    q: np.ndarray,
    support: SupportSamples,
    gains: PreviewGains,
    retrack: Callable[[np.ndarray], np.ndarray | None],
    *,
    window: np.ndarray,
    settle_samples: int,
    margin_m: float,
    max_corrections: int,
) -> ZmpCorrection:
    """The second stage around a whole-body tracker (Kajita 2003, section IV-B).

    Args:
        model: the pinocchio model of the motion (with any carried mass the ZMP must account for).
        q: the first tracked motion (n, nq).
        support: the motion's support and reference ZMP.
        gains: the preview controller of the pattern (its CoM height).
        retrack: the tracker: the motion tracked with the CoM reference offset by (n, 2) [m], or None
            when the tracker rejects it (the last motion is then kept).
        window: weight (n,) of the ZMP error (0 where a correction cannot act: before the start, after
            the robot has come to rest).
        settle_samples: the correction is brought to rest at zero over this many last samples.
        margin_m: the multibody ZMP must stay this far inside the support polygon [m].
        max_corrections: tracking passes after the first at most.
    """
    offset = np.zeros((q.shape[0], 2))
    corrections = 0
    history: list[dict[str, float]] = []
    while True:
        mb, dist = support.zmp_distance(model, q)
        error = np.abs(mb.zmp_m - support.zmp_ref_m)
        history.append(
            {
                "pass": float(len(history)),
                "worst_outside_mm": 1e3 * max(0.0, float(dist.max())),
                "min_margin_mm": -1e3 * float(dist.max()),
                "max_zmp_error_mm": 1e3 * float(error.max()),
                "max_zmp_error_walking_mm": 1e3 * float(error[window >= 1.0].max(initial=0.0)),
            }
        )
        if dist.max() <= -margin_m or corrections >= max_corrections:
            break
        dp = window[:, None] * (support.zmp_ref_m - mb.zmp_m)
        corr = second_stage_correction(gains, dp, np.zeros_like(dp))
        corr = settle_at_end(corr, settle_samples, support.dt_s, gains.com_height_m, np.zeros(2))
        candidate = retrack(offset + corr.com_m)
        if candidate is None:
            break
        offset = offset + corr.com_m
        q = candidate
        corrections += 1
    return ZmpCorrection(q, mb, dist, offset, corrections, tuple(history))


@dataclass(frozen=True)
class WalkAdjustment:
    """A change of the first stage that keeps the whole-body motion within the joints' speed limits:
    the walk's CoM lowered by ``com_lowering_m`` [m] (a leg stretched to a step at the corner of the
    footstep bounds has its knee near the singular straight configuration, where the IK flips it back
    and forth: no slower timing helps there), and the single and double supports ``slowdown`` times
    longer (fast swings)."""

    com_lowering_m: float = 0.0
    slowdown: float = 1.0

    def timing(self, base: WalkTiming) -> WalkTiming:
        """``base`` with its single and double supports ``slowdown`` times longer."""
        if self.slowdown == 1.0:
            return base
        return dataclasses.replace(
            base,
            single_support_s=base.single_support_s * self.slowdown,
            double_support_s=base.double_support_s * self.slowdown,
        )


#: CoM lowerings [m] tried, in order, when a walk's whole-body motion has a joint faster than its
#: limit. The usual cause is a leg stretched near its straight knee: a front leg at heel strike while
#: the CoM is still over the rear foot (seed 6 of the fetch: after a reach the robot stood 3.2 cm
#: higher than half-sitting, knee 0.25 rad on a 0.21 m diagonal step), where the IK flips the knee or
#: swings a free arm to hold the CoM height (LARM_JOINT0 at 4.8-11.5 rad/s).
COM_LOWERINGS_M = (0.0, 0.02, 0.04, 0.06)

#: Tried in order by :func:`executable_walk`: the CoM lowered by 0-6 cm first (the usual cause is a
#: stretched knee), then the same with 1.5x longer supports.
WALK_ADJUSTMENTS = tuple(
    WalkAdjustment(lowering, slowdown) for slowdown in (1.0, 1.5) for lowering in COM_LOWERINGS_M
)


def executable_walk(
    robot: Any,
    footsteps: FootstepSequence,
    q_start: np.ndarray,
    timing: WalkTiming | None = None,
    options: PatternOptions | None = None,
    *,
    planner: Any = None,
    adjustments: tuple[WalkAdjustment, ...] = WALK_ADJUSTMENTS,
) -> tuple[Any, WalkAdjustment]:
    """``plan_walk`` of ``footsteps`` with the first :class:`WalkAdjustment` of ``adjustments`` whose
    whole-body motion keeps every joint within its speed limit and has a ZMP (a joint flipping between
    two IK knots has none): (``services.walking.wholebody.WholeBodyResult``, the adjustment used).
    ``planner``: a ``WholeBodyPlanner`` to reuse.

    Raises:
        InfeasibleError: none does (the last error's message and details, ``adjustments_tried``); any
            other error of the walking planner (footsteps outside the bounds, ...) at once.
    """
    # wholebody.py tracks the patterns of this module: imported here, at call time.
    from services.walking.wholebody import WholeBodyPlanner

    if not adjustments:
        raise InvalidRequestError("executable_walk needs at least one adjustment")
    planner = planner or WholeBodyPlanner(robot)
    base = timing or WalkTiming()
    last: InfeasibleError | None = None
    for adjustment in adjustments:
        pattern = robot_pattern(
            robot,
            footsteps,
            q_start,
            adjustment.timing(base),
            options,
            com_lowering_m=adjustment.com_lowering_m,
        )
        try:
            return planner.solve(pattern, q_start), adjustment
        except InfeasibleError as exc:
            if "joint" not in exc.details and "vertical_force_n" not in exc.details:
                raise
            last = exc
    assert last is not None
    tried = [(a.com_lowering_m, a.slowdown) for a in adjustments]
    raise InfeasibleError(
        f"{last.message} (with every adjustment tried: CoM lowered by, supports slowed by {tried})",
        {**last.details, "adjustments_tried": tried},
    )
