"""Messages every service shares: heartbeats, error envelopes, launcher events."""

from __future__ import annotations

from typing import Any

import msgspec

from services.bus.limits import Point3, Size
from services.bus.spec import TopicSpec

#: The planners (footsteps, reaching, navigation, walking's goals) start from a measured ``q_start`` only
#: when both soles are within this of the ground [m] and of horizontal [rad]: a robot standing. The
#: supervisor asks walking to settle the feet when they are not (``walking/goal`` ``kind: settle``).
START_SOLE_MAX_HEIGHT_M = 0.005
START_SOLE_MAX_TILT_RAD = 0.02


class Heartbeat(msgspec.Struct, kw_only=True, frozen=True):
    """Published at 2 Hz on ``hrp/<robot>/<service>/heartbeat`` once a service is ready."""

    service: str
    pid: int
    seq: int
    wall_time_s: float  # time.time() of the publisher [s]
    uptime_s: float  # since the service became ready [s]
    requests_served: int
    requests_failed: int


class LogLine(msgspec.Struct, kw_only=True, frozen=True):
    """A Python log record of a service, published on ``hrp/<robot>/<service>/log``
    (:mod:`services.bus.buslog`; warnings and up by default)."""

    service: str
    pid: int
    level: str  # DEBUG, INFO, WARNING, ERROR or CRITICAL
    logger: str  # the Python logger's name, e.g. humanoid.walking
    message: str  # the formatted message (with the traceback of an exception, if any)
    file: str = ""
    line: int = 0
    wall_time_s: float = 0.0  # record's time.time() [s]


class ErrorInfo(msgspec.Struct, kw_only=True, frozen=True):
    """An error reply: ``code`` is one of services.errors.ERROR_CODES; ``message`` says what to do."""

    code: str
    message: str
    details: dict[str, Any] = msgspec.field(default_factory=dict)


class LauncherEvent(msgspec.Struct, kw_only=True, frozen=True):
    """A lifecycle event of the launcher: started, ready, died, restarting, gave_up, stopped."""

    service: str
    event: str
    pid: int = 0
    attempt: int = 0
    exit_code: int | None = None
    message: str = ""
    wall_time_s: float = 0.0


LAUNCHER_EVENTS = TopicSpec("launcher", "events", LauncherEvent, "service lifecycle events of `humanoid up`")


class Footstep(msgspec.Struct, kw_only=True, frozen=True):
    """A landing (footsteps/plan, reaching/reach): the ``side`` sole at (x, y) [m] with ``yaw`` [rad],
    world frame."""

    side: str
    x: float
    y: float
    yaw: float


class Sphere(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A sphere above the ground that a reaching arm keeps out of, its gripper included (a ball beside the
    one to grasp): centre [x, y, z], radius [m], world. ``hand_obstacles`` of footsteps/plan (the final
    posture) and of reaching/reach (the whole motion): paper 000's eqs. 12-13 on the arm's capsules
    (``services.ik.hand_obstacles``)."""

    center: Point3
    radius: Size
