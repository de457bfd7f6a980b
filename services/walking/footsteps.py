"""Footstep generators on flat ground: straight walks, turns in place, side steps and arcs, each split
into more steps when it would break the robot's stepping bounds.

The footstep sequences, the bounds type and their validation are the ground geometry of
:mod:`services.model.ground` (re-exported here: ``SolePose``, ``Footstep``, ``FootstepSequence``,
``FootstepBounds``, ``validate_footsteps``...); this module only generates sequences.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from services.errors import InfeasibleError, InvalidRequestError
from services.model.ground import (
    BOUND_TOLERANCE,
    SIDES,
    Footstep,
    FootstepBounds,
    FootstepSequence,
    Side,
    SolePose,
    mid_feet,
    other_side,
    rectangles_overlap_depth,
    sole_corners,
    validate_footsteps,
    wrap_angle,
)

__all__ = [
    "BOUND_TOLERANCE",
    "DEFAULT_LIMITS",
    "SIDES",
    "Footstep",
    "FootstepBounds",
    "FootstepSequence",
    "Side",
    "SolePose",
    "arc_walk",
    "fit_to_bounds",
    "footsteps_along_mid_poses",
    "other_side",
    "rectangles_overlap_depth",
    "side_steps",
    "sole_corners",
    "straight_walk",
    "turn_in_place",
    "validate_footsteps",
    "wrap_angle",
]


# ----------------------------------------------------------------------------------------------- generators

DEFAULT_LIMITS = FootstepBounds()
"""HRP-2's bounds (footstep paper §4, the form of §3.3) and sole: what the generators check by default. Pass
``FootstepBounds.from_robot(robot)`` for another robot, or ``limits=None`` for the raw geometry."""
MAX_SPLIT_FACTOR = 8
"""The generators try up to this many times the requested number of steps before giving up."""


def fit_to_bounds(
    make: Callable[[int], FootstepSequence],
    n_steps: int,
    limits: FootstepBounds | None,
    what: str,
    *,
    increment: int = 1,
) -> FootstepSequence:
    """``make(n)`` for the smallest ``n = n_steps + k * increment`` (k >= 0) whose sequence is within
    ``limits`` (:func:`validate_footsteps`): a walk that would break the bounds in ``n_steps`` steps is
    split into more, shorter steps (``increment`` 2 keeps the parity of the count, and with it how the
    walk ends). ``limits=None``: ``make(n_steps)`` unchecked.

    Raises:
        InfeasibleError: no count up to ``MAX_SPLIT_FACTOR * n_steps`` (at least 16 more steps) fits
            (steps beyond the bounds, or soles overlapping after a step); the message says why the last
            one tried fails.
        InvalidRequestError: the requested walk is malformed (soles overlapping at the start, a
            non-finite value).
    """
    if limits is None:
        return make(n_steps)
    n_max = max(MAX_SPLIT_FACTOR * n_steps, n_steps + 16)
    n = n_steps
    while True:
        seq = make(n)
        try:
            validate_footsteps(seq, limits)
            return seq
        except (InfeasibleError, InvalidRequestError) as exc:
            # A step beyond the bounds, or soles overlapping after a step (a turn too coarse): split.
            if isinstance(exc, InvalidRequestError) and exc.details.get("step_index", -1) < 0:
                raise
            if n + increment > n_max:
                raise InfeasibleError(
                    f"{what} does not fit the footstep bounds in {n_steps} to {n} steps: with {n} steps, "
                    f"{exc.message}",
                    {**exc.details, "n_steps_tried": n},
                ) from exc
        n += increment


def _start_frame(
    left_start: SolePose | None, right_start: SolePose | None, feet_spacing_m: float
) -> tuple[SolePose, SolePose, SolePose, float]:
    """(left, right, mid-feet frame, spacing [m]) from optional starting soles."""
    if (left_start is None) != (right_start is None):
        raise InvalidRequestError("give both left_start and right_start, or neither")
    if left_start is None or right_start is None:
        if not feet_spacing_m > 0:
            raise InvalidRequestError(f"feet_spacing_m must be > 0, got {feet_spacing_m}")
        mid = SolePose(0.0, 0.0, 0.0)
        return (
            mid.compose(0, feet_spacing_m / 2, 0),
            mid.compose(0, -feet_spacing_m / 2, 0),
            mid,
            feet_spacing_m,
        )
    mid = mid_feet(left_start, right_start)
    spacing = left_start.relative_to(mid)[1] - right_start.relative_to(mid)[1]
    return left_start, right_start, mid, spacing


def footsteps_along_mid_poses(
    mid_poses: Sequence[tuple[float, float, float]],
    first_side: Side,
    *,
    left_start: SolePose | None = None,
    right_start: SolePose | None = None,
    feet_spacing_m: float = 0.19,
) -> FootstepSequence:
    """Step k places the moving foot (alternating from ``first_side``) at ``mid_poses[k]`` offset by
    +-spacing/2 along that frame's y axis. ``mid_poses`` are (dx [m], dy [m], dyaw [rad]) in the starting
    mid-feet frame."""
    if first_side not in SIDES:
        raise InvalidRequestError(f"first_side must be one of {SIDES}, got {first_side!r}")
    left, right, mid, spacing = _start_frame(left_start, right_start, feet_spacing_m)
    steps = []
    side = first_side
    for dx, dy, dyaw in mid_poses:
        frame = mid.compose(dx, dy, dyaw)
        offset = spacing / 2 if side == "left" else -spacing / 2
        steps.append(Footstep(side, frame.compose(0.0, offset, 0.0)))
        side = other_side(side)
    return FootstepSequence(left, right, tuple(steps))


def straight_walk(
    n_steps: int,
    step_length_m: float,
    *,
    first_side: Side = "right",
    close_feet: bool = True,
    left_start: SolePose | None = None,
    right_start: SolePose | None = None,
    feet_spacing_m: float = 0.19,
    limits: FootstepBounds | None = DEFAULT_LIMITS,
) -> FootstepSequence:
    """``n_steps`` straight steps: step k (1-based) lands ``k * step_length_m`` ahead of the start, each
    foot landing one step length ahead of the other. With ``close_feet`` the last step brings the
    moving foot alongside the other one (so the walk ends with the feet side by side, after
    ``(n_steps - 1) * step_length_m``). Negative lengths walk backwards.

    Steps beyond ``limits`` (default HRP-2's) are split: the same distance in more, shorter steps
    (:func:`fit_to_bounds`); ``limits=None`` returns the steps as asked.
    """
    _check_count(n_steps, "n_steps")

    def n_advancing(n: int) -> int:
        return n - 1 if close_feet and n > 1 else n

    distance_m = step_length_m * n_advancing(n_steps)

    def make(n: int) -> FootstepSequence:
        length = distance_m / n_advancing(n)
        poses = [(length * min(k, n_advancing(n)), 0.0, 0.0) for k in range(1, n + 1)]
        return footsteps_along_mid_poses(
            poses, first_side, left_start=left_start, right_start=right_start, feet_spacing_m=feet_spacing_m
        )

    return fit_to_bounds(make, n_steps, limits, f"a straight walk of {distance_m:.3f} m")


def turn_in_place(
    angle_rad: float,
    n_steps: int,
    *,
    left_start: SolePose | None = None,
    right_start: SolePose | None = None,
    feet_spacing_m: float = 0.19,
    sole_size_m: tuple[float, float] = (0.24, 0.14),
    clearance_m: float = 0.005,
    max_outward_m: float = 0.06,
    limits: FootstepBounds | None = DEFAULT_LIMITS,
) -> FootstepSequence:
    """Turn by ``angle_rad`` (> 0: to the left) in ``n_steps`` steps about the starting mid-feet point P.

    Pair j of steps turns the mid-feet frame about P to yaw ``j * 2 * angle / n_steps``: the foot on the
    turning side opens to that frame and the other foot closes onto it at half the spacing from P. A
    sole turned by a large angle (45 deg) about P would put its inner heel on the other sole, so the
    opening foot also moves outward by the smallest multiple of 5 mm (up to ``max_outward_m``) that keeps
    ``clearance_m`` between the soles (``sole_size_m`` = length, width). An even ``n_steps`` ends with
    the feet parallel, the spacing wider by the last outward shift (e.g. 0.19 -> 0.24 m for HRP-2 turning
    90 deg in 4 steps).

    A turn beyond ``limits`` (default HRP-2's: pi/4 per opening step) is split into more steps, two at a
    time so that the walk ends the same way (:func:`fit_to_bounds`); ``limits=None``: as asked.
    """
    _check_count(n_steps, "n_steps")
    return fit_to_bounds(
        lambda n: _turn_in_place(
            angle_rad, n, left_start, right_start, feet_spacing_m, sole_size_m, clearance_m, max_outward_m
        ),
        n_steps,
        limits,
        f"a turn in place of {angle_rad:.3f} rad",
        increment=2,
    )


def _turn_in_place(
    angle_rad: float,
    n_steps: int,
    left_start: SolePose | None,
    right_start: SolePose | None,
    feet_spacing_m: float,
    sole_size_m: tuple[float, float],
    clearance_m: float,
    max_outward_m: float,
) -> FootstepSequence:
    """:func:`turn_in_place` in exactly ``n_steps`` steps, unchecked."""
    left, right, pivot, spacing = _start_frame(left_start, right_start, feet_spacing_m)
    opening: Side = "left" if angle_rad >= 0 else "right"
    closing = other_side(opening)
    sign = 1.0 if opening == "left" else -1.0
    n_pairs = math.ceil(n_steps / 2)
    length, width = sole_size_m
    feet = {"left": left, "right": right}
    steps: list[Footstep] = []
    for k in range(n_steps):
        turned = SolePose(pivot.x_m, pivot.y_m, pivot.yaw_rad + angle_rad * (k // 2 + 1) / n_pairs)
        if k % 2 == 0:
            stance = feet[closing]
            outward = 0.0
            pose = turned.compose(0.0, sign * spacing / 2, 0.0)
            while outward <= max_outward_m + 1e-9:
                pose = turned.compose(0.0, sign * (spacing / 2 + outward), 0.0)
                depth = rectangles_overlap_depth(
                    sole_corners(pose, length, width), sole_corners(stance, length, width)
                )
                if depth <= -clearance_m:
                    break
                outward += 0.005
            steps.append(Footstep(opening, pose))
            feet[opening] = pose
        else:
            pose = turned.compose(0.0, -sign * spacing / 2, 0.0)
            steps.append(Footstep(closing, pose))
            feet[closing] = pose
    return FootstepSequence(left, right, tuple(steps))


def side_steps(
    n_steps: int,
    step_width_m: float,
    *,
    left_start: SolePose | None = None,
    right_start: SolePose | None = None,
    feet_spacing_m: float = 0.19,
    limits: FootstepBounds | None = DEFAULT_LIMITS,
) -> FootstepSequence:
    """Side steps of ``step_width_m`` (> 0: to the left): the foot on that side opens by the width and
    the other foot closes, so every pair of steps moves the robot sideways by ``step_width_m``.

    Steps beyond ``limits`` (default HRP-2's) are split: the same distance in more, narrower steps, two
    at a time (:func:`fit_to_bounds`); ``limits=None``: as asked."""
    _check_count(n_steps, "n_steps")
    first: Side = "left" if step_width_m >= 0 else "right"
    distance_m = step_width_m * math.ceil(n_steps / 2)

    def make(n: int) -> FootstepSequence:
        width = distance_m / math.ceil(n / 2)
        poses = [(0.0, width * (k // 2 + 1), 0.0) for k in range(n)]
        return footsteps_along_mid_poses(
            poses, first, left_start=left_start, right_start=right_start, feet_spacing_m=feet_spacing_m
        )

    return fit_to_bounds(make, n_steps, limits, f"side steps over {distance_m:.3f} m", increment=2)


def arc_walk(
    radius_m: float,
    angle_rad: float,
    n_steps: int,
    *,
    close_feet: bool = True,
    left_start: SolePose | None = None,
    right_start: SolePose | None = None,
    feet_spacing_m: float = 0.19,
    limits: FootstepBounds | None = DEFAULT_LIMITS,
) -> FootstepSequence:
    """Walk forward along a circular arc of ``radius_m`` (the mid-feet path) turning by ``angle_rad``
    (> 0: to the left, centre on the left) in ``n_steps`` steps, the inner foot moving first. With
    ``close_feet`` the last step lands alongside the other foot at the end of the arc.

    Every step turns the feet by the same angle, so the outer foot turns towards the inner one by that
    much: the bound on it (0.1 rad for HRP-2, ``dtheta`` of the footstep paper) limits the turn per step
    (90 deg takes 17 advancing steps, + 1 to close). An arc beyond ``limits`` (default HRP-2's) is split
    into more steps (:func:`fit_to_bounds`); ``limits=None``: as asked.
    """
    _check_count(n_steps, "n_steps")
    if not radius_m > 0:
        raise InvalidRequestError(f"radius_m must be > 0, got {radius_m}")
    first: Side = "left" if angle_rad >= 0 else "right"

    def make(n: int) -> FootstepSequence:
        n_adv = n - 1 if close_feet and n > 1 else n
        poses = []
        for k in range(1, n + 1):
            a = angle_rad * min(k, n_adv) / n_adv
            poses.append(
                (radius_m * math.sin(abs(a)), math.copysign(radius_m * (1 - math.cos(a)), angle_rad), a)
            )
        return footsteps_along_mid_poses(
            poses, first, left_start=left_start, right_start=right_start, feet_spacing_m=feet_spacing_m
        )

    return fit_to_bounds(make, n_steps, limits, f"an arc of {radius_m:.3f} m radius and {angle_rad:.3f} rad")


def _check_count(n: int, name: str) -> None:
    if not isinstance(n, int | np.integer) or n < 1:
        raise InvalidRequestError(f"{name} must be an integer >= 1, got {n!r}")
