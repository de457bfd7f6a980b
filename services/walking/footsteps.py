"""Footstep sequences on flat ground, their validation against a robot's stepping bounds, and generators.

A :class:`FootstepSequence` holds the two starting sole poses and the ordered list of :class:`Footstep`
landings. Each footstep says which foot moves and where its sole lands (x, y, yaw in the world frame,
on the flat ground z = 0). The stance foot of a step is the other foot, at its latest pose.

The stepping bounds are those of section 5 of the footstep paper (000, Kanoun et al.): the left sole
expressed in the right sole frame must satisfy ``-0.22 < dx < 0.22 m``, ``0.07 < dy < 0.25 m``,
``-0.1 < dtheta < pi/4 rad``; the right sole in the left sole frame satisfies the mirrored bounds
(``-0.25 < dy < -0.07``, ``-pi/4 < dtheta < 0.1``). The bounds are checked inclusive of the limit
itself, up to ``BOUND_TOLERANCE`` (0.1 mm, 1e-4 rad): a 90-degree turn in 4 steps (pi/4 per opening
step) is admissible, also from soles measured on a standing robot (the simulated robot stands with its
soles yawed by a few 1e-5 rad, which puts such a turn 2e-5 rad "beyond" the bound).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from services.errors import InfeasibleError, InvalidRequestError

Side = Literal["left", "right"]
SIDES: tuple[Side, Side] = ("left", "right")
BOUND_TOLERANCE = 1e-4
"""Tolerance of the bounds check [m or rad]: measurement noise, not a relaxation of the bounds."""


def wrap_angle(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi) [rad]."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def other_side(side: Side) -> Side:
    """The other foot."""
    return "right" if side == "left" else "left"


@dataclass(frozen=True)
class SolePose:
    """A sole frame on the flat ground: position [m] and yaw [rad] in the world frame (z = 0)."""

    x_m: float
    y_m: float
    yaw_rad: float

    def relative_to(self, other: SolePose) -> tuple[float, float, float]:
        """(dx [m], dy [m], dyaw [rad]) of this sole expressed in the frame of ``other``."""
        c, s = math.cos(other.yaw_rad), math.sin(other.yaw_rad)
        ex, ey = self.x_m - other.x_m, self.y_m - other.y_m
        return c * ex + s * ey, -s * ex + c * ey, wrap_angle(self.yaw_rad - other.yaw_rad)

    def compose(self, dx_m: float, dy_m: float, dyaw_rad: float) -> SolePose:
        """The pose reached by moving (dx, dy) in this frame and turning by dyaw."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return SolePose(
            self.x_m + c * dx_m - s * dy_m, self.y_m + s * dx_m + c * dy_m, self.yaw_rad + dyaw_rad
        )

    def as_array(self) -> np.ndarray:
        """[x, y, yaw] as a float array."""
        return np.array([self.x_m, self.y_m, self.yaw_rad])


@dataclass(frozen=True)
class Footstep:
    """One step: foot ``side`` lifts off and lands with its sole at ``pose`` (world frame)."""

    side: Side
    pose: SolePose


