"""Stage 2, first step: turn the stage-1 path into footsteps along it, within the stepping bounds.

"Then the path is transformed into dynamic humanoid locomotion at the second stage by applying the
dynamic walking pattern generator" ("Coupling the Motion Planner with Perception",
`001_771c0ce3779b0683.txt`). The pattern generator (``services/walking``) consumes footsteps; this module
places them: the feet alternate, each landing on the path at arc length s_k, offset by half the feet
spacing along the path normal, with the path heading as yaw. The step length adapts to curvature (at
most ``max_turn_per_step_rad`` of path heading per step) and to the bounds of section 4 of the footstep
paper (left sole in the right sole frame: -0.22 < dx < 0.22 m, 0.07 < dy < 0.25 m, -0.1 < dtheta < pi/4,
mirrored for the right foot): a landing outside them is retried with a shorter step.

Because the trailing foot of a turn may only turn 0.1 rad past the leading one, the yaw of a landing is
the path heading clipped to the bounds relative to the stance sole; the leading foot (which may turn by
pi/4) catches up on the next step. Where soles would overlap (large relative yaw), the landing moves
outward in 5 mm steps. Each direction change of the path (Reeds-Shepp cusp) and the goal end with the
feet side by side at the path pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NoReturn

import numpy as np

from services.bus.schemas.navigation import REASON_FOOTSTEP_BOUNDS
from services.errors import InfeasibleError, InvalidRequestError
from services.navigation.geometry import BodyModel
from services.navigation.path import SampledPath
from services.walking.footsteps import (
    Footstep,
    FootstepBounds,
    FootstepSequence,
    Side,
    SolePose,
    other_side,
    rectangles_overlap_depth,
    sole_corners,
    validate_footsteps,
    wrap_angle,
)
from services.walking.goals import MAX_STRIDE_M


@dataclass(frozen=True)
class FootstepOptions:
    """Options of :func:`footsteps_along_path`.

    - ``feet_spacing_m`` [m]: lateral distance between the sole centres (0.19 m on HRP-2);
    - ``max_step_m`` / ``max_back_step_m`` [m]: arc length advanced per step walking forward / backward
      (forward: walking's ``MAX_STRIDE_M``, 0.2 m: the bounds allow 0.22 m, HRP-2's knee with a held
      object ahead not);
    - ``min_step_m`` [m]: below this, a step that still breaks the bounds makes the call infeasible;
    - ``max_turn_per_step_rad`` [rad]: path heading change per step (the bounds allow about
      (pi/4 + 0.1) / 2 on average);
    - ``bounds_margin``: the bounds are shrunk by this fraction of their width before use;
    - ``max_outward_m`` [m]: how far a landing may move outward to keep the soles apart.
    """

    feet_spacing_m: float = 0.19
    max_step_m: float = MAX_STRIDE_M
    max_back_step_m: float = 0.10
    min_step_m: float = 0.01
    max_turn_per_step_rad: float = 0.35
    bounds_margin: float = 0.03
    max_outward_m: float = 0.06

    def __post_init__(self) -> None:
        for name in (
            "feet_spacing_m",
            "max_step_m",
            "max_back_step_m",
            "min_step_m",
            "max_turn_per_step_rad",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise InvalidRequestError(f"{name} must be a finite number > 0, got {value}")
        if not 0.0 <= self.bounds_margin < 0.5:
            raise InvalidRequestError(f"bounds_margin must be in [0, 0.5), got {self.bounds_margin}")

    @staticmethod
    def for_body(body: BodyModel) -> FootstepOptions:
        """Defaults with the feet spacing of ``body`` (twice ``body.foot_half_spacing_m``)."""
        return FootstepOptions(feet_spacing_m=2.0 * body.foot_half_spacing_m)


@dataclass(frozen=True)
class PathFootsteps:
    """The footstep sequence and, for each step, the path arc length [m] its landing was placed at."""

    sequence: FootstepSequence
    s_m: tuple[float, ...]


def _segments(path: SampledPath) -> list[tuple[int, int, float]]:
    """(first index, last index, direction +1/-1) of the path's constant-direction stretches."""
    n = len(path.s_m)
    direction = np.where(path.forward, 1.0, -1.0)
    out: list[tuple[int, int, float]] = []
    start = 0
    for k in range(2, n):
        if direction[k] != direction[k - 1]:
            out.append((start, k - 1, float(direction[k - 1])))
            start = k - 1
    out.append((start, n - 1, float(direction[min(start + 1, n - 1)])))
    return out


