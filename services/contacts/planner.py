"""One contact-before-motion planning request end to end (the service's algorithm, no bus): the scene's
environment, the posture generator, the rough trajectory's potential, the best-first search over
contact sets (§2), then the interpolated, statically stable motion (§3.3)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from services import budget
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
    q_start = np.asarray(problem.q_start, float).reshape(-1)
    if q_start.shape != (robot.nq,) or not np.all(np.isfinite(q_start)):
        raise InvalidRequestError(
            f"q_start must have nq={robot.nq} finite values for {robot.name}, got shape {q_start.shape}"
        )
    env = environment_of(layout(load_scene(problem.scene)))
    all_spots = robot_spots(robot)
    surfaces = [s.name for s in env.select(problem.surfaces)]
    if problem.pairs is not None:
        pairs = [(str(a), str(b)) for a, b in problem.pairs]
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
                f"unknown surface {surface!r}; surfaces of {problem.scene}: {sorted(known_surfaces)}"
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
    elif load_scene(problem.scene).name == "chair_egress":
        keys = np.array(chair_egress.key_postures(robot, env, q_start))
    else:
        raise InvalidRequestError(
            "give key_postures (the rough trajectory T, §2.7): no default for this scene"
        )
    keys = keys.copy()
    keys[0] = q_start
    trajectory = RoughTrajectory(gen.model, keys, k=problem.slope_k)
    return gen, trajectory, tuple(start), pairs


def plan(robot: RobotModel, problem: PlanProblem, progress: ProgressHook | None = None) -> Plan:
    """Search and interpolate. Raises InfeasibleError (tree exhausted; details: best set reached and why),
    RequestTimeoutError (time or node budget spent, in the search or in the interpolation, whose time
    is the request's budget (:mod:`services.budget`) when one is open; details: the partial plan to the
    best node, ``status`` "reached" when the search had found the goal)."""
    gen, trajectory, start, pairs = build(robot, problem)
    budget.check("the set-up (scene, posture generator, key postures), before the search")
    planner = ContactPlanner(gen, trajectory, problem.goal, pairs, problem.search, progress)
    result = planner.plan(start, problem.q_start)
    if result.status != "reached":
        details = partial_details(result)
        if result.status == "exhausted":
            raise InfeasibleError(
                f"no contact sequence reaches the goal: {result.message}; best set reached "
                f"{[c.describe() for c in result.best.contacts]} at waist {problem.goal.axis} = "
                f"{result.best.q['xyz'.index(problem.goal.axis)]:.3f} m (goal {problem.goal.value_m} m)",
                details,
            )
        raise RequestTimeoutError(
            f"{result.message} before reaching the goal ({result.nodes_generated} nodes generated, "
            f"{result.nodes_expanded} expanded); the partial plan reaches waist {problem.goal.axis} = "
            f"{result.best.q['xyz'.index(problem.goal.axis)]:.3f} m (goal {problem.goal.value_m} m)",
            details,
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
                {**exc.details, **partial_details(result)},
            ) from exc
    return Plan(result, motion, trajectory, gen.env)


def partial_details(result: SearchResult) -> dict:
    """The partial plan of a failed search, for an error's details (JSON)."""
    return {
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
