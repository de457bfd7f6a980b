"""One contact-before-motion planning request end to end (the service's algorithm, no bus): the scene's
environment, the posture generator, the rough trajectory's potential, the best-first search over
contact sets (§2), then the interpolated, statically stable motion (§3.3)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from services import budget
from services.bus.schemas import contacts as msg
from services.contacts import chair_egress
from services.contacts.defaults import LIMB_LOAD, SLOPE_K
from services.contacts.environment import Environment, environment_of
from services.contacts.interpolate import InterpolationConfig, Motion, interpolate_plan
from services.contacts.posture import PostureGenerator, posture_config
from services.contacts.potential import RoughTrajectory
from services.contacts.search import ContactPlanner, Goal, ProgressHook, SearchConfig, SearchResult
from services.contacts.sets import ContactSet, contact_at, spot_surface_gap
from services.contacts.spots import robot_spots, select_spots
from services.errors import InfeasibleError, InvalidRequestError, RequestTimeoutError
from services.model import RobotModel
from sim.scene import layout, load_scene

START_TOLERANCE_M = 0.01  # a start contact's spot must be this close to its surface [m]
MAX_KEY_POSTURES = 1000  # postures of the rough trajectory T a request may give (§2.7; the chair's: 4)
# how far the waist may be beyond a surface a final contact is on, horizontally and vertically (a
# stretched leg or arm with its lean; HRP-2's waist stands 0.65-0.75 m over its soles): goals farther
# are refused before the search [m]
WAIST_REACH_M = {"x": 1.0, "y": 1.0, "z": 1.0}
JOINT_TOLERANCE_RAD = 1e-3  # q_start's joints may be this far past their limits (measured) [rad]


@dataclass(frozen=True)
class PlanProblem:
    """What a plan needs (all in the request: the planner is stateless). Lengths [m], angles [rad]."""

    scene: str
    q_start: np.ndarray
    start_pairs: tuple[tuple[str, str], ...]
    goal: Goal
    key_postures: np.ndarray | None = None  # (k x nq); None: the chair scenario's (chair_egress only)
    spots: tuple[str, ...] | None = None
    surfaces: tuple[str, ...] | None = None
    pairs: tuple[tuple[str, str], ...] | None = None
    slope_k: float = SLOPE_K  # f_T's k (eq. 1; defaults.py)
    search: SearchConfig = field(default_factory=SearchConfig)
    interpolation: InterpolationConfig | None = field(default_factory=InterpolationConfig)
    # the arms' contact forces bounded by their joints' torques (limb_load.py; an extension of §2.2)
    limb_load: bool = LIMB_LOAD


@dataclass(frozen=True)
class Plan:
    """A plan: the search's outcome and the interpolated motion (None if not asked or not reached)."""

    search: SearchResult
    motion: Motion | None
    trajectory: RoughTrajectory
    environment: Environment

    @property
    def sets(self) -> list[ContactSet]:
        return [n.contacts for n in self.search.path]

    @property
    def witnesses(self) -> np.ndarray:
        return np.array([n.q for n in self.search.path])


