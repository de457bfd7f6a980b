"""The service base: a service is a thin adapter declaring typed endpoints over a pure package.

::

    class WalkingService(Service):
        name = "walking"
        Config = WalkingConfig            # frozen dataclass, defaults in code, YAML section "walking"

        @handles(schemas.walking.PLAN)
        def plan(self, request: PlanRequest) -> PlanReply:
            return to_reply(pure_planner(...))   # raise InfeasibleError(...) etc.

    if __name__ == "__main__":
        raise SystemExit(run_service(WalkingService))

What the base does for every service:

* each endpoint's queries are queued by the zenoh callback (which must not block) and served in
  order by one worker thread per endpoint;
* a payload that does not decode, or does not match the request type, gets an ``invalid_request``
  error reply naming the field and the expected type; an exception in a handler gets ``internal``;
  a :class:`~services.errors.HumanoidError` gets its own code. The service keeps serving;
* a copy of each request and reply is published on ``<endpoint>/request`` and ``<endpoint>/reply``
  (or ``/error``) with the request id as attachment, so the recorder logs them and replay can
  re-send them;
* when ready: a liveliness token ``hrp/<robot>/<service>/alive`` and a 2 Hz heartbeat;
* SIGTERM/SIGINT: undeclare, close the session, exit within a second.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import itertools
import logging
import os
import queue
import signal
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import zenoh

from services.bus import keys
from services.bus.codec import decode, encode
from services.bus.config import BusConfig, load_bus_config, load_section
from services.bus.schemas.common import ErrorInfo, Heartbeat
from services.bus.session import Client, TypedPublisher, open_session, request_id_bytes
from services.bus.spec import EndpointSpec, TopicSpec
from services.errors import HumanoidError, InternalError

HEARTBEAT_PERIOD_S = 0.5
_QUEUE_LIMIT = 64


@dataclass(frozen=True)
class NoConfig:
    """For services without options."""


def handles(spec: EndpointSpec) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Mark a method as the handler of ``spec``: ``handler(self, request) -> reply``."""

    def mark(fn: Callable[..., Any]) -> Callable[..., Any]:
        fn.__bus_endpoint__ = spec  # type: ignore[attr-defined]
        return fn

    return mark


