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

* each endpoint gets a bounded queue (:data:`QUEUE_CAPACITY` requests) and one worker thread that
  takes the queries from it in order and runs the handler; zenoh's callback only puts the query in
  the queue, and a query that finds it full is refused at once (``unavailable``, reason ``busy``),
  so a slow or flooded endpoint never stalls zenoh's delivery to the service's other endpoints. Each
  subscription gets a zenoh FIFO channel and a worker. The endpoints of a service run concurrently,
  each endpoint serves one request at a time. A handler declared ``blocking=False`` (microseconds,
  never waits) runs in zenoh's callback instead: no hand-off;
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
import logging
import os
import queue
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import zenoh

from services.bus import encodings, keys
from services.bus.codec import decode, decode_request, encode, to_builtins
from services.bus.config import BusConfig, load_bus_config, load_section
from services.bus.schemas.common import ErrorInfo, Heartbeat
from services.bus.session import (
    Client,
    MatchingFlag,
    RequestIds,
    TypedPublisher,
    close_session,
    open_session,
    request_id_bytes,
)
from services.bus.spec import EndpointSpec, TopicSpec
from services.errors import HumanoidError, InternalError

HEARTBEAT_PERIOD_S = 0.5
#: Queries (or samples) waiting for a busy handler. A query finding its endpoint's queue full is refused
#: at once (``unavailable``, ``REASON_BUSY``); a subscription's full queue holds zenoh's delivery back.
QUEUE_CAPACITY = 64
#: ``details["reason"]`` of the ``unavailable`` reply to a request that finds its endpoint's queue full.
REASON_BUSY = "busy"
#: ``details["reason"]`` of the ``unavailable`` reply to a request still queued when the service stops.
REASON_STOPPING = "stopping"
#: A stopping service exits after this long even if a handler is still running [s].
EXIT_DEADLINE_S = 0.9


@dataclass(frozen=True)
class NoConfig:
    """For services without options."""


