"""Opening zenoh sessions from a :class:`BusConfig`, and the typed publisher/client built on them."""

from __future__ import annotations

import struct
import time
from typing import Any, TypeVar

import zenoh

from services.bus import keys
from services.bus.codec import decode, encode
from services.bus.config import BusConfig
from services.bus.schemas.common import ErrorInfo
from services.bus.spec import EndpointSpec, TopicSpec
from services.errors import RequestTimeoutError, UnavailableError, error_from_code

R = TypeVar("R")
_REQUEST_ID = struct.Struct("<Q")


def open_session(bus: BusConfig, *, as_hub: bool = False) -> zenoh.Session:
    """Open a zenoh session; close it (or use ``with``) before the interpreter exits."""
    return zenoh.open(bus.zenoh_config(as_hub=as_hub))


def request_id_bytes(request_id: int) -> bytes:
    return _REQUEST_ID.pack(request_id & 0xFFFF_FFFF_FFFF_FFFF)


def request_id_from(attachment: Any) -> int | None:
    """The request id carried as a sample's attachment, or None."""
    if attachment is None:
        return None
    raw = attachment.to_bytes() if hasattr(attachment, "to_bytes") else bytes(attachment)
    return _REQUEST_ID.unpack(raw)[0] if len(raw) == _REQUEST_ID.size else None


class TypedPublisher:
    """Publishes messages of one :class:`TopicSpec` (encoded with the bus codec)."""

    def __init__(self, session: zenoh.Session, robot: str, spec: TopicSpec) -> None:
        self.spec = spec
        self.key = keys.key(robot, spec.service, spec.name)
        self._pub = session.declare_publisher(self.key)

    def put(self, msg: Any) -> None:
        if not isinstance(msg, self.spec.message):
            raise TypeError(f"{self.key} carries {self.spec.message.__name__}, not {type(msg).__name__}")
        self._pub.put(encode(msg))

    def undeclare(self) -> None:
        self._pub.undeclare()


class Client:
    """Calls endpoints of running services; raises the typed error of an error reply.

    >>> client = Client(session, "hrp2")
    >>> reply = client.call(walking.PLAN, request, timeout_s=30)
    """

    def __init__(self, session: zenoh.Session, robot: str, default_timeout_s: float = 10.0) -> None:
        self.session = session
        self.robot = robot
        self.default_timeout_s = default_timeout_s

    def call(self, spec: EndpointSpec, request: Any, timeout_s: float | None = None) -> Any:
        """Send ``request`` to ``spec`` and return the decoded reply (an instance of ``spec.reply``)."""
        if not isinstance(request, spec.request):
            raise TypeError(f"{spec.path} takes {spec.request.__name__}, not {type(request).__name__}")
        return decode(self.call_raw(spec.service, spec.name, encode(request), timeout_s), spec.reply)

    def call_raw(self, service: str, name: str, payload: bytes, timeout_s: float | None = None) -> bytes:
        """Send raw request bytes; return the raw ok-reply bytes or raise the typed error."""
        timeout = self.default_timeout_s if timeout_s is None else timeout_s
        key = keys.key(self.robot, service, name)
        started = time.monotonic()
        replies = self.session.get(key, payload=payload, timeout=timeout)
        for reply in replies:
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
            raw = reply.err.payload.to_bytes()
            try:
                info = decode(raw, ErrorInfo)
            except Exception:
                info = ErrorInfo(code="internal", message=raw.decode("utf-8", "replace"))
            raise error_from_code(info.code, info.message, info.details)
        waited = time.monotonic() - started
        if waited < 0.9 * timeout and not self.is_alive(service):
            token = keys.alive(self.robot, service)
            raise UnavailableError(f"service {service!r} is not running (no liveliness token at {token})")
        raise RequestTimeoutError(f"{service}/{name} gave no reply within {timeout:.1f} s")

    def is_alive(self, service: str, timeout_s: float = 0.5) -> bool:
        return service in self.alive_services(timeout_s)

    def alive_services(self, timeout_s: float = 0.5) -> set[str]:
        """Names of the services whose liveliness token is present now."""
        found = set()
        for reply in self.session.liveliness().get(keys.all_alive(self.robot), timeout=timeout_s):
            if reply.ok is not None:
                found.add(keys.parse(str(reply.ok.key_expr))[1])
        return found

    def wait_for(self, services: list[str] | tuple[str, ...], timeout_s: float = 20.0) -> None:
        """Block until every named service is alive; UnavailableError naming the missing ones."""
        deadline = time.monotonic() + timeout_s
        missing = set(services)
        while True:
            missing = set(services) - self.alive_services()
            if not missing:
                return
            if time.monotonic() > deadline:
                raise UnavailableError(
                    f"service(s) {', '.join(sorted(missing))} not alive after {timeout_s:.0f} s"
                )
            time.sleep(0.05)
