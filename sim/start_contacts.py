"""Contacts the robot is already in when a motion starts: does the motion leave them or push into them?

After a collision stopped a motion, a hand (or a shank) may be left resting on the object it hit. Every
next motion starts in that contact; judged as a new one, it stops at the first control period (5 ms)
whatever the motion does, and the robot is stuck. The rule here (sim/README "Contacts at the start"):

* each unplanned (link, object) contact present when an execution starts is measured once: its contact
  points ``p`` on the link (world) and the contact normals ``n`` (from the object toward the link);
* the planned trajectory moves those points with their link; their displacement along the normal at
  sample ``k`` is ``d_k = (M T_k T^-1 p - p) . n`` [m], ``T_k`` the link's planned pose, ``T`` its
  measured one and ``M`` the rigid move of the planned base onto the measured base at the start
  (planned kinematics: position control follows the plan, and a contact force does not tell whether the
  link is meant to move away; a first sample commanded deeper than the link is counts as pushing);
* the contact is allowed while ``d_k >= -tolerance_m`` (the motion leaves it, slides along it or
  holds still on it) and reported as a collision as soon as ``d_k < -tolerance_m`` (the motion pushes
  further into the object than at the start);
* once the motion has moved the link away (``d_k > tolerance_m``) and the contact has broken, it is
  released: touching that object again with that link is a collision.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

# Indices in the tuples returned by pybullet.getContactPoints.
_LINK_A, _BODY_B, _POS_ON_A, _NORMAL_ON_B = 3, 2, 5, 7

Pair = tuple[int, int]  # (robot link index, other body id)


@dataclass
class StartContacts:
    """The contacts an execution started in (``away_m``: per (link, body) pair, the smallest planned
    displacement of its contact points along their normals at every trajectory sample [m], > 0 away
    from the object) and which of them the motion has left for good (``released``)."""

    away_m: dict[Pair, np.ndarray]
    tolerance_m: float
    released: set[Pair] = field(default_factory=set)

    @staticmethod
    def measure(
        robot: object,
        data: pin.Data,
        link_name: dict[int, str],
        contacts: Iterable[tuple],
        q_measured: np.ndarray,
        q_trajectory: np.ndarray,
        tolerance_m: float,
    ) -> StartContacts:
        """The start contacts of an execution of ``q_trajectory`` (N, nq) from the measured
        configuration ``q_measured`` (nq,), with the kinematics of the ``services.model`` ``robot``
        (``data``: its pinocchio data); ``contacts``: the unplanned contact points at the start
        (pybullet ``getContactPoints`` tuples, robot = body A). The planned motion is placed at the
        measured base pose (a rigid correction of the planned one), so that a first sample commanded
        deeper into the object than the link is (a robot told to hold a posture it was stopped short
        of) counts as pushing into it. A link pinocchio does not know is left out (its contact stays a
        collision)."""
        points: dict[Pair, list[tuple[np.ndarray, np.ndarray]]] = {}
        for c in contacts:
            key = (int(c[_LINK_A]), int(c[_BODY_B]))
            point = (np.asarray(c[_POS_ON_A], dtype=float), np.asarray(c[_NORMAL_ON_B], dtype=float))
            points.setdefault(key, []).append(point)
        model = robot.model  # type: ignore[attr-defined]
        frames: dict[int, int] = {}
        for link, _ in points:
            name = link_name.get(link, "")
            if name and model.existFrame(name):
                frames[link] = model.getFrameId(name)
        if not frames:
            return StartContacts({}, tolerance_m)
        q = np.asarray(q_trajectory, dtype=float)
        pin.forwardKinematics(model, data, np.asarray(q_measured, dtype=float))
        measured = {link: pin.SE3(pin.updateFramePlacement(model, data, fid)) for link, fid in frames.items()}
        root_measured = pin.SE3(data.oMi[1])
        poses: dict[int, list[pin.SE3]] = {link: [] for link in frames}
        for k in range(q.shape[0]):
            pin.forwardKinematics(model, data, q[k])
            if k == 0:  # the planned base onto the measured one
                correction = root_measured * pin.SE3(data.oMi[1]).inverse()
            for link, fid in frames.items():
                poses[link].append(correction * pin.SE3(pin.updateFramePlacement(model, data, fid)))
        away: dict[Pair, np.ndarray] = {}
        for (link, body), pts in points.items():
            if link not in frames:
                continue
            inverse = measured[link].inverse()
            d = np.full(q.shape[0], np.inf)
            for p, n in pts:
                local = inverse.act(p)
                d = np.minimum(d, np.array([float((T.act(local) - p) @ n) for T in poses[link]]))
            away[(link, body)] = d
        return StartContacts(away, tolerance_m)

    def allows(self, pair: Pair, sample: int) -> bool:
        """Whether the contact ``pair`` is allowed at trajectory sample ``sample`` (past the end: the
        last one, the hold): a start contact not released, not pushed into."""
        d = self.away_m.get(pair)
        if d is None or pair in self.released:
            return False
        return bool(d[min(sample, len(d) - 1)] >= -self.tolerance_m)

    def update(self, touching: Sequence[Pair] | set[Pair], sample: int) -> None:
        """Release the start contacts broken (not in ``touching``) after the motion moved away from them."""
        for pair, d in self.away_m.items():
            if pair not in touching and d[min(sample, len(d) - 1)] > self.tolerance_m:
                self.released.add(pair)
