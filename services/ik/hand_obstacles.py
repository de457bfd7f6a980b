"""A reaching arm, its gripper and wrist included, kept out of spheres above the ground (balls beside the
one to grasp): the arm's capsules against spheres with the inequality of the footstep paper's
self-collision, eqs. (12)-(13) (``000_49c4a782ba599e49.txt``; obstacles as inequalities, §4):

    G = r_capsule + r_sphere + d - |A B| <= 0

A sphere is a box with no extent whose radius is added to the margin d, so the rows, the closest points
and the Jacobians are :class:`services.ik.tasks.capsule_box.CapsuleBoxTask`'s (one concept, one place).
Used by the footstep planner (the final posture, ``services.footsteps.arm_obstacles``) and by reaching
(the whole motion, ``services.reaching``).

The arm's capsules are the robot's upper arm and forearm capsules and, for the hand, capsules fitted to
the collision shapes of the links the wrist joint and the gripper joint carry (the palm, the jaws'
bar, each finger: :func:`gripper_capsules`), not the robot's one capsule around the whole hand: that
one (0.075 m on hrp2_like) is wider than the gap between two touching balls, while a neighbour beside
the jaws' plates is a few centimetres clear of them. Every touch of a neighbour seen in the fetch was
the gripper or the wrist (fetch seeds 6, 12, 37; issue 15).

The gripper is not kept out of the sphere it closes on: a sphere that the hand's target lies in or
straight above (:func:`closes_on`); the upper arm and forearm are kept out of every sphere.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.capsule import Capsule, CapsuleLike
from services.ik.tasks.capsule_box import CapsuleBoxTask, ObstacleBox
from services.model.geometry import shape_points


@dataclass(frozen=True)
class SphereObstacle:
    """A sphere above the ground that a reaching arm's capsules keep out of (a ball beside the one to
    grasp; the object itself when the hand is planned above it): centre (x, y, z), radius [m], world."""

    x_m: float
    y_m: float
    z_m: float
    radius_m: float

    @property
    def centre_m(self) -> np.ndarray:
        """(3,) centre [m], world."""
        return np.array([self.x_m, self.y_m, self.z_m], dtype=float)


def check_spheres(spheres: Sequence[SphereObstacle], field: str = "hand_obstacles") -> None:
    """InvalidRequestError naming ``field[i]`` when a sphere has a coordinate that is not finite or a
    radius that is not positive."""
    for i, sphere in enumerate(spheres):
        values = (sphere.x_m, sphere.y_m, sphere.z_m, sphere.radius_m)
        if not all(math.isfinite(v) for v in values) or sphere.radius_m <= 0:
            raise InvalidRequestError(
                f"{field}[{i}]: needs finite x_m, y_m, z_m and radius_m > 0, got {sphere}",
                {"field": f"{field}[{i}]"},
            )


@dataclass(frozen=True)
class HandCapsules:
    """The capsules of one reaching arm: ``capsules`` (the upper arm and forearm first, then the
    gripper's), ``gripper`` the indices of the gripper's among them."""

    capsules: tuple[CapsuleLike, ...]
    gripper: frozenset[int]


def _fitted_capsule(name: str, frame: str, points_in_frame: np.ndarray) -> Capsule:
    """The capsule along the principal axis of ``points_in_frame`` (m x 3, [m]) that contains them: the
    segment spans their extent along that axis, the radius is their largest distance from it."""
    centre = 0.5 * (points_in_frame.min(axis=0) + points_in_frame.max(axis=0))
    local = points_in_frame - centre
    axis = np.linalg.svd(local, full_matrices=False)[2][0]
    t = local @ axis
    radial = local - np.outer(t, axis)
    radius = float(np.sqrt((radial * radial).sum(axis=1)).max())
    p0, p1 = centre + t.min() * axis, centre + t.max() * axis
    return Capsule(name, frame, tuple(map(float, p0)), tuple(map(float, p1)), radius)


@functools.lru_cache(maxsize=8)
def gripper_capsules(robot: Any, hand: str) -> tuple[Capsule, ...]:
    """Capsules fitted to each collision shape (URDF, ``RobotModel.build_geometry_model``) of the links
    carried by ``hand``'s wrist joint (the grasp frame's parent joint: the palm, the jaws' bar, the fixed
    finger) and by its gripper joint (the moving finger), in the frame of the shape's link, one per
    shape (a box's capsule lies along its longest side, the radius is the half diagonal of the two
    others: on hrp2_like 0.019 m for a finger plate, 0.05 m for the palm)."""
    model = robot.model
    wrist = model.frames[robot.frame_id(robot.frames.grasp(hand))].parentJoint
    carried = {wrist, model.getJointId(robot.gripper_joint(hand))}
    geometry = robot.build_geometry_model("collision")
    out: list[Capsule] = []
    for g in geometry.geometryObjects:
        if g.parentJoint not in carried:
            continue
        frame = model.frames[g.parentFrame]
        # the shape's placement is relative to its parent joint; the capsule's points to its link frame
        T_frame_shape = frame.placement.inverse() * g.placement
        points = shape_points(g.geometry) @ T_frame_shape.rotation.T + T_frame_shape.translation
        out.append(_fitted_capsule(f"{hand}_gripper:{g.name}", frame.name, points))
    return tuple(out)


def hand_capsules(robot: Any, hand: str) -> HandCapsules:
    """The capsules of ``hand``'s arm (a ``services.model.RobotModel``): the robot's capsules carried by
    the arm's joints except the one around the whole hand (the upper arm and forearm), then the
    gripper's (:func:`gripper_capsules`)."""
    model = robot.model
    joints = {model.getJointId(name) for name in robot.arm_joints(hand)}
    wrist = model.frames[robot.frame_id(robot.frames.grasp(hand))].parentJoint
    arm = [c for c in robot.capsules if model.frames[robot.frame_id(c.frame)].parentJoint in joints - {wrist}]
    gripper = gripper_capsules(robot, hand)
    return HandCapsules((*arm, *gripper), frozenset(range(len(arm), len(arm) + len(gripper))))


