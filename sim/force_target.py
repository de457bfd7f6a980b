"""The force target of a limb in contact (:mod:`sim.compliance`'s input): plain data, no pybullet, so that
a planner can make one (``services.contacts.contact_forces``) without loading the simulator."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ForceTarget:
    """A limb whose contact force follows a plan: its ``joints`` (names, the tip first: the joint whose
    link and the links under it touch), the scene object it touches (``other``), the surface's unit
    ``normal`` (world, out of the object) and the planned normal force ``force_n`` [N] at every
    trajectory sample (N values); ``point_m``: where the limb touches, in its tip joint's frame [m]
    (the offset moves that point along the normal)."""

    joints: tuple[str, ...]
    other: str
    normal: tuple[float, float, float]
    force_n: np.ndarray
    point_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the contact point in the tip joint's frame
