"""The ``contacts`` service: contact-before-motion planning on the bus (Escande et al.).

Run: ``python -m services.contacts.service [--model hrp2_like]`` (plus the common service options:
``--config``, ``--robot``, ``--hub``, ``--log-level``).

Endpoint ``contacts/plan`` (:mod:`services.bus.schemas.contacts`): a stateless planner (the reply is a
function of the request). Endpoint ``contacts/transition``: one transition of a plan re-planned from
the measured configuration (executing set by set, ``closed_loop.py``), within its own
``time_budget_s`` (``timeout`` naming the step reached: the witness's regeneration or the
interpolation's posture, re-planning try or collision check). Every node selected during the
search is published on ``contacts/progress``.
Scenes are named (``sim/scenes``, then the config's ``scene_dirs``: the layouts the sim simulates).
Failure codes: ``invalid_request`` (unknown scene, spot, surface or goal axis, ``q_start`` not a
configuration within the joint limits, a start that is not a feasible set: a contact that does not hold
at ``q_start``, a spot twice, the robot not statically balanced on them; ``details.field``),
``infeasible`` (``details.reason``: ``final_contact_not_allowed`` or ``goal_out_of_reach`` before any
search, ``tree_exhausted`` after it, with the best set reached; or an interpolation step that failed),
``timeout`` (``details.reason`` ``no_path_within_budget``: the time or node budget was spent; the
partial plan: sets, changes, witnesses); every refusal of a goal carries ``residual_m``. ``time_budget_s``
bounds the whole request (set-up, search, interpolation with its re-planning and collision checks):
the reply comes within it plus the longest step between two checks (one posture generation).
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass, replace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small dense problems: threads only add overhead

import numpy as np

from services import budget
from services.bus.schemas import contacts as msg
from services.bus.service import Service, handles, run_service
from services.contacts.closed_loop import execution_generator, replan_transition
from services.contacts.environment import environment_of
from services.contacts.interpolate import InterpolationConfig
from services.contacts.planner import Plan, PlanProblem, plan
from services.contacts.posture import PostureGenerator
from services.contacts.search import Goal, Node, SearchConfig
from services.contacts.sets import Contact, ContactSet
from services.errors import InvalidRequestError
from services.model import RobotModel, load_robot
from services.model.options import add_model_argument, with_model
from sim.scene import find_scene, layout, load_scene

SEARCH_SHARE = 0.7  # of the request's time budget for the search; the rest for the interpolation


@dataclass(frozen=True)
class ContactsConfig:
    """Options of the service: the robot model (only ``hrp2_like`` has contact spots) and more folders
    of scene files ``<name>.yaml`` a request may name (after ``sim/scenes``; the same as the sim's
    ``scene_dirs``, so that the planner sees the layouts the sim simulates)."""

    model: str = "hrp2_like"
    scene_dirs: tuple[str, ...] = ()


class ContactsService(Service):
    """Contact-before-motion planning (stateless planner)."""

    name = "contacts"
    Config = ContactsConfig

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        add_model_argument(parser)
        parser.add_argument(
            "--scene-dir",
            action="append",
            default=[],
            help="a folder of more scenes <name>.yaml that requests may name (repeatable)",
        )

    @classmethod
    def configure(cls, config: ContactsConfig, args: argparse.Namespace) -> ContactsConfig:
        if args.scene_dir:
            config = replace(config, scene_dirs=(*config.scene_dirs, *args.scene_dir))
        return with_model(config, args.model)

    def _scene(self, name: str) -> str:
        """The file of the scene a request names (``sim/scenes``, then ``scene_dirs``; not_found)."""
        return str(find_scene(name, self.config.scene_dirs))

    def start(self) -> None:
        self.robot = load_robot(self.config.model)
        self._generators: dict[tuple[str, bool], PostureGenerator] = {}
        self._progress = self.publisher(msg.PROGRESS)
        self.log.info("contacts planner ready for %s", self.robot.name)

    @handles(msg.PLAN)
    def plan(self, request: msg.PlanRequest) -> msg.PlanReply:
        """The plan of ``request`` within its ``time_budget_s`` (the whole request: set-up, search,
        interpolation, its re-planning and collision checks; issue 16)."""
        with budget.within(request.time_budget_s):
            return self._plan(request)

    def _plan(self, request: msg.PlanRequest) -> msg.PlanReply:
        problem = replace(to_problem(request), scene=self._scene(request.scene))
        request_id = f"{request.scene}@{time.time():.3f}"

        def progress(kind: str, node: Node, generated: int, expanded: int, elapsed: float) -> None:
            self._progress.put(
                msg.Progress(
                    request_id=request_id,
                    depth=node.depth,
                    change=node.change,
                    contacts=[c.describe() for c in node.contacts],
                    f=float(node.f),
                    base_xyz=[float(v) for v in node.q[:3]],
                    nodes_generated=generated,
                    nodes_expanded=expanded,
                    elapsed_s=elapsed,
                )
            )

        return to_reply(plan(self.robot, problem, progress), self.robot)

    @handles(msg.TRANSITION)
    def transition(self, request: msg.TransitionRequest) -> msg.TransitionReply:
        """One transition re-planned from the measured configuration (``closed_loop``) within its
        ``time_budget_s`` (the whole request: the witness regenerated, the interpolation with its
        re-planning and collision checks; issue 16)."""
        with budget.within(request.time_budget_s):
            return self._transition(request)

    def _transition(self, request: msg.TransitionRequest) -> msg.TransitionReply:
        t0 = time.perf_counter()
        gen = self._generator(request.scene, request.limb_load)
        budget.check("the transition's set-up (the scene's posture generator)")
        nq = self.robot.nq
        q = np.asarray(request.q_measured, float).reshape(-1)
        witness = np.asarray(request.witness, float).reshape(-1)
        for name, value in (("q_measured", q), ("witness", witness)):
            if value.shape != (nq,) or not np.all(np.isfinite(value)):
                raise InvalidRequestError(f"{name} must have nq={nq} finite values, got shape {value.shape}")
        sets = [to_contacts(gen, m) for m in (request.from_set, request.to_set, request.released)]
        config = replace(InterpolationConfig(), n=request.n_interpolation)
        step = replan_transition(gen, sets[0], sets[1], witness, q, sets[2], config)
        return msg.TransitionReply(
            dt_s=step.dt_s,
            q=np.ascontiguousarray(step.q),
            witness=np.ascontiguousarray(step.witness),
            support_error_m=step.support_error_m,
            collision=step.collision,
            replan_s=time.perf_counter() - t0,
            effort_scale=step.effort_scale,
        )

    def _generator(self, scene: str, limb_load: bool) -> PostureGenerator:
        """The posture generator of a scene's transitions (``closed_loop.execution_generator``: every
        contact spot of the robot, the arms' limb-load bound on or off, reproducible; cached)."""
        key = (scene, limb_load)
        if key not in self._generators:
            env = environment_of(layout(load_scene(self._scene(scene))))
            self._generators[key] = execution_generator(self.robot, env, limb_load)
        return self._generators[key]


