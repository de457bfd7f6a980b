"""Messages of the ``contacts`` service: contact-before-motion planning (Escande et al., "Planning support
contact-points for acyclic motions", ``004_1528a6467056ab4d.txt``).

Configurations follow the pinocchio layout of the service's robot model: ``q = [x, y, z, qx, qy, qz, qw,
joints...]`` (base position [m] and orientation in the world, then joint positions). World frame: z up,
ground at z = 0. A contact is a (spot, surface) pair with (x, y, theta) in the surface's frame (§2.5).
"""

from __future__ import annotations

from typing import Annotated

import msgspec
import numpy as np
from msgspec import Meta

from services.bus.limits import Angle, Coord, Gain, Name, NameLists, Names, SceneName
from services.bus.schemas.navigation import REASON_NO_PATH_WITHIN_BUDGET
from services.bus.spec import EndpointSpec, TopicSpec

#: ``details["reason"]`` of ``contacts/plan``'s failures (with ``residual_m``, how far the best waist
#: reached is from the goal's coordinate, and the partial plan when there is one):
#: the time or node budget was spent before the goal (code ``timeout``: the search stopped on its own)
NO_PATH_WITHIN_BUDGET = REASON_NO_PATH_WITHIN_BUDGET
#: every leaf was expanded without reaching the goal (code ``infeasible``)
REASON_TREE_EXHAUSTED = "tree_exhausted"
#: the goal's coordinate lies beyond where the final contacts' surfaces let the waist be (``infeasible``,
#: before any search)
REASON_GOAL_OUT_OF_REACH = "goal_out_of_reach"
#: a final contact is neither held at the start nor an allowed pair: no set can match (``infeasible``)
REASON_FINAL_CONTACT_NOT_ALLOWED = "final_contact_not_allowed"


class ContactMsg(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A contact: the robot's ``spot`` (e.g. ``left_sole``) on the environment ``surface`` (e.g.
    ``chair.seat``) at (``x``, ``y`` [m], ``theta`` [rad]) in the surface's frame (origin at its centre)."""

    spot: Name
    surface: Name
    x: Coord
    y: Coord
    theta: Angle


class PlanRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Plan from ``q_start`` (the robot's measured configuration) with the ``start_contacts`` holding there
    (pairs [spot, surface]) until the waist coordinate ``goal_axis`` exceeds ``goal_value_m`` (falls below
    it with ``goal_below``) with exactly the contacts ``final_contacts`` (empty: any). ``key_postures``
    (k x nq) define the rough trajectory T (§2.7); None: made from the layout when the robot starts
    seated (a thigh on a seat: the chair scenario's T, ``chair_egress.key_postures``) or standing on
    its soles (T straight to past the goal); otherwise ``invalid_request``."""

    scene: SceneName  # a scene of sim/scenes (its surfaces and obstacles are read from the scene file)
    q_start: np.ndarray  # (nq,) float64
    start_contacts: NameLists  # [[spot, surface], ...] in contact at q_start
    goal_axis: Name = "y"  # "x", "y" or "z"
    goal_value_m: Coord = 0.75
    goal_below: bool = False  # the waist coordinate must fall below goal_value_m (not exceed it)
    final_contacts: NameLists = msgspec.field(
        default_factory=lambda: [["left_sole", "floor"], ["right_sole", "floor"]]
    )
    key_postures: np.ndarray | None = None  # (k, nq) float64
    # the whole request (search + interpolation) [s]
    time_budget_s: Annotated[float, Meta(gt=0.0, le=600.0)] = 300.0
    max_nodes: Annotated[int, Meta(ge=1, le=100_000)] = 1000  # nodes generated
    spots: Names | None = None  # allowed contact spots (None: all of the robot's)
    surfaces: Names | None = None  # allowed surfaces (None: all of the scene's)
    pairs: NameLists | None = None  # allowed [spot, surface] pairs (overrides spots x surfaces)
    best_first_sons: bool = True  # §2.8: one leaf per (spot, surface) pair, sons in f_T order
    slope_k: Gain = 15.0  # k of f_T (eq. 1); 15 with the limb-load bound ends standing (README)
    interpolate: bool = True  # compute the 5 ms motion (§3.3)
    # the arms' contact forces bounded by what their joints hold (an extension of §2.2; false: friction
    # only, the paper's): on by default, the plans the sim's arms can hold (services/contacts/README.md)
    limb_load: bool = True
    n_interpolation: Annotated[int, Meta(ge=1, le=1000)] = 20  # posture generations per transition (§3.3's n)


class PlanReply(msgspec.Struct, kw_only=True, frozen=True):
    """The contact sets with their witness postures, and the statically stable motion (send ``q`` to
    ``sim/execute``)."""

    model: str
    joint_names: list[str]
    sets: list[list[ContactMsg]]  # the sequence of contact sets, start first
    changes: list[str]  # what changed into each set ("start", "+ contact", "- contact")
    witnesses: np.ndarray  # (S, nq) witness postures of the sets
    f_values: list[float]  # f_T of each witness (eq. 1)
    progress: list[float]  # s' of each witness along T [m-rad]
    dt_s: float  # sample period of q [s]
    q: np.ndarray  # (N, nq) the interpolated motion (empty (0, nq) if not asked)
    set_samples: list[int]  # index in q of each set's witness
    nodes_generated: int
    nodes_expanded: int
    posture_generations: int
    plan_s: float  # search wall time [s]
    interpolation_s: float  # interpolation wall time [s]


ContactList = Annotated[list[ContactMsg], Meta(max_length=32)]


class TransitionRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """One transition of a plan re-planned from the robot's measured configuration ``q_measured``
    (executing set by set): the contacts of ``from_set`` are re-read where their spots are at
    ``q_measured``, the witness of ``to_set`` (a son of ``from_set``: one contact more or less, §2.3) is
    generated again for them near ``witness`` (its planned posture), and the motion to it interpolated
    (§3.3). ``released``: the contacts removed at the previous transition, still touched at
    ``q_measured`` (their bodies leave now). ``time_budget_s`` bounds the whole request: past it the
    reply is ``timeout`` naming the step reached (issue 16)."""

    scene: SceneName
    q_measured: np.ndarray  # (nq,) float64
    from_set: ContactList  # the planned contacts holding at q_measured
    to_set: ContactList  # the next planned set
    witness: np.ndarray  # (nq,) the planned witness of to_set
    released: ContactList = msgspec.field(default_factory=list)
    n_interpolation: Annotated[int, Meta(ge=2, le=100)] = 10  # bounded work: <= 7 tries of 2n postures
    # the whole request (witness regeneration, interpolation, its re-planning and collision checks) [s]
    time_budget_s: Annotated[float, Meta(gt=0.0, le=600.0)] = 60.0
    limb_load: bool = True  # as in PlanRequest: the arms' contact forces bounded by their joints


class TransitionReply(msgspec.Struct, kw_only=True, frozen=True):
    """The motion of one transition from the measured configuration (send ``q`` to ``sim/execute``)."""

    dt_s: float
    q: np.ndarray  # (N, nq) samples every dt_s, the first at q_measured
    witness: np.ndarray  # (nq,) the regenerated witness (the last sample)
    support_error_m: float  # largest distance between a held contact's measured and planned place
    # played anyway: a segment still colliding after local re-planning, or the planned witness used
    # because none was found for the supports where they slid ("" if nothing)
    collision: str
    replan_s: float  # wall time [s]
    # joint name -> fraction of its effort limit to play q with (sim/execute's effort_scale): the arm of
    # a hand or forearm in contact, compliant in the loop it closes (services/contacts/closed_loop.py)
    effort_scale: dict[str, float] = {}


class Progress(msgspec.Struct, kw_only=True, frozen=True):
    """A node selected for expansion during a search (published on ``contacts/progress``)."""

    request_id: str  # the scene and start of the plan it belongs to
    depth: int
    change: str
    contacts: list[str]  # described contacts of the node's set
    f: float
    base_xyz: list[float]  # the witness's waist position [m]
    nodes_generated: int
    nodes_expanded: int
    elapsed_s: float


PLAN = EndpointSpec(
    "contacts",
    "plan",
    PlanRequest,
    PlanReply,
    "contact-before-motion plan (best-first search over contact sets) and its statically stable motion",
)
TRANSITION = EndpointSpec(
    "contacts",
    "transition",
    TransitionRequest,
    TransitionReply,
    "one transition of a plan re-planned from the measured configuration (executing set by set)",
)
PROGRESS = TopicSpec("contacts", "progress", Progress, "nodes expanded by a running contacts/plan")