def closes_on(sphere: SphereObstacle, target_m: np.ndarray) -> bool:
    """Whether ``target_m`` (a grasp frame's target [m], world) lies in ``sphere`` or straight above it:
    the object the gripper closes on (the hand reaches it, or a point above it to come down onto it)."""
    dx, dy = float(target_m[0]) - sphere.x_m, float(target_m[1]) - sphere.y_m
    return dx * dx + dy * dy <= sphere.radius_m**2 and float(target_m[2]) >= sphere.z_m - sphere.radius_m


def sphere_pairs(
    arm: HandCapsules, spheres: Sequence[SphereObstacle], target_m: np.ndarray | None
) -> list[tuple[int, int]]:
    """The (capsule, sphere) index pairs kept apart: every capsule against every sphere, but the
    gripper's not against a sphere it closes on (:func:`closes_on` ``target_m``; None: none)."""
    exempt = {j for j, s in enumerate(spheres) if target_m is not None and closes_on(s, target_m)}
    return [
        (i, j)
        for i in range(len(arm.capsules))
        for j in range(len(spheres))
        if not (i in arm.gripper and j in exempt)
    ]


def sphere_tasks(
    model: pin.Model,
    capsules: Sequence[CapsuleLike],
    spheres: Sequence[SphereObstacle],
    pairs: Sequence[tuple[int, int]],
    margin_m: float,
    gain: float,
    to_model: Callable[[np.ndarray], np.ndarray] = lambda p: p,
) -> list[CapsuleBoxTask]:
    """Inequality tasks keeping each (capsule, sphere) of ``pairs`` at least ``margin_m`` apart surface to
    surface (eqs. 12-13), one :class:`CapsuleBoxTask` per sphere radius (the radius is part of a task's
    margin); ``to_model`` brings a sphere's world centre into ``model``'s frame. [] without pairs."""
    by_radius: dict[float, list[int]] = {}
    for j in sorted({j for _, j in pairs}):
        by_radius.setdefault(float(spheres[j].radius_m), []).append(j)
    tasks: list[CapsuleBoxTask] = []
    for k, (radius, members) in enumerate(sorted(by_radius.items())):
        column = {j: c for c, j in enumerate(members)}
        boxes = [
            ObstacleBox(f"sphere{j}", pin.SE3(np.eye(3), to_model(spheres[j].centre_m)), np.zeros(3))
            for j in members
        ]
        task_pairs = [(i, column[j]) for i, j in pairs if j in column]
        tasks.append(
            CapsuleBoxTask(
                model,
                capsules,
                boxes,
                task_pairs,
                margin_m=margin_m + radius,
                gain=gain,
                name=f"arm_out_of_spheres_r{radius:.3f}_{k}",
            )
        )
    return tasks


class SphereDistances:
    """Surface distances [m] (negative: penetration) of (capsule, sphere) pairs at configurations of a
    model: the same distances as the rows of :func:`sphere_tasks` (point boxes, radii subtracted)."""

    def __init__(
        self,
        model: pin.Model,
        capsules: Sequence[CapsuleLike],
        spheres: Sequence[SphereObstacle],
        pairs: Sequence[tuple[int, int]],
    ) -> None:
        self.model = model
        self.capsules = tuple(capsules)
        self.pairs = [(int(i), int(j)) for i, j in pairs]
        boxes = [
            ObstacleBox(f"sphere{j}", pin.SE3(np.eye(3), s.centre_m), np.zeros(3))
            for j, s in enumerate(spheres)
        ]
        self._task = CapsuleBoxTask(model, self.capsules, boxes, self.pairs, margin_m=0.0)
        self._radii = np.array([spheres[j].radius_m for _, j in self.pairs], dtype=float)
        self._data = model.createData()

    def at(self, q: np.ndarray) -> np.ndarray:
        """(pairs,) surface distances [m] at ``q`` (a configuration of the model)."""
        if not self.pairs:
            return np.zeros(0)
        pin.framesForwardKinematics(self.model, self._data, np.asarray(q, dtype=float))
        return self._task.distances(self._data) - self._radii

    def closest(self, q: np.ndarray) -> tuple[float, int]:
        """(the smallest distance [m], its pair's index) at ``q``; (inf, -1) without pairs."""
        d = self.at(q)
        if not d.size:
            return float("inf"), -1
        k = int(np.argmin(d))
        return float(d[k]), k
