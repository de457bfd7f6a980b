"""Pure converters: the stack's messages (decoded, :mod:`services.bus.schemas`) -> Foxglove messages.

Each function returns ``[(topic, message), ...]`` where a message is a ``foxglove.messages`` object
(protobuf) or a :class:`JsonMessage`. Every SceneUpdate first deletes what its topic showed before, so
the panel shows the latest plan, map or scene. Times are the log time of the bus message [ns]: the 3D
panel looks transforms up by message time. World frame: z up, floor at z = 0, [m], [rad].
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from foxglove.messages import (
    CameraCalibration,
    CompressedImage,
    CubePrimitive,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Log,
    LogLevel,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Vector3,
)

from services.bus.schemas import footsteps as fs_msg
from services.bus.schemas import navigation as nav_msg
from services.bus.schemas import perception as per_msg
from services.bus.schemas import reaching as reach_msg
from services.bus.schemas import sim as sim_msg
from services.bus.schemas import walking as walk_msg
from services.bus.schemas.common import ErrorInfo, LauncherEvent, LogLine
from services.bus.schemas.supervisor import SupervisorEvent
from services.model import ground
from services.viz import common as c
from services.viz.common import WORLD, color, point, stamp

Out = list[tuple[str, Any]]
#: Sole rectangle [m] (length, width) drawn when the robot model is not known yet (HRP-2's).
DEFAULT_SOLE_M = (0.24, 0.14)
#: The most points a line strip or a plotted series gets (plans have one sample every 5 ms).
MAX_POINTS = 400
JPEG_QUALITY = 85


@dataclass(frozen=True)
class JsonMessage:
    """A JSON message with its JSON Schema (typed as Foxglove's reader requires)."""

    schema_name: str
    schema: dict[str, Any]
    doc: dict[str, Any]

    def encode(self) -> bytes:
        return json.dumps(self.doc).encode()


def _yaw_quaternion(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def _pose(x: float, y: float, z: float, yaw: float = 0.0) -> Pose:
    return Pose(position=Vector3(x=float(x), y=float(y), z=float(z)), orientation=_yaw_quaternion(float(yaw)))


def _quat_pose(position: list[float], quaternion: list[float]) -> Pose:
    x, y, z, w = (float(v) for v in quaternion)
    return Pose(
        position=Vector3(x=float(position[0]), y=float(position[1]), z=float(position[2])),
        orientation=Quaternion(x=x, y=y, z=z, w=w),
    )


def _size(x: float, y: float, z: float) -> Vector3:
    return Vector3(x=float(x), y=float(y), z=float(z))


def _replace_all(stamp_ns: int, entities: list[SceneEntity]) -> SceneUpdate:
    """A scene update that clears the topic's entities and shows ``entities``."""
    clear = SceneEntityDeletion(timestamp=stamp(stamp_ns), type=SceneEntityDeletionType.All)
    return SceneUpdate(deletions=[clear], entities=entities)


def _entity(stamp_ns: int, id_: str, **primitives: Any) -> SceneEntity:
    return SceneEntity(timestamp=stamp(stamp_ns), frame_id=WORLD, id=id_, **primitives)


def _decimate(a: np.ndarray, n: int = MAX_POINTS) -> np.ndarray:
    a = np.asarray(a)
    if len(a) <= n:
        return a
    idx = np.unique(np.linspace(0, len(a) - 1, n).round().astype(int))
    return a[idx]


def _strip(points_xyz: np.ndarray, col: Any, thickness: float = 0.01) -> LinePrimitive:
    pts = _decimate(np.asarray(points_xyz, dtype=float))
    return LinePrimitive(
        type=LinePrimitiveLineType.LineStrip,
        thickness=thickness,
        points=[point(*p) for p in pts],
        color=col,
    )


def _loop(points_xy: np.ndarray, col: Any, z: float = 0.002) -> LinePrimitive:
    return LinePrimitive(
        type=LinePrimitiveLineType.LineLoop,
        thickness=0.006,
        points=[point(p[0], p[1], z) for p in points_xy],
        color=col,
    )


def _xy0(xy: np.ndarray, z: float = 0.003) -> np.ndarray:
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    return np.column_stack([xy, np.full(len(xy), z)])


# ---------------------------------------------------------------------------------------------------
# Footsteps and support polygons
# ---------------------------------------------------------------------------------------------------
def sole_cube(side: str, x: float, y: float, yaw: float, sole_m: tuple[float, float]) -> CubePrimitive:
    """A flat sole rectangle on the floor, blue for the left foot, red for the right."""
    col = c.LEFT_COLOR if side == "left" else c.RIGHT_COLOR
    return CubePrimitive(pose=_pose(x, y, 0.003, yaw), size=_size(sole_m[0], sole_m[1], 0.006), color=col)


def sole_corners(x: float, y: float, yaw: float, sole_m: tuple[float, float]) -> np.ndarray:
    """The 4 corners (4, 2) [m] of a sole rectangle (length, width) at (x, y, yaw)."""
    return ground.sole_corners(ground.SolePose(x, y, yaw), sole_m[0], sole_m[1])


def support_polygon(soles: list[tuple[float, float, float]], sole_m: tuple[float, float]) -> np.ndarray:
    """Convex hull (counter-clockwise, (N, 2)) of sole rectangles (x, y, yaw)."""
    return ground.convex_hull_ccw(np.vstack([sole_corners(x, y, yaw, sole_m) for x, y, yaw in soles]))


def footsteps_update(
    stamp_ns: int, source: str, steps: list[tuple[str, float, float, float]], sole_m: tuple[float, float]
) -> SceneUpdate:
    """Soles ``(side, x, y, yaw)`` in walking order, numbered."""
    cubes = [sole_cube(side, x, y, yaw, sole_m) for side, x, y, yaw in steps]
    texts = [
        TextPrimitive(
            pose=_pose(x, y, 0.02),
            billboard=True,
            font_size=14.0,
            scale_invariant=True,
            color=color(1, 1, 1),
            text=str(i + 1),
        )
        for i, (_side, x, y, _yaw) in enumerate(steps)
    ]
    return _replace_all(stamp_ns, [_entity(stamp_ns, f"footsteps/{source}", cubes=cubes, texts=texts)])


def _walk_supports(
    steps: list[tuple[str, float, float, float]],
    left: tuple[float, float, float],
    right: tuple[float, float, float],
    sole_m: tuple[float, float],
) -> list[np.ndarray]:
    """The double-support polygon before the walk and after each landing."""
    feet = {"left": left, "right": right}
    polygons = [support_polygon([feet["left"], feet["right"]], sole_m)]
    for side, x, y, yaw in steps:
        feet[side] = (x, y, yaw)
        polygons.append(support_polygon([feet["left"], feet["right"]], sole_m))
    return polygons


def supports_update(stamp_ns: int, source: str, polygons: list[np.ndarray]) -> SceneUpdate:
    col = color(0.9, 0.9, 0.9, 0.8)
    return _replace_all(
        stamp_ns, [_entity(stamp_ns, f"support/{source}", lines=[_loop(p, col) for p in polygons])]
    )


def com_zmp(stamp_ns: int, source: str, times_s: np.ndarray, com_m: np.ndarray, zmp_m: np.ndarray) -> Out:
    """Planned CoM (3-D) and ZMP (on the floor) as line strips, and as numbers for the Plot panel."""
    com_m = np.asarray(com_m, dtype=float).reshape(-1, 3)
    zmp_m = np.asarray(zmp_m, dtype=float).reshape(-1, 2)
    lines = [_strip(com_m, c.COM_COLOR), _strip(_xy0(zmp_m), c.ZMP_COLOR, 0.008)]
    scene = _replace_all(stamp_ns, [_entity(stamp_ns, f"com_zmp/{source}", lines=lines)])
    t = _decimate(np.asarray(times_s, dtype=float))
    com, zmp = _decimate(com_m), _decimate(zmp_m)
    n = min(len(t), len(com), len(zmp))
    doc = {
        "source": source,
        "t_s": t[:n].tolist(),
        "com_x_m": com[:n, 0].tolist(),
        "com_y_m": com[:n, 1].tolist(),
        "com_z_m": com[:n, 2].tolist(),
        "zmp_x_m": zmp[:n, 0].tolist(),
        "zmp_y_m": zmp[:n, 1].tolist(),
    }
    return [(c.PLAN_COM_ZMP, scene), (c.PLAN_SERIES, JsonMessage("hrp.viz.ComZmpSeries", SERIES_SCHEMA, doc))]


_NUMBERS = {"type": "array", "items": {"type": "number"}}
SERIES_SCHEMA: dict[str, Any] = {
    "title": "ComZmpSeries",
    "description": "a plan's CoM and ZMP over time (world frame [m], time from the plan's start [s])",
    "type": "object",
    "properties": {
        "source": {"type": "string"},
        "t_s": _NUMBERS,
        "com_x_m": _NUMBERS,
        "com_y_m": _NUMBERS,
        "com_z_m": _NUMBERS,
        "zmp_x_m": _NUMBERS,
        "zmp_y_m": _NUMBERS,
    },
}


# ---------------------------------------------------------------------------------------------------
# Plans
# ---------------------------------------------------------------------------------------------------
def navigation_plan(stamp_ns: int, reply: nav_msg.GotoReply, sole_m: tuple[float, float]) -> Out:
    """navigation/goto's reply: the path, the footsteps, the support polygons, CoM and ZMP."""
    path = np.asarray(reply.path_xy_m, dtype=float).reshape(-1, 2)
    goal = reply.goal
    arrow_entity = _entity(
        stamp_ns, "navigation/path",
        lines=[_strip(_xy0(path, 0.01), c.PATH_COLOR, 0.015)],
        spheres=[SpherePrimitive(pose=_pose(goal[0], goal[1], 0.02), size=_size(0.08, 0.08, 0.04),
                                 color=c.PATH_COLOR)],
    )  # fmt: skip
    steps = [
        (side, float(p[0]), float(p[1]), float(p[2]))
        for side, p in zip(reply.step_sides, np.asarray(reply.step_poses).reshape(-1, 3), strict=False)
    ]
    left, right = tuple(reply.left_start[:3]), tuple(reply.right_start[:3])
    times = np.arange(len(reply.com_m)) * reply.dt_s
    return [
        (c.PLAN_PATH, _replace_all(stamp_ns, [arrow_entity])),
        (c.PLAN_FOOTSTEPS, footsteps_update(stamp_ns, "navigation", steps, sole_m)),
        (c.PLAN_SUPPORT, supports_update(stamp_ns, "navigation", _walk_supports(steps, left, right, sole_m))),
        *com_zmp(stamp_ns, "navigation", times, reply.com_m, reply.zmp_m),
    ]


def walking_plan(stamp_ns: int, reply: walk_msg.PlanReply, sole_m: tuple[float, float]) -> Out:
    """walking/plan's reply: footsteps, support polygons, CoM and multibody ZMP."""
    steps = [(s.side, float(s.pose[0]), float(s.pose[1]), float(s.pose[2])) for s in reply.steps]
    left0 = np.asarray(reply.left_sole, dtype=float).reshape(-1, 4)[0]
    right0 = np.asarray(reply.right_sole, dtype=float).reshape(-1, 4)[0]
    left, right = (left0[0], left0[1], left0[3]), (right0[0], right0[1], right0[3])
    return [
        (c.PLAN_FOOTSTEPS, footsteps_update(stamp_ns, "walking", steps, sole_m)),
        (c.PLAN_SUPPORT, supports_update(stamp_ns, "walking", _walk_supports(steps, left, right, sole_m))),
        *com_zmp(stamp_ns, "walking", reply.times_s, reply.com_m, reply.zmp_multibody_m),
    ]


def footstep_planner_result(stamp_ns: int, reply: fs_msg.PlanReply, sole_m: tuple[float, float]) -> Out:
    """footsteps/plan's reply: the planned footsteps (section 5 of the footstep paper)."""
    steps = [(f.side, f.x, f.y, f.yaw) for f in reply.footsteps]
    return [(c.PLAN_FOOTSTEP_PLANNER, footsteps_update(stamp_ns, "footstep_planner", steps, sole_m))]


def reach_target(stamp_ns: int, request: reach_msg.ReachRequest) -> Out:
    """reaching/reach's request: the target point."""
    x, y, z = (float(v) for v in request.target[:3])
    target = SpherePrimitive(pose=_pose(x, y, z), size=_size(0.05, 0.05, 0.05), color=color(1, 0.2, 0.8, 0.9))
    entity = _entity(stamp_ns, "reach/target", spheres=[target])
    return [(c.PLAN_REACH, SceneUpdate(deletions=[_delete(stamp_ns, "reach/target")], entities=[entity]))]


def reach_plan(
    stamp_ns: int, reply: reach_msg.ReachReply, hand_path_m: np.ndarray, sole_m: tuple[float, float]
) -> Out:
    """reaching/reach's reply: the hand's path (grasp frame positions (N, 3) [m]), footsteps, ZMP."""
    lines = [
        _strip(hand_path_m, color(1, 0.2, 0.8), 0.008),
        _strip(_xy0(np.asarray(reply.zmp_multibody)), c.ZMP_COLOR, 0.006),
    ]
    entity = _entity(stamp_ns, "reach/hand_path", lines=lines)
    out: Out = [
        (c.PLAN_REACH, SceneUpdate(deletions=[_delete(stamp_ns, "reach/hand_path")], entities=[entity]))
    ]
    if reply.footsteps:
        steps = [(f.side, f.x, f.y, f.yaw) for f in reply.footsteps]
        out.append((c.PLAN_FOOTSTEPS, footsteps_update(stamp_ns, "reaching", steps, sole_m)))
    return out


def _delete(stamp_ns: int, id_: str) -> SceneEntityDeletion:
    return SceneEntityDeletion(timestamp=stamp(stamp_ns), type=SceneEntityDeletionType.MatchingId, id=id_)


# ---------------------------------------------------------------------------------------------------
# The world and the belief
# ---------------------------------------------------------------------------------------------------
def _object_primitives(obj: sim_msg.ObjectState) -> dict[str, list[Any]]:
    col = color(*(list(obj.colour) + [1.0] * 4)[:4])
    base = _quat_pose(obj.position, obj.quaternion)
    if obj.kind == "ball":
        d = 2 * obj.radius_m
        return {"spheres": [SpherePrimitive(pose=base, size=_size(d, d, d), color=col)]}
    if obj.kind == "box":
        return {"cubes": [CubePrimitive(pose=base, size=_size(*obj.size_m[:3]), color=col)]}
    if obj.kind in ("bar", "disk"):
        d = 2 * obj.radius_m
        if obj.kind == "disk":
            return {"cylinders": [CylinderPrimitive(pose=base, size=_size(d, d, 0.004), bottom_scale=1,
                                                    top_scale=1, color=col)]}  # fmt: skip
        # A bar lies along its x axis: a cylinder (along z) turned by 90 degrees about y.
        x, y, z, w = (float(v) for v in obj.quaternion)
        q_bar = _quat_mul((x, y, z, w), (0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4)))
        pose = _quat_pose(obj.position, list(q_bar))
        return {"cylinders": [CylinderPrimitive(pose=pose, size=_size(d, d, obj.length_m), bottom_scale=1,
                                                top_scale=1, color=col)]}  # fmt: skip
    if obj.kind in ("table", "chair"):  # reference point on the floor: the top, and the legs
        sx, sy, h = (float(v) for v in obj.size_m[:3])
        yaw = _yaw_of(obj.quaternion)
        px, py = float(obj.position[0]), float(obj.position[1])
        top = CubePrimitive(pose=_pose(px, py, h - 0.02, yaw), size=_size(sx, sy, 0.04), color=col)
        legs = []
        for ix in (-1, 1):
            for iy in (-1, 1):
                lx, ly = ix * (sx / 2 - 0.03), iy * (sy / 2 - 0.03)
                wx = px + lx * math.cos(yaw) - ly * math.sin(yaw)
                wy = py + lx * math.sin(yaw) + ly * math.cos(yaw)
                legs.append(CubePrimitive(pose=_pose(wx, wy, (h - 0.04) / 2, yaw),
                                          size=_size(0.05, 0.05, h - 0.04), color=col))  # fmt: skip
        return {"cubes": [top, *legs]}
    return {}


def _quat_mul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _yaw_of(quaternion: list[float]) -> float:
    x, y, z, w = (float(v) for v in quaternion)
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def world_objects(stamp_ns: int, reply: sim_msg.GroundTruthReply) -> Out:
    """What is there: the sim's objects (sim/ground_truth), each an entity named after it."""
    entities = []
    for obj in reply.objects:
        prims = _object_primitives(obj)
        if prims:
            entities.append(_entity(stamp_ns, f"object/{obj.name}", **prims))
    return [(c.WORLD_OBJECTS, _replace_all(stamp_ns, entities))]


def map_obstacles(stamp_ns: int, request: nav_msg.GotoRequest) -> Out:
    """What the robot believes: the obstacles the supervisor sent navigation (its map), translucent."""
    entities = []
    for ob in request.obstacles:
        cx, cy, cz = (float(v) for v in (list(ob.center) + [0.0] * 3)[:3])
        if ob.kind == "cylinder":
            d = 2 * ob.radius
            prims: dict[str, Any] = {"cylinders": [CylinderPrimitive(
                pose=_pose(cx, cy, cz), size=_size(d, d, ob.height), bottom_scale=1, top_scale=1,
                color=c.MAP_COLOR)]}  # fmt: skip
        else:
            sx, sy, sz = (float(v) for v in (list(ob.size) + [0.0] * 3)[:3])
            prims = {"cubes": [CubePrimitive(pose=_pose(cx, cy, cz, ob.yaw), size=_size(sx, sy, sz),
                                             color=c.MAP_COLOR)]}  # fmt: skip
        label = TextPrimitive(pose=_pose(cx, cy, cz + 0.3), billboard=True, font_size=12.0,
                              scale_invariant=True, color=color(1, 1, 1), text=ob.name)  # fmt: skip
        entities.append(_entity(stamp_ns, f"map/{ob.name}", texts=[label], **prims))
    return [(c.MAP_OBSTACLES, _replace_all(stamp_ns, entities))]


def sighting(stamp_ns: int, reply: per_msg.LocateReply) -> Out:
    """A located object: a marker at its position and its footprint on the floor (replaces the
    previous sighting of the same object)."""
    x, y, z = (float(v) for v in reply.position[:3])
    col = color(1.0, 1.0, 0.2, 0.9)
    prims: dict[str, Any] = {
        "spheres": [SpherePrimitive(pose=_pose(x, y, z), size=_size(0.04, 0.04, 0.04), color=col)],
        "texts": [
            TextPrimitive(
                pose=_pose(x, y, z + 0.1),
                billboard=True,
                font_size=12.0,
                scale_invariant=True,
                color=col,
                text=f"{reply.object} ({reply.confidence:.2f})",
            )
        ],
    }
    fp = reply.footprint
    if fp is not None:
        prims["lines"] = [_loop(fp.rectangle.corners(), col, z=float(fp.top_z))]
    id_ = f"sighting/{reply.object}"
    entity = _entity(stamp_ns, id_, **prims)
    return [(c.MAP_SIGHTINGS, SceneUpdate(deletions=[_delete(stamp_ns, id_)], entities=[entity]))]


# ---------------------------------------------------------------------------------------------------
# Cameras
# ---------------------------------------------------------------------------------------------------
def camera(stamp_ns: int, image: sim_msg.CameraImage, frame_id: str) -> Out:
    """A head camera's calibration and its image (JPEG), in ``frame_id`` (the optical frame in /tf)."""
    K = np.asarray(image.K, dtype=float).reshape(3, 3)
    P = np.hstack([K, np.zeros((3, 1))])
    calibration = CameraCalibration(
        timestamp=stamp(stamp_ns), frame_id=frame_id, width=int(image.width_px), height=int(image.height_px),
        distortion_model="plumb_bob", D=[0.0] * 5, K=K.ravel().tolist(), R=np.eye(3).ravel().tolist(),
        P=P.ravel().tolist(),
    )  # fmt: skip
    rgb = np.ascontiguousarray(image.rgb)
    ok, jpeg = cv2.imencode(
        ".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]
    )
    out: Out = [(c.camera_calibration_topic(image.name), calibration)]
    if ok:
        compressed = CompressedImage(
            timestamp=stamp(stamp_ns), frame_id=frame_id, data=jpeg.tobytes(), format="jpeg"
        )
        out.append((c.camera_image_topic(image.name), compressed))
    return out


def snapshot(stamp_ns: int, reply: sim_msg.SnapshotReply) -> Out:
    """sim/snapshot's PNG as it is."""
    png = np.asarray(reply.png, dtype=np.uint8).tobytes()
    return [
        (c.SNAPSHOT, CompressedImage(timestamp=stamp(stamp_ns), frame_id="snapshot", data=png, format="png"))
    ]


# ---------------------------------------------------------------------------------------------------
# Text
# ---------------------------------------------------------------------------------------------------
_EVENT_LEVELS = {"failed": LogLevel.Warning, "stopped": LogLevel.Warning, "retried": LogLevel.Info}


def supervisor_log(stamp_ns: int, event: SupervisorEvent) -> Out:
    level = _EVENT_LEVELS.get(event.kind, LogLevel.Info)
    if event.kind == "run_finished" and not event.ok:
        level = LogLevel.Error
    parts = [
        event.kind,
        event.step,
        f"attempt {event.attempt}" if event.attempt else "",
        event.reason,
        event.message,
    ]
    text = ": ".join(p for p in parts if p)
    return [
        (c.LOG, Log(timestamp=stamp(stamp_ns), level=level, message=text, name="supervisor", line=event.line))
    ]


def launcher_log(stamp_ns: int, event: LauncherEvent) -> Out:
    bad = event.event in ("died", "gave_up", "timeout")
    text = f"{event.service}: {event.event}" + (f" ({event.message})" if event.message else "")
    level = LogLevel.Warning if bad else LogLevel.Info
    return [(c.LOG, Log(timestamp=stamp(stamp_ns), level=level, message=text, name="launcher"))]


_PY_LEVELS = {
    "DEBUG": LogLevel.Debug,
    "INFO": LogLevel.Info,
    "WARNING": LogLevel.Warning,
    "ERROR": LogLevel.Error,
    "CRITICAL": LogLevel.Fatal,
}


def service_log(stamp_ns: int, line: LogLine) -> Out:
    """A service's Python log line (:mod:`services.bus.buslog`), stamped with the record's own time."""
    when = int(line.wall_time_s * 1e9) if line.wall_time_s > 0 else stamp_ns
    log = Log(
        timestamp=stamp(when), level=_PY_LEVELS.get(line.level, LogLevel.Unknown), message=line.message,
        name=f"{line.service} ({line.logger})", file=line.file, line=line.line,
    )  # fmt: skip
    return [(c.LOG, log)]


def error_log(stamp_ns: int, service: str, endpoint: str, error: ErrorInfo) -> Out:
    text = f"{endpoint}: {error.code}: {error.message}"
    level = LogLevel.Error if error.code == "internal" else LogLevel.Warning
    return [(c.LOG, Log(timestamp=stamp(stamp_ns), level=level, message=text, name=service))]
