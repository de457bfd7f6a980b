"""Best-first search in the space of contact sets (§2.2-2.8 of Escande et al.).

The tree's nodes are sets of contacts with a witness posture; a son differs from its father by exactly
one contact (§2.2). At each iteration the best leaf according to the potential f_T (§2.7) is selected
and becomes a node; its sons are built by

* removing each of its contacts in turn: the removed contact stays as a geometric constraint but no
  longer takes part in the stability (the conservative rule of §2.3);
* adding a contact for each allowed pair (spot R, surface E) whose spot is free: the posture generator
  itself chooses (x, y, theta) inside a convex search volume C_i, with f_T as its criterion (§2.6,
  §2.8); the new contact does not take part in the stability either (§2.3). After a contact P is found,
  a volume V around P is subtracted and C_i \\ V cut into convex parts searched again (Fig. 1).

With ``best_first_sons`` (§2.8), each (node, pair) keeps a single leaf: the best son of the pair in
f_T order; the next one is generated only when that leaf is selected. Without it, every son of every
pair is generated at once (the paper's comparison: about four times more nodes).

New leaves too close to an existing node or leaf (same pairs, every contact within ``close_m`` and
``close_rad``) are discarded (§2.2).

Deviation from the paper, for speed on this machine: the search volume of a pair is C = E x ]-pi, pi]
intersected with a box of half size ``reach_m`` around the spot's current position and
``reach_theta_rad`` around its current heading (still convex, §2.6), and surfaces more than
``reach_z_m`` above or below the spot are not tried. C also keeps the spot ``edge_margin_m`` inside the
surface's edges, and a sole ``stance_width_m`` to its own side of the other one (``stance_pairs``).
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from services import budget
from services.contacts.posture import Floating, PostureGenerator
from services.contacts.potential import PotentialTask, RoughTrajectory
from services.contacts.sets import Contact, ContactSet, canonical, sets_close, turn_moving_corners_by
from services.contacts.volumes import SearchVolume, around, full_volume, subtract
from services.errors import InvalidRequestError
from services.model.ground import yaw_of


@dataclass(frozen=True)
class SearchConfig:
    """Settings of the search (§2.6-2.8); lengths [m], angles [rad], times [s]."""

    best_first_sons: bool = True
    max_nodes: int = 1000
    time_budget_s: float = 300.0  # wall clock
    # CPU time of this process (one core: the BLAS is single-threaded), None: no such bound. On a
    # loaded machine the wall clock measures the other processes too (scripts/bench contacts --cpu)
    cpu_budget_s: float | None = None
    reach_m: float = 0.6
    reach_theta_rad: float = 0.8
    reach_z_m: float = 0.7
    v_half: tuple[float, float, float] = (0.15, 0.15, 0.8)
    min_part: tuple[float, float, float] = (0.02, 0.02, 0.1)
    close_m: float = 0.08
    close_rad: float = 0.4
    max_sons_per_pair: int = 8
    # (left spot, right spot): a new one lands at least stance_width_m to its own side of the other
    stance_pairs: tuple[tuple[str, str], ...] = (("left_sole", "right_sole"),)
    stance_width_m: float = 0.10
    # a new contact's spot at least this far inside its surface's edges [m] (a hand planned 4 mm from
    # a table's corner bore nothing in the sim: its clipped patch was a sliver)
    edge_margin_m: float = 0.05
    # the angles of V and of "too close" at least the turn that moves the spot's patch corners by
    # half of v_half's / close_m's length: a small patch (a hand's 6 x 6 cm) turned is the same support
    patch_turns: bool = False


@dataclass(frozen=True)
class Goal:
    """The end condition: the waist (base) coordinate ``axis`` ('x', 'y' or 'z') at least ``value_m``
    (§3.1: "a coordinate the waist must exceed"; ``sense`` -1: at most ``value_m``, the other way), with
    exactly the contact pairs ``final_pairs`` (the robot standing; empty: any set)."""

    axis: str
    value_m: float
    final_pairs: tuple[tuple[str, str], ...] = ()
    sense: float = 1.0  # +1: exceed value_m upward; -1: downward

    def __post_init__(self) -> None:
        if self.axis not in ("x", "y", "z"):
            raise InvalidRequestError(f"goal axis must be 'x', 'y' or 'z', got {self.axis!r}")
        if self.sense not in (1.0, -1.0):
            raise InvalidRequestError(f"goal sense must be +1 or -1, got {self.sense!r}")

    def residual_m(self, q: np.ndarray) -> float:
        """How far the waist of ``q`` is from exceeding the goal's coordinate [m] (<= 0: exceeded)."""
        return self.sense * (self.value_m - float(q["xyz".index(self.axis)]))

    def reached(self, contacts: ContactSet, q: np.ndarray) -> bool:
        pairs_ok = not self.final_pairs or sorted(c.pair for c in contacts) == sorted(self.final_pairs)
        return self.residual_m(q) <= 0.0 and pairs_ok