def build(
    robot: RobotModel, problem: PlanProblem
) -> tuple[PostureGenerator, RoughTrajectory, ContactSet, list[tuple[str, str]]]:
    """Validate the problem and make the posture generator, T, the start set and the allowed pairs."""
    q_start = start_configuration(robot, problem.q_start)
    scene = load_scene(problem.scene)
    env = environment_of(layout(scene))
    all_spots = robot_spots(robot)
    surfaces = [s.name for s in env.select(problem.surfaces)]
    if problem.pairs is not None:
        pairs = list(dict.fromkeys((str(a), str(b)) for a, b in problem.pairs))  # once each, in order
    else:
        names = problem.spots or tuple(s.name for s in all_spots)
        pairs = [(s, e) for s in names for e in surfaces]
    used = sorted({p[0] for p in pairs} | {p[0] for p in problem.start_pairs})
    spots = select_spots(all_spots, used)
    known_spots, known_surfaces = {s.name for s in spots}, {s.name for s in env.surfaces}
    for spot, surface in [*pairs, *problem.start_pairs]:
        if spot not in known_spots:
            raise InvalidRequestError(f"unknown contact spot {spot!r}; spots: {sorted(known_spots)}")
        if surface not in known_surfaces:
            raise InvalidRequestError(
                f"unknown surface {surface!r}; surfaces of {scene.name}: {sorted(known_surfaces)}"
            )
    start_spots = [spot for spot, _ in problem.start_pairs]
    if not start_spots or len(set(start_spots)) != len(start_spots):
        raise InvalidRequestError(
            "start_contacts must name the contacts holding the robot at q_start, each spot once (§2.2: "
            f"a feasible starting set), got {[list(p) for p in problem.start_pairs]}",
            {"field": "start_contacts"},
        )
    gen = PostureGenerator(robot, env, spots, posture_config(problem.limb_load))
    start = []
    for spot, surface in problem.start_pairs:
        T = gen.spot_pose(q_start, spot)
        height, tilt, inside = spot_surface_gap(T, env, surface)
        if abs(height) > START_TOLERANCE_M or tilt > 0.1 or not inside:
            raise InvalidRequestError(
                f"start contact {spot} on {surface} does not hold at q_start: the spot is {height:+.3f} m "
                f"from the surface's plane (tolerance {START_TOLERANCE_M} m), tilted "
                f"{math.degrees(tilt):.1f} deg, "
                f"{'inside' if inside else 'outside'} the surface",
                {"field": "start_contacts", "spot": spot, "surface": surface},
            )
        start.append(contact_at(gen.spots[spot], surface, env, T))
    com = pin.centerOfMass(gen.model, gen.data, q_start)
    if not gen.stable_at(tuple(start), com):
        raise InvalidRequestError(
            f"the start contacts {[list(p) for p in problem.start_pairs]} do not hold the robot statically "
            f"at q_start (no contact forces in their friction cones balance its weight at the CoM "
            f"({com[0]:.3f}, {com[1]:.3f}, {com[2]:.3f}) m; §2.2: the search starts from a feasible set)",
            {"field": "start_contacts"},
        )
    reachable(robot, env, problem.goal, pairs, problem.start_pairs)
    budget.check("the set-up (scene, posture generator, start contacts), before the key postures")
    if problem.key_postures is not None:
        keys = np.asarray(problem.key_postures, float)
        if keys.ndim != 2 or not 1 <= len(keys) <= MAX_KEY_POSTURES or keys.shape[1] != robot.nq:
            raise InvalidRequestError(
                f"key_postures must be (k, nq={robot.nq}) with 1 <= k <= {MAX_KEY_POSTURES}, got shape "
                f"{keys.shape}",
                {"field": "key_postures"},
            )
        if not np.all(np.isfinite(keys)):
            raise InvalidRequestError("key_postures has a non-finite value", {"field": "key_postures"})
    else:
        keys = np.array(default_key_postures(robot, env, q_start, tuple(start), problem.goal))
    keys = keys.copy()
    keys[0] = q_start
    trajectory = RoughTrajectory(gen.model, keys, k=problem.slope_k)
    return gen, trajectory, tuple(start), pairs


