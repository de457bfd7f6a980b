"""Smooth motion reshaping of the carried bar: key frames around an obstacle, smooth interpolation in
task space, resampling at the pattern's 5 ms (Figure 2 (a)-(c) of `001_771c0ce3779b0683.txt`).

"The reshaping limits are set by identifying the anticipating, colliding and regaining times" (Figure 2
(a)); "Smooth motion is specified in the task space by interpolating the bar's configuration at key
frames" (b); "The bar's motion is resampled at 5 millisecond to replace its original motion" (c); the
whole-body IK then enforces it (d, in :mod:`services.navigation.stage2`).

The bar's configuration at a key frame is a :class:`BarOffset` from its nominal pose: a translation and
two rotations (roll: tilt about the walking direction; yaw: about the vertical) in the walk frame at the
bar. The sixth coordinate of the object's pose, the rotation about the bar's own axis, is left to the
whole-body IK: the hand task holds a cylinder at any roll about it and the capsule does not see it.

A :class:`ReshapeWindow` is one reshaping: the bar keeps its nominal pose until the anticipating time,
moves to the offset by the colliding time, holds it until the end of the collision and comes back to
the nominal pose at the regaining time. The four key frames are joined by quintics (zero velocity and
acceleration at every key frame, "accounting for motion continuity"); the ramp durations follow from
the largest displacement of a point of the bar and the speed and acceleration bounds of
:class:`ReshapeOptions`. Which offset a window holds is decided by
:mod:`services.navigation.keyframes` (random sampling near the collision, or a lift over it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from services.errors import InvalidRequestError
from services.navigation.carry import BarTrajectory
from services.walking.zmp_reference import smoothstep5

# Peak speed and acceleration of a quintic 0 -> 1 over T: 1.875 / T and 10 / sqrt(3) / T^2.
_QUINTIC_PEAK_SPEED = 1.875
_QUINTIC_PEAK_ACC = 10.0 / math.sqrt(3.0)
MODES = ("sample", "lift")
_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class SamplingOptions:
    """Random sampling of the bar's configuration near a collision (the paper's "a new random
    collision-free configuration near the colliding one is first generated, and then an IK solver is
    applied", section "Smooth Motion Reshaping").

    - ``seed``: the generator's seed (same request, same plan);
    - ``rings``, ``samples_per_ring``: candidates are drawn uniformly in boxes around the colliding
      configuration scaled by 1/rings, 2/rings, ... 1 of the bounds, ``samples_per_ring`` per box; the
      first box holding a collision-free candidate the arms reach gives the nearest such one;
    - bounds of the offset (the arms' reach around the carrying posture): ``max_forward_m``,
      ``max_left_m`` [m] (either sign), ``max_down_m``, ``max_up_m`` [m], ``max_roll_rad``,
      ``max_yaw_rad`` [rad] (either sign);
    - ``hand_radius_m`` [m]: a sphere around each held point, checked with the bar;
    - ``check_every``: the candidate's task-space motion is checked every this many 5 ms samples;
    - ``ik_iterations``, ``track_every``: the arms-only IK that checks the reach follows the candidate's
      reshaped motion every ``track_every`` samples with ``ik_iterations`` Gauss-Newton steps each (as
      the walk's whole-body IK tracks its knots); ``max_speed_ratio``: the arm joints must stay below
      this fraction of their speed limits there (an arm stretched to its reach flips: fast joints);
    - ``max_ik_checks``: reach checks at most per reshaping (the nearest collision-free candidates
      first);
    - ``reject_radius``: a configuration the whole-body IK could not follow is not drawn again, nor
      any within this distance of it (in units of the bounds' half ranges).
    """

    seed: int = 0
    rings: int = 6
    samples_per_ring: int = 64
    max_forward_m: float = 0.08
    max_left_m: float = 0.05
    max_down_m: float = 0.10
    max_up_m: float = 0.35
    max_roll_rad: float = math.radians(30.0)
    max_yaw_rad: float = math.radians(30.0)
    hand_radius_m: float = 0.05
    check_every: int = 4
    ik_iterations: int = 2
    track_every: int = 8
    max_speed_ratio: float = 0.5
    max_ik_checks: int = 8
    reject_radius: float = 0.3

    def __post_init__(self) -> None:
        for name in (
            "rings",
            "samples_per_ring",
            "check_every",
            "ik_iterations",
            "track_every",
            "max_ik_checks",
        ):
            if getattr(self, name) < 1:
                raise InvalidRequestError(f"sampling option {name} must be >= 1, got {getattr(self, name)}")
        for name in (
            "max_forward_m",
            "max_left_m",
            "max_down_m",
            "max_up_m",
            "max_roll_rad",
            "max_yaw_rad",
            "hand_radius_m",
            "max_speed_ratio",
            "reject_radius",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise InvalidRequestError(f"sampling option {name} must be a finite number >= 0, got {value}")

    @property
    def lower(self) -> np.ndarray:
        """Lower bounds of :meth:`BarOffset.as_array` (5,)."""
        return -np.array(
            [self.max_forward_m, self.max_left_m, self.max_down_m, self.max_roll_rad, self.max_yaw_rad]
        )

    @property
    def upper(self) -> np.ndarray:
        """Upper bounds of :meth:`BarOffset.as_array` (5,)."""
        return np.array(
            [self.max_forward_m, self.max_left_m, self.max_up_m, self.max_roll_rad, self.max_yaw_rad]
        )


@dataclass(frozen=True)
class ReshapeOptions:
    """Options of the reshaping loop (:func:`services.navigation.stage2.plan_motion`).

    - ``mode``: ``"sample"`` (the paper: random collision-free configurations of the bar's pose near
      the collision, checked by IK) or ``"lift"`` (height only, deterministic: the bar's centre at the
      obstacle's top + its radius + the target clearance; off in the paper's experiment, kept to show
      where lifting alone does not suffice);
    - ``required_clearance_m`` [m]: a motion is accepted when every part (robot and bar) stays at least
      this far from every obstacle (a margin for the tracking errors of the real execution);
    - ``target_clearance_m`` [m]: a reshaped bar passes this far from an obstacle; the anticipating and
      regaining limits are where a part first and last comes within it (at the motion being reshaped);
    - ``max_lift_speed_m_s`` [m/s], ``max_lift_acc_m_s2`` [m/s^2]: bounds of the speed and acceleration
      of every point of the bar relative to its nominal motion, which set the ramp durations;
      ``min_ramp_s`` [s] the shortest ramp;
    - ``max_bar_height_m`` [m]: the highest the arms may hold the bar's centre (None: no bound besides the
      IK's tracking check);
    - ``max_iterations``: whole-body solutions at most (the first, unreshaped one included);
    - ``max_hand_error_m`` [m]: a motion whose hands end up farther than this from the bar's planned
      pose is rejected (the arms cannot hold it there);
    - ``sampling``: :class:`SamplingOptions` (mode ``"sample"``).
    """

    required_clearance_m: float = 0.02
    target_clearance_m: float = 0.05
    max_lift_speed_m_s: float = 0.25
    max_lift_acc_m_s2: float = 0.6
    min_ramp_s: float = 0.6
    max_bar_height_m: float | None = 1.25
    max_iterations: int = 5
    max_hand_error_m: float = 0.02
    mode: str = "sample"
    sampling: SamplingOptions = field(default_factory=SamplingOptions)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise InvalidRequestError(f"reshape mode must be one of {MODES}, got {self.mode!r}")
        for name in (
            "target_clearance_m",
            "max_lift_speed_m_s",
            "max_lift_acc_m_s2",
            "min_ramp_s",
            "max_hand_error_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise InvalidRequestError(f"reshape option {name} must be a finite number > 0, got {value}")
        if not (
            math.isfinite(self.required_clearance_m)
            and 0.0 <= self.required_clearance_m <= self.target_clearance_m
        ):
            raise InvalidRequestError(
                f"required_clearance_m must be within 0 and target_clearance_m={self.target_clearance_m}, "
                f"got {self.required_clearance_m}"
            )
        if self.max_iterations < 1:
            raise InvalidRequestError(f"max_iterations must be >= 1, got {self.max_iterations}")

    def ramp_s(self, displacement_m: float) -> float:
        """Duration [s] of a quintic move of ``displacement_m`` [m] within the speed/acceleration bounds."""
        d = abs(displacement_m)
        return max(
            self.min_ramp_s,
            _QUINTIC_PEAK_SPEED * d / self.max_lift_speed_m_s,
            math.sqrt(_QUINTIC_PEAK_ACC * d / self.max_lift_acc_m_s2),
        )


@dataclass(frozen=True)
class BarOffset:
    """The bar's configuration relative to its nominal pose, in the walk frame at the bar: ``forward``
    is the horizontal normal of the nominal axis (axis x up), ``left`` the nominal axis made horizontal,
    ``up`` the world vertical.

    ``forward_m``, ``left_m``, ``up_m`` [m]: translation of the centre; ``roll_rad`` [rad]: rotation about
    ``forward`` (tilts the bar, its left end up when > 0); ``yaw_rad`` [rad]: rotation about the vertical
    (counter-clockwise seen from above), applied after the roll.
    """

    forward_m: float = 0.0
    left_m: float = 0.0
    up_m: float = 0.0
    roll_rad: float = 0.0
    yaw_rad: float = 0.0

    def as_array(self) -> np.ndarray:
        """[forward_m, left_m, up_m, roll_rad, yaw_rad] (5,)."""
        return np.array([self.forward_m, self.left_m, self.up_m, self.roll_rad, self.yaw_rad])

    @classmethod
    def from_array(cls, values: np.ndarray) -> BarOffset:
        """The offset of :meth:`as_array`'s layout."""
        f, left, u, r, y = (float(v) for v in values)
        return cls(f, left, u, r, y)

    def displacement_m(self, half_length_m: float) -> float:
        """Upper bound [m] of how far a point of the bar moves (its ends: translation + rotation arcs)."""
        return math.sqrt(self.forward_m**2 + self.left_m**2 + self.up_m**2) + half_length_m * (
            abs(self.roll_rad) + abs(self.yaw_rad)
        )

    @property
    def is_zero(self) -> bool:
        return not np.any(self.as_array())


ZERO_OFFSET = BarOffset()


@dataclass(frozen=True)
class ReshapeWindow:
    """One reshaping of the bar (times [s]): nominal until ``t_anticipate_s``, moved to ``offset`` from
    ``t_collide_s`` to ``t_collide_end_s``, nominal again from ``t_regain_s``. ``height_m`` [m] is the
    bar centre's height at the colliding key frame, ``obstacles`` those it avoids."""

    t_anticipate_s: float
    t_collide_s: float
    t_collide_end_s: float
    t_regain_s: float
    offset: BarOffset
    height_m: float
    obstacles: tuple[str, ...]

    def key_frames(self) -> list[tuple[str, float, BarOffset]]:
        """(name, time [s], offset) of the four key frames of Figure 2 (b)."""
        return [
            ("anticipating", self.t_anticipate_s, ZERO_OFFSET),
            ("colliding", self.t_collide_s, self.offset),
            ("collision_end", self.t_collide_end_s, self.offset),
            ("regaining", self.t_regain_s, ZERO_OFFSET),
        ]

    def weight(self, times_s: np.ndarray) -> np.ndarray:
        """Quintic weight (n,) of the offset: 0 before the anticipating time, 1 between the colliding
        times, 0 after the regaining time, C2 at the key frames."""
        t = np.asarray(times_s, dtype=float)
        w = np.zeros_like(t)
        up = (t >= self.t_anticipate_s) & (t < self.t_collide_s)
        if self.t_collide_s > self.t_anticipate_s:
            w[up] = smoothstep5((t[up] - self.t_anticipate_s) / (self.t_collide_s - self.t_anticipate_s))
        w[(t >= self.t_collide_s) & (t <= self.t_collide_end_s)] = 1.0
        down = (t > self.t_collide_end_s) & (t <= self.t_regain_s)
        if self.t_regain_s > self.t_collide_end_s:
            w[down] = 1.0 - smoothstep5(
                (t[down] - self.t_collide_end_s) / (self.t_regain_s - self.t_collide_end_s)
            )
        return w

    def overlaps(self, other: ReshapeWindow) -> bool:
        """The two windows' spans (anticipating to regaining) intersect."""
        return self.t_anticipate_s <= other.t_regain_s and other.t_anticipate_s <= self.t_regain_s


def make_window(
    t_collide_s: float,
    t_collide_end_s: float,
    offset: BarOffset,
    obstacles: tuple[str, ...],
    options: ReshapeOptions,
    t_first_s: float,
    t_last_s: float,
    half_length_m: float,
    nominal_height_m: float,
) -> ReshapeWindow:
    """A window holding ``offset`` over [t_collide_s, t_collide_end_s], with ramps from and back to the
    nominal pose sized by ``options`` for a bar of half length ``half_length_m`` [m], clipped to
    [t_first_s, t_last_s] (the ramps get shorter there, the speed bound then gives way to the time
    available). ``nominal_height_m`` [m]: the bar centre's nominal height at the colliding time."""
    ramp = options.ramp_s(offset.displacement_m(half_length_m))
    t_c = max(t_collide_s, t_first_s + options.min_ramp_s)
    t_ce = min(t_collide_end_s, t_last_s - options.min_ramp_s)
    t_ce = max(t_ce, t_c)
    return ReshapeWindow(
        t_anticipate_s=max(t_first_s, t_c - ramp),
        t_collide_s=t_c,
        t_collide_end_s=t_ce,
        t_regain_s=min(t_last_s, t_ce + ramp),
        offset=offset,
        height_m=nominal_height_m + offset.up_m,
        obstacles=obstacles,
    )


def offsets_on_grid(times_s: np.ndarray, windows: list[ReshapeWindow]) -> np.ndarray:
    """The bar's offset (n, 5) (:meth:`BarOffset.as_array` layout) at every sample of ``times_s``: each
    window's key frames joined by quintics (Figure 2 (b)) and resampled at every sample (Figure 2 (c))."""
    t = np.asarray(times_s, dtype=float)
    out = np.zeros((t.shape[0], 5))
    for w in windows:
        out += w.weight(t)[:, None] * w.offset.as_array()[None, :]
    return out


def _rotate(v: np.ndarray, k: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues: vectors v (n, 3) rotated about unit axes k (n, 3) by ``angle`` (n,) [rad]."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    kv = np.sum(k * v, axis=1, keepdims=True)
    return v * c + np.cross(k, v) * s + k * kv * (1.0 - c)


def apply_offsets(
    centre_m: np.ndarray, axis: np.ndarray, offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Bar poses (centre (n, 3) [m], unit axis (n, 3)) moved by ``offsets`` (n, 5) (see
    :class:`BarOffset`: the walk frame at each nominal pose)."""
    centre_m = np.atleast_2d(np.asarray(centre_m, dtype=float))
    axis = np.atleast_2d(np.asarray(axis, dtype=float))
    offsets = np.atleast_2d(np.asarray(offsets, dtype=float))
    left = axis.copy()
    left[:, 2] = 0.0
    left /= np.linalg.norm(left, axis=1, keepdims=True)
    forward = np.cross(left, _Z)
    centre = centre_m + offsets[:, [0]] * forward + offsets[:, [1]] * left + offsets[:, [2]] * _Z
    rolled = _rotate(axis, forward, offsets[:, 3])
    new_axis = _rotate(rolled, np.broadcast_to(_Z, rolled.shape), offsets[:, 4])
    return centre, new_axis


def reshaped_trajectory(nominal: BarTrajectory, windows: list[ReshapeWindow]) -> BarTrajectory:
    """The bar's task-space trajectory on the 5 ms grid with ``windows`` applied (Figure 2 (b)-(c))."""
    if not windows:
        return nominal
    centre, axis = apply_offsets(nominal.centre_m, nominal.axis, offsets_on_grid(nominal.times_s, windows))
    return BarTrajectory(nominal.times_s, centre, axis)


__all__ = [
    "MODES",
    "ZERO_OFFSET",
    "BarOffset",
    "ReshapeOptions",
    "ReshapeWindow",
    "SamplingOptions",
    "apply_offsets",
    "make_window",
    "offsets_on_grid",
    "reshaped_trajectory",
]