@dataclass
class Node:
    """A node or leaf of the tree: its contact set, witness posture ``q``, f_T value, father, and
    what changed from the father (``+ contact`` / ``- contact``)."""

    index: int
    parent: int | None
    contacts: ContactSet
    q: np.ndarray
    f: float
    change: str
    depth: int
    expanded: bool = False


@dataclass
class _PairStream:
    """The sons of one node for one pair (R, E), in f_T order (§2.6, §2.8): volumes not yet searched
    and found candidates not yet emitted."""

    node: Node
    spot: str
    surface: str
    pending: list[SearchVolume]
    found: list[tuple[float, int, Contact, np.ndarray, SearchVolume]] = field(default_factory=list)
    emitted: int = 0


@dataclass
class SearchResult:
    """Outcome of a search: ``status`` ``reached`` / ``timeout`` / ``exhausted`` / ``max_nodes``, the
    path (root to the goal, or to the best node reached) as nodes, counters and time."""

    status: str
    path: list[Node]
    nodes_generated: int
    nodes_expanded: int
    posture_generations: int
    plan_s: float
    best: Node
    message: str
    plan_cpu_s: float = 0.0  # CPU time of the process during the search [s]


ProgressHook = Callable[[str, Node, int, int, float], None]


class ContactPlanner:
    """Best-first contact planner over ``generator`` (posture generator) toward ``goal``, guided by f_T
    of ``trajectory``, with the allowed ``pairs`` (spot, surface)."""

    def __init__(
        self,
        generator: PostureGenerator,
        trajectory: RoughTrajectory,
        goal: Goal,
        pairs: Sequence[tuple[str, str]],
        config: SearchConfig | None = None,
        progress: ProgressHook | None = None,
    ) -> None:
        self.gen = generator
        self.trajectory = trajectory
        self.goal = goal
        self.pairs = list(pairs)
        self.config = config or SearchConfig()
        self.progress = progress
        self.criterion = PotentialTask(trajectory)
        self.nodes: list[Node] = []
        self._by_pairs: dict[tuple[tuple[str, str], ...], list[Node]] = {}  # nodes by their pairs
        self._heap: list[tuple[float, int, int, int, _PairStream | None]] = []
        self._seq = itertools.count()
        self._deadline = math.inf
        self._cpu_deadline = math.inf
        cfg = self.config
        spots = generator.spots.values() if cfg.patch_turns else ()
        # per spot: V's half angle and the "too close" angle (SearchConfig.patch_turns)
        self._v_rad = {
            s.name: max(cfg.v_half[2], turn_moving_corners_by(s, 0.5 * cfg.v_half[0])) for s in spots
        }
        self._close_rad = {
            s.name: max(cfg.close_rad, turn_moving_corners_by(s, 0.5 * cfg.close_m)) for s in spots
        }

    # -------------------------------------------------------------------------------- helpers
    def _too_close(self, contacts: ContactSet) -> bool:
        """Some node or leaf has the same pairs with every contact close (only those can be close)."""
        cfg = self.config
        same_pairs = self._by_pairs.get(tuple(c.pair for c in contacts), ())
        return any(
            sets_close(contacts, n.contacts, cfg.close_m, cfg.close_rad, self._close_rad) for n in same_pairs
        )

    def _add(
        self,
        parent: Node | None,
        contacts: ContactSet,
        q: np.ndarray,
        change: str,
        stream: _PairStream | None = None,
    ) -> Node | None:
        contacts = canonical(contacts)
        if parent is not None and self._too_close(contacts):
            return None
        node = Node(
            len(self.nodes),
            None if parent is None else parent.index,
            contacts,
            q,
            self.trajectory.value(q),
            change,
            0 if parent is None else parent.depth + 1,
        )
        self.nodes.append(node)
        self._by_pairs.setdefault(tuple(c.pair for c in contacts), []).append(node)
        heapq.heappush(self._heap, (node.f, -node.depth, next(self._seq), node.index, stream))
        return node

    def _timed_out(self) -> str:
        """Why the search must stop for time ("" if it need not): its own share of the budget
        (``config.time_budget_s``) or the whole request's (:mod:`services.budget`, issue 16)."""
        if time.perf_counter() > self._deadline:
            return f"the search's time budget of {self.config.time_budget_s:.3g} s spent"
        if self._cpu_deadline < math.inf and time.process_time() > self._cpu_deadline:
            return f"the search's CPU budget of {self.config.cpu_budget_s:.3g} s spent"
        if budget.expired():
            request = budget.current()
            assert request is not None
            return f"the request's time budget of {request.budget_s:.3g} s spent"
        return ""

    def _out_of_time(self) -> bool:
        return bool(self._timed_out()) or len(self.nodes) >= self.config.max_nodes

    def _volume(self, node: Node, spot: str, surface_name: str) -> SearchVolume | None:
        """C of the pair, limited to the spot's reach (see the module docstring)."""
        cfg = self.config
        surface = self.gen.env.surface(surface_name)
        T_spot = self.gen.spot_pose(node.q, spot)
        local = surface.T_world_surface.actInv(T_spot)
        if abs(local.translation[2]) > cfg.reach_z_m:
            return None
        x, y = float(local.translation[0]), float(local.translation[1])
        heading = yaw_of(local.rotation)
        full = full_volume(*(max(h - cfg.edge_margin_m, 0.0) for h in surface.half_size_m))
        reach = SearchVolume(
            (x - cfg.reach_m, y - cfg.reach_m, heading - cfg.reach_theta_rad),
            (x + cfg.reach_m, y + cfg.reach_m, heading + cfg.reach_theta_rad),
        )
        xy = full.intersect(
            SearchVolume(
                (reach.lower[0], reach.lower[1], -math.inf), (reach.upper[0], reach.upper[1], math.inf)
            )
        )
        if xy is None:
            return None
        xy = self._stance_side(node, spot, surface_name, xy)
        if xy is None:
            return None
        return SearchVolume(
            (xy.lower[0], xy.lower[1], reach.lower[2]), (xy.upper[0], xy.upper[1], reach.upper[2])
        )

    def _stance_side(
        self, node: Node, spot: str, surface_name: str, volume: SearchVolume
    ) -> SearchVolume | None:
        """``volume`` cut to the side of the spot's partner (``stance_pairs``) when the partner is on the
        same surface: a left sole at least ``stance_width_m`` at +y (the surface's frame) of the right
        one, a right sole as much at -y of the left one (a convex restriction of C, §2.6). Without it
        the search crossed the feet (a right sole ahead of the left one and 1 cm to its left): the
        weight transfer onto it was a tandem stance, and the next step had no way out between the
        stance leg and the chair's leg (services/contacts/README.md)."""
        width = self.config.stance_width_m
        for left, right in self.config.stance_pairs:
            if spot not in (left, right):
                continue
            partner = right if spot == left else left
            other = next((c for c in node.contacts if c.spot == partner and c.surface == surface_name), None)
            if other is None:
                continue
            if spot == left:
                side = SearchVolume((-math.inf, other.y + width, -math.inf), (math.inf, math.inf, math.inf))
            else:
                side = SearchVolume((-math.inf, -math.inf, -math.inf), (math.inf, other.y - width, math.inf))
            return volume.intersect(side)
        return volume

    # -------------------------------------------------------------------------------- sons
    def _removal_sons(self, node: Node) -> None:
        """§2.3: every contact removed in turn (kept as geometry, out of the stability)."""
        if len(node.contacts) < 2:
            return
        for contact in node.contacts:
            if self._out_of_time():
                return
            rest = tuple(c for c in node.contacts if c != contact)
            result = self.gen.generate(node.contacts, rest, node.q, self.criterion)
            if result.ok:
                self._add(node, rest, result.q, f"- {contact.describe()}")

    def _advance(self, stream: _PairStream) -> None:
        """Emit the pair's next son in f_T order (§2.8): search the pending volumes (best contact of
        each, §2.6), then emit the best found; its volume minus V goes back to the pending ones."""
        cfg = self.config
        node = stream.node
        while not self._out_of_time():
            while stream.pending and not self._out_of_time():
                volume = stream.pending.pop()
                result = self.gen.generate(
                    node.contacts,
                    node.contacts,
                    node.q,
                    self.criterion,
                    Floating(stream.spot, stream.surface, volume),
                )
                if result.ok and result.contact is not None:
                    f = self.trajectory.value(result.q)
                    heapq.heappush(stream.found, (f, next(self._seq), result.contact, result.q, volume))
            if not stream.found or stream.emitted >= cfg.max_sons_per_pair:
                return
            _, _, contact, q, volume = heapq.heappop(stream.found)
            point = (contact.x, contact.y, _unwrap(contact.theta, volume))
            v_half = (cfg.v_half[0], cfg.v_half[1], self._v_rad.get(stream.spot, cfg.v_half[2]))
            stream.pending.extend(subtract(volume, around(point, v_half), cfg.min_part))
            son = self._add(
                node,
                (*node.contacts, contact),
                q,
                f"+ {contact.describe()}",
                stream if cfg.best_first_sons else None,
            )
            if son is not None:
                stream.emitted += 1
                if cfg.best_first_sons:
                    return  # one leaf per pair (§2.8)

    def _addition_sons(self, node: Node) -> None:
        busy = {c.spot for c in node.contacts}
        for spot, surface in self.pairs:
            if spot in busy or self._out_of_time():
                continue
            volume = self._volume(node, spot, surface)
            if volume is None:
                continue
            self._advance(_PairStream(node, spot, surface, [volume]))

    # -------------------------------------------------------------------------------- search
    def plan(self, start: ContactSet, q_start: np.ndarray) -> SearchResult:
        """Search from the start set (its witness ``q_start``) until the goal, the budget or the
        tree's exhaustion."""
        cfg = self.config
        t0, cpu0 = time.perf_counter(), time.process_time()
        self._deadline = t0 + cfg.time_budget_s
        if cfg.cpu_budget_s is not None:
            self._cpu_deadline = cpu0 + cfg.cpu_budget_s
        root = self._add(None, start, np.asarray(q_start, float), "start")
        assert root is not None
        expanded = 0
        status, message = "exhausted", "every leaf was expanded without reaching the goal"
        goal_node: Node | None = None
        while self._heap:
            spent = self._timed_out()
            if spent or len(self.nodes) >= cfg.max_nodes:
                top = self.nodes[self._heap[0][3]]
                if not self.goal.reached(top.contacts, top.q):  # else the best leaf is the goal: take it
                    status, message = (
                        ("timeout", spent) if spent else ("max_nodes", f"{cfg.max_nodes} nodes generated")
                    )
                    break
            _, _, _, index, stream = heapq.heappop(self._heap)
            node = self.nodes[index]
            node.expanded = True
            expanded += 1
            if self.progress is not None:
                self.progress("expand", node, len(self.nodes), expanded, time.perf_counter() - t0)
            if self.goal.reached(node.contacts, node.q):
                status, message, goal_node = "reached", "goal reached", node
                break
            if stream is not None:  # §2.8: the pair's next son replaces the selected leaf
                self._advance(stream)
            self._removal_sons(node)
            self._addition_sons(node)
        # the best set reached; the root when the budget or max_nodes ended the search before its
        # first expansion (a budget spent by the root's own posture generation, max_nodes 1)
        expanded_nodes = [n for n in self.nodes if n.expanded] or [root]
        best = goal_node or min(expanded_nodes, key=lambda n: n.f)
        return SearchResult(
            status,
            self.path_to(best),
            len(self.nodes) - 1,
            expanded,
            self.gen.calls,
            time.perf_counter() - t0,
            best,
            message,
            time.process_time() - cpu0,
        )

    def path_to(self, node: Node) -> list[Node]:
        path = [node]
        while path[-1].parent is not None:
            path.append(self.nodes[path[-1].parent])
        return path[::-1]


def _unwrap(theta: float, volume: SearchVolume) -> float:
    """theta moved by multiples of 2 pi next to the volume's middle (volumes may straddle +-pi)."""
    mid = 0.5 * (volume.lower[2] + volume.upper[2])
    return mid + (theta - mid + math.pi) % (2.0 * math.pi) - math.pi