class _Walker:
    """Greedy footstep placement along a path (state: both soles, the moving side, the steps so far)."""

    def __init__(
        self,
        path: SampledPath,
        bounds: FootstepBounds,
        options: FootstepOptions,
        start_soles: tuple[SolePose, SolePose] | None = None,
    ) -> None:
        self.path = path
        self.options = options
        self.bounds = bounds
        shrink = options.bounds_margin
        self.limits: dict[str, dict[str, tuple[float, float]]] = {}
        for side in ("left", "right"):
            lim = bounds.limits_for(side)  # type: ignore[arg-type]
            self.limits[side] = {
                k: (lo + shrink * (hi - lo), hi - shrink * (hi - lo)) for k, (lo, hi) in lim.items()
            }
        self.curvature = np.concatenate([path.curvature(), [0.0]])
        half = 0.5 * options.feet_spacing_m
        p0 = path.start
        if start_soles is None:
            start_soles = (
                self._offset(p0.x_m, p0.y_m, p0.theta_rad, +half, p0.theta_rad),
                self._offset(p0.x_m, p0.y_m, p0.theta_rad, -half, p0.theta_rad),
            )
        self.feet: dict[str, SolePose] = {"left": start_soles[0], "right": start_soles[1]}
        self.left_start, self.right_start = self.feet["left"], self.feet["right"]
        self.steps: list[Footstep] = []
        self.step_s: list[float] = []

    @staticmethod
    def _offset(x: float, y: float, theta: float, lateral: float, yaw: float) -> SolePose:
        return SolePose(x - lateral * math.sin(theta), y + lateral * math.cos(theta), yaw)

    def _landing(self, side: Side, s: float, outward: float) -> SolePose:
        pose = self.path.pose_at(s)
        stance = self.feet[other_side(side)]
        lo, hi = self.limits[side]["dyaw"]
        yaw = stance.yaw_rad + min(max(wrap_angle(pose.theta_rad - stance.yaw_rad), lo), hi)
        lateral = (0.5 * self.options.feet_spacing_m + outward) * (1.0 if side == "left" else -1.0)
        return self._offset(pose.x_m, pose.y_m, pose.theta_rad, lateral, yaw)

    def _admissible(self, side: Side, landing: SolePose) -> bool:
        stance = self.feet[other_side(side)]
        rel = dict(zip(("dx", "dy", "dyaw"), landing.relative_to(stance), strict=True))
        return all(lo <= rel[name] <= hi for name, (lo, hi) in self.limits[side].items())

    def _separated(self, side: Side, landing: SolePose) -> bool:
        stance = self.feet[other_side(side)]
        L, W = self.bounds.sole_length_m, self.bounds.sole_width_m
        return rectangles_overlap_depth(sole_corners(landing, L, W), sole_corners(stance, L, W)) <= -0.005

    def place(self, side: Side, s: float) -> SolePose | None:
        """The landing of ``side`` at arc length ``s`` (moved outward if the soles would overlap), or None."""
        outward = 0.0
        while outward <= self.options.max_outward_m + 1e-9:
            landing = self._landing(side, s, outward)
            if not self._admissible(side, landing):
                return None
            if self._separated(side, landing):
                return landing
            outward += 0.005
        return None

    def commit(self, side: Side, landing: SolePose, s: float) -> None:
        self.steps.append(Footstep(side, landing))
        self.step_s.append(s)
        self.feet[side] = landing

    def step_length(self, s: float, direction: float) -> float:
        o = self.options
        nominal = o.max_step_m if direction > 0 else o.max_back_step_m
        window = (self.path.s_m >= s - 1e-9) & (self.path.s_m <= s + nominal)
        kappa = float(self.curvature[window].max()) if window.any() else 0.0
        return min(nominal, o.max_turn_per_step_rad / kappa) if kappa > 1e-9 else nominal

    def walk_segment(self, s0: float, s1: float, direction: float, side: Side) -> Side:
        """Steps from arc length s0 to s1, ending with both feet at s1; returns the next moving side."""
        s_feet = s0
        while s_feet < s1 - 1e-9:
            length = self.step_length(s_feet, direction)
            s_next = min(s_feet + length, s1)
            landing = self.place(side, s_next)
            while landing is None:  # too far for the bounds: shorten the step
                length = 0.7 * (s_next - s_feet)
                if length < self.options.min_step_m:
                    self._fail(side, s_next)
                s_next = s_feet + length
                landing = self.place(side, s_next)
            self.commit(side, landing, s_next)
            s_feet = s_next
            side = other_side(side)
        # square up: the other foot comes alongside, then both turn onto the path heading if clipped
        theta_end = self.path.pose_at(s1).theta_rad
        for _ in range(8):
            if all(self._squared(f, s1, theta_end) for f in ("left", "right")):
                return side
            landing = self.place(side, s1)
            if landing is None:
                self._fail(side, s1)
            self.commit(side, landing, s1)
            side = other_side(side)
        self._fail(side, s1)
        return side

    def _squared(self, side: Side, s: float, theta: float) -> bool:
        foot = self.feet[side]
        target = self._landing(side, s, 0.0)
        return (
            abs(wrap_angle(foot.yaw_rad - theta)) < 1e-6
            and math.hypot(foot.x_m - target.x_m, foot.y_m - target.y_m) < 1e-6
        )

    def _fail(self, side: Side, s: float) -> NoReturn:
        pose = self.path.pose_at(s)
        raise InfeasibleError(
            f"no {side} footstep within the stepping bounds reaches the path at s={s:.2f} m "
            f"({pose.x_m:.2f}, {pose.y_m:.2f}); the path turns too sharply for the feet there "
            f"(turning radius {self.path.turning_radius_m} m): plan with a larger turning radius",
            {"reason": REASON_FOOTSTEP_BOUNDS, "side": side, "s_m": s},
        )


