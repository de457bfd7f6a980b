"""Contact spots on the robot (§2.1 and §2.3 of Escande et al.): a point and a frame attached to a body
of the robot, with a convex (rectangular) contact patch.

The spot frame's z axis is the *inner* normal of the body's surface (pointing into the body), its x
axis a vector of the patch's plane (§2.1). A contact matches the spot frame with a frame of an
environment surface whose z axis is the surface's outer normal: the frames coincide.

The spots are added to a copy of the robot's pinocchio model as frames named ``spot_<name>`` (the
shared model of ``services.model`` is never mutated).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.model import RobotModel

# Rotation of a spot on the underside of a link hanging along its -z axis (thighs, forearms): the
# spot's z (inner normal) is the link's +x, its x runs along the link (-z of the link).
_UNDERSIDE = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
# A spot on the front of a shank (kneeling): inner normal -x of the link, x along the link.
_FRONT = np.array([[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class ContactSpot:
    """A contact spot: ``name``, the ``frame`` (a pinocchio frame or link) it is attached to, its
    placement in that frame (``xyz`` [m], rotation ``R`` columns = spot x, y, z), the patch's half
    sizes along the spot's x and y [m], and the robot capsules in contact with the surface when the spot
    is (excluded from collisions with the object it touches: a thigh on a seat also seats the waist)."""

    name: str
    frame: str
    xyz: tuple[float, float, float]
    R: tuple[tuple[float, float, float], ...]
    half_size_m: tuple[float, float]
    capsules: tuple[str, ...]

    @property
    def frame_name(self) -> str:
        return f"spot_{self.name}"

    @property
    def placement(self) -> pin.SE3:
        return pin.SE3(np.array(self.R, dtype=float), np.array(self.xyz, dtype=float))

    def corners_local(self) -> np.ndarray:
        """(4, 3) patch corners in the spot frame [m]."""
        hx, hy = self.half_size_m
        return np.array([[hx, hy, 0.0], [-hx, hy, 0.0], [-hx, -hy, 0.0], [hx, -hy, 0.0]])


def _spot(
    name: str,
    frame: str,
    xyz: tuple[float, float, float],
    R: np.ndarray,
    half: tuple[float, float],
    *capsules: str,
) -> ContactSpot:
    return ContactSpot(name, frame, xyz, tuple(tuple(float(v) for v in row) for row in R), half, capsules)


def hrp2_like_spots() -> tuple[ContactSpot, ...]:
    """The spots of the chair scenario (§3.1: feet, thighs, knees, forearms and hands) on hrp2_like."""
    eye = np.eye(3)  # soles: the sole frame; hands: the fist pointing down its link's -z, pushing up
    spots = []
    for side, s, leg, arm in (("left", "l", "LLEG", "LARM"), ("right", "r", "RLEG", "RARM")):
        spots += [
            _spot(f"{side}_sole", f"{side}_sole", (0.0, 0.0, 0.0), eye, (0.11, 0.06), f"{s}_foot"),
            _spot(
                f"{side}_thigh",
                f"{leg}_LINK2",
                (-0.065, 0.0, -0.08),  # on the URDF's thigh cylinder (radius 0.065 m)
                _UNDERSIDE,
                (0.10, 0.04),
                f"{s}_thigh",
                "waist",
            ),
            _spot(f"{side}_knee", f"{leg}_LINK3", (0.06, 0.0, -0.04), _FRONT, (0.03, 0.03), f"{s}_shank"),
            _spot(
                f"{side}_forearm",
                f"{arm}_LINK3",
                (-0.045, 0.0, -0.16),
                _UNDERSIDE,
                (0.04, 0.025),
                f"{s}_forearm",
            ),
            # the hand's lowest point: the fixed finger's tip, 0.185 m below the wrist (the URDF's
            # collision box; the hand capsule reaches 0.205 m and is excluded from what it touches)
            _spot(f"{side}_hand", f"{arm}_LINK5", (0.0, 0.0, -0.185), eye, (0.03, 0.03), f"{s}_hand"),
        ]
    return tuple(spots)


SPOTS = {"hrp2_like": hrp2_like_spots}


def robot_spots(robot: RobotModel) -> tuple[ContactSpot, ...]:
    """The contact spots of ``robot``; InvalidRequestError for a robot without spots."""
    if robot.name not in SPOTS:
        raise InvalidRequestError(
            f"robot {robot.name!r} has no contact spots; robots with spots: {sorted(SPOTS)}"
        )
    return SPOTS[robot.name]()


def select_spots(spots: Sequence[ContactSpot], names: Sequence[str] | None) -> tuple[ContactSpot, ...]:
    """The spots named in ``names`` (all when None); InvalidRequestError lists the valid names."""
    if names is None:
        return tuple(spots)
    by_name = {s.name: s for s in spots}
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise InvalidRequestError(f"unknown contact spots {unknown}; valid spots: {sorted(by_name)}")
    return tuple(by_name[n] for n in names)


def model_with_spots(model: pin.Model, spots: Sequence[ContactSpot]) -> pin.Model:
    """A copy of ``model`` with one frame per spot (``spot.frame_name``)."""
    out = pin.Model(model)
    for spot in spots:
        parent_frame = out.frames[out.getFrameId(spot.frame)]
        placement = parent_frame.placement * spot.placement
        out.addFrame(
            pin.Frame(
                spot.frame_name,
                parent_frame.parentJoint,
                out.getFrameId(spot.frame),
                placement,
                pin.FrameType.OP_FRAME,
            )
        )
    return out
