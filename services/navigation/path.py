"""Stage 1 of the two-stage planner: a smooth, car-like, collision-free path for the lower body.

"At the first stage, the motion planner computes a collision-free walking path for the lower part of the
robot body approximated by a bounding box" ("Two-stage Planning Method", `001_771c0ce3779b0683.txt`), and
"It is desirable for the robot to walk forward [...]. This preference can be modeled as a nonholonomic
constraint, and we can benefit from well-developed planning method of a smooth path for car-like robot"
("Coupling the Motion Planner with Perception", same paper).

The curves are OMPL's: ``DubinsStateSpace`` (forward only) and ``ReedsSheppStateSpace`` (forward and
backward), both with minimum turning radius ``turning_radius_m``. The search is one of OMPL's sampling
planners under a time budget (BIT* by default: on the demo room it finds a first path in about 20 ms and
shortens it for ``optimize_time_s``; RRT-Connect is not offered: with the asymmetric Dubins distance it
fails on the demo room), followed by OMPL's path simplifier (vertex reduction, shortcuts).

Walking-forward preference, ``curve="forward_preferred"`` (the default): plan with Dubins curves first
(to every goal candidate of an object goal) and fall back to Reeds-Shepp only when no forward path is
found within ``dubins_budget_fraction`` of the budget. A Reeds-Shepp objective with a per-metre penalty
on reverse driving was the alternative; the OMPL 2.0.1 Python bindings do not expose the Reeds-Shepp
segment lengths (``ReedsSheppPathType`` only has ``length()``), so such a cost would have to re-sample
every motion in a Python callback, and it would still let an optimizing planner trade a little reverse
against length. The lexicographic rule is cheaper
and never walks backward when a forward path is found within its share of the budget.
``scripts/bench.d/navigation.py`` measures both families on the demo room and in clutter.

Collision checks use :class:`FootprintChecker` with the footprint grown by the largest displacement of a
footprint corner between two checked states, so the continuous sweep of the rectangle (not only the
checked samples) clears the obstacles by ``body.margin_m``.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from services.bus.schemas.navigation import (
    REASON_GOAL_IN_COLLISION,
    REASON_NO_PATH_WITHIN_BUDGET,
    REASON_START_IN_COLLISION,
)
from services.collision.obstacles import Scene
from services.errors import InfeasibleError, InternalError, InvalidRequestError
from services.navigation.geometry import BodyModel, FootprintChecker, Pose2D
from services.navigation.goals import ObjectGoal, resolve_goal
from services.navigation.reachability import check_reachable

CURVES = ("forward_preferred", "dubins", "reeds_shepp")
PLANNERS = {
    "rrtstar": og.RRTstar,
    "informed_rrtstar": og.InformedRRTstar,
    "bitstar": og.BITstar,
    "rrt": og.RRT,
}
OPTIMIZING_PLANNERS = ("rrtstar", "informed_rrtstar", "bitstar")

ou.setLogLevel(ou.LOG_WARN)


@dataclass(frozen=True)
class PlannerConfig:
    """Options of :func:`plan_path`.

    - ``turning_radius_m`` [m]: minimum turning radius of the walking path;
    - ``curve``: one of :data:`CURVES` (see the module docstring);
    - ``planner``: one of :data:`PLANNERS`; the optimizing ones (:data:`OPTIMIZING_PLANNERS`) search for
      ``optimize_time_s`` [s] (less when within 5 % of the obstacle-free curve length), then, still without
      a solution, until the first one; the others stop at their first solution;
    - ``time_budget_s`` [s]: total search time before giving up with ``infeasible``;
    - ``dubins_budget_fraction``: share of the budget spent on forward-only curves by ``forward_preferred``;
    - ``simplify_rounds``: rounds of OMPL vertex reduction + shortcutting (0 = none);
    - ``check_step_m`` [m]: arc length between two collision-checked states;
    - ``sample_step_m`` [m]: arc length between two samples of the returned path;
    - ``grid_resolution_m`` [m]: spacing of the checker's distance grid;
    - ``max_goal_candidates``: approach poses of an :class:`ObjectGoal` tried before giving up;
    - ``seed`` (> 0): seed of OMPL's random number generator, set before each call;
    - ``optimize_batches`` (BIT* only; 0: off): bound the improvement search by this many of BIT*'s
      batches of samples instead of ``optimize_time_s`` of wall-clock time (still within the budget), so
      that the path does not depend on the machine's load: the demo room's path to the yellow table was
      4.94 m or 8.13 m for the same request and seed depending on how much of the 50 ms window the
      machine gave (session 12); with 2 batches it is 4.94 m on every run (~0.25 s CPU). Off by
      default: the services keep their wall-clock window (a fetch's walks are planned under a budget).
    """

    turning_radius_m: float = 0.5
    curve: str = "forward_preferred"
    planner: str = "bitstar"
    time_budget_s: float = 1.0
    optimize_time_s: float = 0.05
    dubins_budget_fraction: float = 0.3
    simplify_rounds: int = 3
    check_step_m: float = 0.02
    sample_step_m: float = 0.02
    grid_resolution_m: float = 0.05
    max_goal_candidates: int = 3
    seed: int = 1
    optimize_batches: int = 0

    def __post_init__(self) -> None:
        if self.curve not in CURVES:
            raise InvalidRequestError(f"curve must be one of {list(CURVES)}, got {self.curve!r}")
        if self.planner not in PLANNERS:
            raise InvalidRequestError(f"planner must be one of {sorted(PLANNERS)}, got {self.planner!r}")
        positive = {
            "turning_radius_m": self.turning_radius_m,
            "time_budget_s": self.time_budget_s,
            "check_step_m": self.check_step_m,
            "sample_step_m": self.sample_step_m,
            "grid_resolution_m": self.grid_resolution_m,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0.0):
                raise InvalidRequestError(f"{name} must be a finite number > 0, got {value}")
        if not 0.0 < self.dubins_budget_fraction <= 1.0:
            raise InvalidRequestError(
                f"dubins_budget_fraction must be in (0, 1], got {self.dubins_budget_fraction}"
            )
        if self.max_goal_candidates < 1:
            raise InvalidRequestError(f"max_goal_candidates must be >= 1, got {self.max_goal_candidates}")
        if self.seed <= 0:
            raise InvalidRequestError(f"seed must be > 0 (OMPL ignores 0), got {self.seed}")
        if self.optimize_time_s < 0.0 or self.simplify_rounds < 0:
            raise InvalidRequestError("optimize_time_s and simplify_rounds must be >= 0")
        if self.optimize_batches < 0 or (self.optimize_batches and self.planner != "bitstar"):
            raise InvalidRequestError(
                f"optimize_batches must be >= 0, and 0 unless the planner is 'bitstar' (batches of samples "
                f"are BIT*'s), got {self.optimize_batches} with {self.planner!r}"
            )


@dataclass(frozen=True, eq=False)
class SampledPath:
    """A path densely sampled by arc length (world frame).

    Arrays of N samples: ``xy_m`` (N, 2) [m], ``theta_rad`` (N,) [rad] heading of the base (unwrapped,
    continuous), ``s_m`` (N,) [m] arc length from the start, ``forward`` (N,) True where the base moves
    along its heading over the step that ends at that sample (sample 0 copies sample 1).
    ``waypoints`` (K, 3) are the OMPL path vertices (x, y, theta) joined by ``curve`` curves.
    """

    xy_m: np.ndarray
    theta_rad: np.ndarray
    s_m: np.ndarray
    forward: np.ndarray
    waypoints: np.ndarray
    turning_radius_m: float
    curve: str
    planner: str
    plan_time_s: float = 0.0
    stats: dict[str, float] = field(default_factory=dict)

    @property
    def length_m(self) -> float:
        """Total arc length [m]."""
        return float(self.s_m[-1])

    @property
    def reverse_length_m(self) -> float:
        """Arc length [m] walked backward."""
        ds = np.diff(self.s_m)
        return float(ds[~self.forward[1:]].sum())

    @property
    def start(self) -> Pose2D:
        return Pose2D(float(self.xy_m[0, 0]), float(self.xy_m[0, 1]), float(self.theta_rad[0]))

    @property
    def goal(self) -> Pose2D:
        return Pose2D(float(self.xy_m[-1, 0]), float(self.xy_m[-1, 1]), float(self.theta_rad[-1]))

    def pose_at(self, s_m: float) -> Pose2D:
        """Pose at arc length ``s_m`` [m] (clamped to the path), linear between samples."""
        s = min(max(s_m, 0.0), self.length_m)
        return Pose2D(
            float(np.interp(s, self.s_m, self.xy_m[:, 0])),
            float(np.interp(s, self.s_m, self.xy_m[:, 1])),
            float(np.interp(s, self.s_m, self.theta_rad)),
        )

    def curvature(self) -> np.ndarray:
        """|d theta / d s| [1/m] over each sampling step, (N - 1,) (0 where the step has no length)."""
        ds = np.diff(self.s_m)
        dtheta = np.abs(np.diff(self.theta_rad))
        return np.divide(dtheta, ds, out=np.zeros_like(ds), where=ds > 1e-12)


def make_state_space(
    curve: str, turning_radius_m: float, bounds_xy_m: tuple[float, float, float, float]
) -> ob.StateSpace:
    """OMPL's Dubins (``curve == "dubins"``) or Reeds-Shepp space with radius [m] and (x, y) bounds [m]."""
    if curve == "dubins":
        space = ob.DubinsStateSpace(turning_radius_m, False)  # asymmetric: distance == the curve followed
    else:
        space = ob.ReedsSheppStateSpace(turning_radius_m)
    bounds = ob.RealVectorBounds(2)
    xmin, xmax, ymin, ymax = bounds_xy_m
    bounds.setLow(0, xmin)
    bounds.setHigh(0, xmax)
    bounds.setLow(1, ymin)
    bounds.setHigh(1, ymax)
    space.setBounds(bounds)
    return space


def _seed_ompl(seed: int) -> None:
    """Reseed OMPL's process-wide seed generator: the samplers created by the next search then draw the
    same numbers, so equal requests get equal paths (up to the time budget cutting a search short)."""
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)  # OMPL logs an error when reseeding after its first use; expected here
    try:
        ou.RNG.setSeed(seed)
    finally:
        ou.setLogLevel(level)