def handles(
    spec: EndpointSpec, *, blocking: bool = True
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Mark a method as the handler of ``spec``: ``handler(self, request) -> reply``.

    ``blocking=False`` declares a handler that takes microseconds and never waits (no bus call, no
    I/O, no lock held by a slow thread): it then runs in zenoh's callback thread, which saves the
    hand-off to a worker thread (a context switch per request). A planner keeps the default.
    """

    def mark(fn: Callable[..., Any]) -> Callable[..., Any]:
        fn.__bus_endpoint__ = spec  # type: ignore[attr-defined]
        fn.__bus_blocking__ = blocking  # type: ignore[attr-defined]
        return fn

    return mark


def subscribes(
    spec: TopicSpec, *, blocking: bool = True
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Mark a method as the subscriber of ``spec``: ``handler(self, message) -> None``.

    ``blocking=False``: as for :func:`handles`, the handler runs in zenoh's callback thread.
    """

    def mark(fn: Callable[..., Any]) -> Callable[..., Any]:
        fn.__bus_topic__ = spec  # type: ignore[attr-defined]
        fn.__bus_blocking__ = blocking  # type: ignore[attr-defined]
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

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        """Command-line options of this service beyond the common ones (``python -m <module> --help``)."""

    @classmethod
    def configure(cls, config: Any, args: argparse.Namespace) -> Any:
        """The config to run with, given the YAML one and the parsed options of :meth:`add_arguments`."""
        return config

    # Helpers ----------------------------------------------------------------------------------------
    def publisher(self, spec: TopicSpec, **options: Any) -> TypedPublisher:
        """A typed publisher on this service's session (options: see TypedPublisher)."""
        return TypedPublisher(self.session, self.bus.robot, spec, **options)


@dataclass
class _EndpointStats:
    """Requests one endpoint answered, for the heartbeat. Counted from the endpoint's worker and from
    zenoh's callback threads (a busy refusal, a ``blocking=False`` handler) at once: under ``lock``,
    so that no increment is lost."""

    served: int = 0
    failed: int = 0
    lock: threading.Lock = dataclasses.field(default_factory=threading.Lock, repr=False, compare=False)

    def count(self, ok: bool) -> None:
        """One more request answered: served (``ok``) or failed."""
        with self.lock:
            if ok:
                self.served += 1
            else:
                self.failed += 1


class _Mirror:
    """A publisher of request/reply copies that knows, for free, whether anyone subscribes.

    With no recorder (or ``humanoid echo``) listening, serving a request publishes nothing.
    """

    def __init__(self, session: zenoh.Session, key: str) -> None:
        # BLOCK, not zenoh's default DROP: a large reply copy (a goto's 1.4 MB, a render's 2.4 MB)
        # published right after the reply itself found the transmission queue full and was dropped,
        # so logs lost replies (7 of 416 in a demo log) and the live view missed plans. The copy
        # waits for room in this process's queue to the hub instead (the reply is already sent).
        self._pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        self._flag = MatchingFlag(self._pub)

    @property
    def matching(self) -> bool:
        return self._flag.matching

    def put(self, payload: bytes, attachment: bytes, encoding: zenoh.Encoding) -> None:
        self._pub.put(payload, attachment=attachment, encoding=encoding)

    def undeclare(self) -> None:
        self._flag.undeclare()
        self._pub.undeclare()


class _Runtime:
    """Declarations, workers and health of one running service instance."""

    def __init__(self, service: Service) -> None:
        self.service = service
        self.stopping = threading.Event()
        self.stats: dict[str, _EndpointStats] = {}
        self._ids = RequestIds()
        self._channels: list[Any] = []  # queryables and subscribers: undeclared first at shutdown
        self._queues: list[queue.SimpleQueue[Any]] = []  # requests waiting for an endpoint's worker
        self._declared: list[Any] = []
        self._threads: list[threading.Thread] = []

    def declare(self) -> None:
        svc = self.service
        for attr in dir(type(svc)):
            fn = getattr(type(svc), attr)
            blocking = getattr(fn, "__bus_blocking__", True)
            spec = getattr(fn, "__bus_endpoint__", None)
            if spec is not None:
                self._declare_endpoint(spec, getattr(svc, attr), blocking)
            topic = getattr(fn, "__bus_topic__", None)
            if topic is not None:
                self._declare_subscription(topic, getattr(svc, attr), blocking)

    def _declare_endpoint(self, spec: EndpointSpec, handler: Callable[[Any], Any], blocking: bool) -> None:
        svc = self.service
        robot = svc.bus.robot
        if spec.service != svc.name:
            raise ValueError(f"{svc.name} cannot serve {spec.path}: it belongs to service {spec.service}")
        mirrors = tuple(
            _Mirror(svc.session, k(robot, spec.service, spec.name))
            for k in (keys.request_mirror, keys.reply_mirror, keys.error_mirror)
        )
        self._declared.extend(mirrors)
        stats = self.stats.setdefault(spec.path, _EndpointStats())
        key = keys.key(robot, spec.service, spec.name)

        def serve_one(query: zenoh.Query) -> None:
            self._serve_one(spec, handler, query, mirrors, stats, key)

        if not blocking:
            self._channels.append(svc.session.declare_queryable(key, serve_one))
            return
        # A bounded queue filled from zenoh's callback, never blocking it: a zenoh FIFO channel that is
        # full holds zenoh's delivery thread, and with it every other endpoint of the service (90 queued
        # diag/stream requests held a diag/echo for 10.6 s). A request finding the queue full is
        # refused at once, ``unavailable`` with ``details.reason`` "busy".
        # queue.SimpleQueue (C, no lock of its own in Python) and a depth count: a queue.Queue's
        # Condition cost the hand-off ~60 us per request (scripts/bench bus, the worker thread row)
        pending: queue.SimpleQueue[zenoh.Query | None] = queue.SimpleQueue()
        depth = [0]  # requests in ``pending`` (zenoh may call back from several threads: under ``lock``)
        lock = threading.Lock()
        self._queues.append(pending)

        def enqueue(query: zenoh.Query) -> None:  # zenoh's callback thread: microseconds
            with lock:
                full = depth[0] >= QUEUE_CAPACITY
                if not full:
                    depth[0] += 1
            if full:
                self._refuse_busy(spec, query, stats)
            else:
                pending.put(query)

        self._channels.append(svc.session.declare_queryable(key, enqueue))

        def work() -> None:
            while (query := pending.get()) is not None:  # None: the service stops
                with lock:
                    depth[0] -= 1
                try:
                    serve_one(query)
                except Exception:  # a bug after the reply (its copies): the endpoint serves on
                    svc.log.error("%s: after the reply:\n%s", spec.path, traceback.format_exc())

        self._start_worker(spec.path, work)

    def _refuse_busy(self, spec: EndpointSpec, query: zenoh.Query, stats: _EndpointStats) -> None:
        frame = error_frame(
            "unavailable",
            f"{spec.path} is busy: {QUEUE_CAPACITY} requests are waiting for it; try again later",
            {"reason": REASON_BUSY, "waiting": QUEUE_CAPACITY},
        )
        # zenoh's callback thread: replying to the query in hand does not wait (as a blocking=False
        # handler's reply); what CONVENTIONS forbids there is waiting, or calling another endpoint
        with contextlib.suppress(zenoh.ZError):
            query.reply_err(frame, encoding=encodings.JSON)
        with contextlib.suppress(zenoh.ZError):
            query.drop()
        stats.count(ok=False)

    def _serve_one(
        self,
        spec: EndpointSpec,
        handler: Callable[[Any], Any],
        query: zenoh.Query,
        mirrors: tuple[_Mirror, _Mirror, _Mirror],
        stats: _EndpointStats,
        key: str,
    ) -> None:
        raw = query.payload.to_bytes() if query.payload is not None else b""
        ok, frame = self._handle(spec, handler, raw)
        try:
            if ok:
                # the endpoint's own key, not the query's: a query may name it with wildcards
                # (``hrp/*/sim/state``), and zenoh refuses a reply on a key with wildcards
                query.reply(key, frame, encoding=encodings.of_frame(frame))
            else:
                query.reply_err(frame, encoding=encodings.JSON)
        except zenoh.ZError as exc:
            self.service.log.warning("could not reply to a %s request: %s", spec.path, exc)
        finally:
            with contextlib.suppress(zenoh.ZError):
                query.drop()  # the final message: the caller stops waiting now
        stats.count(ok)
        mirror_request, mirror_reply, mirror_error = mirrors
        outcome = mirror_reply if ok else mirror_error
        if mirror_request.matching or outcome.matching:
            rid = request_id_bytes(self._ids.next())
            with contextlib.suppress(zenoh.ZError):
                mirror_request.put(raw, rid, encodings.of_bytes(raw))
                outcome.put(frame, rid, encodings.of_frame(frame))

    def _handle(self, spec: EndpointSpec, handler: Callable[[Any], Any], raw: bytes) -> tuple[bool, bytes]:
        """Run one request: ``(True, reply frame)`` or ``(False, error frame)``; never raises."""
        log = self.service.log
        try:
            request = decode_request(raw or b"{}", spec.request)
            reply = handler(request)
            if not isinstance(reply, spec.reply):
                raise InternalError(
                    f"{spec.path} handler returned {type(reply).__name__}, expected {spec.reply.__name__}"
                )
            return True, encode(reply)
        except HumanoidError as exc:
            log.info("%s -> %s: %s", spec.path, exc.code, exc.message)
            return False, error_frame(exc.code, exc.message, exc.details)
        except Exception as exc:  # a bug in the handler: reply internal, keep serving
            if self.stopping.is_set() and isinstance(exc, zenoh.ZError):
                log.info("%s interrupted by the shutdown: %s", spec.path, exc)
            else:
                log.error("%s raised:\n%s", spec.path, traceback.format_exc())
            return False, error_frame("internal", f"{type(exc).__name__}: {exc}")

    def _declare_subscription(self, spec: TopicSpec, handler: Callable[[Any], Any], blocking: bool) -> None:
        svc = self.service
        key = keys.key(svc.bus.robot, spec.service, spec.name)

        def consume_one(sample: zenoh.Sample) -> None:
            try:
                handler(decode(sample.payload.to_bytes(), spec.message))
            except HumanoidError as exc:
                svc.log.warning("dropped a %s message: %s", spec.path, exc.message)
            except Exception:
                svc.log.error("subscriber of %s raised:\n%s", spec.path, traceback.format_exc())

        if not blocking:
            self._channels.append(svc.session.declare_subscriber(key, consume_one))
            return
        subscriber = svc.session.declare_subscriber(key, zenoh.handlers.FifoChannel(QUEUE_CAPACITY))
        self._channels.append(subscriber)
        channel = subscriber.handler

        def consume() -> None:
            while True:
                try:
                    sample = channel.recv()
                except zenoh.ZError:
                    return
                consume_one(sample)

        self._start_worker(f"sub:{spec.path}", consume)

    def announce(self) -> None:
        svc = self.service
        self._token = svc.session.liveliness().declare_token(keys.alive(svc.bus.robot, svc.name))
        self._start_worker("heartbeat", self._heartbeat)

    def _heartbeat(self) -> None:
        svc = self.service
        pub = svc.session.declare_publisher(keys.heartbeat(svc.bus.robot, svc.name))
        self._declared.append(pub)
        started = time.monotonic()
        seq = 0
        while True:
            beat = Heartbeat(
                service=svc.name,
                pid=os.getpid(),
                seq=seq,
                wall_time_s=time.time(),
                uptime_s=time.monotonic() - started,
                requests_served=sum(s.served for s in self.stats.values()),
                requests_failed=sum(s.failed for s in self.stats.values()),
            )
            seq += 1
            try:
                pub.put(encode(beat), encoding=encodings.JSON)
            except zenoh.ZError:
                return
            if self.stopping.wait(HEARTBEAT_PERIOD_S):
                return

    def _start_worker(self, name: str, target: Callable[[], None]) -> None:
        thread = threading.Thread(target=target, name=f"{self.service.name}:{name}", daemon=True)
        thread.start()
        self._threads.append(thread)

    def withdraw(self) -> None:
        """Stop being visible and taking work: liveliness token, queryables and subscribers go."""
        self.stopping.set()
        token = getattr(self, "_token", None)
        for declared in ([token] if token is not None else []) + self._channels:
            with contextlib.suppress(zenoh.ZError):
                declared.undeclare()
        stopping = error_frame(
            "unavailable", f"{self.service.name} is stopping: not served", {"reason": REASON_STOPPING}
        )
        for pending in self._queues:  # the workers stop after the request they serve
            with contextlib.suppress(queue.Empty):
                while True:
                    waiting = pending.get_nowait()
                    if isinstance(waiting, zenoh.Query):  # its one reply: not served (samples: dropped)
                        with contextlib.suppress(zenoh.ZError):
                            waiting.reply_err(stopping, encoding=encodings.JSON)
                        with contextlib.suppress(zenoh.ZError):
                            waiting.drop()
            pending.put(None)

    def shutdown(self, deadline: float) -> None:
        """Wait for the workers (until ``deadline``, monotonic) and undeclare the publishers."""
        for thread in self._threads:
            thread.join(timeout=max(0.0, deadline - time.monotonic()))
        for declared in reversed(self._declared):
            with contextlib.suppress(zenoh.ZError):
                declared.undeclare()


def error_frame(code: str, message: str, details: dict[str, Any] | None = None) -> bytes:
    """The payload of an error reply (:class:`ErrorInfo` JSON)."""
    return encode(ErrorInfo(code=code, message=message, details=_jsonable(details or {})))


def _jsonable(details: dict[str, Any]) -> dict[str, Any]:
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
    bus_log_level: str | None = None,
) -> None:
    """Run ``service_type`` until ``stop`` is set (in this thread; the session is closed on return).
    Log records at ``bus_log_level`` and up go on the bus too (:mod:`services.bus.buslog`)."""
    from services.bus import buslog

    session = open_session(bus, identity=service_type.name)
    bus_log = None
    try:
        service = service_type(config, bus, session)
        runtime = _Runtime(service)
        runtime.declare()
        bus_log = buslog.attach(session, bus.robot, service.name, bus_log_level)
        service.start()
        runtime.announce()
        service.log.info("ready (pid %d) on %s", os.getpid(), keys.alive(bus.robot, service.name))
        if ready is not None:
            ready(service)
        stop.wait()
        deadline = time.monotonic() + 0.5
        service.log.info("stopping")
        runtime.withdraw()
        try:
            service.stop()
        finally:
            runtime.shutdown(deadline)
    finally:
        if bus_log is not None:
            bus_log.close()
        close_session(session)


