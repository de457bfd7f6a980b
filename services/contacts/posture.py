"""The posture generator (§2.2 of Escande et al.): for a set of contacts, an optimization over the
robot's degrees of freedom with the contacts' point-and-frame matches, joint limits, self-collisions,
collisions with the environment and static stability, and an optional criterion (a reference posture,
or the potential f_T of §2.7-2.8).

It is solved as a prioritized IK on ``services.ik`` (hierarchical QP on proxsuite):

    level 0 (hard): joint limits
    level 1 "safety": capsules out of the scene's boxes, self-collision capsules, and the CoM inside
                      the static-equilibrium region of the contacts taking part in the stability
                      (Bretl-Lall projection, ``stability.py``)
    level 2 "contacts": each fixed contact's frame match (FramePoseTask on the spot frame) and, for
                      a new contact, the spot on the surface's plane inside the search volume C_i
                      (its x, y, theta left to the optimization, §2.6)
    level 3 "criterion": f_T (PotentialTask) or the distance to a reference posture

A posture is a success when levels 1 and 2 are met (values under ``tol``) and the force QP confirms
static equilibrium at the final CoM. Contacts kept as geometry only (a removed contact, §2.3, or the
new contact) are matched but do not enter the stability region.

Extension (not in the paper, which checks friction only; off by default): the force a spot of
``PostureConfig.limb_load_spots`` (the hands and forearms, ``posture_config(limb_load=True)``) may carry
is bounded by what its limb's joints hold in any posture (``limb_load.py``), in the equilibrium region
and the force QP alike.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.contacts.contact_tasks import InVolumeTask, OnPlaneTask
from services.contacts.defaults import LIMB_LOAD
from services.contacts.environment import Environment
from services.contacts.limb_load import GRAVITY_M_S2, force_cap_n
from services.contacts.robot_geometry import belongs_to, planner_capsules
from services.contacts.sets import Contact, ContactSet, contact_at, patch_of
from services.contacts.spots import ContactSpot, model_with_spots
from services.contacts.stability import ContactPatch, equilibrium_region, is_statically_stable
from services.contacts.volumes import SearchVolume
from services.errors import InfeasibleError
from services.ik import (
    ComSupportPolygonTask,
    FramePoseTask,
    HierarchicalSolver,
    Level,
    SelfCollisionTask,
    SolverConfig,
    Task,
)
from services.ik.tasks.capsule_box import CapsuleBoxTask, ObstacleBox
from services.model import RobotModel

ARM_SPOTS = ("left_hand", "right_hand", "left_forearm", "right_forearm")
GUIDE_WEIGHT = 100.0  # the guide level's task value against the criterion's in the best iterate's choice


@dataclass(frozen=True)
class PostureConfig:
    """Settings of the posture generator: ``com_margin_m`` inside the equilibrium region [m] (
    ``single_contact_margin_m`` when one contact holds the robot),
    ``collision_margin_m`` between capsules and boxes [m], ``self_margin_m`` between capsules [m],
    ``tol`` on levels 1-2 (m / rad), ``max_iters`` IK iterations per posture."""

    com_margin_m: float = 0.02
    # one support contact (a sole): the open-loop replay's sole slip is 3-6 cm (services/contacts/README.md)
    single_contact_margin_m: float = 0.04
    collision_margin_m: float = 0.015  # the capsules are not the sim's shapes: room for the difference
    self_margin_m: float = 0.005
    tol: float = 2e-3
    max_iters: int = 60
    # spots whose force is bounded by their limb's joint torques (limb_load.py; an extension of §2.2,
    # read when the generator is made: a per-call config does not change it)
    limb_load_spots: tuple[str, ...] = ARM_SPOTS if LIMB_LOAD else ()


@dataclass(frozen=True)
class Floating:
    """A new contact whose (x, y, theta) the posture generator chooses inside ``volume`` (§2.6)."""

    spot: str
    surface: str
    volume: SearchVolume


@dataclass(frozen=True)
class PostureResult:
    """Outcome of one posture generation: ``ok``, the witness posture ``q`` (also on failure: the last
    iterate), the new contact found (``floating`` requests), ``reason`` of a failure, IK iterations and
    wall time [s]."""

    ok: bool
    q: np.ndarray
    contact: Contact | None
    reason: str
    iterations: int
    wall_time_s: float


class PostureGenerator:
    """Posture generation for ``robot`` in ``env`` with the contact ``spots``."""

    def __init__(
        self,
        robot: RobotModel,
        env: Environment,
        spots: Sequence[ContactSpot],
        config: PostureConfig | None = None,
    ) -> None:
        self.robot = robot
        self.env = env
        self.spots = {s.name: s for s in spots}
        self.config = config or PostureConfig()
        self.model = model_with_spots(robot.model, spots)
        # Goldfarb-Idnani's dual active set (services/ik/active_set.py): the same optima as proxsuite's
        # working set to the feasibility tolerance, bitwise reproducible (proxsuite's results vary from
        # run to run at the 1e-15 level, which a closed-loop execution amplified into a replay that fell
        # in one run and held in the next), and about a quarter less CPU per posture generation here
        # (services/contacts/README.md, plan time)
        self.solver = HierarchicalSolver(
            self.model, robot.q_lower, robot.q_upper, config=SolverConfig(qp_method="dual_active_set")
        )
        self.data = self.model.createData()
        self.capsules = planner_capsules(robot)  # the model's capsules + the URDF's foot boxes
        self.boxes = tuple(ObstacleBox(b.name, b.T_world_box, b.half_extents_m) for b in env.boxes)
        self._box_owner = [b.owner for b in env.boxes]
        self.self_collision = SelfCollisionTask(
            self.model, self.capsules, robot.collision_pairs, margin_m=self.config.self_margin_m
        )
        self._regions: dict[ContactSet, np.ndarray] = {}
        self.calls = 0
        weight_n = robot.total_mass_kg * GRAVITY_M_S2
        # |force| a spot may carry, as a fraction of the robot's weight (limb_load.py)
        self.max_load = {
            name: force_cap_n(self.model, self.spots[name]) / weight_n
            for name in self.config.limb_load_spots
            if name in self.spots
        }

    def patches(self, stable: Sequence[Contact]) -> list[ContactPatch]:
        """The stability patches of the contacts ``stable`` (with their limbs' load bounds)."""
        return [
            patch_of(c, self.spots[c.spot], self.env, self.max_load.get(c.spot, math.inf)) for c in stable
        ]

    # ------------------------------------------------------------------------------------ pieces
    def region(self, stable: ContactSet) -> np.ndarray:
        """Static-equilibrium CoM polygon of the contacts ``stable`` (cached per set)."""
        key = tuple(sorted(stable))
        if key not in self._regions:
            self._regions[key] = equilibrium_region(self.patches(key))
        return self._regions[key]

    def stable_at(self, stable: ContactSet, com: np.ndarray) -> bool:
        """The force QP (proxsuite) at a CoM position."""
        return is_statically_stable(self.patches(stable), com)[0]

    def box_pairs(
        self, touching: Sequence[tuple[str, str]], moving: Sequence[tuple[str, str]] = ()
    ) -> list[tuple[int, int]]:
        """Every (capsule, box) pair but those of a spot's capsules with the object it touches
        (``touching``), or only with the box whose face the surface is (``moving``: a body coming to or
        leaving a surface must not pass through the rest of the object, e.g. under a table's top)."""
        excluded = set()
        for pairs, whole in ((touching, True), (moving, False)):
            for spot_name, surface_name in pairs:
                surface = self.env.surface(surface_name)
                for capsule in self.spots[spot_name].capsules:
                    for i, c in enumerate(self.capsules):
                        if not belongs_to(c.name, capsule):
                            continue
                        for j, box in enumerate(self.boxes):
                            if (self._box_owner[j] == surface.owner) if whole else (box.name == surface.box):
                                excluded.add((i, j))
        every = ((i, j) for i in range(len(self.capsules)) for j in range(len(self.boxes)))
        return [pair for pair in every if pair not in excluded]

    def contact_pose(self, contact: Contact) -> pin.SE3:
        return self.env.surface(contact.surface).placement(contact.x, contact.y, contact.theta)

    def spot_pose(self, q: np.ndarray, spot: str) -> pin.SE3:
        pin.framesForwardKinematics(self.model, self.data, q)
        return pin.SE3(self.data.oMf[self.model.getFrameId(self.spots[spot].frame_name)])

    def contact_tasks(self, geometric: ContactSet) -> list[Task]:
        return [
            FramePoseTask(
                self.model,
                self.spots[c.spot].frame_name,
                self.contact_pose(c),
                max_step=0.1,
                name=f"contact:{c.spot}",
            )
            for c in geometric
        ]

    # ------------------------------------------------------------------------------------ generate
    def generate(
        self,
        geometric: ContactSet,
        stable: ContactSet,
        q_init: np.ndarray,
        criterion: Task | None = None,
        floating: Floating | None = None,
        extra: Sequence[Task] = (),
        extra_touching: Sequence[tuple[str, str]] = (),
        guide: Sequence[Task] = (),
        config: PostureConfig | None = None,
    ) -> PostureResult:
        """A posture matching every contact of ``geometric`` (and the ``floating`` one inside its
        volume), statically stable on ``stable`` (a subset of ``geometric``), collision free, within
        joint limits, optimizing ``criterion`` from ``q_init``. ``extra`` tasks join the contacts'
        level (interpolation constraints C_i, §3.3); ``extra_touching`` lists the (spot, surface) pairs
        they bring in contact (excluded from the collision pairs); ``guide`` tasks form a level of their
        own between the contacts and the criterion, met as well as the levels above allow (the path of
        a moving body, §3.3). ``config`` overrides the generator's settings for this call."""
        start = time.perf_counter()
        self.calls += 1
        self.solver.reset()  # the QPs' warm starts within this generation only: it depends on its inputs
        cfg = config or self.config
        try:
            region = self.region(stable)
        except InfeasibleError as exc:
            return PostureResult(
                False,
                np.asarray(q_init, float),
                None,
                f"unstable contacts: {exc}",
                0,
                time.perf_counter() - start,
            )
        touching = [c.pair for c in geometric] + list(extra_touching)
        if floating is not None:
            touching.append((floating.spot, floating.surface))
        safety: list[Task] = [
            CapsuleBoxTask(
                self.model,
                self.capsules,
                self.boxes,
                self.box_pairs(touching),
                margin_m=cfg.collision_margin_m,
            ),
            self.self_collision,
        ]
        if region.shape[0] >= 3:
            margin = cfg.com_margin_m
            if len(stable) == 1:
                margin = max(margin, cfg.single_contact_margin_m)
            safety.append(
                ComSupportPolygonTask(self.model, margin, polygon_world_xy=region, all_edges=True)
            )
        contacts: list[Task] = self.contact_tasks(geometric) + list(extra)
        if floating is not None:
            surface = self.env.surface(floating.surface)
            frame = self.spots[floating.spot].frame_name
            contacts += [
                OnPlaneTask(self.model, frame, surface),
                InVolumeTask(self.model, frame, surface, floating.volume),
            ]
        levels = [Level(tuple(safety), name="safety"), Level(tuple(contacts), name="contacts")]
        if guide:
            levels.append(Level(tuple(guide), name="guide", tol=math.inf))
        if criterion is not None:
            # no error damping: f_T's task keeps a large value by design (the slope k t / 2)
            levels.append(Level((criterion,), name="criterion", tol=math.inf, error_damping=0.0))
        q, iterations, residual = self._optimize(levels, np.asarray(q_init, float), criterion, cfg)
        elapsed = time.perf_counter() - start
        safety_value, contact_value = residual
        if contact_value > cfg.tol:
            return PostureResult(
                False, q, None, f"contacts not matched (residual {contact_value:.3g})", iterations, elapsed
            )
        if safety_value > cfg.tol:
            return PostureResult(
                False,
                q,
                None,
                f"collision or CoM outside the equilibrium region (residual {safety_value:.3g})",
                iterations,
                elapsed,
            )
        com = pin.centerOfMass(self.model, self.data, q)
        if region.shape[0] < 3 or not self.stable_at(stable, com):
            return PostureResult(
                False,
                q,
                None,
                "the force QP finds no equilibrium at the final CoM",
                iterations,
                elapsed,
            )
        contact = None
        if floating is not None:
            contact = contact_at(
                self.spots[floating.spot], floating.surface, self.env, self.spot_pose(q, floating.spot)
            )
        return PostureResult(True, q, contact, "", iterations, elapsed)

    def _optimize(
        self, levels: list[Level], q: np.ndarray, criterion: Task | None, cfg: PostureConfig
    ) -> tuple[np.ndarray, int, tuple[float, float]]:
        """Prioritized IK steps from ``q``: first until the constraints (levels 1-2) are met, then on
        while the criterion still decreases; returns the best feasible iterate (lowest criterion), or
        the last one when none was feasible, with its (safety, contacts) residuals.

        (``services.ik.run`` stops once the required levels are met or when their task values stall;
        the criterion f_T's task value ||P (-) Q - k t / 2|| does not measure f_T's decrease, so the
        loop here watches f_T itself.)"""
        solver = self.solver
        bound = solver.bound_q_idx
        lower, upper = solver.q_lower[bound], solver.q_upper[bound]
        value = self._criterion_value(criterion, levels)
        best: tuple[float, np.ndarray, int, tuple[float, float]] | None = None
        last = (q, 0, (math.inf, math.inf))
        f_history: list[float] = []
        residual_history: list[float] = []
        for it in range(cfg.max_iters + 1):
            systems = solver.evaluate(levels, q)
            residual = (systems[0].value, systems[1].value)
            last = (q, it, residual)
            if max(residual) <= cfg.tol:
                f = value(q, systems)
                if best is None or f < best[0]:
                    best = (f, q, it, residual)
                f_history.append(f)
                # met, and the criterion no longer decreases (by 0.1 % over 5 iterations)
                if len(levels) == 2 or (len(f_history) > 5 and f_history[-6] - f < 1e-3 * max(1.0, abs(f))):
                    break
            else:
                # not met, and the constraints' residual no longer decreases (by 1 % over 6 iterations)
                residual_history.append(max(residual))
                if len(residual_history) > 6 and residual_history[-7] - residual_history[-1] < (
                    0.01 * residual_history[-7]
                ):
                    break
            if it == cfg.max_iters:
                break
            step = solver.solve_systems(levels, systems, q, 1.0)
            q = pin.integrate(self.model, q, step)
            q[bound] = q.take(bound).clip(lower, upper)
            if np.abs(step).max() < 1e-9:
                break
        if best is not None:
            return best[1], best[2], best[3]
        return last

    def _criterion_value(
        self, criterion: Task | None, levels: Sequence[Level]
    ) -> Callable[[np.ndarray, list], float]:
        """f_T for the potential task (eq. 1), else the task values of the guide and criterion levels,
        the guide's weighted by ``GUIDE_WEIGHT``: its priority holds in the choice of the best iterate
        too (with a plain sum, an iterate that follows the guide at the cost of the criterion lost to
        the start, and an interpolated body stayed where it was: the hand under the table's edge)."""
        trajectory = getattr(criterion, "trajectory", None)
        if trajectory is not None:
            return lambda q, systems: trajectory.value(q)
        weights = [GUIDE_WEIGHT if level.name == "guide" else 1.0 for level in levels[2:]]
        return lambda q, systems: sum(w * s.value for w, s in zip(weights, systems[2:], strict=True))


def posture_config(limb_load: bool = LIMB_LOAD) -> PostureConfig:
    """The default settings, with the arms' limb-load bound (``limb_load``) or without it (the paper's
    friction-only stability)."""
    return PostureConfig(limb_load_spots=ARM_SPOTS if limb_load else ())


def pairs_allowed(spots: Sequence[ContactSpot], surfaces: Sequence[str]) -> list[tuple[str, str]]:
    """Every (spot, surface) pair (§2.6's double loop)."""
    return [(s.name, e) for s in spots for e in surfaces]
