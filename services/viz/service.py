"""``viz``: the live Foxglove view, a WebSocket server (Foxglove's protocol, foxglove-sdk) fed by the bus.

Started by ``humanoid up --foxglove [PORT]`` (a service of the launcher, in its own process: the
converters never run in the sim's or a planner's) or ``humanoid view`` against a running stack.
Open Foxglove, "Open connection", Foxglove WebSocket, ``ws://127.0.0.1:8765``.

It subscribes to what the converters read (:func:`services.viz.converter.key_exprs`: the joint
state, the plans' requests and replies, events, error replies and log lines, not ``hrp/**``) and
serves the topics of :mod:`services.viz.common` (the same as the
recorder's views): the zenoh callback only decides whether a message is wanted (joint states are
taken at ``transform_hz`` of wall time, and only while a viewer watches ``/tf``) and hands it to one
worker thread through a bounded queue, holding at most one joint state (the converters' slowest
input must not crowd the plans out); when the queue is full the message is dropped (``dropped``),
never queued further. The SDK's server keeps at most ``backlog`` messages per viewer and drops the
oldest for a slow one. A viewer that subscribes to a topic gets its latest message again at once
(the map, the plans, the robot's body).

``world_poll_s`` > 0: while a viewer watches ``/world/objects``, the service asks ``sim/ground_truth``
that often, so "what is there" can be shown against "what the robot believes" (``/map/*``). This
is a viewer's privilege: the supervisor and the planners never read ground truth.
"""

from __future__ import annotations

import argparse
import contextlib
import queue
import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

import foxglove
import zenoh
from foxglove.websocket import ServerListener

from services.bus import world
from services.bus.config import from_mapping
from services.bus.schemas.sim import GROUND_TRUTH
from services.bus.service import Service, run_service
from services.errors import InvalidRequestError
from services.viz import common as c
from services.viz.converter import Converter, encoded, key_exprs, route


@dataclass(frozen=True)
class VizConfig:
    """Options of the live view (YAML section ``viz``).

    Attributes:
        host: address the WebSocket server listens on (loopback by default).
        port: its TCP port (0: any free port, printed in the log).
        model: robot model ("": recognised from the joint state's size).
        transform_hz: rate of the robot's transforms [Hz of wall time].
        queue_capacity: bus messages waiting for the converters; more are dropped.
        backlog: messages the server keeps per viewer; the oldest are dropped for a slow viewer.
        world_poll_s: period of sim/ground_truth requests while /world/objects is watched [s]; 0: never.
    """

    host: str = "127.0.0.1"
    port: int = 8765
    model: str = ""
    transform_hz: float = 30.0
    queue_capacity: int = 64
    backlog: int = 256
    world_poll_s: float = 1.0

    def __post_init__(self) -> None:
        if not 0 <= self.port < 65536:
            raise InvalidRequestError(f"port {self.port} is not a TCP port (0..65535)")
        if self.transform_hz <= 0 or self.queue_capacity <= 0 or self.backlog <= 0 or self.world_poll_s < 0:
            raise InvalidRequestError(
                "transform_hz, queue_capacity and backlog must be > 0, world_poll_s >= 0"
            )


class _Listener(ServerListener):
    """Counts subscriptions per topic (SDK thread: only touches a counter and a queue); the SDK's
    other callbacks keep their no-op defaults."""

    def __init__(self, resend: queue.Queue[Any]) -> None:
        self.lock = threading.Lock()
        self.topics: Counter[str] = Counter()
        self._resend = resend

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self.lock:
            self.topics[channel.topic] += 1
        with contextlib.suppress(queue.Full):
            self._resend.put_nowait(("resend", channel.topic, 0))

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self.lock:
            self.topics[channel.topic] = max(0, self.topics[channel.topic] - 1)

    def watched(self, topic: str) -> bool:
        with self.lock:
            return self.topics[topic] > 0


