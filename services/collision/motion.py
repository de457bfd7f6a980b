"""The whole-body motion and the carried bar against the scene, in 3D: navigation's stage 2 check, walking's
legs sweep.

"If the generated dynamic motion induces unpredicted collisions due to deviation from the geometrically
and kinematically planned path, then the planner goes back to the first stage to 'reshape' the previous
path" ("Two-stage Planning Method", `001_771c0ce3779b0683.txt`). :class:`MotionChecker` measures, at every
sample of a joint trajectory, the signed distance (coal, through pinocchio's geometry model; < 0 is a
penetration depth) between each collision shape of the robot (its URDF collision boxes and cylinders, or
meshes for TALOS), the bar (a capsule rigid with the left hand, as the sim's grasp holds it) and each
obstacle of the scene.

Parts are grouped: ``bar``, ``arms`` (arm and hand links), ``body`` (waist, chest, head) and ``legs``.
Reshaping the bar's motion can move the first two away from an obstacle; a collision of the others is
the first stage's business (the footprint and upper-body boxes were too small).

A contact present at the first sample (the bar still lying on its stands when the walk starts) is not a
collision until the pair has separated by ``release_m`` once, like the sim's rule for held objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from services.collision.carried import BarGrip
from services.collision.obstacles import BoxObstacle, Obstacle, Scene, obstacle_geometry

GROUPS = ("bar", "arms", "body", "legs")
RESHAPABLE_GROUPS = ("bar", "arms")
_R_CAPSULE_Z_TO_X = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # capsule axis z -> x


def part_group(geometry_name: str) -> str:
    """The group of a collision shape from its name (``bar``, ``arms``, ``legs`` or ``body``)."""
    name = geometry_name.lower()
    if name == "carried_bar":
        return "bar"
    if "arm" in name or "gripper" in name or "hand" in name or "wrist" in name:
        return "arms"
    if "leg" in name or "foot" in name or "ankle" in name or "knee" in name or "hip" in name:
        return "legs"
    return "body"


@dataclass(frozen=True)
class CollisionEvent:
    """A stretch of samples ``k_start`` .. ``k_end`` (inclusive; times [s]) where part group ``group``
    comes closer than the required clearance to ``obstacle``: ``min_distance_m`` [m] is the deepest
    signed distance, at ``link`` (the closest collision shape) and time ``t_min_s``."""

    group: str
    obstacle: str
    k_start: int
    k_end: int
    t_start_s: float
    t_end_s: float
    min_distance_m: float
    link: str
    t_min_s: float


@dataclass(frozen=True, eq=False)
class MotionCheck:
    """Per-sample signed distances ``distance_m`` (n, len(groups), len(obstacles)) [m] of each part group
    to each obstacle (+inf: farther than the broad phase, or an initial contact not yet released), the
    closest shape of each entry ``closest_shape`` (same shape, index into ``shape_names``), and the
    sample times."""

    times_s: np.ndarray
    groups: tuple[str, ...]
    obstacles: tuple[str, ...]
    distance_m: np.ndarray
    closest_shape: np.ndarray
    shape_names: tuple[str, ...]

    def min_distance(self, group: str | None = None) -> np.ndarray:
        """(n,) smallest distance [m] of ``group`` (all groups when None) to any obstacle."""
        d = self.distance_m if group is None else self.distance_m[:, [self.groups.index(group)]]
        return d.min(axis=(1, 2)) if d.shape[2] else np.full(d.shape[0], math.inf)

    @property
    def min_clearance_m(self) -> float:
        """Smallest distance [m] of any part to any obstacle over the motion."""
        d = self.min_distance()
        return float(d.min()) if d.size else math.inf

    def events(self, clearance_m: float) -> list[CollisionEvent]:
        """Every stretch where a group is closer than ``clearance_m`` [m] to an obstacle, by start time."""
        out: list[CollisionEvent] = []
        t = self.times_s
        for g, group in enumerate(self.groups):
            for o, obstacle in enumerate(self.obstacles):
                d = self.distance_m[:, g, o]
                close = d < clearance_m
                if not close.any():
                    continue
                edges = np.diff(close.astype(np.int8), prepend=0, append=0)
                starts = np.flatnonzero(edges == 1)
                stops = np.flatnonzero(edges == -1) - 1
                for k0, k1 in zip(starts, stops, strict=True):
                    k_min = int(k0 + np.argmin(d[k0 : k1 + 1]))
                    out.append(
                        CollisionEvent(
                            group=group,
                            obstacle=obstacle,
                            k_start=int(k0),
                            k_end=int(k1),
                            t_start_s=float(t[k0]),
                            t_end_s=float(t[k1]),
                            min_distance_m=float(d[k_min]),
                            link=self.shape_names[int(self.closest_shape[k_min, g, o])],
                            t_min_s=float(t[k_min]),
                        )
                    )
        out.sort(key=lambda e: (e.t_start_s, e.group, e.obstacle))
        return out

    def near_interval(
        self, group: str, obstacle: str, k_start: int, k_end: int, within_m: float
    ) -> tuple[int, int]:
        """Widen samples ``k_start`` .. ``k_end`` while ``group`` stays within ``within_m`` [m] of
        ``obstacle``: the anticipating and regaining limits of Figure 2 (a)."""
        d = self.distance_m[:, self.groups.index(group), self.obstacles.index(obstacle)]
        a, b = k_start, k_end
        while a > 0 and d[a - 1] < within_m:
            a -= 1
        while b + 1 < d.shape[0] and d[b + 1] < within_m:
            b += 1
        return a, b


class MotionChecker:
    """Distances between the robot (and the carried bar) and the scene's obstacles along a motion.

    ``robot`` is a ``services.model.RobotModel``; ``grip`` the bar held (None: nothing carried);
    ``reach_m`` [m] the horizontal radius around the base beyond which a robot part cannot be (the
    broad phase; the bar's half length is added when one is carried).
    """

    def __init__(
        self, robot: object, scene: Scene, grip: BarGrip | None = None, reach_m: float = 1.2
    ) -> None:
        self.robot = robot
        self.scene = scene
        self.grip = grip
        model: pin.Model = robot.model  # type: ignore[attr-defined]
        self.model = model
        gmodel = robot.build_geometry_model("collision")  # type: ignore[attr-defined]
        n_robot = gmodel.ngeoms
        if grip is not None:
            frame = model.frames[model.getFrameId(grip.grasp_frames["left"])]
            T_joint_bar = frame.placement * grip.T_left_grasp_bar
            shape = coal.Capsule(grip.bar.radius_m, grip.bar.length_m)
            placement = pin.SE3(T_joint_bar.rotation @ _R_CAPSULE_Z_TO_X, T_joint_bar.translation)
            gmodel.addGeometryObject(pin.GeometryObject("carried_bar", frame.parentJoint, placement, shape))
        self.part_ids = list(range(gmodel.ngeoms))
        self.shape_names = tuple(gmodel.geometryObjects[i].name for i in self.part_ids)
        self.part_groups = [GROUPS.index(part_group(name)) for name in self.shape_names]
        self.obstacle_ids: list[int] = []
        for o in scene.obstacles:
            shape, T_world_o, _ = obstacle_geometry(o)
            placement = pin.SE3(T_world_o.getRotation(), T_world_o.getTranslation())
            self.obstacle_ids.append(
                gmodel.addGeometryObject(pin.GeometryObject(f"obstacle:{o.name}", 0, placement, shape))
            )
        self.gmodel = gmodel
        self.n_robot_shapes = n_robot
        self.reach_m = reach_m + (0.5 * grip.bar.length_m + grip.bar.radius_m if grip is not None else 0.0)

    def check(
        self,
        qs: np.ndarray,
        dt_s: float,
        release_m: float = 0.01,
        stride: int = 1,
        exact_within_m: float = 0.25,
    ) -> MotionCheck:
        """Distances along ``qs`` (n, nq) sampled every ``dt_s`` [s], every ``stride``-th sample (the
        samples in between copy the last checked one). Contacts at the first sample are ignored until
        their pair first separates by ``release_m`` [m].

        Broad phase: each shape's bounding sphere (coal's local AABB radius) against each obstacle's
        bounding box gives a lower bound of their distance; pairs whose bound is below ``exact_within_m``
        [m] get coal's exact signed distance, the others keep the bound (so distances above
        ``exact_within_m`` are lower bounds, exact below it)."""
        qs = np.asarray(qs, dtype=float)
        n = qs.shape[0]
        obstacles = self.scene.obstacles
        n_obs = len(obstacles)
        names = tuple(o.name for o in obstacles)
        times = np.arange(n) * dt_s
        distance = np.full((n, len(GROUPS), n_obs), math.inf)
        closest = np.zeros((n, len(GROUPS), n_obs), dtype=np.int32)
        # obstacles whose floor disc comes within reach of the base at some sample
        used = [
            j
            for j, o in enumerate(obstacles)
            if (
                np.hypot(qs[:, 0] - o.center_xyz_m[0], qs[:, 1] - o.center_xyz_m[1])
                < self.reach_m + o.bounding_radius_xy_m
            ).any()
        ]
        if not used:
            return MotionCheck(times, GROUPS, names, distance, closest, self.shape_names)
        gmodel = pin.GeometryModel(self.gmodel)  # a copy holding only the pairs needed
        gmodel.removeAllCollisionPairs()
        parts = self.part_ids
        n_parts = len(parts)
        for j in used:
            for part in parts:
                gmodel.addCollisionPair(pin.CollisionPair(part, self.obstacle_ids[j]))
        gdata = pin.GeometryData(gmodel)
        data = self.model.createData()
        n_pairs = n_parts * len(used)
        results = gdata.distanceResults
        # bounding spheres of the parts (local centre, radius) and boxes of the obstacles
        local_c, radius = [], []
        for part in parts:
            geometry = gmodel.geometryObjects[part].geometry
            geometry.computeLocalAABB()
            local_c.append(np.array(geometry.aabb_center))
            radius.append(float(geometry.aabb_radius))
        rad = np.array(radius)[:, None]
        c_obs = np.array([obstacles[j].center_xyz_m for j in used])  # (U, 3)
        half = np.array([_half_extents(obstacles[j]) for j in used])  # (U, 3)
        yaw = np.array([getattr(obstacles[j], "yaw_rad", 0.0) for j in used])
        cos_y, sin_y = np.cos(yaw), np.sin(yaw)
        active = np.ones(n_pairs, dtype=bool)
        exempt = np.zeros(n_pairs, dtype=bool)
        d_all = np.empty((n, n_pairs))  # pair (u, part) at column u * n_parts + part
        for k in range(n):
            if k % stride and k != n - 1:
                d_all[k] = d_all[k - 1]
                continue
            pin.updateGeometryPlacements(self.model, data, gmodel, gdata, qs[k])
            centres = np.array([gdata.oMg[part].act(local_c[i]) for i, part in enumerate(parts)])  # (P, 3)
            rel = centres[None, :, :] - c_obs[:, None, :]  # (U, P, 3)
            lx = np.abs(cos_y[:, None] * rel[..., 0] + sin_y[:, None] * rel[..., 1]) - half[:, None, 0]
            ly = np.abs(-sin_y[:, None] * rel[..., 0] + cos_y[:, None] * rel[..., 1]) - half[:, None, 1]
            lz = np.abs(rel[..., 2]) - half[:, None, 2]
            outside = np.sqrt(np.maximum(lx, 0) ** 2 + np.maximum(ly, 0) ** 2 + np.maximum(lz, 0) ** 2)
            bound = (outside - rad.T).reshape(-1)  # (U * P,)
            need = bound < exact_within_m
            for i in np.flatnonzero(need != active):
                if need[i]:
                    gdata.activateCollisionPair(int(i))
                else:
                    gdata.deactivateCollisionPair(int(i))
            active = need
            d = bound.copy()
            idx = np.flatnonzero(need)
            if idx.size:
                pin.computeDistances(gmodel, gdata)
                d[idx] = [results[int(i)].min_distance for i in idx]
            exempt = d < release_m if k == 0 else exempt & (d < release_m)
            d[exempt] = math.inf
            d_all[k] = d
        rows = np.arange(n)
        part_group = np.array(self.part_groups)
        for u, j in enumerate(used):
            block = d_all[:, u * n_parts : (u + 1) * n_parts]
            for g in range(len(GROUPS)):
                members = np.flatnonzero(part_group == g)
                if members.size == 0:
                    continue
                arg = np.argmin(block[:, members], axis=1)
                distance[:, g, j] = block[rows, members[arg]]
                closest[:, g, j] = np.array(parts)[members[arg]]
        return MotionCheck(times, GROUPS, names, distance, closest, self.shape_names)


def _half_extents(o: Obstacle) -> tuple[float, float, float]:
    """Half extents [m] of an obstacle's bounding box in its own frame (yaw only)."""
    if isinstance(o, BoxObstacle):
        return (0.5 * o.size_xyz_m[0], 0.5 * o.size_xyz_m[1], 0.5 * o.size_xyz_m[2])
    return (o.radius_m, o.radius_m, 0.5 * o.height_m)