def to_contacts(gen: PostureGenerator, contacts: list[msg.ContactMsg]) -> ContactSet:
    """Contacts of messages, their spots and surfaces checked (InvalidRequestError names the bad one)."""
    out = []
    for c in contacts:
        if c.spot not in gen.spots:
            raise InvalidRequestError(f"unknown contact spot {c.spot!r}; spots: {sorted(gen.spots)}")
        gen.env.surface(c.surface)  # raises InvalidRequestError with the valid names
        out.append(Contact(c.spot, c.surface, c.x, c.y, c.theta))
    return tuple(out)


def to_problem(request: msg.PlanRequest) -> PlanProblem:
    """The planner's problem of a request (validated)."""
    if not request.time_budget_s > 0.0:
        raise InvalidRequestError(f"time_budget_s must be positive, got {request.time_budget_s}")
    if request.max_nodes < 1:
        raise InvalidRequestError(f"max_nodes must be >= 1, got {request.max_nodes}")
    if request.n_interpolation < 2:
        raise InvalidRequestError(f"n_interpolation must be >= 2, got {request.n_interpolation}")
    for name, pairs in (
        ("start_contacts", request.start_contacts),
        ("final_contacts", request.final_contacts),
        ("pairs", request.pairs or []),
    ):
        if any(len(p) != 2 for p in pairs):
            raise InvalidRequestError(f"{name} must be a list of [spot, surface] pairs, got {pairs}")
    search = SearchConfig(
        best_first_sons=request.best_first_sons,
        max_nodes=request.max_nodes,
        time_budget_s=SEARCH_SHARE * request.time_budget_s if request.interpolate else request.time_budget_s,
    )
    interpolation = (
        replace(InterpolationConfig(), n=request.n_interpolation)
        if request.interpolate
        else None
    )
    keys = None if request.key_postures is None else np.asarray(request.key_postures, float)
    return PlanProblem(
        scene=request.scene,
        q_start=np.asarray(request.q_start, float).reshape(-1),
        start_pairs=tuple((a, b) for a, b in request.start_contacts),
        goal=Goal(
            request.goal_axis,
            request.goal_value_m,
            tuple((a, b) for a, b in request.final_contacts),
            -1.0 if request.goal_below else 1.0,
        ),
        key_postures=keys,
        spots=None if request.spots is None else tuple(request.spots),
        surfaces=None if request.surfaces is None else tuple(request.surfaces),
        pairs=None if request.pairs is None else tuple((a, b) for a, b in request.pairs),
        slope_k=request.slope_k,
        search=search,
        interpolation=interpolation,
        limb_load=request.limb_load,
    )


def to_reply(result: Plan, robot: RobotModel) -> msg.PlanReply:
    """The bus message of a plan."""
    path = result.search.path
    motion = result.motion
    return msg.PlanReply(
        model=robot.name,
        joint_names=list(robot.joint_names),
        sets=[
            [msg.ContactMsg(spot=c.spot, surface=c.surface, x=c.x, y=c.y, theta=c.theta) for c in n.contacts]
            for n in path
        ],
        changes=[n.change for n in path],
        witnesses=np.ascontiguousarray(result.witnesses),
        f_values=[float(n.f) for n in path],
        progress=[float(result.trajectory.progress(n.q)) for n in path],
        dt_s=motion.dt_s if motion else 0.005,
        q=np.ascontiguousarray(motion.q if motion else np.zeros((0, robot.nq))),
        set_samples=list(motion.set_samples) if motion else [],
        nodes_generated=result.search.nodes_generated,
        nodes_expanded=result.search.nodes_expanded,
        posture_generations=result.search.posture_generations,
        plan_s=result.search.plan_s,
        interpolation_s=motion.interpolation_s if motion else 0.0,
    )


if __name__ == "__main__":
    raise SystemExit(run_service(ContactsService))
