"""Every key expression of the stack, built in one place: ``hrp/<robot>/<service>/<name>``.

Endpoints (queryables) and topics live at ``hrp/<robot>/<service>/<name>``. Each service also has:

* ``hrp/<robot>/<service>/alive``          liveliness token, declared when the service is ready;
* ``hrp/<robot>/<service>/heartbeat``      :class:`~services.bus.schemas.common.Heartbeat` at 2 Hz;
* ``hrp/<robot>/<service>/<name>/request`` a copy of every request it served (for MCAP + replay);
* ``hrp/<robot>/<service>/<name>/reply``   a copy of every ok reply it gave (the reply frame);
* ``hrp/<robot>/<service>/<name>/error``   a copy of every error reply (:class:`ErrorInfo` JSON).

The three copies of one exchange carry the same request id as their attachment (u64, little endian),
which the recorder stores as the MCAP message sequence number.

The launcher publishes its events at ``hrp/<robot>/launcher/events``.
"""

from __future__ import annotations

import re

PREFIX = "hrp"
_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def _check(part: str, what: str) -> str:
    if not _NAME.match(part):
        raise ValueError(f"{what} {part!r} must be lower_snake_case ([a-z][a-z0-9_]*)")
    return part


def key(robot: str, service: str, name: str) -> str:
    """``hrp/<robot>/<service>/<name>`` for an endpoint or topic."""
    return f"{PREFIX}/{_check(robot, 'robot')}/{_check(service, 'service')}/{_check(name, 'name')}"


def alive(robot: str, service: str) -> str:
    return key(robot, service, "alive")


def heartbeat(robot: str, service: str) -> str:
    return key(robot, service, "heartbeat")


def request_mirror(robot: str, service: str, endpoint: str) -> str:
    return key(robot, service, endpoint) + "/request"


def reply_mirror(robot: str, service: str, endpoint: str) -> str:
    return key(robot, service, endpoint) + "/reply"


def error_mirror(robot: str, service: str, endpoint: str) -> str:
    return key(robot, service, endpoint) + "/error"


def all_alive(robot: str) -> str:
    return f"{PREFIX}/{robot}/*/alive"


def all_heartbeats(robot: str) -> str:
    return f"{PREFIX}/{robot}/*/heartbeat"


def everything(robot: str | None = None) -> str:
    return f"{PREFIX}/**" if robot is None else f"{PREFIX}/{robot}/**"


def parse(key_expr: str) -> tuple[str, str, str]:
    """Split ``hrp/<robot>/<service>/<rest...>`` into (robot, service, rest)."""
    parts = str(key_expr).split("/", 3)
    if len(parts) < 4 or parts[0] != PREFIX:
        raise ValueError(f"{key_expr!r} is not a key of the form {PREFIX}/<robot>/<service>/<name>")
    return parts[1], parts[2], parts[3]
