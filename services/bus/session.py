"""Opening zenoh sessions from a :class:`BusConfig`, and the typed publisher/subscriber/client on them."""

from __future__ import annotations

import contextlib
import itertools
import os
import struct
import time
from collections.abc import Iterator
from typing import Any, TypeVar

import zenoh

from services.bus import encodings, keys
from services.bus.codec import decode, encode
from services.bus.config import BusConfig
from services.bus.schemas.common import ErrorInfo
from services.bus.shm import cleanup_segments
from services.bus.spec import EndpointSpec, TopicSpec
from services.errors import RequestTimeoutError, UnavailableError, error_from_code

R = TypeVar("R")
_REQUEST_ID = struct.Struct("<Q")
_ID_MASK = 0xFFFF_FFFF


def open_session(bus: BusConfig, *, as_hub: bool = False, identity: str = "") -> zenoh.Session:
    """Open a zenoh session; close it (or use :func:`bus_session`) before the interpreter exits.

    ``identity``: who opens it when the bus config does not say (a service passes its name), see
    :attr:`BusConfig.identity`."""
    try:
        return zenoh.open(bus.zenoh_config(as_hub=as_hub, identity=identity))
    except zenoh.ZError as exc:
        if as_hub:
            raise UnavailableError(
                f"cannot listen on the hub endpoint {bus.hub} ({exc}); is another `humanoid up` running? "
                "Stop it or choose another hub (--hub, or `hub:` in the bus section of the config)"
            ) from None
        raise UnavailableError(f"cannot open a zenoh session: {exc}") from None


@contextlib.contextmanager
def bus_session(bus: BusConfig, *, as_hub: bool = False) -> Iterator[zenoh.Session]:
    """A session closed on exit, then this process's orphaned shared-memory segments removed."""
    session = open_session(bus, as_hub=as_hub)
    try:
        yield session
    finally:
        close_session(session)


def close_session(session: zenoh.Session) -> None:
    """Close ``session`` and unlink the ``/dev/shm`` segments nobody else holds (see services.bus.shm)."""
    with contextlib.suppress(zenoh.ZError):
        session.close()
    cleanup_segments()


def request_id_bytes(request_id: int) -> bytes:
    """The attachment carrying a request id: u64 little endian (values fit in 32 bits, see RequestIds)."""
    return _REQUEST_ID.pack(request_id & 0xFFFF_FFFF_FFFF_FFFF)


def request_id_from(attachment: Any) -> int | None:
    """The request id carried as a sample's attachment, or None."""
    if attachment is None:
        return None
    raw = attachment.to_bytes() if hasattr(attachment, "to_bytes") else bytes(attachment)
    return _REQUEST_ID.unpack(raw)[0] if len(raw) == _REQUEST_ID.size else None


class RequestIds:
    """Request ids of one service process: a random non-zero 32-bit start, then +1 (wrapping, never 0).

    32 bits because the recorder stores them as the MCAP message ``sequence`` (a u32); the random
    start keeps the ids of a restarted service apart from the ones it gave before.
    """

    def __init__(self) -> None:
        self._count = itertools.count(int.from_bytes(os.urandom(4), "little"))

    def next(self) -> int:
        while True:
            value = next(self._count) & _ID_MASK
            if value:
                return value


class MatchingFlag:
    """Whether any subscriber matches a zenoh publisher, kept current by a matching listener.

    Reading :attr:`matching` costs nothing, so a publisher can skip building messages nobody
    receives (the sim's 200 Hz state, the request/reply mirrors).
    """

    def __init__(self, publisher: zenoh.Publisher) -> None:
        self.matching = False
        self._listener = publisher.declare_matching_listener(self._on_matching)  # zenoh thread, rare
        self.matching = publisher.matching_status.matching

    def _on_matching(self, status: Any) -> None:
        self.matching = status.matching

    def undeclare(self) -> None:
        with contextlib.suppress(zenoh.ZError):
            self._listener.undeclare()


class TypedPublisher:
    """Publishes messages of one :class:`TopicSpec` (encoded with the bus codec)."""

    def __init__(
        self,
        session: zenoh.Session,
        robot: str,
        spec: TopicSpec,
        *,
        congestion_control: zenoh.CongestionControl | None = None,
        track_matching: bool = False,
    ) -> None:
        """``congestion_control``: zenoh's default DROP drops messages to a subscriber whose queue is
        full (right for camera streams); BLOCK makes ``put`` wait instead. ``track_matching``: keep
        :attr:`matching` current (a :class:`MatchingFlag`, one listener thread)."""
        self.spec = spec
        self.key = keys.key(robot, spec.service, spec.name)
        options = {} if congestion_control is None else {"congestion_control": congestion_control}
        self._pub = session.declare_publisher(self.key, **options)
        self._matching = MatchingFlag(self._pub) if track_matching else None

    @property
    def matching(self) -> bool:
        """Whether a subscriber receives this topic now (always True without ``track_matching``)."""
        return self._matching is None or self._matching.matching

    def put(self, msg: Any) -> None:
        if not isinstance(msg, self.spec.message):
            raise TypeError(f"{self.key} carries {self.spec.message.__name__}, not {type(msg).__name__}")
        frame = encode(msg)
        self._pub.put(frame, encoding=encodings.of_frame(frame))

    def undeclare(self) -> None:
        if self._matching is not None:
            self._matching.undeclare()
        with contextlib.suppress(zenoh.ZError):
            self._pub.undeclare()