def _module_name(service_type: type[Service]) -> str:
    """The importable module of a service class, also when it runs as ``python -m module``."""
    module = service_type.__module__
    if module == "__main__":
        spec = getattr(sys.modules["__main__"], "__spec__", None)
        module = spec.name if spec is not None else service_type.name
    return module


def service_argparser(service_type: type[Service]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=f"python -m {_module_name(service_type)}",
        description=(service_type.__doc__ or service_type.name).strip().splitlines()[0],
    )
    parser.add_argument("--config", help="YAML file: a 'bus:' section and a section named after the service")
    parser.add_argument("--robot", help="robot name in the key expressions (default: hrp2)")
    parser.add_argument("--hub", help="zenoh endpoint of the hub, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--log-level", default="INFO", help="DEBUG, INFO, WARNING or ERROR")
    parser.add_argument(
        "--bus-log-level",
        help="log records published on hrp/<robot>/<service>/log from this level up: DEBUG, INFO, "
        "WARNING, ERROR or OFF (default: $HUMANOID_BUS_LOG_LEVEL, else WARNING)",
    )
    parser.add_argument(
        "--parent-pid",
        type=int,
        help="stop when this process (the launcher) is gone: no orphan service if it is killed",
    )
    service_type.add_arguments(parser)
    return parser


