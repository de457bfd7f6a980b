"""Contacts and sets of contacts (§2.1-2.3 of Escande et al.).

A contact matches a robot spot's frame with a frame of an environment surface (§2.1): the pair
(spot, surface) plus the three parameters (x, y, theta) on the surface (§2.5). A set of contacts is
the node of the search (§2.2); all its contacts take part in the stability.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.contacts.environment import Environment
from services.contacts.spots import ContactSpot
from services.contacts.stability import ContactPatch
from services.errors import InfeasibleError


@dataclass(frozen=True, order=True)
class Contact:
    """A fixed contact: spot name, surface name, and (x [m], y [m], theta [rad]) in the surface frame."""

    spot: str
    surface: str
    x: float
    y: float
    theta: float

    @property
    def pair(self) -> tuple[str, str]:
        return (self.spot, self.surface)

    def close_to(self, other: Contact, tol_m: float, tol_rad: float) -> bool:
        """Same pair and within ``tol_m`` / ``tol_rad`` of each other (sons too close to a node, §2.2)."""
        if self.pair != other.pair:
            return False
        dtheta = abs((self.theta - other.theta + math.pi) % (2.0 * math.pi) - math.pi)
        return math.hypot(self.x - other.x, self.y - other.y) <= tol_m and dtheta <= tol_rad

    def describe(self) -> str:
        return f"{self.spot}@{self.surface}({self.x:+.2f},{self.y:+.2f},{math.degrees(self.theta):+.0f}deg)"


ContactSet = tuple[Contact, ...]


def canonical(contacts: ContactSet | list[Contact]) -> ContactSet:
    """Contacts sorted by (spot, surface): one representation per set."""
    return tuple(sorted(contacts))


def sets_close(
    a: ContactSet, b: ContactSet, tol_m: float, tol_rad: float, tol_rad_of: dict[str, float] | None = None
) -> bool:
    """Two sets are too close when they have the same pairs and each contact is close to its
    counterpart (§2.2: such a new leaf is discarded); ``tol_rad_of``: a spot's own angle tolerance
    (default ``tol_rad``)."""
    if len(a) != len(b):
        return False
    tols = tol_rad_of or {}
    pairs = zip(canonical(a), canonical(b), strict=True)
    return all(x.close_to(y, tol_m, tols.get(x.spot, tol_rad)) for x, y in pairs)


def turn_moving_corners_by(spot: ContactSpot, distance_m: float) -> float:
    """The rotation about the patch's centre [rad] that moves its farthest corner by ``distance_m``
    (a chord): pi when no rotation does (a small patch, e.g. a hand's, turned is the same support)."""
    radius = math.hypot(*spot.half_size_m)
    return math.pi if distance_m >= 2.0 * radius else 2.0 * math.asin(distance_m / (2.0 * radius))


def clip_to_rectangle(polygon: np.ndarray, hx: float, hy: float) -> np.ndarray:
    """The part of a convex polygon (k x 2, in order) inside the rectangle [-hx, hx] x [-hy, hy]
    (Sutherland-Hodgman); (0, 2) if none."""
    out = np.asarray(polygon, float)
    for axis, bound, sign in ((0, hx, 1.0), (0, -hx, -1.0), (1, hy, 1.0), (1, -hy, -1.0)):
        if out.shape[0] == 0:
            break
        kept = []
        for i in range(out.shape[0]):
            a, b = out[i], out[(i + 1) % out.shape[0]]
            a_in, b_in = sign * (a[axis] - bound) <= 0.0, sign * (b[axis] - bound) <= 0.0
            if a_in:
                kept.append(a)
            if a_in != b_in:
                t = (bound - a[axis]) / (b[axis] - a[axis])
                kept.append(a + t * (b - a))
        out = np.array(kept).reshape(-1, 2)
    return out


def patch_of(
    contact: Contact, spot: ContactSpot, env: Environment, max_load: float = math.inf
) -> ContactPatch:
    """The stability patch of a contact: the spot's rectangle placed on the surface, clipped to the
    surface's rectangle (a thigh on a seat bears only up to the seat's front edge), in the world;
    ``max_load`` bounds its force as a fraction of the robot's weight (``limb_load.py``; none by
    default). Raises InfeasibleError when the patch lies off the surface."""
    surface = env.surface(contact.surface)
    c, s = math.cos(contact.theta), math.sin(contact.theta)
    R = np.array([[c, -s], [s, c]])
    local = spot.corners_local()[:, :2].dot(R.T) + np.array([contact.x, contact.y])  # surface frame
    clipped = clip_to_rectangle(local, *surface.half_size_m)
    if clipped.shape[0] < 3:
        raise InfeasibleError(f"the patch of {contact.describe()} lies off the surface {surface.name}")
    corners = np.column_stack([clipped, np.zeros(len(clipped))])
    world = corners.dot(surface.T_world_surface.rotation.T) + surface.T_world_surface.translation
    return ContactPatch(world, surface.T_world_surface.rotation[:, 2].copy(), surface.friction, max_load)


def contact_at(spot: ContactSpot, surface_name: str, env: Environment, T_world_spot: pin.SE3) -> Contact:
    """The contact a spot frame at ``T_world_spot`` makes with a surface (its (x, y, theta) there)."""
    x, y, theta = env.surface(surface_name).coordinates(T_world_spot)
    return Contact(spot.name, surface_name, x, y, theta)


def spot_surface_gap(T_world_spot: pin.SE3, env: Environment, surface_name: str) -> tuple[float, float, bool]:
    """(height of the spot above the surface's plane [m], tilt between the normals [rad], whether the
    spot's origin projects inside the surface's rectangle)."""
    surface = env.surface(surface_name)
    local = surface.T_world_surface.actInv(T_world_spot)
    tilt = math.acos(float(np.clip(local.rotation[2, 2], -1.0, 1.0)))
    hx, hy = surface.half_size_m
    inside = abs(local.translation[0]) <= hx and abs(local.translation[1]) <= hy
    return float(local.translation[2]), tilt, inside
