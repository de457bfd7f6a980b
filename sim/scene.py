"""Scenes as data: parse and validate a scene YAML file, and lay it out (optionally randomized by a seed).

A scene file (``sim/scenes/<name>.yaml``) looks like::

    name: ball_fetch
    description: a green box with balls on it far from the robot, a yellow table elsewhere
    robot: {x: 0.0, y: 0.0, yaw: 0.0}            # where the soles' midpoint stands, heading [m, rad]
    floor: {colour: grey, friction: 1.0}
    objects:
      - {name: green_box, kind: box, size: [0.5, 0.5, 0.7], colour: green, xy: [3.5, 1.0],
         random: {x: [-0.3, 0.3], yaw: [-0.3, 0.3]}}
      - {name: orange_ball, kind: ball, radius: 0.05, colour: orange, on_top_of: green_box, xy: [0.1, 0.0]}

Object kinds and their geometry (every object is named; names are unique):

* ``box``: ``size`` [sx, sy, sz] full extents [m]; rests on its support.
* ``table``: ``size`` [sx, sy, height] [m]: a top 0.04 m thick at ``height``, four legs.
* ``chair``: ``size`` [sx, sy, seat height] [m] plus a backrest on the -x side, ``back_height`` above
  the seat.
* ``ball``: ``radius`` [m].
* ``bar``: a horizontal cylinder, ``length`` and ``radius`` [m], its axis along the object's x axis.
* ``disk``: a flat region on the floor, ``radius`` [m]: drawn but without collision (the footstep
  paper's virtual obstacle that feet must avoid).

Placement: ``xy`` [m] and ``yaw`` [rad] in the world frame, or relative to the
centre and heading of the top surface of an object declared earlier (``on_top_of: <name>``; not
``on``, which YAML reads as ``true``). ``z`` [m] (the object's centre
in the world) overrides the resting height. ``random: {x: [lo, hi], y: [lo, hi], yaw: [lo, hi]}`` adds
uniform offsets when the scene is laid out with a seed (objects on the same support never overlap).
``mass`` [kg]: 0 makes the object static; defaults per kind (balls 0.1, bars 0.5, others static).
Colours are names from :data:`COLOURS` or ``[r, g, b]`` / ``[r, g, b, a]`` in [0, 1]; the named ones
are saturated and far apart in hue so that perception can learn Hue-Saturation histograms.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from services.bus.schemas.rectangle import Rectangle
from services.errors import InvalidRequestError, NotFoundError

SCENES_DIR = Path(__file__).resolve().parent / "scenes"

# Saturated, well separated hues (HSV hue in degrees in the comments) + unsaturated neutrals.
COLOURS: dict[str, tuple[float, float, float, float]] = {
    "red": (0.85, 0.05, 0.05, 1.0),  # 0
    "orange": (1.0, 0.45, 0.0, 1.0),  # 27
    "yellow": (1.0, 0.88, 0.0, 1.0),  # 53
    "green": (0.05, 0.7, 0.1, 1.0),  # 124
    "cyan": (0.0, 0.75, 0.85, 1.0),  # 187
    "blue": (0.05, 0.2, 0.95, 1.0),  # 228
    "purple": (0.55, 0.05, 0.85, 1.0),  # 277
    "brown": (0.45, 0.32, 0.22, 1.0),
    "grey": (0.55, 0.55, 0.55, 1.0),
    "light_grey": (0.78, 0.78, 0.76, 1.0),
    "white": (0.95, 0.95, 0.95, 1.0),
    "dark": (0.2, 0.2, 0.22, 1.0),
}

KINDS = ("box", "table", "chair", "ball", "bar", "disk")
TABLE_TOP_THICKNESS_M = 0.04
TABLE_LEG_WIDTH_M = 0.05
CHAIR_BACK_THICKNESS_M = 0.04
DISK_THICKNESS_M = 0.002
_DEFAULT_MASS_KG = {"ball": 0.1, "bar": 0.5}

_TOP_KEYS = ("name", "description", "robot", "floor", "objects")
_ROBOT_KEYS = ("x", "y", "yaw", "random", "posture")
_POSTURE_KEYS = ("base_z", "pitch", "joints")
_FLOOR_KEYS = ("colour", "friction")
_RANDOM_KEYS = ("x", "y", "yaw")
_OBJECT_KEYS = {
    "common": ("name", "kind", "colour", "xy", "yaw", "z", "on_top_of", "random", "mass", "friction"),
    "box": ("size",),
    "table": ("size",),
    "chair": ("size", "back_height"),
    "ball": ("radius",),
    "bar": ("length", "radius"),
    "disk": ("radius",),
}
_REQUIRED = {
    "box": ("size",),
    "table": ("size",),
    "chair": ("size",),
    "ball": ("radius",),
    "bar": ("length", "radius"),
    "disk": ("radius",),
}


@dataclass(frozen=True)
class RandomRange:
    """Uniform offsets applied when a layout is drawn with a seed: x, y [m], yaw [rad] as (lo, hi)."""

    x: tuple[float, float] = (0.0, 0.0)
    y: tuple[float, float] = (0.0, 0.0)
    yaw: tuple[float, float] = (0.0, 0.0)

    def sample(self, rng: np.random.Generator) -> tuple[float, float, float]:
        return (float(rng.uniform(*self.x)), float(rng.uniform(*self.y)), float(rng.uniform(*self.yaw)))

    @property
    def is_zero(self) -> bool:
        return self.x == (0.0, 0.0) and self.y == (0.0, 0.0) and self.yaw == (0.0, 0.0)


@dataclass(frozen=True)
class ObjectSpec:
    """One object of a scene file, as written (placement not yet resolved)."""

    name: str
    kind: str
    colour: tuple[float, float, float, float]
    xy: tuple[float, float] = (0.0, 0.0)
    yaw_rad: float = 0.0
    z_m: float | None = None
    on: str | None = None
    random: RandomRange = field(default_factory=RandomRange)
    mass_kg: float = 0.0
    friction: float = 0.8
    size_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius_m: float = 0.0
    length_m: float = 0.0
    back_height_m: float = 0.4

    @property
    def is_static(self) -> bool:
        return self.mass_kg == 0.0

    @property
    def height_m(self) -> float:
        """Vertical extent of the object [m] (chairs: seat height)."""
        if self.kind in ("box", "table", "chair"):
            return self.size_m[2]
        if self.kind == "ball":
            return 2.0 * self.radius_m
        if self.kind == "bar":
            return 2.0 * self.radius_m
        return DISK_THICKNESS_M

    @property
    def footprint_radius_m(self) -> float:
        """Radius of a vertical cylinder around the object [m] (to keep randomized objects apart)."""
        if self.kind in ("box", "table", "chair"):
            return 0.5 * math.hypot(self.size_m[0], self.size_m[1])
        if self.kind == "bar":
            return 0.5 * self.length_m
        return self.radius_m

    @property
    def top_height_m(self) -> float:
        """Height of the supporting top surface above the object's bottom [m]."""
        return self.height_m

    @property
    def centre_height_m(self) -> float:
        """Height of the object's reference point (its pybullet base) above its bottom [m].

        Boxes, balls, bars, disks: the geometric centre. Tables and chairs: the floor (legs start there).
        """
        if self.kind in ("table", "chair"):
            return 0.0
        return 0.5 * self.height_m


