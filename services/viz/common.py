"""Names and small helpers every converter shares: the world frame, the topics, timestamps, colours."""

from __future__ import annotations

from typing import Any

from foxglove.messages import Color, Point3, Timestamp

from services.errors import InvalidRequestError

#: The fixed frame of the 3D panel (z up, the sim's world frame).
WORLD = "world"

# Topics of the Foxglove view (live and in logs).
TF = "/tf"  # foxglove.FrameTransforms: world -> base -> links, ~30 Hz
ROBOT = "/robot"  # foxglove.SceneUpdate: the body, locked to the link frames
WORLD_OBJECTS = "/world/objects"  # SceneUpdate: what is there (the sim's objects)
MAP_OBSTACLES = "/map/obstacles"  # SceneUpdate: what the robot believes (the supervisor's map)
MAP_SIGHTINGS = "/map/sightings"  # SceneUpdate: perception's located objects and footprints
PLAN_PATH = "/plan/path"  # SceneUpdate: navigation's path
PLAN_FOOTSTEPS = "/plan/footsteps"  # SceneUpdate: planned soles, coloured by side
PLAN_SUPPORT = "/plan/support"  # SceneUpdate: support polygons at each landing
PLAN_COM_ZMP = "/plan/com_zmp"  # SceneUpdate: planned CoM and ZMP line strips
PLAN_SERIES = "/plan/com_zmp_series"  # JSON: the planned CoM/ZMP as numbers, for the Plot panel
PLAN_REACH = "/plan/reach"  # SceneUpdate: reaching target and the hand's path
PLAN_FOOTSTEP_PLANNER = "/plan/footstep_planner"  # SceneUpdate: footsteps/plan's result
SNAPSHOT = "/snapshot"  # foxglove.CompressedImage (png)
LOG = "/log"  # foxglove.Log: supervisor and launcher events, error replies, services' log lines


def camera_image_topic(camera: str) -> str:
    return f"/camera/{camera}/image"


def camera_calibration_topic(camera: str) -> str:
    return f"/camera/{camera}/calibration"


def stamp(ns: int) -> Timestamp:
    """A Foxglove timestamp from nanoseconds (the log time: the 3D panel looks frames up by it)."""
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return Timestamp(sec=sec, nsec=nsec)


def color(r: float, g: float, b: float, a: float = 1.0) -> Color:
    return Color(r=float(r), g=float(g), b=float(b), a=float(a))


def point(x: float, y: float, z: float = 0.0) -> Point3:
    return Point3(x=float(x), y=float(y), z=float(z))


LEFT_COLOR = color(0.2, 0.5, 1.0, 0.8)  # left soles: blue
RIGHT_COLOR = color(1.0, 0.35, 0.2, 0.8)  # right soles: red
COM_COLOR = color(0.1, 0.8, 0.2)
ZMP_COLOR = color(0.95, 0.75, 0.1)
PATH_COLOR = color(0.1, 0.9, 0.9)
MAP_COLOR = color(0.9, 0.3, 0.9, 0.35)


def start_ws_server(**kwargs: Any) -> Any:
    """``foxglove.start_server(**kwargs)``; a port already taken (another viewer server, a second
    ``humanoid view``) is an InvalidRequestError naming the port and how to choose another, not a
    traceback (nor, under ``humanoid up --foxglove``, a viz service dying at every restart)."""
    import foxglove

    try:
        return foxglove.start_server(**kwargs)
    except RuntimeError as exc:
        if "bind" not in str(exc).lower():
            raise
        where = f"{kwargs.get('host', '127.0.0.1')}:{kwargs.get('port', 8765)}"
        why = (
            "another server holds the port: choose another (humanoid view --port P, humanoid up "
            "--foxglove P, humanoid replay FILE --foxglove P)"
            if "in use" in str(exc).lower()
            else "this host has no such address (--host: 127.0.0.1, or one of this machine's addresses)"
        )
        raise InvalidRequestError(
            f"cannot serve Foxglove on {where}: {exc}; {why}", {"field": "port"}
        ) from exc