def run_service(
    service_type: type[Service], argv: list[str] | None = None, *, config: Any | None = None
) -> int:
    """Command-line entry of a service process: parse options, serve until SIGTERM/SIGINT.

    ``config`` replaces the one read from the YAML section (services with options of their own).
    """
    args = service_argparser(service_type).parse_args(argv)
    configure_logging(args.log_level)
    log = logging.getLogger(f"humanoid.{service_type.name}")
    try:
        bus = load_bus_config(args.config, robot=args.robot, hub=args.hub)
        if config is None:
            config = load_section(args.config, service_type.name, service_type.Config)
        config = service_type.configure(config, args)
        from services.bus.buslog import level_from

        level_from(args.bus_log_level)
    except HumanoidError as exc:
        log.error("%s", exc.message)
        return 2
    except ValueError as exc:  # a bad --bus-log-level
        log.error("%s", exc)
        return 2
    stop = threading.Event()

    def on_signal(signum: int, _frame: Any) -> None:
        if not stop.is_set():
            stop.set()
            _exit_after(EXIT_DEADLINE_S, log)

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    if args.parent_pid:
        _watch_parent(args.parent_pid, stop, log)
    try:
        serve(service_type, config, bus, stop, bus_log_level=args.bus_log_level)
    except HumanoidError as exc:
        log.error("%s", exc.message)
        return 2
    exit_if_still_busy(service_type.name, log)
    return 0