@dataclass(frozen=True)
class RobotPosture:
    """A start posture other than half-sitting (``robot.posture`` in a scene file, e.g. seated on a
    chair): the base (waist) height ``base_z_m`` [m] and pitch ``pitch_rad`` [rad] (the heading is the
    scene's ``robot.yaw``, the base's x, y the scene's ``robot.x``, ``robot.y``) and joint values
    [rad] overriding half-sitting (``joints: {NAME: value}``)."""

    base_z_m: float
    pitch_rad: float
    joints: tuple[tuple[str, float], ...]


@dataclass(frozen=True)
class SceneSpec:
    """A parsed scene file. ``robot_posture`` None: the robot starts in half-sitting with its soles'
    midpoint at ``robot_xy``; otherwise its base is at ``robot_xy`` in that posture."""

    name: str
    description: str
    robot_xy: tuple[float, float]
    robot_yaw_rad: float
    robot_random: RandomRange
    floor_colour: tuple[float, float, float, float]
    floor_friction: float
    objects: tuple[ObjectSpec, ...]
    robot_posture: RobotPosture | None = None

    def object(self, name: str) -> ObjectSpec:
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise NotFoundError(f"scene {self.name} has no object {name!r}; objects: {self.names()}")

    def names(self) -> list[str]:
        return [o.name for o in self.objects]