def footsteps_along_path(
    path: SampledPath,
    bounds: FootstepBounds | None = None,
    options: FootstepOptions | None = None,
    start_soles: tuple[SolePose, SolePose] | None = None,
) -> PathFootsteps:
    """Footsteps walking ``path`` from its start (feet side by side on the start pose) to its goal.

    Returns the sequence (``services.walking.footsteps.FootstepSequence``: the two starting soles and the
    landings, alternating feet) and the arc length of each landing. The first moving foot is the one on
    the side the path first turns to (the right one on a straight start). ``start_soles`` (left, right)
    are where the soles really are (the robot's starting configuration; a few millimetres off the path's
    start pose), default: on the start pose ``feet_spacing_m`` apart. Raises InfeasibleError when a turn is
    too sharp for the bounds.
    """
    bounds = bounds or FootstepBounds()
    options = options or FootstepOptions()
    walker = _Walker(path, bounds, options, start_soles)
    # first moving foot: the inner one of the first turn (it may turn pi/4 relative to the other)
    look = path.s_m <= min(path.length_m, 0.5)
    turn = float(path.theta_rad[look][-1] - path.theta_rad[0]) if look.any() else 0.0
    side: Side = "left" if turn > 1e-3 else "right"
    for first, last, direction in _segments(path):
        side = walker.walk_segment(float(path.s_m[first]), float(path.s_m[last]), direction, side)
    sequence = FootstepSequence(walker.left_start, walker.right_start, tuple(walker.steps))
    if sequence.steps:
        validate_footsteps(sequence, bounds)
    return PathFootsteps(sequence, tuple(walker.step_s))