def exit_if_still_busy(name: str, log: logging.Logger) -> None:
    """Exit at once (status 0) when a thread of service ``name`` (``name:...``) is still running after
    its orderly stop: a handler past the stop's deadline, a zenoh call still waiting. The interpreter's
    finalization would end such a thread inside zenoh's native code, and glibc aborts the process then
    ("FATAL: exception not rethrown", exit -6). The same hard exit as :func:`_exit_after`'s."""
    busy = [t.name for t in threading.enumerate() if t.name.startswith(f"{name}:") and t.is_alive()]
    if busy:
        log.info("still busy after the stop (%s): exiting now", ", ".join(busy))
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)


def _exit_after(delay_s: float, log: logging.Logger) -> None:
    """Hard exit if the orderly shutdown overruns (a handler stuck in a long computation)."""

    def expire() -> None:
        log.warning("shutdown took longer than %.1f s: exiting now", delay_s)
        logging.shutdown()
        os._exit(0)

    timer = threading.Timer(delay_s, expire)
    timer.daemon = True
    timer.start()


def _watch_parent(parent_pid: int, stop: threading.Event, log: logging.Logger) -> None:
    def watch() -> None:
        while not stop.wait(0.25):
            if os.getppid() != parent_pid:
                log.warning("launcher (pid %d) is gone: stopping", parent_pid)
                stop.set()
                _exit_after(EXIT_DEADLINE_S, log)
                return

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def configure_logging(level: str = "INFO") -> None:
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
    )


def config_with(config: Any, **changes: Any) -> Any:
    """A copy of a frozen config with ``changes`` (tests and the launcher)."""
    return dataclasses.replace(config, **changes)