def set_se2_state(state: ob.State, x: float, y: float, theta: float) -> None:
    """Write a pose (x [m], y [m], theta [rad], any angle) into an OMPL SE2 state."""
    state.setX(x)
    state.setY(y)
    state.setYaw((theta + math.pi) % (2.0 * math.pi) - math.pi)  # OMPL's SO2 bounds are [-pi, pi)


def sweep_inflation_m(body: BodyModel, check_step_m: float, turning_radius_m: float) -> float:
    """Extra footprint margin [m] covering the motion between two checked states.

    A sample of the continuous path is within ``check_step_m / 2`` of arc length of a checked state; over
    that arc the base moves at most that far and turns at most ``check_step_m / (2 R)``, so a footprint
    corner (at most ``body.max_reach_m`` from the base, the arms' rectangle included) moves at most
    ``check_step_m / 2 * (1 + reach / R)``.
    """
    return 0.5 * check_step_m * (1.0 + body.max_reach_m / turning_radius_m)


def _search(
    curve: str,
    checker: FootprintChecker,
    start: Pose2D,
    goal: Pose2D,
    config: PlannerConfig,
    budget_s: float,
) -> tuple[list[tuple[float, float, float]], dict[str, float]] | None:
    """One OMPL search with one curve family; the simplified vertices, or None when the budget ran out."""
    space = make_state_space(curve, config.turning_radius_m, checker.scene.bounds_xy_m)
    ss = og.SimpleSetup(space)
    n_checks = [0]
    is_free = checker.is_free

    def valid(state: ob.State) -> bool:
        n_checks[0] += 1
        return is_free(state.getX(), state.getY(), state.getYaw())

    ss.setStateValidityChecker(valid)
    si = ss.getSpaceInformation()
    si.setStateValidityCheckingResolution(config.check_step_m / space.getMaximumExtent())
    planner = PLANNERS[config.planner](si)
    ss.setPlanner(planner)
    a, g = space.allocState(), space.allocState()
    set_se2_state(a, start.x_m, start.y_m, start.theta_rad)
    set_se2_state(g, goal.x_m, goal.y_m, goal.theta_rad)
    ss.setStartAndGoalStates(a, g)
    # Optimizing planners first search for optimize_time_s, stopping early once within 5 % of the
    # obstacle-free curve length; without a solution by then, the search goes on until the budget with an
    # infinite cost threshold, which any solution meets (stop at the first). (A second solve() call after
    # a first solution does not keep improving BIT*'s path in OMPL 2.0.1, hence this order.)
    objective = ob.PathLengthOptimizationObjective(si)
    ss.setOptimizationObjective(objective)
    ss.setup()
    t0 = time.perf_counter()
    if config.optimize_batches > 0:  # BIT*: a fixed amount of work, not of wall-clock time
        objective.setCostThreshold(ob.Cost(1.05 * space.distance(a, g)))
        deadline = t0 + budget_s
        ss.solve(
            ob.PlannerTerminationCondition(
                lambda: planner.numBatches() > config.optimize_batches or time.perf_counter() > deadline
            )
        )
    elif config.planner in OPTIMIZING_PLANNERS and config.optimize_time_s > 0.0:
        objective.setCostThreshold(ob.Cost(1.05 * space.distance(a, g)))
        ss.solve(min(config.optimize_time_s, budget_s))
    remaining = budget_s - (time.perf_counter() - t0)
    if not ss.haveExactSolutionPath() and remaining > 0.0:
        objective.setCostThreshold(ob.Cost(math.inf))
        ss.solve(remaining)
    t_solve = time.perf_counter() - t0
    if not ss.haveExactSolutionPath():
        return None
    path = ss.getSolutionPath()
    n_raw = path.getStateCount()
    length_raw = path.length()
    t1 = time.perf_counter()
    if config.simplify_rounds > 0:
        simplifier = og.PathSimplifier(si)
        # No B-spline smoothing (OMPL's simplify() runs it on metric spaces such as Reeds-Shepp): it moves
        # vertices off the curves' geometry. Vertex reduction only joins vertices by checked motions; the
        # partial shortcut cuts curves at interpolated states, which on Dubins curves (asymmetric, not a
        # metric) occasionally yields an invalid path (measured: 1 in 40 room plans): keep it only when
        # the result checks.
        for _ in range(config.simplify_rounds):
            changed = simplifier.reduceVertices(path)
            candidate = og.PathGeometric(path)
            if simplifier.partialShortcutPath(candidate) and candidate.check():
                path.assign(candidate)
                changed = True
            simplifier.collapseCloseVertices(path)
            if not changed:
                break
    t_simplify = time.perf_counter() - t1
    if not path.check():
        raise InternalError(
            f"OMPL {config.planner} + simplification returned an invalid path (please report)"
        )
    vertices = [(s.getX(), s.getY(), s.getYaw()) for s in path.getStates()]
    stats = {
        "solve_s": t_solve,
        "simplify_s": t_simplify,
        "raw_vertices": float(n_raw),
        "raw_length_m": float(length_raw),
        "validity_checks": float(n_checks[0]),
    }
    return vertices, stats


