"""Which robot-scene contacts are planned, and which are collisions.

Planned contacts:

* a sole (foot link) on the floor;
* a hand (gripper links) on an object it holds, or on an object named in ``allowed`` (the grasp target,
  a table the hand puts something on);
* an object held by the robot touching a hand, an ``allowed`` object, or an object it already touched
  when the motion started (lifting it off its support);
* any link on an object the motion is ``leaving`` (backing out of a collision), until that contact
  first breaks: touching it again later is a collision;
* any link on a ``supports`` object (a multi-contact motion's supports: the chair the robot gets up
  from, the table it leans on; the contact planner chose where);
* any link on an object it already touched when the motion started, while the planned motion does not
  push it further into that object (:mod:`sim.start_contacts`: a hand left resting on a box after a
  stop may move off it; a motion pressing on into it still stops).

Every other contact between the robot (or an object it holds) and the scene is a collision. Contacts
among scene objects (a ball resting on a box) are never reported. Self-contacts of the robot are not
simulated (planners check self-collision on the capsule model).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import pybullet as p

from sim.start_contacts import StartContacts

# Indices in the tuples returned by pybullet.getContactPoints.
_BODY_A, _BODY_B, _LINK_A, _LINK_B, _POS_ON_A, _DISTANCE, _NORMAL_FORCE = 1, 2, 3, 4, 5, 8, 9


@dataclass(frozen=True)
class Contact:
    """A contact between the robot side (``robot_link``: a link name or ``held:<object>``) and ``other``
    (an object name or ``floor``) at ``position`` [m] (world) with ``normal_force_n`` [N]."""

    robot_link: str
    other: str
    position: tuple[float, float, float]
    normal_force_n: float


@dataclass
class ContactRules:
    """Everything needed to tell planned contacts from collisions (pybullet ids)."""

    client: int
    robot_id: int
    floor_id: int
    names: dict[int, str]  # body id -> object name (scene objects)
    link_name: dict[int, str]  # robot link index -> link name
    foot_links: frozenset[int]
    hand_links: frozenset[int]
    held: dict[str, int] = field(default_factory=dict)  # held object name -> body id
    allowed: frozenset[str] = frozenset()
    already_touching: frozenset[tuple[str, str]] = frozenset()  # (held object, other) at motion start
    min_force_n: float = 0.05
    leaving: set[str] = field(default_factory=set)  # objects still touched since the start (shrinks)
    supports: frozenset[str] = frozenset()  # objects any link may touch (multi-contact supports)
    start: StartContacts | None = None  # the contacts the motion started in (None: none)

    def other_name(self, body: int) -> str:
        return "floor" if body == self.floor_id else self.names.get(body, f"body{body}")

    def robot_contact_points(self, points: Sequence[tuple] | None = None) -> list[tuple]:
        """The robot-scene contact points now (pybullet ``getContactPoints`` tuples, robot = body A) of
        at least ``min_force_n``, a sole on the floor left out (always planned); ``points``: the
        robot's contact points now, as ``pybullet.getContactPoints(bodyA=robot)`` returns them, else
        queried here."""
        if points is None:
            points = p.getContactPoints(bodyA=self.robot_id, physicsClientId=self.client)
        floor, feet = self.floor_id, self.foot_links
        return [
            c
            for c in points
            if c[_BODY_B] != self.robot_id
            and c[_NORMAL_FORCE] >= self.min_force_n
            and not (c[_BODY_B] == floor and c[_LINK_A] in feet)
        ]

    def pushing_force(self, points: Sequence[tuple] | None = None) -> float:
        """Total normal force [N] of the contacts on the robot other than its soles on the floor and its
        hands on the objects they hold (``points``: as :meth:`robot_contact_points`)."""
        held = set(self.held.values())
        return float(
            sum(c[_NORMAL_FORCE] for c in self.robot_contact_points(points) if c[_BODY_B] not in held)
        )

    def robot_contacts(
        self, points: Sequence[tuple] | None = None
    ) -> list[tuple[int, int, tuple[float, float, float], float]]:
        """(robot link, other body, position, normal force) of every current robot-scene contact
        (:meth:`robot_contact_points`)."""
        return [
            (c[_LINK_A], c[_BODY_B], c[_POS_ON_A], c[_NORMAL_FORCE])
            for c in self.robot_contact_points(points)
        ]

    def held_contacts(self) -> list[tuple[str, int, tuple[float, float, float], float]]:
        """(held object, other body, position, normal force) of contacts of held objects with the scene."""
        held_ids = set(self.held.values())
        out = []
        for name, body in self.held.items():
            for c in p.getContactPoints(bodyA=body, physicsClientId=self.client):
                other = c[_BODY_B]
                if other == self.robot_id or other in held_ids or c[_NORMAL_FORCE] < self.min_force_n:
                    continue
                out.append((name, other, c[_POS_ON_A], c[_NORMAL_FORCE]))
        return out

    def touching_pairs(self) -> frozenset[tuple[str, str]]:
        """(held object, other) pairs in contact now (recorded when a motion starts)."""
        return frozenset((name, self.other_name(other)) for name, other, _, _ in self.held_contacts())

    def collisions(self, points: Sequence[tuple] | None = None, sample: int = 0) -> list[Contact]:
        """Unplanned contacts now, one per (robot link or held object, other) pair (strongest point);
        ``points``: as :meth:`robot_contacts`; ``sample``: the trajectory sample commanded now (for the
        contacts the motion started in, :attr:`start`)."""
        found: dict[tuple[str, str], Contact] = {}
        held_names = {body: name for name, body in self.held.items()}
        contacts = self.robot_contacts(points)
        if self.leaving:
            self.leaving &= {self.other_name(other) for _, other, _, _ in contacts}  # broken: no longer
        start = self.start
        if start is not None:
            start.update({(link, other) for link, other, _, _ in contacts}, sample)
        for link, other, pos, force in contacts:
            other_name = self.other_name(other)
            if other_name in self.leaving or other_name in self.supports:
                continue
            if link in self.hand_links and (other in held_names or other_name in self.allowed):
                continue
            if start is not None and start.allows((link, other), sample):
                continue
            _keep(found, Contact(self.link_name.get(link, f"link{link}"), other_name, tuple(pos), force))
        for name, other, pos, force in self.held_contacts():
            other_name = self.other_name(other)
            if other_name in self.allowed or (name, other_name) in self.already_touching:
                continue
            _keep(found, Contact(f"held:{name}", other_name, tuple(pos), force))
        return list(found.values())


def _keep(found: dict[tuple[str, str], Contact], contact: Contact) -> None:
    key = (contact.robot_link, contact.other)
    if key not in found or found[key].normal_force_n < contact.normal_force_n:
        found[key] = contact


def floor_force(
    client: int, robot_id: int, floor_id: int, links: Iterable[int], points: Sequence[tuple] | None = None
) -> dict[int, float]:
    """Total normal force [N] of the floor on each of ``links`` (``points``: the robot's contact points
    now, as ``pybullet.getContactPoints(bodyA=robot_id)`` returns them, else queried here)."""
    forces = dict.fromkeys(links, 0.0)
    if points is None:
        points = p.getContactPoints(bodyA=robot_id, bodyB=floor_id, physicsClientId=client)
    for c in points:
        if c[_BODY_B] == floor_id and c[_LINK_A] in forces:
            forces[c[_LINK_A]] += c[_NORMAL_FORCE]
    return forces