class TypedSubscriber:
    """Receives decoded messages of one :class:`TopicSpec` outside a service (tools, benchmarks).

    Messages wait in a zenoh FIFO channel of ``capacity`` messages; ``recv`` takes them in order.
    A message that does not decode raises :class:`~services.errors.InvalidRequestError` from ``recv``.
    """

    def __init__(self, session: zenoh.Session, robot: str, spec: TopicSpec, capacity: int = 256) -> None:
        self.spec = spec
        self.key = keys.key(robot, spec.service, spec.name)
        self._sub = session.declare_subscriber(self.key, zenoh.handlers.FifoChannel(capacity))
        self._handler = self._sub.handler

    def recv(self, timeout_s: float | None = None) -> Any:
        """The next message, or TimeoutError after ``timeout_s``.

        Without a timeout it blocks in zenoh without the GIL (the lowest latency, but Ctrl-C waits
        for the next message); with one it polls, sleeping up to 1 ms between looks.
        """
        if timeout_s is None:
            sample = self._handler.recv()
        else:
            deadline = time.monotonic() + timeout_s
            pause = 0.00005
            while (sample := self._handler.try_recv()) is None:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"no message on {self.key} within {timeout_s:.1f} s")
                time.sleep(pause)
                pause = min(0.001, pause * 2)
        return decode(sample.payload.to_bytes(), self.spec.message)

    def undeclare(self) -> None:
        with contextlib.suppress(zenoh.ZError):
            self._sub.undeclare()


#: The error payload zenoh itself replies with when a query times out (not an ErrorInfo).
ZENOH_TIMEOUT = b"Timeout"


class Client:
    """Calls endpoints of running services; raises the typed error of an error reply.

    >>> client = Client(session, "hrp2")
    >>> reply = client.call(walking.PLAN, request, timeout_s=30)
    """

    def __init__(self, session: zenoh.Session, robot: str, default_timeout_s: float = 10.0) -> None:
        self.session = session
        self.robot = robot
        self.default_timeout_s = default_timeout_s
        self._keys: dict[tuple[str, str], str] = {}

    def call(self, spec: EndpointSpec, request: Any, timeout_s: float | None = None) -> Any:
        """Send ``request`` to ``spec`` and return the decoded reply (an instance of ``spec.reply``)."""
        if not isinstance(request, spec.request):
            raise TypeError(f"{spec.path} takes {spec.request.__name__}, not {type(request).__name__}")
        return decode(self.call_raw(spec.service, spec.name, encode(request), timeout_s), spec.reply)

    def call_raw(self, service: str, name: str, payload: bytes, timeout_s: float | None = None) -> bytes:
        """Send raw request bytes; return the raw ok-reply bytes or raise the typed error."""
        timeout = self.default_timeout_s if timeout_s is None else timeout_s
        key = self._keys.get((service, name))
        if key is None:
            key = self._keys[(service, name)] = keys.key(self.robot, service, name)
        started = time.monotonic()
        label = encodings.of_frame(payload)
        replies = self.session.get(key, payload=payload, encoding=label, timeout=timeout)
        for reply in replies:
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
            raw = reply.err.payload.to_bytes()
            if raw == ZENOH_TIMEOUT:
                break  # zenoh's own end of the query: no reply in time (below)
            raise error_from_reply(raw)
        waited = time.monotonic() - started
        if waited < 0.9 * timeout and not self.is_alive(service):
            token = keys.alive(self.robot, service)
            raise UnavailableError(
                f"service {service!r} is not running (no liveliness token at {token}); "
                f"start it with `humanoid up --services {service}`"
            )
        raise RequestTimeoutError(f"{service}/{name} gave no reply within {timeout:.1f} s")

    def is_alive(self, service: str, timeout_s: float = 0.5) -> bool:
        return service in self.alive_services(timeout_s)

    def alive_services(self, timeout_s: float = 0.5) -> set[str]:
        """Names of the services whose liveliness token is present now."""
        return alive_services(self.session, self.robot, timeout_s)

    def wait_for(self, services: list[str] | tuple[str, ...], timeout_s: float = 20.0) -> None:
        """Block until every named service is alive; UnavailableError naming the missing ones."""
        deadline = time.monotonic() + timeout_s
        while True:
            missing = set(services) - self.alive_services()
            if not missing:
                return
            if time.monotonic() > deadline:
                raise UnavailableError(
                    f"service(s) {', '.join(sorted(missing))} not alive after {timeout_s:.0f} s"
                )
            time.sleep(0.05)


def alive_services(session: zenoh.Session, robot: str, timeout_s: float = 0.5) -> set[str]:
    """Names of the services of ``robot`` whose liveliness token is present now."""
    found = set()
    for reply in session.liveliness().get(keys.all_alive(robot), timeout=timeout_s):
        if reply.ok is not None:
            found.add(keys.parse(str(reply.ok.key_expr))[1])
    return found


def error_from_reply(raw: bytes) -> Exception:
    """The typed exception of an error-reply frame (:class:`ErrorInfo` JSON)."""
    try:
        info = decode(raw, ErrorInfo)
    except Exception:
        info = ErrorInfo(code="internal", message=raw.decode("utf-8", "replace"))
    return error_from_code(info.code, info.message, info.details)
