"""Walk timing and the phase schedule on the sampling grid.

The walk is a sequence of segments on the grid t_k = k * dt_s:

    start hold | initial double support | (single support, double support) per step ... | final double
    support | final hold

The robot first stands still for ``initial_hold_s`` with the ZMP reference at its starting point: the
preview controller moves the CoM ahead of the ZMP (by a few sqrt(z_c/g), Kajita 2003), and without
this lead-in the CoM, at rest at t = 0, would have to jerk to catch up with the first weight transfer.
The last step has no double support of its own: the final double support follows it, then the robot
stands for ``final_hold_s`` with the ZMP reference at rest between the feet ("stop at the end") while
the CoM settles. Durations are rounded to the nearest multiple of ``dt_s``; the effective durations are
in :class:`Schedule`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.errors import InvalidRequestError

DOUBLE = 0
"""Support phase code: both soles on the ground."""
LEFT = 1
"""Support phase code: the left sole supports, the right foot swings."""
RIGHT = 2
"""Support phase code: the right sole supports, the left foot swings."""
PHASE_NAMES = {DOUBLE: "double", LEFT: "left", RIGHT: "right"}


@dataclass(frozen=True)
class WalkTiming:
    """Durations [s] of the walk phases and the sampling period [s].

    ``double_support_s`` is the double support between two steps; ``initial_double_support_s`` is the
    first weight transfer (from standing to the first stance foot) and ``final_double_support_s`` the
    last one (back between the feet); ``initial_hold_s`` is standing still before the first transfer
    and ``final_hold_s`` standing still at the end.

    The default double support is 0.3 s: played open loop (position control, no stabilizer) in the
    pybullet sim, walks with 0.1 s of double support are fragile: the landing foot touches 0.1-0.2 mm
    early, bounces, and the weight goes over in one jolt that excites the robot's undamped rocking on
    its sole contacts (about 3 Hz); a 20 um change of the ground height decides whether the 18-step arc
    falls. With 0.3 s every walk of the tests ended on its footsteps under +-60 um perturbations
    (README, "In the simulation"). Kajita's 0.1 s (and the benchmark's 12.5 % of the step) remain a
    parameter away.

    The stop (issue 15, session 9): a last transfer of 0.5 s and a final hold of 0.2 s (were 0.7 and
    0.4), the pattern's end blended to rest over both together (``pattern.plan_pattern``).
    Measured on 10 steps of 0.2 m, a 90 deg turn in place and 10 steps back (hrp2_like): planned
    multibody ZMP margins 50, 44, 50 mm (56, 52, 56 mm with 0.7 + 0.4 s), no second-stage pass; in the
    sim every walk ends on its footsteps within 0.5 mm and the base turns at 0.22-0.24 deg/s at the end
    and after it, as with 0.7 + 0.4 s (0.22-0.23). Blended over the hold alone, 0.5 + 0.2 s left the
    base rocking at up to 3 deg/s after the walk. The lead-in and first transfer stay at 0.6 and 0.8 s:
    0.5 and 0.7 s halve the margins (25 mm).

    ``slow_steps`` are indices of steps whose single support lasts ``slow_step_factor`` times longer
    (a step that would move a joint faster than its limit is walked slower, not the whole walk).
    """

    single_support_s: float = 0.7
    double_support_s: float = 0.3
    initial_double_support_s: float = 0.8
    final_double_support_s: float = 0.5
    final_hold_s: float = 0.2
    initial_hold_s: float = 0.6
    dt_s: float = 0.005
    slow_steps: tuple[int, ...] = ()
    slow_step_factor: float = 1.5

    def validate(self) -> None:
        """Raise InvalidRequestError for a non-finite, zero or negative duration, or one below dt_s."""
        if not (math.isfinite(self.dt_s) and self.dt_s > 0):
            raise InvalidRequestError(f"dt_s must be a positive number of seconds, got {self.dt_s}")
        for name in (
            "single_support_s",
            "double_support_s",
            "initial_double_support_s",
            "final_double_support_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InvalidRequestError(f"{name} must be > 0 s, got {value}")
            if round(value / self.dt_s) < 1:
                raise InvalidRequestError(
                    f"{name}={value} s is shorter than one sample (dt_s={self.dt_s} s); use at least dt_s"
                )
        if not (math.isfinite(self.slow_step_factor) and self.slow_step_factor >= 1.0):
            raise InvalidRequestError(f"slow_step_factor must be >= 1, got {self.slow_step_factor}")
        if any(i < 0 for i in self.slow_steps):
            raise InvalidRequestError(f"slow_steps are step indices >= 0, got {list(self.slow_steps)}")
        for name in ("initial_hold_s", "final_hold_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InvalidRequestError(f"{name} must be >= 0 s, got {value}")

    def samples(self, duration_s: float) -> int:
        """Number of samples of a duration [s] on this grid."""
        return round(duration_s / self.dt_s)


@dataclass(frozen=True)
class Segment:
    """A phase on the grid: samples ``start`` (inclusive) to ``stop`` (exclusive).

    ``kind`` is DOUBLE, LEFT or RIGHT; ``step_index`` is the step swinging during a single support, the
    step just landed during a double support (-1 before the first step). ``role`` is one of
    ``"start"`` (standing before the first transfer), ``"initial"`` (first weight transfer),
    ``"swing"``, ``"transfer"`` (between two steps), ``"final"`` (last weight transfer) and ``"hold"``.
    """

    kind: int
    start: int
    stop: int
    step_index: int
    role: str

    @property
    def n(self) -> int:
        """Number of samples."""
        return self.stop - self.start


@dataclass(frozen=True)
class Schedule:
    """Segments covering samples ``0 .. n_samples - 1``, and the phase code of every sample."""

    dt_s: float
    segments: tuple[Segment, ...]
    n_samples: int
    phase: np.ndarray  # (n_samples,) int8: DOUBLE / LEFT / RIGHT

    @property
    def times_s(self) -> np.ndarray:
        """Sample times [s]."""
        return np.arange(self.n_samples) * self.dt_s

    @property
    def duration_s(self) -> float:
        """Time of the last sample [s]."""
        return (self.n_samples - 1) * self.dt_s

    def steps_at(self, t_s: float) -> tuple[int, ...]:
        """The steps moving at time ``t_s`` [s]: the one swinging, or the two a double support joins
        (the step just landed and the next one); () before the first transfer ends and in the hold."""
        k = round(t_s / self.dt_s)
        for seg in self.segments:
            if seg.start <= k < seg.stop or (seg is self.segments[-1] and k >= seg.stop):
                if seg.role == "swing":
                    return (seg.step_index,)
                if seg.role in ("transfer", "final", "initial"):
                    n_steps = max(s.step_index for s in self.segments) + 1
                    return tuple(i for i in (seg.step_index, seg.step_index + 1) if 0 <= i < n_steps)
                return ()
        return ()


def build_schedule(step_sides: list[str], timing: WalkTiming) -> Schedule:
    """Lay the phases of a walk whose steps move the feet ``step_sides`` (in order) on the grid (the
    single supports of ``timing.slow_steps`` ``slow_step_factor`` times longer)."""
    timing.validate()
    n_init = timing.samples(timing.initial_double_support_s)
    n_ss = timing.samples(timing.single_support_s)
    n_ss_slow = timing.samples(timing.single_support_s * timing.slow_step_factor)
    slow = set(timing.slow_steps)
    n_ds = timing.samples(timing.double_support_s)
    n_final = timing.samples(timing.final_double_support_s)
    n_hold = timing.samples(timing.final_hold_s)
    n_start = timing.samples(timing.initial_hold_s)

    segments = []
    if n_start > 0:
        segments.append(Segment(DOUBLE, 0, n_start, -1, "start"))
    segments.append(Segment(DOUBLE, n_start, n_start + n_init, -1, "initial"))
    k = n_start + n_init
    for i, side in enumerate(step_sides):
        support = RIGHT if side == "left" else LEFT
        n_swing = n_ss_slow if i in slow else n_ss
        segments.append(Segment(support, k, k + n_swing, i, "swing"))
        k += n_swing
        last = i == len(step_sides) - 1
        n = n_final if last else n_ds
        segments.append(Segment(DOUBLE, k, k + n, i, "final" if last else "transfer"))
        k += n
    if n_hold > 0:
        segments.append(Segment(DOUBLE, k, k + n_hold, len(step_sides) - 1, "hold"))
        k += n_hold
    n_samples = k + 1  # the last sample closes the last segment
    phase = np.full(n_samples, DOUBLE, dtype=np.int8)
    for seg in segments:
        phase[seg.start : seg.stop] = seg.kind
    return Schedule(timing.dt_s, tuple(segments), n_samples, phase)
