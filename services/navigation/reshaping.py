"""Smooth motion reshaping of the carried bar: key frames around an obstacle, smooth interpolation in
task space, resampling at the pattern's 5 ms (Figure 2 (a)-(c) of `001_771c0ce3779b0683.txt`).

"The reshaping limits are set by identifying the anticipating, colliding and regaining times" (Figure 2
(a)); "Smooth motion is specified in the task space by interpolating the bar's configuration at key
frames" (b); "The bar's motion is resampled at 5 millisecond to replace its original motion" (c); the
whole-body IK then enforces it (d, in :mod:`services.navigation.stage2`).

A :class:`LiftWindow` is one reshaping: the bar keeps its nominal height until the anticipating time,
rises to ``height_m`` by the colliding time, holds it until the end of the collision and comes back to
the nominal height at the regaining time. The key frames are joined by quintics (zero velocity and
acceleration at every key frame, "accounting for motion continuity"); the ramp durations follow from the
height change and the speed and acceleration bounds of :class:`ReshapeOptions`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from services.errors import InvalidRequestError
from services.walking.zmp_reference import smoothstep5

# Peak speed and acceleration of a quintic 0 -> 1 over T: 1.875 / T and 10 / sqrt(3) / T^2.
_QUINTIC_PEAK_SPEED = 1.875
_QUINTIC_PEAK_ACC = 10.0 / math.sqrt(3.0)


@dataclass(frozen=True)
class ReshapeOptions:
    """Options of the reshaping loop (:func:`services.navigation.stage2.plan_motion`).

    - ``required_clearance_m`` [m]: a motion is accepted when every part (robot and bar) stays at least
      this far from every obstacle (a margin for the tracking errors of the real execution);
    - ``target_clearance_m`` [m]: the lifted bar passes this far above an obstacle; the anticipating and
      regaining limits are where a part first and last comes within it (at the motion being reshaped);
    - ``max_lift_speed_m_s`` [m/s], ``max_lift_acc_m_s2`` [m/s^2]: bounds of the bar's vertical motion,
      which set the ramp durations; ``min_ramp_s`` [s] the shortest ramp;
    - ``max_bar_height_m`` [m]: the highest the arms may hold the bar's centre (None: no bound besides the
      IK's tracking check);
    - ``max_iterations``: whole-body solutions at most (the first, unreshaped one included);
    - ``max_hand_error_m`` [m]: a motion whose hands end up farther than this from the bar's planned
      pose is rejected (the arms cannot hold it there).
    """

    required_clearance_m: float = 0.02
    target_clearance_m: float = 0.05
    max_lift_speed_m_s: float = 0.25
    max_lift_acc_m_s2: float = 0.6
    min_ramp_s: float = 0.6
    max_bar_height_m: float | None = 1.25
    max_iterations: int = 5
    max_hand_error_m: float = 0.02

    def __post_init__(self) -> None:
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

    def ramp_s(self, dh_m: float) -> float:
        """Duration [s] of a quintic height change of ``dh_m`` [m] within the speed/acceleration bounds."""
        dh = abs(dh_m)
        return max(
            self.min_ramp_s,
            _QUINTIC_PEAK_SPEED * dh / self.max_lift_speed_m_s,
            math.sqrt(_QUINTIC_PEAK_ACC * dh / self.max_lift_acc_m_s2),
        )


@dataclass(frozen=True)
class LiftWindow:
    """One reshaping of the bar height (times [s], height of the bar's centre [m]): nominal until
    ``t_anticipate_s``, ``height_m`` from ``t_collide_s`` to ``t_collide_end_s``, nominal again from
    ``t_regain_s``; ``obstacles`` it passes over."""

    t_anticipate_s: float
    t_collide_s: float
    t_collide_end_s: float
    t_regain_s: float
    height_m: float
    obstacles: tuple[str, ...]

    def key_frames(self, nominal_at: Callable[[float], float]) -> list[tuple[float, float]]:
        """(time [s], height [m]) of the four key frames, ``nominal_at(t)`` giving the nominal height."""
        return [
            (self.t_anticipate_s, float(nominal_at(self.t_anticipate_s))),
            (self.t_collide_s, self.height_m),
            (self.t_collide_end_s, self.height_m),
            (self.t_regain_s, float(nominal_at(self.t_regain_s))),
        ]


def make_window(
    t_collide_s: float,
    t_collide_end_s: float,
    height_m: float,
    nominal_height_m: float,
    obstacles: tuple[str, ...],
    options: ReshapeOptions,
    t_first_s: float,
    t_last_s: float,
) -> LiftWindow:
    """A window holding ``height_m`` over [t_collide_s, t_collide_end_s], with ramps from and back to
    ``nominal_height_m`` sized by ``options`` and clipped to [t_first_s, t_last_s] (the ramps get shorter
    there, the speed bound then gives way to the time available)."""
    ramp = options.ramp_s(height_m - nominal_height_m)
    t_c = max(t_collide_s, t_first_s + options.min_ramp_s)
    t_ce = min(t_collide_end_s, t_last_s - options.min_ramp_s)
    t_ce = max(t_ce, t_c)
    return LiftWindow(
        t_anticipate_s=max(t_first_s, t_c - ramp),
        t_collide_s=t_c,
        t_collide_end_s=t_ce,
        t_regain_s=min(t_last_s, t_ce + ramp),
        height_m=height_m,
        obstacles=obstacles,
    )


def merge_windows(
    windows: list[LiftWindow],
    nominal_height_m: float,
    options: ReshapeOptions,
    t_first_s: float,
    t_last_s: float,
) -> list[LiftWindow]:
    """Windows whose ramps overlap become one (hold from the first colliding time to the last, the higher
    height, ramps resized), so the height profile stays one smooth rise and fall per obstacle group."""
    out = sorted(windows, key=lambda w: w.t_anticipate_s)
    changed = True
    while changed:  # each merge removes a window: terminates
        changed = False
        merged: list[LiftWindow] = []
        for w in out:
            if merged and w.t_anticipate_s <= merged[-1].t_regain_s:
                prev = merged.pop()
                merged.append(
                    make_window(
                        min(prev.t_collide_s, w.t_collide_s),
                        max(prev.t_collide_end_s, w.t_collide_end_s),
                        max(prev.height_m, w.height_m),
                        nominal_height_m,
                        tuple(sorted(set(prev.obstacles) | set(w.obstacles))),
                        options,
                        t_first_s,
                        t_last_s,
                    )
                )
                changed = True
            else:
                merged.append(w)
        out = sorted(merged, key=lambda w: w.t_anticipate_s)
    return out


def reshaped_height(times_s: np.ndarray, nominal_m: np.ndarray, windows: list[LiftWindow]) -> np.ndarray:
    """The bar height on the 5 ms grid ``times_s``: the nominal profile ``nominal_m`` (n,) [m] with each
    window's key frames joined by quintics (Figure 2 (b)) and resampled at every sample (Figure 2 (c)).

    With w(t) the quintic weight (0 before the anticipating time, 1 between the colliding times, 0 after
    the regaining time), h(t) = nominal(t) + w(t) (height - nominal(t)): where the nominal height is
    constant this is exactly the quintic between the key frames."""
    h = np.array(nominal_m, dtype=float)
    t = np.asarray(times_s, dtype=float)
    for w in windows:
        weight = np.zeros_like(t)
        up = (t >= w.t_anticipate_s) & (t < w.t_collide_s)
        if w.t_collide_s > w.t_anticipate_s:
            weight[up] = smoothstep5((t[up] - w.t_anticipate_s) / (w.t_collide_s - w.t_anticipate_s))
        weight[(t >= w.t_collide_s) & (t <= w.t_collide_end_s)] = 1.0
        down = (t > w.t_collide_end_s) & (t <= w.t_regain_s)
        if w.t_regain_s > w.t_collide_end_s:
            weight[down] = 1.0 - smoothstep5(
                (t[down] - w.t_collide_end_s) / (w.t_regain_s - w.t_collide_end_s)
            )
        h = h + weight * (w.height_m - h)
    return h


def with_height(
    window: LiftWindow,
    height_m: float,
    nominal_height_m: float,
    options: ReshapeOptions,
    t_first_s: float,
    t_last_s: float,
) -> LiftWindow:
    """The same window at another height (ramps resized)."""
    return make_window(
        window.t_collide_s,
        window.t_collide_end_s,
        height_m,
        nominal_height_m,
        window.obstacles,
        options,
        t_first_s,
        t_last_s,
    )


__all__ = ["LiftWindow", "ReshapeOptions", "make_window", "merge_windows", "reshaped_height", "with_height"]
