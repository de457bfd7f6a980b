"""The robot's collision geometry for the posture generator (§2.2 of Escande et al.: collisions with the
environment): the model's capsules (``services.model``), plus capsules covering the URDF's collision
boxes of the feet, the shapes pybullet simulates.

The model's foot capsule (one segment along the sole, 4.5 cm radius) is 2.5 cm narrower than the URDF's
foot box (0.24 x 0.14 x 0.035 m): plans certified clear on it put the heels into the chair's front legs
in the sim. The boxes are read from the URDF through pinocchio (``RobotModel.build_geometry_model``),
the same file pybullet loads, so the planner and the sim share one description.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from services.model import RobotModel
from services.model.specs import Capsule

BOX_LINK_SUFFIX = "LEG_LINK5"  # the links whose URDF boxes are covered (the feet)


def box_capsules(name: str, frame: str, T_frame_box: pin.SE3, half: np.ndarray) -> list[Capsule]:
    """Capsules covering a box (``half`` extents [m] in its frame ``T_frame_box``, expressed in the
    robot frame ``frame``): radius the smallest half extent, segments along the longest axis, spread
    across the middle one at most one radius apart (the box's outer faces are reached, its edges rounded
    by the radius)."""
    order = np.argsort(half)
    thin, middle, long_ = (int(i) for i in order)
    r = float(half[thin])
    span = float(half[middle]) - r
    count = max(1, math.ceil(span / r) + 1) if span > 1e-9 else 1
    out = []
    for k in range(count):
        offset = -span + 2.0 * span * k / (count - 1) if count > 1 else 0.0
        ends = []
        for sign in (-1.0, 1.0):
            local = np.zeros(3)
            local[long_] = sign * (float(half[long_]) - r)
            local[middle] = offset
            ends.append(tuple(float(v) for v in T_frame_box.act(local)))
        out.append(Capsule(f"{name}.box{k}", frame, ends[0], ends[1], r))
    return out


def planner_capsules(robot: RobotModel) -> tuple[Capsule, ...]:
    """The model's capsules and, after each capsule on a foot link (``*LEG_LINK5``), the capsules of that
    link's URDF collision boxes, named ``<capsule>.box<k>`` (they follow the capsule's collision rules:
    :func:`belongs_to`)."""
    geometry = robot.build_geometry_model("collision")
    model = robot.model
    boxes: dict[str, list[tuple[pin.SE3, np.ndarray]]] = {}
    for obj in geometry.geometryObjects:
        frame = model.frames[obj.parentFrame]
        half = getattr(obj.geometry, "halfSide", None)
        if half is None or not frame.name.endswith(BOX_LINK_SUFFIX):
            continue
        # geometry placements are in the parent joint's frame; capsules are in the link's frame
        boxes.setdefault(frame.name, []).append((frame.placement.actInv(obj.placement), np.array(half)))
    out: list[Capsule] = []
    for capsule in robot.capsules:
        out.append(capsule)
        for T, half in boxes.pop(capsule.frame, []):
            out += box_capsules(capsule.name, capsule.frame, T, half)
    return tuple(out)


def belongs_to(capsule_name: str, name: str) -> bool:
    """True if ``capsule_name`` is the capsule ``name`` or one of its box capsules."""
    return capsule_name == name or capsule_name.startswith(f"{name}.box")