def densify(
    vertices: list[tuple[float, float, float]], curve: str, turning_radius_m: float, step_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sample the ``curve`` curves joining consecutive ``vertices`` every <= ``step_m`` of arc length.

    Returns ``xy_m`` (N, 2), unwrapped ``theta_rad`` (N,), ``s_m`` (N,), ``forward`` (N,).
    """
    huge = 1e6
    space = make_state_space(curve, turning_radius_m, (-huge, huge, -huge, huge))
    a, b, out = space.allocState(), space.allocState(), space.allocState()
    xs: list[float] = [vertices[0][0]]
    ys: list[float] = [vertices[0][1]]
    ths: list[float] = [vertices[0][2]]
    ss: list[float] = [0.0]
    for (x0, y0, t0), (x1, y1, t1) in itertools.pairwise(vertices):
        set_se2_state(a, x0, y0, t0)
        set_se2_state(b, x1, y1, t1)
        length = space.distance(a, b)  # the arc length of the curve interpolate() follows
        n = max(1, math.ceil(length / step_m))
        s0 = ss[-1]
        for k in range(1, n + 1):
            space.interpolate(a, b, k / n, out)
            xs.append(out.getX())
            ys.append(out.getY())
            ths.append(out.getYaw())
            ss.append(s0 + length * k / n)
    xy = np.column_stack([xs, ys])
    theta = np.unwrap(np.asarray(ths))
    s = np.asarray(ss)
    step = np.diff(xy, axis=0)
    along = step[:, 0] * np.cos(theta[1:]) + step[:, 1] * np.sin(theta[1:])
    forward = np.empty(len(s), dtype=bool)
    forward[1:] = along >= 0.0
    forward[0] = forward[1] if len(s) > 1 else True
    return xy, theta, s, forward


def stage1_checker(scene: Scene, body: BodyModel, config: PlannerConfig) -> FootprintChecker:
    """The footprint checker :func:`plan_path` tests poses with: the body's margin plus the sweep
    inflation between checked states (:func:`sweep_inflation_m`)."""
    nominal = FootprintChecker(scene, body, config.grid_resolution_m)
    return nominal.with_margin(
        body.margin_m + sweep_inflation_m(body, config.check_step_m, config.turning_radius_m)
    )


def escape_pose(
    checker: FootprintChecker,
    start: Pose2D,
    max_m: float = 0.6,
    step_m: float = 0.02,
    n_directions: int = 24,
) -> Pose2D | None:
    """The nearest base pose, same heading, whose footprint (margin included) ``checker`` finds free,
    when ``start``'s is not: the way out of a start that overlaps an obstacle (a robot that ended a
    reach or a turn close beside a chair), which :func:`plan_path` refuses to start from.

    Translations of ``step_m``, 2 ``step_m``, ... up to ``max_m`` [m] in ``n_directions`` directions are
    tried, shortest first; among free poses at one distance, the one farthest from the obstacles
    (``centre_distance_m``). ``start`` itself when it is free; None when nothing within ``max_m`` is."""
    if checker.is_free(start.x_m, start.y_m, start.theta_rad):
        return start
    angles = 2.0 * math.pi * np.arange(n_directions) / n_directions
    for k in range(1, round(max_m / step_m) + 1):
        d = k * step_m
        free = [
            (checker.centre_distance_m(x, y), x, y)
            for x, y in zip(start.x_m + d * np.cos(angles), start.y_m + d * np.sin(angles), strict=True)
            if checker.in_bounds(float(x), float(y)) and checker.is_free(float(x), float(y), start.theta_rad)
        ]
        if free:
            _, x, y = max(free)
            return Pose2D(float(x), float(y), start.theta_rad)
    return None


def plan_path(
    scene: Scene,
    body: BodyModel,
    start: Pose2D,
    goal: Pose2D | ObjectGoal,
    config: PlannerConfig | None = None,
) -> SampledPath:
    """A car-like collision-free path of the lower-body footprint from ``start`` to ``goal``.

    ``goal`` is a base pose or an :class:`ObjectGoal` ("in front of the yellow table, facing it, at
    0.4 m"): the usable approach poses are tried best first (at most ``max_goal_candidates``) within the
    one time budget; ``SampledPath.goal`` is the pose reached.

    Raises InfeasibleError (``details["reason"]`` one of ``start_in_collision``, ``goal_in_collision``,
    ``goal_enclosed``, ``no_free_approach_pose``, ``no_path_within_budget``), NotFoundError for an
    unknown object name, InvalidRequestError for poses outside the scene.
    """
    config = config or PlannerConfig()
    t_start = time.perf_counter()
    _seed_ompl(config.seed)
    poses = [("start", start)] + ([("goal", goal)] if isinstance(goal, Pose2D) else [])
    xmin, xmax, ymin, ymax = scene.bounds_xy_m
    for label, pose in poses:
        if not (xmin <= pose.x_m <= xmax and ymin <= pose.y_m <= ymax):
            raise InvalidRequestError(
                f"{label} ({pose.x_m:.2f}, {pose.y_m:.2f}) is outside the scene bounds "
                f"x in [{xmin}, {xmax}], y in [{ymin}, {ymax}] m"
            )
    checker = stage1_checker(scene, body, config)
    nominal = checker.with_margin(body.margin_m)
    inflation = sweep_inflation_m(body, config.check_step_m, config.turning_radius_m)
    for label, pose in poses:
        hits = checker.colliding_obstacles(pose.x_m, pose.y_m, pose.theta_rad)
        if hits:
            raise InfeasibleError(
                f"the {label} pose ({pose.x_m:.2f}, {pose.y_m:.2f}, {pose.theta_rad:.2f} rad) puts the "
                f"robot's footprint ({2 * checker.hx:.2f} x {2 * checker.hy:.2f} m incl. margin"
                + (
                    f"; {2 * body.arms_half_extents_m[1]:.2f} m wide with the arms at "
                    f"{body.arms_z_range_m[0]:.2f}-{body.arms_z_range_m[1]:.2f} m"
                    if body.arms_width_m > 0.0
                    else ""
                )
                + f") into {hits}; choose a pose farther from them",
                {
                    "reason": REASON_START_IN_COLLISION if label == "start" else REASON_GOAL_IN_COLLISION,
                    "obstacles": hits,
                },
            )
    if isinstance(goal, ObjectGoal):
        goals = [c.pose for c in resolve_goal(checker, goal, start)][: config.max_goal_candidates]
    else:
        check_reachable(checker, start, goal)
        goals = [goal]
    t_setup = time.perf_counter() - t_start

    if config.curve == "forward_preferred":
        attempts = [("dubins", config.dubins_budget_fraction), ("reeds_shepp", 1.0)]
    else:
        attempts = [(config.curve, 1.0)]
    result = None
    used = attempts[-1][0]
    # Every goal candidate with forward curves before any with Reeds-Shepp: a forward path to the second
    # face of an object beats walking backward to the first one.
    for curve, fraction in attempts:
        t_phase = time.perf_counter()
        phase_budget = fraction * (config.time_budget_s - (t_phase - t_start))
        for index, candidate in enumerate(goals):
            remaining = phase_budget - (time.perf_counter() - t_phase)
            budget = max(remaining / (len(goals) - index), 1e-3)  # leave budget for the other candidates
            result = _search(curve, checker, start, candidate, config, budget)
            if result is not None:
                used = curve
                break
        if result is not None:
            break
    if result is None:
        target = ", ".join(f"({p.x_m:.2f}, {p.y_m:.2f})" for p in goals)
        raise InfeasibleError(
            f"no {' or '.join(c for c, _ in attempts)} path with turning radius {config.turning_radius_m} m "
            f"found within {config.time_budget_s:.2f} s from ({start.x_m:.2f}, {start.y_m:.2f}) to {target}: "
            f"the passages may be too narrow or too tight to turn in; try a smaller turning radius, a larger "
            f"budget or another goal",
            {
                "reason": REASON_NO_PATH_WITHIN_BUDGET,
                "time_budget_s": config.time_budget_s,
                "goals": [[p.x_m, p.y_m, p.theta_rad] for p in goals],
            },
        )
    vertices, stats = result
    xy, theta, s, forward = densify(vertices, used, config.turning_radius_m, config.sample_step_m)
    for k in range(len(s)):
        if not nominal.is_free(float(xy[k, 0]), float(xy[k, 1]), float(theta[k])):
            hits = nominal.colliding_obstacles(float(xy[k, 0]), float(xy[k, 1]), float(theta[k]))
            raise InternalError(f"planned path sample at s={s[k]:.2f} m collides with {hits} (please report)")
    stats["setup_s"] = t_setup
    stats["sweep_inflation_m"] = inflation
    return SampledPath(
        xy_m=xy,
        theta_rad=theta,
        s_m=s,
        forward=forward,
        waypoints=np.asarray(vertices),
        turning_radius_m=config.turning_radius_m,
        curve=used,
        planner=config.planner,
        plan_time_s=time.perf_counter() - t_start,
        stats=stats,
    )
