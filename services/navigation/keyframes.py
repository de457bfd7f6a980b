"""The key frames of one reshaping iteration: from the collisions of a whole-body motion to the windows
the next one is solved with (Figure 2 (a)-(b) of `001_771c0ce3779b0683.txt`).

For each collision of the bar or an arm (:class:`~services.collision.motion.CollisionEvent`), the
colliding times are where the part comes within the target clearance of the obstacle ("The reshaping
limits are set by identifying the anticipating, colliding and regaining times", Figure 2 (a)); the bar's
configuration held there is

- mode ``"sample"`` (the paper): "a new random collision-free configuration near the colliding one"
  checked by "an IK solver" (:class:`~services.navigation.bar_sampling.BarPoseSampler`);
- mode ``"lift"``: the bar's centre at the obstacle's top + its radius + the target clearance (the
  height-only reshaping of the paper's experiment, Figure 3).

Collisions during a window already applied reshape that window again (sampled near its offset);
collisions whose windows would overlap are held by one window (one smooth move per obstacle group).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from services.bus.schemas.navigation import REASON_LIFT_TOO_HIGH, REASON_NO_COLLISION_FREE_SAMPLE
from services.collision.carried import BarGrip
from services.collision.motion import CollisionEvent, MotionCheck
from services.collision.obstacles import Scene
from services.errors import InfeasibleError
from services.navigation.bar_sampling import BarPoseSampler, SampleStats
from services.navigation.carry import BarTrajectory
from services.navigation.reshaping import (
    ZERO_OFFSET,
    BarOffset,
    ReshapeOptions,
    ReshapeWindow,
    make_window,
)


@dataclass(frozen=True)
class _Request:
    """A hold to realise: [t0_s, t1_s], the obstacles, the colliding configuration (``base``), the lift
    height (mode ``"lift"``), and ``window`` when it is an applied window kept as it is."""

    t0_s: float
    t1_s: float
    obstacles: tuple[str, ...]
    base: BarOffset
    lift_height_m: float
    window: ReshapeWindow | None = None

    def merged(self, other: _Request) -> _Request:
        base = max(
            (self.base, other.base), key=lambda b: float(np.abs(b.as_array()).sum())
        )  # resample near the larger of the two configurations
        return _Request(
            min(self.t0_s, other.t0_s),
            max(self.t1_s, other.t1_s),
            tuple(sorted(set(self.obstacles) | set(other.obstacles))),
            base,
            max(self.lift_height_m, other.lift_height_m),
        )


def clear_height_m(
    event: CollisionEvent, scene: Scene, grip: BarGrip, current_m: float, options: ReshapeOptions
) -> float:
    """Bar-centre height [m] that passes ``event``'s part over its obstacle (mode ``"lift"``): for the
    bar, the obstacle's top + the bar's radius + the target clearance; for an arm, the current height
    raised by what the arm misses; never lower than the current height raised by the missing clearance."""
    missing = options.target_clearance_m - event.min_distance_m
    raised = current_m + max(missing, 0.0)
    if event.group == "bar":
        top = scene.find(event.obstacle).z_range_m[1]
        return max(top + grip.bar.radius_m + options.target_clearance_m, raised)
    return raised


def next_windows(
    events: list[CollisionEvent],
    check: MotionCheck,
    windows: list[ReshapeWindow],
    realised_centre_m: np.ndarray,
    qs: np.ndarray,
    nominal: BarTrajectory,
    scene: Scene,
    grip: BarGrip,
    options: ReshapeOptions,
    sampler: BarPoseSampler | None,
    rejected: list[ReshapeWindow] | None = None,
) -> tuple[list[ReshapeWindow], list[SampleStats]]:
    """The windows of the next whole-body solution, from the ``events`` (bar or arms) of the motion
    ``qs`` (n, nq) checked by ``check``, the ``windows`` it was solved with, the bar's realised centre
    (n, 3) [m] and the nominal task-space trajectory. ``sampler`` is needed in mode ``"sample"``;
    ``rejected``: sampled windows the whole-body IK could not follow (not drawn again).

    Raises InfeasibleError: ``lift_too_high`` (mode ``"lift"``: clearing needs the bar above
    ``max_bar_height_m``), ``no_collision_free_sample`` (mode ``"sample"``: no drawn configuration is
    both collision-free and within the arms' reach)."""
    times = nominal.times_s
    t_first, t_last = float(times[0]), float(times[-1])
    half = 0.5 * grip.bar.length_m
    fresh: list[_Request] = []
    for e in events:
        k0, k1 = check.near_interval(e.group, e.obstacle, e.k_start, e.k_end, options.target_clearance_m)
        height = 0.0
        if options.mode == "lift":
            current = float(realised_centre_m[k0 : k1 + 1, 2].max())
            height = clear_height_m(e, scene, grip, current, options)
            if options.max_bar_height_m is not None and height > options.max_bar_height_m:
                top = scene.find(e.obstacle).z_range_m[1]
                raise InfeasibleError(
                    f"clearing {e.obstacle!r} (top at {top:.2f} m) with the {e.group} needs the bar's "
                    f"centre at {height:.2f} m, above the {options.max_bar_height_m:.2f} m the arms may "
                    f"hold it: go around {e.obstacle!r}, or reshape by sampling (mode 'sample')",
                    {
                        "reason": REASON_LIFT_TOO_HIGH,
                        "obstacle": e.obstacle,
                        "height_m": height,
                        "max_bar_height_m": options.max_bar_height_m,
                    },
                )
        fresh.append(_Request(float(times[k0]), float(times[k1]), (e.obstacle,), ZERO_OFFSET, height))

    # applied windows: kept, unless a new collision falls within one (then it is reshaped again)
    requests = [
        _Request(w.t_collide_s, w.t_collide_end_s, w.obstacles, w.offset, w.height_m, window=w)
        for w in windows
    ]
    for f in sorted(fresh, key=lambda r: r.t0_s):
        for i, r in enumerate(requests):
            span = (r.window.t_anticipate_s, r.window.t_regain_s) if r.window else (r.t0_s, r.t1_s)
            pad = 0.0 if r.window else 2.0 * options.min_ramp_s
            if f.t0_s <= span[1] + pad and span[0] - pad <= f.t1_s:
                requests[i] = r.merged(f)
                break
        else:
            requests.append(f)

    stats: list[SampleStats] = []
    exempt = sampler.initial_contacts(nominal) if sampler is not None else set()
    while True:
        requests.sort(key=lambda r: r.t0_s)
        realised: list[ReshapeWindow] = []
        for i, r in enumerate(requests):
            if r.window is not None:
                realised.append(r.window)
                continue
            k0 = int(np.searchsorted(times, r.t0_s))
            nominal_z = float(nominal.centre_m[min(k0, times.shape[0] - 1), 2])
            if options.mode == "lift":
                offset = BarOffset(up_m=max(r.lift_height_m - nominal_z, 0.0))
                window = make_window(
                    r.t0_s, r.t1_s, offset, r.obstacles, options, t_first, t_last, half, nominal_z
                )
            else:
                assert sampler is not None
                kept = [q.window for q in requests if q.window is not None]
                window, st = sampler.sample(
                    r.t0_s, r.t1_s, r.obstacles, r.base, nominal, qs, kept, exempt, rejected or []
                )
                stats.append(st)
                if window is None:
                    raise InfeasibleError(
                        f"no collision-free configuration of the bar within the arms' reach near "
                        f"{list(r.obstacles)} between t={r.t0_s:.2f} and {r.t1_s:.2f} s ({st.drawn} drawn: "
                        f"{st.collide} too close to an obstacle, {st.unreachable} out of reach): go around "
                        f"{list(r.obstacles)}",
                        {
                            "reason": REASON_NO_COLLISION_FREE_SAMPLE,
                            "obstacles": list(r.obstacles),
                            "t_s": [r.t0_s, r.t1_s],
                            "drawn": st.drawn,
                            "collide": st.collide,
                            "unreachable": st.unreachable,
                        },
                    )
            requests[i] = replace(r, window=window)
            realised.append(window)
        # windows whose spans overlap become one hold (and are realised again)
        pair = next(
            (
                (a, b)
                for a in range(len(requests))
                for b in range(a + 1, len(requests))
                if realised[a].overlaps(realised[b])
            ),
            None,
        )
        if pair is None:
            return realised, stats
        a, b = pair
        merged = requests[a].merged(requests[b])
        requests = [r for i, r in enumerate(requests) if i not in pair] + [merged]


__all__ = ["clear_height_m", "next_windows"]