class VizService(Service):
    """Serves the stack to Foxglove over its WebSocket protocol (see the module docstring)."""

    name = "viz"
    Config = VizConfig

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--port", type=int, help="WebSocket port (default: the config's, 8765)")
        parser.add_argument("--host", help="address to listen on (default 127.0.0.1)")

    @classmethod
    def configure(cls, config: VizConfig, args: argparse.Namespace) -> VizConfig:
        values = dict(config.__dict__)
        if getattr(args, "port", None) is not None:
            values["port"] = args.port
        if getattr(args, "host", None):
            values["host"] = args.host
        return from_mapping(VizConfig, values, where="--port/--host")

    def start(self) -> None:
        cfg: VizConfig = self.config
        self.converter = Converter(cfg.model, cfg.transform_hz)
        self.dropped = 0
        self.served = 0
        self._period_ns = int(1e9 / cfg.transform_hz)
        self._next_tf_ns = 0
        self._tf_pending = False
        self._inbox: queue.Queue[Any] = queue.Queue(maxsize=cfg.queue_capacity)
        self._listener = _Listener(self._inbox)
        self._context = foxglove.Context()
        self._channels: dict[str, foxglove.Channel] = {}
        self._last: dict[str, tuple[bytes, int]] = {}
        self._done = threading.Event()
        for topic, msg in _static_topics():
            self._channel(topic, msg)
        self.server = c.start_ws_server(
            name=f"humanoid {self.bus.robot}",
            host=cfg.host,
            port=cfg.port,
            context=self._context,
            server_listener=self._listener,
            message_backlog_size=cfg.backlog,
        )
        self.port = self.server.port
        self._worker = threading.Thread(target=self._work, name="viz:convert", daemon=True)
        self._worker.start()
        self._subscribers = [
            self.session.declare_subscriber(key_expr, self._on_sample)
            for key_expr in key_exprs(self.bus.robot)
        ]
        self._poller = None
        if cfg.world_poll_s > 0:
            self._poller = threading.Thread(target=self._poll_world, name="viz:world", daemon=True)
            self._poller.start()
        self.log.info("Foxglove WebSocket server on ws://%s:%d", cfg.host, self.port)

    # zenoh thread: decide and hand over, never block ------------------------------------------------
    def _on_sample(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        tail = route(key)
        if not tail:
            return
        now = time.time_ns()
        if tail == "sim/joint_state":
            # At most one joint state waits for the converters (the latest rate-limited one), so a
            # slow conversion never crowds the rare messages (plans, map) out of the queue.
            if self._tf_pending or now < self._next_tf_ns or not self._listener.watched(c.TF):
                return
            self._next_tf_ns = now + self._period_ns
            self._tf_pending = True
        try:
            self._inbox.put_nowait(("bus", key, (sample.payload.to_bytes(), now)))
        except queue.Full:
            self.dropped += 1
            if tail == "sim/joint_state":
                self._tf_pending = False

    # worker thread ------------------------------------------------------------------------------------
    def _work(self) -> None:
        while not self._done.is_set():
            try:
                kind, key, item = self._inbox.get(timeout=0.2)
            except queue.Empty:
                continue
            if kind == "resend":
                last = self._last.get(key)
                if last is not None:
                    self._channels[key].log(last[0], log_time=last[1])
                continue
            frame, t = item
            if key.endswith("/sim/joint_state"):
                self._tf_pending = False
            for topic, msg in self.converter.convert(key, frame, t):
                data = msg.encode()
                self._channel(topic, msg).log(data, log_time=t)
                if topic != c.TF:
                    self._last[topic] = (data, t)
                self.served += 1

    def _channel(self, topic: str, msg: Any) -> foxglove.Channel:
        channel = self._channels.get(topic)
        if channel is None:
            view = encoded(topic, msg, 0)
            schema = foxglove.Schema(
                name=view.schema_name, encoding=view.schema_encoding, data=view.schema_data
            )
            channel = self._channels[topic] = foxglove.Channel(
                topic, schema=schema, message_encoding=view.message_encoding, context=self._context
            )
        return channel

    def _poll_world(self) -> None:
        period = self.config.world_poll_s
        while not self._done.wait(period):
            if self._listener.watched(c.WORLD_OBJECTS):  # the reply's copy comes through _on_sample
                world.ask(self.session, self.bus.robot, GROUND_TRUTH, timeout_s=2.0)

    def stop(self) -> None:
        self._done.set()
        for subscriber in self._subscribers:
            with contextlib.suppress(zenoh.ZError):
                subscriber.undeclare()
        self._worker.join(timeout=1.0)
        if self._poller is not None:
            self._poller.join(timeout=2.5)
        self.server.stop()
        self.log.info("served %d messages, dropped %d", self.served, self.dropped)


def _static_topics() -> list[tuple[str, Any]]:
    """The topics advertised from the start (a viewer can subscribe before anything happened)."""
    from foxglove.messages import CompressedImage, FrameTransforms, Log, SceneUpdate

    from services.viz.convert import SERIES_SCHEMA, JsonMessage

    scenes = (
        c.ROBOT, c.WORLD_OBJECTS, c.MAP_OBSTACLES, c.MAP_SIGHTINGS, c.PLAN_PATH, c.PLAN_FOOTSTEPS,
        c.PLAN_SUPPORT, c.PLAN_COM_ZMP, c.PLAN_REACH, c.PLAN_FOOTSTEP_PLANNER,
    )  # fmt: skip
    return [
        (c.TF, FrameTransforms()),
        *((topic, SceneUpdate()) for topic in scenes),
        (c.PLAN_SERIES, JsonMessage("hrp.viz.ComZmpSeries", SERIES_SCHEMA, {})),
        (c.SNAPSHOT, CompressedImage()),
        (c.LOG, Log()),
    ]


def main(argv: list[str] | None = None, **kwargs: Any) -> int:
    return run_service(VizService, argv, **kwargs)


if __name__ == "__main__":
    raise SystemExit(main())