@dataclass(frozen=True)
class PlacedObject:
    """An object with its resolved world pose: ``position`` of its reference point [m], ``yaw_rad``."""

    spec: ObjectSpec
    position: tuple[float, float, float]
    yaw_rad: float

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def top_z_m(self) -> float:
        """World height of the top surface [m]."""
        return self.position[2] - self.spec.centre_height_m + self.spec.top_height_m


@dataclass(frozen=True)
class Layout:
    """A scene laid out for one seed: robot start pose on the floor and every object's pose."""

    scene: SceneSpec
    seed: int | None
    robot_xy: tuple[float, float]
    robot_yaw_rad: float
    objects: tuple[PlacedObject, ...]

    def object(self, name: str) -> PlacedObject:
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise NotFoundError(f"scene {self.scene.name} has no object {name!r}; objects: {self.scene.names()}")


# ------------------------------------------------------------------------------------------------ parsing
def available_scenes() -> list[str]:
    """Names of the scenes shipped in ``sim/scenes``."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.yaml"))


def scene_path(name_or_path: str | Path) -> Path:
    """The file of a shipped scene name, or an explicit ``.yaml`` path."""
    text = str(name_or_path)
    if text.endswith((".yaml", ".yml")):
        path = Path(text)
        if not path.is_file():
            raise NotFoundError(f"scene file {path} does not exist")
        return path
    path = SCENES_DIR / f"{text}.yaml"
    if not path.is_file():
        raise NotFoundError(f"unknown scene {text!r}; available scenes: {', '.join(available_scenes())}")
    return path


def load_scene(name_or_path: str | Path) -> SceneSpec:
    """Read and validate a scene (a shipped name such as ``ball_fetch`` or a YAML path)."""
    path = scene_path(name_or_path)
    try:
        doc = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise InvalidRequestError(f"scene file {path} is not valid YAML: {exc}") from None
    return parse_scene(doc, source=str(path))


def parse_scene(doc: Any, source: str = "<scene>") -> SceneSpec:
    """Validate a scene document (the parsed YAML mapping) into a :class:`SceneSpec`."""
    doc = _mapping(source, doc, _TOP_KEYS)
    name = _string(f"{source}: name", doc.get("name", Path(source).stem))
    robot = _mapping(f"{source}: robot", doc.get("robot") or {}, _ROBOT_KEYS)
    floor = _mapping(f"{source}: floor", doc.get("floor") or {}, _FLOOR_KEYS)
    raw_objects = doc.get("objects") or []
    if not isinstance(raw_objects, list):
        raise InvalidRequestError(f"{source}: objects must be a list of mappings")
    objects: list[ObjectSpec] = []
    for i, raw in enumerate(raw_objects):
        obj = _parse_object(f"{source}: objects[{i}]", raw)
        if obj.name in (o.name for o in objects):
            raise InvalidRequestError(
                f"{source}: object name {obj.name!r} is used twice; names must be unique"
            )
        if obj.on is not None:
            support = next((o for o in objects if o.name == obj.on), None)
            if support is None:
                raise InvalidRequestError(
                    f"{source}: object {obj.name!r} is on {obj.on!r}, which is not declared before it "
                    f"(declared so far: {[o.name for o in objects]})"
                )
            if support.kind in ("ball", "bar", "disk"):
                raise InvalidRequestError(f"{source}: object {obj.name!r} cannot rest on a {support.kind}")
        objects.append(obj)
    return SceneSpec(
        name=name,
        description=str(doc.get("description", "")),
        robot_xy=(
            _number(f"{source}: robot.x", robot.get("x", 0.0)),
            _number(f"{source}: robot.y", robot.get("y", 0.0)),
        ),
        robot_yaw_rad=_number(f"{source}: robot.yaw", robot.get("yaw", 0.0)),
        robot_random=_parse_random(f"{source}: robot.random", robot.get("random")),
        floor_colour=_colour(f"{source}: floor.colour", floor.get("colour", "light_grey")),
        floor_friction=_positive(f"{source}: floor.friction", floor.get("friction", 1.0)),
        objects=tuple(objects),
        robot_posture=_parse_posture(f"{source}: robot.posture", robot.get("posture")),
    )


def _parse_posture(where: str, raw: Any) -> RobotPosture | None:
    if raw is None:
        return None
    raw = _mapping(where, raw, _POSTURE_KEYS)
    if "base_z" not in raw:
        raise InvalidRequestError(f"{where}: a posture needs 'base_z' (the waist height [m])")
    joints = raw.get("joints") or {}
    if not isinstance(joints, dict):
        raise InvalidRequestError(f"{where}.joints: expected a mapping of joint names to values [rad]")
    return RobotPosture(
        base_z_m=_positive(f"{where}.base_z", raw["base_z"]),
        pitch_rad=_number(f"{where}.pitch", raw.get("pitch", 0.0)),
        joints=tuple((str(k), _number(f"{where}.joints.{k}", v)) for k, v in joints.items()),
    )


def _parse_object(where: str, raw: Any) -> ObjectSpec:
    if not isinstance(raw, dict):
        raise InvalidRequestError(f"{where}: expected a mapping, got {type(raw).__name__}")
    kind = raw.get("kind")
    if kind not in KINDS:
        raise InvalidRequestError(f"{where}: kind must be one of {list(KINDS)}, got {kind!r}")
    allowed = _OBJECT_KEYS["common"] + _OBJECT_KEYS[kind]
    _mapping(where, raw, allowed)
    name = _string(f"{where}: name", raw.get("name"))
    where = f"{where} ({name})"
    for key in ("name", *_REQUIRED[kind]):
        if key not in raw:
            raise InvalidRequestError(f"{where}: a {kind} needs {key!r}")
    values: dict[str, Any] = {
        "name": name,
        "kind": kind,
        "colour": _colour(f"{where}: colour", raw.get("colour", "grey")),
        "xy": _vector(f"{where}: xy", raw.get("xy", [0.0, 0.0]), 2),
        "yaw_rad": _number(f"{where}: yaw", raw.get("yaw", 0.0)),
        "z_m": None if raw.get("z") is None else _number(f"{where}: z", raw["z"]),
        "on": None if raw.get("on_top_of") is None else _string(f"{where}: on_top_of", raw["on_top_of"]),
        "random": _parse_random(f"{where}: random", raw.get("random")),
        "mass_kg": _non_negative(f"{where}: mass", raw.get("mass", _DEFAULT_MASS_KG.get(kind, 0.0))),
        "friction": _positive(f"{where}: friction", raw.get("friction", 0.8)),
    }
    if "size" in raw:
        size = _vector(f"{where}: size", raw["size"], 3)
        if min(size) <= 0.0:
            raise InvalidRequestError(f"{where}: size entries must be positive, got {list(size)}")
        values["size_m"] = size
    if "radius" in raw:
        values["radius_m"] = _positive(f"{where}: radius", raw["radius"])
    if "length" in raw:
        values["length_m"] = _positive(f"{where}: length", raw["length"])
    if "back_height" in raw:
        values["back_height_m"] = _positive(f"{where}: back_height", raw["back_height"])
    if kind == "table" and values["size_m"][2] <= TABLE_TOP_THICKNESS_M:
        raise InvalidRequestError(f"{where}: a table must be higher than its top ({TABLE_TOP_THICKNESS_M} m)")
    if kind == "disk" and values["mass_kg"] != 0.0:
        raise InvalidRequestError(f"{where}: a disk is a floor region and cannot have a mass")
    return ObjectSpec(**values)


def _parse_random(where: str, raw: Any) -> RandomRange:
    if raw is None:
        return RandomRange()
    raw = _mapping(where, raw, _RANDOM_KEYS)
    ranges = {}
    for key in _RANDOM_KEYS:
        lo, hi = _vector(f"{where}.{key}", raw.get(key, [0.0, 0.0]), 2)
        if lo > hi:
            raise InvalidRequestError(f"{where}.{key}: lower bound {lo} is above the upper bound {hi}")
        ranges[key] = (lo, hi)
    return RandomRange(**ranges)


def _mapping(where: str, value: Any, keys: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise InvalidRequestError(f"{where}: expected a mapping, got {type(value).__name__}")
    unknown = sorted(set(value) - set(keys))
    if unknown:
        raise InvalidRequestError(f"{where}: unknown keys {unknown}; valid keys are {list(keys)}")
    return value


def _string(where: str, value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise InvalidRequestError(f"{where}: expected a non-empty string, got {value!r}")
    return value


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InvalidRequestError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _positive(where: str, value: Any) -> float:
    x = _number(where, value)
    if x <= 0.0:
        raise InvalidRequestError(f"{where}: must be positive, got {x}")
    return x


def _non_negative(where: str, value: Any) -> float:
    x = _number(where, value)
    if x < 0.0:
        raise InvalidRequestError(f"{where}: must not be negative, got {x}")
    return x


def _vector(where: str, value: Any, n: int) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != n:
        raise InvalidRequestError(f"{where}: expected a list of {n} numbers, got {value!r}")
    return tuple(_number(f"{where}[{i}]", v) for i, v in enumerate(value))


def _colour(where: str, value: Any) -> tuple[float, float, float, float]:
    if isinstance(value, str):
        if value not in COLOURS:
            raise InvalidRequestError(f"{where}: unknown colour {value!r}; named colours: {sorted(COLOURS)}")
        return COLOURS[value]
    if isinstance(value, list | tuple) and len(value) in (3, 4):
        rgba = tuple(_number(f"{where}[{i}]", v) for i, v in enumerate(value))
        if not all(0.0 <= c <= 1.0 for c in rgba):
            raise InvalidRequestError(f"{where}: colour components must be in [0, 1], got {list(rgba)}")
        return (*rgba, 1.0) if len(rgba) == 3 else rgba  # type: ignore[return-value]
    raise InvalidRequestError(f"{where}: expected a colour name or [r, g, b(, a)], got {value!r}")


# ------------------------------------------------------------------------------------------------ layout
def layout(scene: SceneSpec, seed: int | None = None, max_tries: int = 200) -> Layout:
    """Resolve every object's world pose; with a ``seed``, draw the ``random`` offsets (reproducibly).

    Objects sharing a support (the floor or another object) are redrawn until their footprint circles
    do not overlap; :class:`InvalidRequestError` if ``max_tries`` draws do not separate them.
    """
    rng = np.random.default_rng(seed) if seed is not None else None
    dx, dy, dyaw = scene.robot_random.sample(rng) if rng is not None else (0.0, 0.0, 0.0)
    robot_xy = (scene.robot_xy[0] + dx, scene.robot_xy[1] + dy)
    robot_yaw = scene.robot_yaw_rad + dyaw
    placed: dict[str, PlacedObject] = {}
    for spec in scene.objects:
        tries = max_tries if (rng is not None and not spec.random.is_zero) else 1
        for _ in range(tries):
            obj = _place(spec, placed, rng)
            if rng is None or spec.random.is_zero or _fits(obj, placed, robot_xy):
                break
        else:
            raise InvalidRequestError(
                f"scene {scene.name}: could not place {spec.name!r} without overlapping its neighbours "
                f"in {max_tries} draws (seed {seed}); shrink its random ranges"
            )
        placed[spec.name] = obj
    return Layout(scene, seed, robot_xy, robot_yaw, tuple(placed.values()))


def _place(
    spec: ObjectSpec, placed: dict[str, PlacedObject], rng: np.random.Generator | None
) -> PlacedObject:
    ox, oy, oyaw = spec.random.sample(rng) if rng is not None else (0.0, 0.0, 0.0)
    local_x, local_y, yaw = spec.xy[0] + ox, spec.xy[1] + oy, spec.yaw_rad + oyaw
    if spec.on is None:
        x, y, base_z = local_x, local_y, 0.0
    else:
        support = placed[spec.on]
        c, s = math.cos(support.yaw_rad), math.sin(support.yaw_rad)
        x = support.position[0] + c * local_x - s * local_y
        y = support.position[1] + s * local_x + c * local_y
        yaw += support.yaw_rad
        base_z = support.top_z_m
    z = spec.z_m if spec.z_m is not None else base_z + spec.centre_height_m
    return PlacedObject(spec, (x, y, z), _wrap(yaw))


ROBOT_CLEARANCE_M = 0.45  # randomized floor objects stay this far from the robot's start [m]


def _fits(obj: PlacedObject, placed: dict[str, PlacedObject], robot_xy: tuple[float, float]) -> bool:
    """A randomized draw is kept if it overlaps nothing on the same support, stays on its support's
    top and keeps clear of the robot."""
    if obj.spec.kind == "disk":
        return True
    for other in placed.values():
        if other.spec.on != obj.spec.on or other.spec.kind == "disk":
            continue
        distance = math.hypot(obj.position[0] - other.position[0], obj.position[1] - other.position[1])
        if distance < obj.spec.footprint_radius_m + other.spec.footprint_radius_m:
            return False
    if obj.spec.on is None:
        distance = math.hypot(obj.position[0] - robot_xy[0], obj.position[1] - robot_xy[1])
        return distance > obj.spec.footprint_radius_m + ROBOT_CLEARANCE_M
    support = placed[obj.spec.on]
    size = (support.spec.size_m[0], support.spec.size_m[1])
    top = Rectangle((support.position[0], support.position[1]), size, support.yaw_rad)
    return top.grown(-obj.spec.footprint_radius_m).contains(obj.position[:2])


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def with_object(scene: SceneSpec, obj: ObjectSpec) -> SceneSpec:
    """A copy of ``scene`` with ``obj`` added (tests and scripted set-ups)."""
    if obj.name in scene.names():
        raise InvalidRequestError(f"scene {scene.name} already has an object {obj.name!r}")
    return replace(scene, objects=(*scene.objects, obj))


def find_scene(name: str, folders: Sequence[str | Path] = ()) -> Path:
    """The file of the scene ``name`` (a name, never a path): ``sim/scenes`` first, then ``folders`` in
    order (a service's ``scene_dirs``, e.g. layouts written by a benchmark). NotFoundError lists the
    names available there."""
    dirs = [SCENES_DIR, *(Path(f) for f in folders)]
    for folder in dirs:
        if (folder / f"{name}.yaml").is_file():
            return folder / f"{name}.yaml"
    names = sorted({p.stem for f in dirs if f.is_dir() for p in f.glob("*.yaml")})
    raise NotFoundError(f"unknown scene {name!r}; available scenes: {', '.join(names)}", {"field": "scene"})