@dataclass(frozen=True)
class FootstepSequence:
    """Starting sole poses and the ordered landings. ``steps[0].side`` is the first moving foot."""

    left_start: SolePose
    right_start: SolePose
    steps: tuple[Footstep, ...]

    @property
    def first_moving_side(self) -> Side:
        """The foot that moves first."""
        if not self.steps:
            raise InvalidRequestError("the footstep sequence has no step")
        return self.steps[0].side

    def stances(self) -> list[tuple[SolePose, SolePose]]:
        """(left, right) sole poses before the first step and after each step (len = n_steps + 1)."""
        left, right = self.left_start, self.right_start
        out = [(left, right)]
        for step in self.steps:
            if step.side == "left":
                left = step.pose
            else:
                right = step.pose
            out.append((left, right))
        return out

    def final_stance(self) -> tuple[SolePose, SolePose]:
        """(left, right) sole poses after the last step."""
        return self.stances()[-1]

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form (for messages and the placo worker)."""

        def pose(p: SolePose) -> list[float]:
            return [p.x_m, p.y_m, p.yaw_rad]

        return {
            "left_start": pose(self.left_start),
            "right_start": pose(self.right_start),
            "steps": [{"side": s.side, "pose": pose(s.pose)} for s in self.steps],
        }

    @staticmethod
    def from_dict(data: dict[str, Any]) -> FootstepSequence:
        """Inverse of :meth:`to_dict`; raises InvalidRequestError on a malformed dict."""
        try:
            steps = []
            for i, s in enumerate(data["steps"]):
                if s["side"] not in SIDES:
                    raise InvalidRequestError(f"step {i}: side {s['side']!r} is not one of {SIDES}")
                steps.append(Footstep(s["side"], SolePose(*map(float, s["pose"]))))
            return FootstepSequence(
                SolePose(*map(float, data["left_start"])),
                SolePose(*map(float, data["right_start"])),
                tuple(steps),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InvalidRequestError(
                f"malformed footstep sequence ({exc!r}); expected keys left_start=[x,y,yaw], "
                "right_start=[x,y,yaw], steps=[{side: left|right, pose: [x,y,yaw]}]"
            ) from exc


@dataclass(frozen=True)
class FootstepLimits:
    """Admissible pose of the left sole in the right sole frame (mirrored for the right foot) [m, rad],
    and the sole rectangle used for the overlap test [m] (centred on the sole frame)."""

    dx_min_m: float = -0.22
    dx_max_m: float = 0.22
    dy_min_m: float = 0.07
    dy_max_m: float = 0.25
    dyaw_min_rad: float = -0.1
    dyaw_max_rad: float = math.pi / 4
    sole_length_m: float = 0.24
    sole_width_m: float = 0.14

    @staticmethod
    def from_robot(robot: Any) -> FootstepLimits:
        """Bounds of a ``services.model`` robot (``params.footstep_bounds``, ``sole_size_m``)."""
        fb = robot.params.footstep_bounds
        length, width = (float(v) for v in robot.sole_size_m)
        return FootstepLimits(
            dx_min_m=float(fb.dx_min_m),
            dx_max_m=float(fb.dx_max_m),
            dy_min_m=float(fb.dy_min_m),
            dy_max_m=float(fb.dy_max_m),
            dyaw_min_rad=float(fb.dtheta_min_rad),
            dyaw_max_rad=float(fb.dtheta_max_rad),
            sole_length_m=length,
            sole_width_m=width,
        )

    def limits_for(self, side: Side) -> dict[str, tuple[float, float]]:
        """Limits of (dx, dy, dyaw) of foot ``side`` in the other sole frame (mirrored for the right)."""
        if side == "left":
            return {
                "dx": (self.dx_min_m, self.dx_max_m),
                "dy": (self.dy_min_m, self.dy_max_m),
                "dyaw": (self.dyaw_min_rad, self.dyaw_max_rad),
            }
        return {
            "dx": (self.dx_min_m, self.dx_max_m),
            "dy": (-self.dy_max_m, -self.dy_min_m),
            "dyaw": (-self.dyaw_max_rad, -self.dyaw_min_rad),
        }


def sole_corners(pose: SolePose, length_m: float, width_m: float) -> np.ndarray:
    """The 4 corners (4, 2) [m] of the sole rectangle centred on the sole frame, counter-clockwise."""
    hl, hw = 0.5 * length_m, 0.5 * width_m
    local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
    c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
    R = np.array([[c, -s], [s, c]])
    return local @ R.T + np.array([pose.x_m, pose.y_m])


def rectangles_overlap_depth(a: np.ndarray, b: np.ndarray) -> float:
    """Penetration depth [m] of two convex polygons (separating axis test); <= 0 when they do not overlap."""
    depth = math.inf
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        pa, pb = a @ normals.T, b @ normals.T
        overlap = np.minimum(pa.max(0), pb.max(0)) - np.maximum(pa.min(0), pb.min(0))
        depth = min(depth, float(overlap.min()))
    return depth


def validate_footsteps(seq: FootstepSequence, bounds: FootstepLimits) -> None:
    """Check a sequence: at least one step, finite poses, no overlapping soles, and every landing within
    the stepping bounds relative to the stance foot.

    Raises:
        InvalidRequestError: empty sequence, non-finite value, overlapping feet (at the start or after
            a step).
        InfeasibleError: a landing outside the bounds; the message names the step, the quantity, the
            bound and the excess, and ``details`` carries them.
    """
    if not seq.steps:
        raise InvalidRequestError("the footstep sequence has no step; give at least one footstep")
    for name, pose in (("left_start", seq.left_start), ("right_start", seq.right_start)):
        if not np.all(np.isfinite(pose.as_array())):
            raise InvalidRequestError(f"{name} has a non-finite value: {pose}")
    for i, step in enumerate(seq.steps):
        if step.side not in SIDES:
            raise InvalidRequestError(f"step {i}: side {step.side!r} is not one of {SIDES}")
        if not np.all(np.isfinite(step.pose.as_array())):
            raise InvalidRequestError(f"step {i} ({step.side} foot) has a non-finite pose: {step.pose}")

    L, W = bounds.sole_length_m, bounds.sole_width_m
    stances = seq.stances()
    for i, (left, right) in enumerate(stances):
        depth = rectangles_overlap_depth(sole_corners(left, L, W), sole_corners(right, L, W))
        if depth > 1e-6:
            where = "at the start" if i == 0 else f"after step {i - 1} ({seq.steps[i - 1].side} foot)"
            raise InvalidRequestError(
                f"the feet overlap {where} by {1000 * depth:.1f} mm (soles {L:.3f} x {W:.3f} m): "
                f"left sole at ({left.x_m:.3f}, {left.y_m:.3f}, {left.yaw_rad:.3f} rad), "
                f"right sole at ({right.x_m:.3f}, {right.y_m:.3f}, {right.yaw_rad:.3f} rad)",
                {"step_index": i - 1, "overlap_m": depth},
            )

    for i, step in enumerate(seq.steps):
        left, right = stances[i]
        stance = right if step.side == "left" else left
        rel = dict(zip(("dx", "dy", "dyaw"), step.pose.relative_to(stance), strict=True))
        for name, (lo, hi) in bounds.limits_for(step.side).items():
            value = rel[name]
            unit = "rad" if name == "dyaw" else "m"
            if value < lo - BOUND_TOLERANCE or value > hi + BOUND_TOLERANCE:
                bound, excess = (lo, lo - value) if value < lo else (hi, value - hi)
                word = "below" if value < lo else "above"
                raise InfeasibleError(
                    f"step {i} ({step.side} foot): {name}={value:.4f} {unit} relative to the "
                    f"{other_side(step.side)} sole is {word} the bound {bound:.4f} {unit} by {excess:.4f} "
                    f"{unit} (admissible {lo:.4f} .. {hi:.4f} {unit})",
                    {
                        "step_index": i,
                        "side": step.side,
                        "quantity": name,
                        "value": value,
                        "bound": bound,
                        "excess": excess,
                    },
                )


# ----------------------------------------------------------------------------------------------- generators

DEFAULT_LIMITS = FootstepLimits()
"""HRP-2's bounds (footstep paper §5) and sole: what the generators check by default. Pass
``FootstepLimits.from_robot(robot)`` for another robot, or ``limits=None`` for the raw geometry."""
MAX_SPLIT_FACTOR = 8
"""The generators try up to this many times the requested number of steps before giving up."""


def fit_to_bounds(
    make: Callable[[int], FootstepSequence],
    n_steps: int,
    limits: FootstepLimits | None,
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
    yaw = right_start.yaw_rad + 0.5 * wrap_angle(left_start.yaw_rad - right_start.yaw_rad)
    mid = SolePose(0.5 * (left_start.x_m + right_start.x_m), 0.5 * (left_start.y_m + right_start.y_m), yaw)
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
    limits: FootstepLimits | None = DEFAULT_LIMITS,
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
    limits: FootstepLimits | None = DEFAULT_LIMITS,
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
    limits: FootstepLimits | None = DEFAULT_LIMITS,
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
    limits: FootstepLimits | None = DEFAULT_LIMITS,
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
