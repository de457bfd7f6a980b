"""The hands kept above the floor: an inequality of the footstep IK and of its final reaching motion
(the form of eqs. (12)-(13) of the footstep paper with the ground as the other body,
:class:`services.ik.tasks.ground_clearance.GroundClearanceTask`).

Section 4.2's reach puts the grasp point on an object lying on the floor. The paper's constraints
(§3.2: joint limits, static equilibrium, self-collision, feet flat) say nothing of the ground under
the hand, so the planned crouch put the gripper's links ~5 cm into the floor and the execution in the
simulator stopped on that contact. The points kept above the floor are the corners of the bounding
boxes of the collision shapes that the URDF (the file pybullet simulates) attaches to each hand: the
links of the grasp frame's joint and of the joints below it (the wrist and the fingers).
"""

from __future__ import annotations

import threading

import numpy as np
import pinocchio as pin

from services.ik.tasks.ground_clearance import GroundClearanceTask
from services.model import RobotModel

# Rows for the corners closer than this to the clearance [m]: more than a planner iteration moves a hand
# (the reach's rate is saturated at 0.1 m per IK time, alpha 0.7), so that no corner skips past the
# rows' activation into the floor in one iteration.
HAND_FLOOR_ACTIVATION_M = 0.1
_CORNER_SIGNS = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
_points: dict[int, tuple[RobotModel, tuple[tuple[str, tuple[float, float, float]], ...]]] = {}
_points_lock = threading.Lock()


def hand_points(robot: RobotModel) -> tuple[tuple[str, tuple[float, float, float]], ...]:
    """(frame name, corner in that frame [m]) of the bounding box of every collision shape of both
    hands (cached per robot: reading the URDF's geometry takes a few milliseconds)."""
    with _points_lock:
        hit = _points.get(id(robot))
        if hit is not None and hit[0] is robot:
            return hit[1]
    model = robot.model
    hand_joints: set[int] = set()
    for side in ("left", "right"):
        joint = model.frames[model.getFrameId(robot.frames.grasp(side))].parentJoint
        hand_joints.update(int(j) for j in model.subtrees[joint])
    geometry = robot.build_geometry_model("collision")
    out: list[tuple[str, tuple[float, float, float]]] = []
    for obj in geometry.geometryObjects:
        if obj.parentJoint not in hand_joints:
            continue
        frame = model.frames[obj.parentFrame]
        shape = obj.geometry
        shape.computeLocalAABB()
        lo, hi = np.array(shape.aabb_local.min_), np.array(shape.aabb_local.max_)
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        # the shape's placement is in its parent joint's frame; the points are in the link's frame
        T_frame_shape = frame.placement.actInv(obj.placement)
        for corner in centre + _CORNER_SIGNS * half:
            out.append((frame.name, tuple(float(v) for v in T_frame_shape.act(corner))))
    points = tuple(out)
    with _points_lock:
        _points[id(robot)] = (robot, points)  # (the robot is kept: its id stays unique)
    return points


def hand_floor_task(
    robot: RobotModel, model: pin.Model, clearance_m: float, ground_z_m: float = 0.0, gain: float = 1.0
) -> GroundClearanceTask:
    """Every corner of :func:`hand_points` at least ``clearance_m`` above the floor z = ``ground_z_m``
    [m] of ``model`` (the robot's model, or a virtual chain's with the robot appended: the frames keep
    their names); ``gain``: lambda of eq. (13) per solver step."""
    return GroundClearanceTask(
        model,
        hand_points(robot),
        clearance_m=clearance_m,
        ground_z_m=ground_z_m,
        activation_m=HAND_FLOOR_ACTIVATION_M,
        gain=gain,
        name="hand_floor",
    )
