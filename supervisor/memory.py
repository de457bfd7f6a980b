"""What the supervisor believes about the world: objects as perception last localized them.

Only perception writes here (never the sim's ground truth): each entry is a ``perception/locate``
reply, with the sim time it was made at. The robot's own pose comes from its proprioception
(``sim/state``) when needed, so nothing about the robot is stored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from services.bus.schemas.perception import FootprintMsg
from services.errors import NotFoundError

#: A sighting without a footprint inherits the last one when it lies this close to it [m].
KEEP_FOOTPRINT_MARGIN_M = 0.25
#: Two footprints of one object disagree when their centres are farther apart than this [m] or a side
#: differs by more than ``DISAGREE_SIZE_M`` [m]; the one less of whose outline was hidden is kept when
#: the other's hidden fraction is larger by more than ``HIDDEN_SLACK``.
DISAGREE_CENTRE_M = 0.1
DISAGREE_SIZE_M = 0.15
HIDDEN_SLACK = 0.05


@dataclass(frozen=True)
class Sighting:
    """An object seen by perception.

    position_m: world position of its reference point (centre of a ball, middle of the visible
    silhouette of a box or table) [m]; size_m: (width, height) of its image box at its depth [m];
    distance_m: from the camera [m]; confidence in [0, 1]; sim_time_s: when [s]; camera_m: world
    position of the camera that saw it [m]; footprint: its floor rectangle from stereo (perception's
    ``footprint``; None for a ball or when its outline did not match).
    """

    name: str
    position_m: np.ndarray
    size_m: tuple[float, float]
    distance_m: float
    confidence: float
    sim_time_s: float
    camera_m: np.ndarray
    footprint: FootprintMsg | None = None

    def describe(self) -> str:
        x, y, z = self.position_m
        text = f"{self.name} at ({x:.2f}, {y:.2f}, {z:.2f}) m, {self.distance_m:.2f} m away"
        fp = self.footprint
        if fp is not None:
            text += (
                f" (floor rectangle {fp.size[0]:.2f} x {fp.size[1]:.2f} m at ({fp.center[0]:.2f}, "
                f"{fp.center[1]:.2f}), yaw {math.degrees(fp.yaw):.0f} deg)"
            )
        return text


def hidden_fraction(fp: FootprintMsg) -> float:
    """The fraction of a footprint's outline edges left out next to an occluder (not seen)."""
    return fp.n_hidden / max(1, fp.n_points + fp.n_hidden)


def disagree(a: FootprintMsg, b: FootprintMsg) -> bool:
    """Whether two footprints of one object place it differently (``DISAGREE_CENTRE_M``,
    ``DISAGREE_SIZE_M``)."""
    centre = float(np.linalg.norm(np.subtract(a.center, b.center)))
    sides = np.abs(np.sort(a.size) - np.sort(b.size))
    return centre > DISAGREE_CENTRE_M or bool((sides > DISAGREE_SIZE_M).any())


@dataclass
class Memory:
    """Latest sighting per object name, and what each hand holds (from grasp/open outcomes)."""

    sightings: dict[str, Sighting] = field(default_factory=dict)
    holding: dict[str, str] = field(default_factory=dict)  # side -> object
    #: World points [m] where a hand touched something perception does not know (no model of it: a
    #: ball beside the one to grasp): felt, not seen; the next approach keeps the fingers off them.
    felt: list[np.ndarray] = field(default_factory=list)
    #: Objects a hand (or what it held) touched on its way above them turned as in footsteps/plan's
    #: final posture (that orientation swept the forearm into them): their next approaches are
    #: position only.
    posture_touched: set[str] = field(default_factory=set)
    #: The sighting of each object a hand was last lowered onto (localized from near, just before): the
    #: reference for where the points a hand felt there lie from it.
    aimed: dict[str, Sighting] = field(default_factory=dict)

    def clear(self) -> None:
        """Forget everything (a new scene)."""
        self.sightings.clear()
        self.holding.clear()
        self.felt.clear()
        self.posture_touched.clear()
        self.aimed.clear()

    def remember(self, sighting: Sighting) -> Sighting:
        """Keep ``sighting`` as the latest of its object; what is kept. Seen without a footprint (cut by
        the image border: close up, or half out of view), it keeps the last footprint of the object
        when its position lies within that rectangle grown by ``KEEP_FOOTPRINT_MARGIN_M``: objects stay
        where they are unless seen elsewhere. Seen with a footprint that disagrees with the last one
        (:func:`disagree`), the better-supported of the two is kept (:func:`hidden_fraction`: a view
        from close up with the robot's arm and the held object in front of the table hides part of
        its outline; the rectangle fitted to the rest is the less sure one)."""
        last = self.sightings.get(sighting.name)
        if last is not None and last.footprint is not None:
            new, old = sighting.footprint, last.footprint
            if new is None:
                keep = old.rectangle.grown(KEEP_FOOTPRINT_MARGIN_M).contains(sighting.position_m[:2])
            else:
                keep = disagree(new, old) and hidden_fraction(new) > hidden_fraction(old) + HIDDEN_SLACK
            if keep:
                sighting = replace(sighting, footprint=last.footprint)
        self.sightings[sighting.name] = sighting
        return sighting

    def drop_footprint(self, name: str) -> None:
        """Forget the floor rectangle of ``name`` (a measurement proved it wrong: an object lowered
        inside it touched nothing); its next sightings without one do not inherit it either."""
        sighting = self.sightings.get(name)
        if sighting is not None and sighting.footprint is not None:
            self.sightings[name] = replace(sighting, footprint=None)

    def forget(self, name: str) -> None:
        self.sightings.pop(name, None)

    def get(self, name: str) -> Sighting:
        """The last sighting of ``name``; NotFoundError saying to localize it first."""
        sighting = self.sightings.get(name)
        if sighting is None:
            known = ", ".join(sorted(self.sightings)) or "none yet"
            raise NotFoundError(
                f"where {name} is is not known: localize it first (`localize {name}`); "
                f"located so far: {known}",
                {"object": name, "reason": "not_localized"},
            )
        return sighting