def subscribes(spec: TopicSpec) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Mark a method as the subscriber of ``spec``: ``handler(self, message) -> None``."""

    def mark(fn: Callable[..., Any]) -> Callable[..., Any]:
        fn.__bus_topic__ = spec  # type: ignore[attr-defined]
        return fn

    return mark


class Service:
    """Base class of every service; see the module docstring."""

    name: ClassVar[str]
    Config: ClassVar[type] = NoConfig

    def __init__(self, config: Any, bus: BusConfig, session: zenoh.Session) -> None:
        self.config = config
        self.bus = bus
        self.session = session
        self.client = Client(session, bus.robot)
        self.log = logging.getLogger(f"humanoid.{self.name}")

    # Hooks for subclasses -------------------------------------------------------------------------
    def start(self) -> None:
        """Called once the endpoints are declared, before the service announces itself ready."""

    def stop(self) -> None:
        """Called on shutdown, before the session closes."""

    # Helpers ----------------------------------------------------------------------------------------
    def publisher(self, spec: TopicSpec) -> TypedPublisher:
        return TypedPublisher(self.session, self.bus.robot, spec)


class _Runtime:
    """Declarations, workers and health of one running service instance."""

    def __init__(self, service: Service) -> None:
        self.service = service
        self.stopping = threading.Event()
        self.served = 0
        self.failed = 0
        self._ids = itertools.count(int.from_bytes(os.urandom(3), "little") << 32)
        self._declared: list[Any] = []
        self._threads: list[threading.Thread] = []

    def declare(self) -> None:
        svc = self.service
        for attr in dir(type(svc)):
            fn = getattr(type(svc), attr)
            spec = getattr(fn, "__bus_endpoint__", None)
            if spec is not None:
                self._declare_endpoint(spec, getattr(svc, attr))
            topic = getattr(fn, "__bus_topic__", None)
            if topic is not None:
                self._declare_subscription(topic, getattr(svc, attr))

    def _declare_endpoint(self, spec: EndpointSpec, handler: Callable[[Any], Any]) -> None:
        svc = self.service
        robot = svc.bus.robot
        if spec.service != svc.name:
            raise ValueError(f"{svc.name} cannot serve {spec.path}: it belongs to service {spec.service}")
        mirrors = tuple(
            svc.session.declare_publisher(k(robot, spec.service, spec.name))
            for k in (keys.request_mirror, keys.reply_mirror, keys.error_mirror)
        )
        pending: queue.Queue[Any] = queue.Queue(maxsize=_QUEUE_LIMIT)

        def on_query(query: zenoh.Query) -> None:  # zenoh thread: never block here
            try:
                pending.put_nowait(query)
            except queue.Full:
                query.reply_err(_error_frame("unavailable", f"{spec.path} is overloaded, retry later"))
                query.drop()

        endpoint_key = keys.key(robot, spec.service, spec.name)
        self._declared.append(svc.session.declare_queryable(endpoint_key, on_query))
        self._declared.extend(mirrors)
        self._start_worker(f"{spec.path}", lambda: self._serve(spec, handler, pending, mirrors))

    def _serve(self, spec: EndpointSpec, handler: Callable[[Any], Any], pending: queue.Queue[Any], mirrors):
        mirror_request, mirror_reply, mirror_error = mirrors
        while not self.stopping.is_set():
            try:
                query = pending.get(timeout=0.1)
            except queue.Empty:
                continue
            rid = request_id_bytes(next(self._ids))
            try:
                raw = query.payload.to_bytes() if query.payload is not None else b""
                mirror_request.put(raw, attachment=rid)
                request = decode(raw or b"{}", spec.request)
                reply = handler(request)
                if not isinstance(reply, spec.reply):
                    raise InternalError(
                        f"{spec.path} handler returned {type(reply).__name__}, expected {spec.reply.__name__}"
                    )
                frame = encode(reply)
                query.reply(query.key_expr, frame)
                mirror_reply.put(frame, attachment=rid)
                self.served += 1
            except Exception as exc:  # every failure becomes an error reply; the service keeps serving
                self.failed += 1
                if isinstance(exc, HumanoidError):
                    code, message, details = exc.code, exc.message, exc.details
                    self.service.log.info("%s -> %s: %s", spec.path, code, message)
                else:
                    code, message, details = "internal", f"{type(exc).__name__}: {exc}", {}
                    self.service.log.error("%s raised:\n%s", spec.path, traceback.format_exc())
                frame = _error_frame(code, message, details)
                try:
                    query.reply_err(frame)
                    mirror_error.put(frame, attachment=rid)
                except zenoh.ZError:
                    self.service.log.warning("could not send the error reply of %s", spec.path)
            finally:
                query.drop()

    def _declare_subscription(self, spec: TopicSpec, handler: Callable[[Any], Any]) -> None:
        svc = self.service
        inbox: queue.Queue[Any] = queue.Queue(maxsize=_QUEUE_LIMIT)

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                inbox.put_nowait(sample.payload.to_bytes())
            except queue.Full:
                svc.log.warning("dropping a %s message: handler too slow", spec.path)

        def consume() -> None:
            while not self.stopping.is_set():
                try:
                    raw = inbox.get(timeout=0.1)
                except queue.Empty:
                    continue
                try:
                    handler(decode(raw, spec.message))
                except Exception:
                    svc.log.error("subscriber of %s raised:\n%s", spec.path, traceback.format_exc())

        key = keys.key(svc.bus.robot, spec.service, spec.name)
        self._declared.append(svc.session.declare_subscriber(key, on_sample))
        self._start_worker(f"sub:{spec.path}", consume)

    def announce(self) -> None:
        svc = self.service
        self._declared.append(svc.session.liveliness().declare_token(keys.alive(svc.bus.robot, svc.name)))
        self._start_worker("heartbeat", self._heartbeat)

    def _heartbeat(self) -> None:
        svc = self.service
        pub = svc.session.declare_publisher(keys.heartbeat(svc.bus.robot, svc.name))
        self._declared.append(pub)
        started = time.monotonic()
        for seq in itertools.count():
            beat = Heartbeat(
                service=svc.name,
                pid=os.getpid(),
                seq=seq,
                wall_time_s=time.time(),
                uptime_s=time.monotonic() - started,
                requests_served=self.served,
                requests_failed=self.failed,
            )
            try:
                pub.put(encode(beat))
            except zenoh.ZError:
                return
            if self.stopping.wait(HEARTBEAT_PERIOD_S):
                return

    def _start_worker(self, name: str, target: Callable[[], None]) -> None:
        thread = threading.Thread(target=target, name=f"{self.service.name}:{name}", daemon=True)
        thread.start()
        self._threads.append(thread)

    def shutdown(self) -> None:
        self.stopping.set()
        for thread in self._threads:
            thread.join(timeout=0.3)
        for declared in reversed(self._declared):
            with contextlib.suppress(zenoh.ZError):
                declared.undeclare()


def _error_frame(code: str, message: str, details: dict[str, Any] | None = None) -> bytes:
    return encode(ErrorInfo(code=code, message=message, details=_jsonable(details or {})))


def _jsonable(details: dict[str, Any]) -> dict[str, Any]:
    from services.bus.codec import to_builtins

    try:
        return to_builtins(details)
    except Exception:
        return {k: repr(v) for k, v in details.items()}


def serve(
    service_type: type[Service],
    config: Any,
    bus: BusConfig,
    stop: threading.Event,
    ready: Callable[[Service], None] | None = None,
) -> None:
    """Run ``service_type`` until ``stop`` is set (in this thread; the session is closed on return)."""
    session = open_session(bus)
    try:
        service = service_type(config, bus, session)
        runtime = _Runtime(service)
        runtime.declare()
        service.start()
        runtime.announce()
        service.log.info("ready (pid %d) on %s", os.getpid(), keys.key(bus.robot, service.name, "alive"))
        if ready is not None:
            ready(service)
        stop.wait()
        service.log.info("stopping")
        try:
            service.stop()
        finally:
            runtime.shutdown()
    finally:
        session.close()


def service_argparser(service_type: type[Service]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=f"humanoid service {service_type.name}",
        description=(service_type.__doc__ or service_type.name).strip().splitlines()[0],
    )
    parser.add_argument("--config", help="YAML file: a 'bus:' section and a section named after the service")
    parser.add_argument("--robot", help="robot name in the key expressions (default: hrp2)")
    parser.add_argument("--hub", help="zenoh endpoint of the hub, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--log-level", default="INFO", help="DEBUG, INFO, WARNING or ERROR")
    return parser


def run_service(service_type: type[Service], argv: list[str] | None = None) -> int:
    """Command-line entry of a service process: parse options, serve until SIGTERM/SIGINT."""
    args = service_argparser(service_type).parse_args(argv)
    configure_logging(args.log_level)
    try:
        bus = load_bus_config(args.config, robot=args.robot, hub=args.hub)
        config = load_section(args.config, service_type.name, service_type.Config)
    except HumanoidError as exc:
        logging.getLogger("humanoid").error("%s", exc.message)
        return 2
    stop = threading.Event()

    def on_signal(signum: int, _frame: Any) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    serve(service_type, config, bus, stop)
    return 0


def configure_logging(level: str = "INFO") -> None:
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
    )


def config_with(config: Any, **changes: Any) -> Any:
    """A copy of a frozen config with ``changes`` (tests and the launcher)."""
    return dataclasses.replace(config, **changes)
