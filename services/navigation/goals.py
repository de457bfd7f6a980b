"""Navigation goals: a pose, or "in front of a named object, facing it, at a given distance".

"This navigation planner allows the humanoid robot to go in front of the visually located colored table
several meters away by avoiding known obstacles" ("Coupling the Motion Planner with Perception",
`001_771c0ce3779b0683.txt`, Figure 10). :func:`approach_poses` lists the candidate standing poses around
the object (best first) and :func:`resolve_goal` picks the first one whose footprint is free and that the
start can reach; :func:`services.navigation.path.plan_to` plans to it.

Distance convention: ``distance_m`` [m] is measured on the floor from the object's face (box side or
cylinder surface) to the robot's base origin (midpoint between the soles), along the robot's heading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from services.bus.schemas.navigation import REASON_NO_FREE_APPROACH_POSE
from services.collision.obstacles import BoxObstacle, Scene
from services.errors import InfeasibleError, InvalidRequestError
from services.navigation.geometry import FootprintChecker, Pose2D
from services.navigation.reachability import check_reachable

SIDES = ("-x", "+x", "-y", "+y")


@dataclass(frozen=True)
class ObjectGoal:
    """Stand in front of obstacle ``name`` facing it, ``distance_m`` [m] from its face to the base.

    ``side`` restricts a box to one face (one of :data:`SIDES`, in the box frame: "-x" is the face whose
    outward normal is the box's -x axis); None picks the free face nearest the start. ``lateral_offsets_m``
    [m] are tried along each face (0 = face centre) when the centre is blocked.
    """

    name: str
    distance_m: float = 0.4
    side: str | None = None
    lateral_offsets_m: tuple[float, ...] = (0.0, -0.25, 0.25, -0.5, 0.5)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.distance_m) and self.distance_m > 0.0):
            raise InvalidRequestError(f"distance_m must be a finite number > 0, got {self.distance_m}")
        if self.side is not None and self.side not in SIDES:
            raise InvalidRequestError(f"side must be one of {list(SIDES)} or None, got {self.side!r}")


@dataclass(frozen=True)
class ApproachPose:
    """A candidate standing pose: the base pose, the face it looks at, the lateral offset along it [m]."""

    pose: Pose2D
    side: str
    lateral_offset_m: float


def approach_poses(scene: Scene, goal: ObjectGoal, start: Pose2D) -> list[ApproachPose]:
    """Candidate poses in front of ``goal.name`` facing it, best first.

    Boxes: one pose per face and lateral offset (offsets that leave the face are skipped); faces ordered
    by the distance from ``start`` to the face-centre pose, offsets by magnitude. Cylinders: 16 directions
    around it ordered by the angle to the start's direction. NotFoundError for an unknown name.
    """
    obstacle = scene.find(goal.name)
    cx, cy = obstacle.center_xyz_m[0], obstacle.center_xyz_m[1]
    candidates: list[tuple[float, float, ApproachPose]] = []
    if isinstance(obstacle, BoxObstacle):
        c, s = math.cos(obstacle.yaw_rad), math.sin(obstacle.yaw_rad)
        hx, hy = 0.5 * obstacle.size_xyz_m[0], 0.5 * obstacle.size_xyz_m[1]
        # side -> (outward normal in the box frame, half depth along it, half length of the face)
        faces = {
            "-x": ((-1.0, 0.0), hx, hy),
            "+x": ((1.0, 0.0), hx, hy),
            "-y": ((0.0, -1.0), hy, hx),
            "+y": ((0.0, 1.0), hy, hx),
        }
        for side, ((nx_b, ny_b), depth, half_face) in faces.items():
            if goal.side is not None and side != goal.side:
                continue
            nx, ny = c * nx_b - s * ny_b, s * nx_b + c * ny_b  # outward normal in world
            tx, ty = -ny, nx  # along the face
            heading = math.atan2(-ny, -nx)  # facing the object
            base_x, base_y = cx + (depth + goal.distance_m) * nx, cy + (depth + goal.distance_m) * ny
            face_rank = math.hypot(base_x - start.x_m, base_y - start.y_m)
            for offset in goal.lateral_offsets_m:
                if abs(offset) > half_face:
                    continue
                pose = Pose2D(base_x + offset * tx, base_y + offset * ty, heading)
                candidates.append((face_rank, abs(offset), ApproachPose(pose, side, offset)))
    else:
        to_start = math.atan2(start.y_m - cy, start.x_m - cx)
        radius = obstacle.radius_m + goal.distance_m
        for k in range(16):
            angle = to_start + 2.0 * math.pi * k / 16
            pose = Pose2D(cx + radius * math.cos(angle), cy + radius * math.sin(angle), angle + math.pi)
            rank = abs(math.atan2(math.sin(angle - to_start), math.cos(angle - to_start)))
            candidates.append((rank, 0.0, ApproachPose(pose, f"{math.degrees(angle):.0f}deg", 0.0)))
    candidates.sort(key=lambda item: (item[0], item[1]))
    return [candidate for _, _, candidate in candidates]


def resolve_goal(checker: FootprintChecker, goal: ObjectGoal, start: Pose2D) -> list[ApproachPose]:
    """The usable approach poses for ``goal`` (free footprint, reachable from ``start``), best first.

    InfeasibleError when none is usable, with every candidate's reason in ``details["rejected"]``.
    """
    usable: list[ApproachPose] = []
    rejected: list[dict[str, object]] = []
    for candidate in approach_poses(checker.scene, goal, start):
        p = candidate.pose
        why: str | None = None
        if not checker.in_bounds(p.x_m, p.y_m):
            why = "outside the scene bounds"
        else:
            hits = checker.colliding_obstacles(p.x_m, p.y_m, p.theta_rad)
            if hits:
                why = f"footprint overlaps {hits}"
            else:
                try:
                    check_reachable(checker, start, p)
                except InfeasibleError as error:
                    why = f"enclosed by {error.details.get('enclosing_obstacles')}"
        if why is None:
            usable.append(candidate)
        else:
            rejected.append(
                {"side": candidate.side, "lateral_offset_m": candidate.lateral_offset_m, "reason": why}
            )
    if not usable:
        min_distance = checker.hx  # half footprint length incl. margin: the base cannot be nearer a face
        raise InfeasibleError(
            f"no free place to stand {goal.distance_m:.2f} m in front of {goal.name!r}"
            + (f" on side {goal.side}" if goal.side else "")
            + f": {rejected[0]['reason'] if rejected else 'no candidate'} (and {max(len(rejected) - 1, 0)} "
            f"other candidates rejected); the footprint needs >= {min_distance:.2f} m from the face and free "
            f"floor around it",
            {"reason": REASON_NO_FREE_APPROACH_POSE, "object": goal.name, "rejected": rejected},
        )
    return usable