def start_configuration(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """``q_start`` checked (InvalidRequestError naming what is wrong): nq finite values, a base
    quaternion that is a rotation (normalized here: any non-zero length is accepted), every joint within
    its limits (:data:`JOINT_TOLERANCE_RAD`)."""
    q = np.asarray(q, float).reshape(-1)
    if q.shape != (robot.nq,) or not np.all(np.isfinite(q)):
        raise InvalidRequestError(
            f"q_start must have nq={robot.nq} finite values for {robot.name}, got shape {q.shape}",
            {"field": "q_start"},
        )
    norm = float(np.linalg.norm(q[3:7]))
    if norm < 1e-6:
        raise InvalidRequestError(
            f"q_start's base quaternion q[3:7] = {q[3:7].tolist()} is not a rotation (zero length)",
            {"field": "q_start"},
        )
    q = q.copy()
    if abs(norm - 1.0) > 1e-9:
        q[3:7] /= norm
    lower, upper = robot.model.lowerPositionLimit[7:], robot.model.upperPositionLimit[7:]
    outside = np.flatnonzero((q[7:] < lower - JOINT_TOLERANCE_RAD) | (q[7:] > upper + JOINT_TOLERANCE_RAD))
    if outside.size:
        i = int(outside[0])
        name = next(n for n in robot.joint_names if robot.joint_index(n).idx_q == 7 + i)
        raise InvalidRequestError(
            f"q_start puts {name} at {q[7 + i]:.3f} rad, outside its limits "
            f"[{lower[i]:.3f}, {upper[i]:.3f}] rad ({outside.size} joint(s) outside)",
            {"field": "q_start", "joint": name},
        )
    return q


def default_key_postures(
    robot: RobotModel, env: Environment, q_start: np.ndarray, start: ContactSet, goal: Goal
) -> list[np.ndarray]:
    """T's key postures (§2.7) when the request gives none, made from the layout: seated (a thigh on a
    seat), the chair scenario's (§3.1, Fig. 4; ``chair_egress.key_postures``, wherever the chair and
    the table are and whichever way the goal lies); standing on its soles alone, straight to standing
    past the goal, facing as at the start. Any other start: InvalidRequestError (give key_postures)."""
    if any(c.spot.endswith("_thigh") for c in start):
        return chair_egress.key_postures(robot, env, q_start, start, goal)
    if start and all(c.spot.endswith("_sole") and c.surface == "floor" for c in start):
        yaw = chair_egress.yaw_of_q(q_start)
        x, y = chair_egress.past_goal((float(q_start[0]), float(q_start[1])), goal)
        return [np.asarray(q_start, float), robot.half_sitting_at(x, y, yaw)]
    raise InvalidRequestError(
        "give key_postures (the rough trajectory T, §2.7): no default for a start that is neither seated "
        "(a thigh on a seat) nor standing on the soles",
        {"field": "key_postures"},
    )


def reachable(
    robot: RobotModel,
    env: Environment,
    goal: Goal,
    pairs: Sequence[tuple[str, str]],
    start_pairs: Sequence[tuple[str, str]],
) -> None:
    """Refuse before any search a goal no contact set can meet (InfeasibleError, ``details``: the
    reason and ``residual_m``): a final contact that is neither held at the start nor an allowed pair,
    or a goal coordinate farther than :data:`WAIST_REACH_M` (the waist over a stretched limb, with its
    lean) beyond every surface the final contacts (or, without them, the allowed pairs) may use."""
    allowed = set(pairs) | set(start_pairs)
    for pair in goal.final_pairs:
        if tuple(pair) not in allowed:
            raise InfeasibleError(
                f"the final contact {pair[0]} on {pair[1]} is neither held at the start nor an allowed pair: "
                "no contact set can match final_contacts",
                {"reason": msg.REASON_FINAL_CONTACT_NOT_ALLOWED, "pair": list(pair)},
            )
    names = {e for _, e in (goal.final_pairs or tuple(allowed))}
    i = "xyz".index(goal.axis)
    best = -math.inf  # the farthest the waist may go in the goal's sense [m]
    for surface in env.surfaces:
        if surface.name not in names:
            continue
        hx, hy = surface.half_size_m
        corners = [surface.placement(sx * hx, sy * hy, 0.0).translation for sx in (-1, 1) for sy in (-1, 1)]
        best = max(best, max(goal.sense * float(c[i]) for c in corners) + WAIST_REACH_M[goal.axis])
    residual = goal.sense * goal.value_m - best
    if residual > 0.0:
        raise InfeasibleError(
            f"the goal (waist {goal.axis} {'>=' if goal.sense > 0 else '<='} {goal.value_m} m) is out of "
            f"reach: {residual:.2f} m beyond where the waist can be over {sorted(names)}",
            {"reason": msg.REASON_GOAL_OUT_OF_REACH, "residual_m": residual, "surfaces": sorted(names)},
        )


def plan(robot: RobotModel, problem: PlanProblem, progress: ProgressHook | None = None) -> Plan:
    """Search and interpolate. Raises InfeasibleError (tree exhausted; details: best set reached and why),
    RequestTimeoutError (time or node budget spent, in the search or in the interpolation, whose time
    is the request's budget (:mod:`services.budget`) when one is open; details: the partial plan to the
    best node, ``status`` "reached" when the search had found the goal)."""
    try:
        gen, trajectory, start, pairs = build(robot, problem)
        budget.check("the set-up (scene, posture generator, key postures), before the search")
    except (RequestTimeoutError, InfeasibleError) as exc:  # the request's budget spent, or refused
        if isinstance(exc, RequestTimeoutError):  # before the search: no set yet
            exc.details.setdefault("reason", msg.NO_PATH_WITHIN_BUDGET)
        exc.details.setdefault("residual_m", problem.goal.residual_m(np.asarray(problem.q_start, float)))
        raise
    planner = ContactPlanner(gen, trajectory, problem.goal, pairs, problem.search, progress)
    result = planner.plan(start, trajectory.keys[0])  # q_start as checked (its quaternion normalized)
    if result.status != "reached":
        details = partial_details(result, problem.goal)
        where = (
            f"best set reached {[c.describe() for c in result.best.contacts]} at waist {problem.goal.axis} = "
            f"{result.best.q['xyz'.index(problem.goal.axis)]:.3f} m (goal {problem.goal.value_m} m, "
            f"residual {details['residual_m']:.3f} m)"
        )
        if result.status == "exhausted":
            raise InfeasibleError(
                f"no contact sequence reaches the goal: {result.message}; {where}",
                {**details, "reason": msg.REASON_TREE_EXHAUSTED},
            )
        raise RequestTimeoutError(
            f"{result.message} before reaching the goal ({result.nodes_generated} nodes generated, "
            f"{result.nodes_expanded} expanded); the partial plan's {where}",
            {**details, "reason": msg.NO_PATH_WITHIN_BUDGET},
        )
    motion = None
    if problem.interpolation is not None:
        try:
            motion = interpolate_plan(
                gen, [n.contacts for n in result.path], [n.q for n in result.path], problem.interpolation
            )
        except RequestTimeoutError as exc:  # the request's budget ran out after the search: the plan
            raise RequestTimeoutError(  # found is the partial result, without its motion
                f"the contact plan was found ({len(result.path)} sets) but not its motion: {exc.message}",
                {**exc.details, **partial_details(result, problem.goal)},
            ) from exc
    return Plan(result, motion, trajectory, gen.env)


def partial_details(result: SearchResult, goal: Goal) -> dict:
    """The partial plan of a failed search, for an error's details (JSON), with ``residual_m``: how far
    its last waist is from the goal's coordinate [m] (<= 0: exceeded, then the final contacts differ)
    and ``missing_pairs`` / ``extra_pairs``, the final contacts its last set lacks / has beyond them."""
    last = result.path[-1]
    have = {c.pair for c in last.contacts}
    final = {tuple(p) for p in goal.final_pairs}
    return {
        "residual_m": goal.residual_m(last.q),
        "missing_pairs": [list(p) for p in goal.final_pairs if tuple(p) not in have],
        "extra_pairs": [list(p) for p in sorted(have - final)] if final else [],
        "status": result.status,
        "sets": [[c.describe() for c in n.contacts] for n in result.path],
        "changes": [n.change for n in result.path],
        "witnesses": [n.q.tolist() for n in result.path],
        "nodes_generated": result.nodes_generated,
        "nodes_expanded": result.nodes_expanded,
        "plan_s": result.plan_s,
    }


def default_problem(robot: RobotModel, q_start: np.ndarray, **overrides: object) -> PlanProblem:
    """The chair scenario (§3.1) from ``q_start`` (seated)."""
    values: dict = dict(
        scene="chair_egress",
        q_start=np.asarray(q_start, float),
        start_pairs=chair_egress.START_PAIRS,
        goal=Goal(chair_egress.GOAL_AXIS, chair_egress.GOAL_VALUE_M, chair_egress.FINAL_PAIRS),
        pairs=chair_egress.PAIRS,
    )
    values.update(overrides)
    return PlanProblem(**values)


__all__: Sequence[str] = ("Plan", "PlanProblem", "build", "default_problem", "plan")
