"""``record``: the recorder service, every message on ``hrp/**`` into an MCAP log.

Started by ``humanoid record FILE`` (in the foreground) or ``humanoid up --record FILE`` (as a
service process of the launcher), or directly: ``python -m services.bus.recorder --output FILE``.
The log layout (one Foxglove-decodable copy of each message, Foxglove's own views made by
:mod:`services.viz`'s converters, schemas) is described in :mod:`services.bus.mcaplog`.

Threads: zenoh pushes samples into a FIFO channel (no GIL on its side); one writer thread takes
them in order and writes. Chunks close by size: a SIGKILL loses at most the open chunk
(``chunk_size_bytes`` of messages); every closed chunk reads back (``humanoid log-info``).

SIGTERM writes what the recorder has received and closes the log; a message still on its way to the
recorder then (published milliseconds before, the recorder's process not yet scheduled to read it)
is not in the log. ``record/status`` (:data:`~services.bus.schemas.record.STATUS`) says what is
written, per key: a client that must have a message in the log asks it before stopping the recorder.
"""

from __future__ import annotations

import argparse
import contextlib
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from services.bus import world
from services.bus.config import from_mapping
from services.bus.mcaplog import LogWriter
from services.bus.schemas.record import STATUS, StatusReply, StatusRequest
from services.bus.schemas.sim import GROUND_TRUTH
from services.bus.service import Service, handles, run_service
from services.bus.session import request_id_from
from services.errors import InvalidRequestError

#: The sim's 200 Hz state topics (``state_every`` thins them out).
STATE_TOPICS = ("/sim/joint_state", "/sim/base_pose", "/sim/clock")
#: The sim's 200 Hz sensor streams written rounded to ``state_decimals`` (their float64 low bits are
#: physics noise that zstd cannot compress: 2/3 of a fetch's log otherwise).
ROUNDED_TOPICS = ("sim/joint_state", "sim/base_pose")
#: How long the recorder waits for ``sim/ground_truth`` [s] (a reply coming later is still recorded: the
#: sim publishes its copy whoever waits); how often it looks for the sim before it answered once [s].
WORLD_TIMEOUT_S = 1.0
WORLD_RETRY_S = 0.5


@dataclass(frozen=True)
class RecorderConfig:
    """Options of the recorder (YAML section ``record``).

    Attributes:
        output: the MCAP file to write (its directory is created).
        key_expr: what to record.
        compression: ``zstd`` (default), ``lz4`` or ``none``.
        chunk_size_bytes: a chunk is closed when its messages reach this size [bytes] (uncompressed):
            at most this much is lost to a SIGKILL.
        queue_capacity: samples waiting for the writer; when full, zenoh holds back further ones.
        foxglove_views: also write Foxglove's own messages (robot transforms and body, scene, map,
            plans, cameras, log lines: :mod:`services.viz`).
        model: robot model of those views ("": recognised from the joint state's size).
        transform_hz: rate of the robot's transforms in the views [Hz].
        state_every: record one in this many messages of the sim's 200 Hz state topics
            (``sim/joint_state``, ``sim/base_pose``, ``sim/clock``); 1 (default): every message. The
            transforms in the views stay above 30 Hz of sim time up to 6.
        world_objects: with ``foxglove_views``, the recorder asks ``sim/ground_truth`` when the log
            begins (once the sim answers) and after each answer of sim/execute, gripper and reset, so
            that the log's ``/world/objects`` shows what is there, as the live view does
            (:mod:`services.bus.world`); only when ``key_expr`` takes the reply's copy.
        state_decimals: the sim's joint state and base pose are written with their floats rounded to
            this many decimals (6: 1 um, 1 urad, 1 um/s; far below what a joint encoder or an IMU
            resolves) as JSON numbers Foxglove plots; None: the exact float64 bytes (lossless, the
            log of a fetch is then about 40 % larger). Requests and replies are always exact.
    """

    output: str = "humanoid.mcap"
    key_expr: str = "hrp/**"
    compression: str = "zstd"
    chunk_size_bytes: int = 1 << 20
    queue_capacity: int = 1024
    foxglove_views: bool = True
    model: str = ""
    transform_hz: float = 30.0
    state_every: int = 1
    world_objects: bool = True
    state_decimals: int | None = 6

    def __post_init__(self) -> None:
        from services.bus.mcaplog import COMPRESSIONS

        if min(self.chunk_size_bytes, self.queue_capacity, self.transform_hz, self.state_every) <= 0:
            raise InvalidRequestError(
                "chunk_size_bytes, queue_capacity, transform_hz and state_every must be > 0"
            )
        if self.state_decimals is not None and not 0 <= self.state_decimals <= 15:
            raise InvalidRequestError(f"state_decimals={self.state_decimals} must be 0..15 or null (exact)")
        if self.compression not in COMPRESSIONS:
            raise InvalidRequestError(
                f"compression {self.compression!r} is not one of: {', '.join(COMPRESSIONS)}"
            )


class RecorderService(Service):
    """Records every message on the bus to an MCAP log (Foxglove opens it; humanoid replay plays it)."""

    name = "record"
    Config = RecorderConfig

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--output", help="MCAP file to write (default: the config's, humanoid.mcap)")

    @classmethod
    def configure(cls, config: RecorderConfig, args: argparse.Namespace) -> RecorderConfig:
        if getattr(args, "output", None):
            values = {**config.__dict__, "output": str(Path(args.output).resolve())}
            return from_mapping(RecorderConfig, values, where="--output")
        return config

    def start(self) -> None:
        cfg: RecorderConfig = self.config
        views = None
        if cfg.foxglove_views:
            from services.viz.converter import Converter

            views = Converter(cfg.model, cfg.transform_hz).views
        self.writer = LogWriter(
            cfg.output,
            compression=cfg.compression,
            chunk_size_bytes=cfg.chunk_size_bytes,
            views=views,
            decimals=(
                dict.fromkeys(ROUNDED_TOPICS, cfg.state_decimals) if cfg.state_decimals is not None else None
            ),
            metadata={
                "robot": self.bus.robot,
                "hub": self.bus.hub,
                "host": socket.gethostname(),
                "started_unix_s": f"{time.time():.3f}",
                "key_expr": cfg.key_expr,
                "state_decimals": str(cfg.state_decimals),
            },
        )
        self._lock = threading.Lock()
        self.recorded = 0
        self._per_key: dict[str, int] = {}  # messages written per key
        self._subscriber = self.session.declare_subscriber(
            cfg.key_expr, zenoh.handlers.FifoChannel(cfg.queue_capacity)
        )
        self._stopping = threading.Event()
        self._moved = threading.Event()  # the world may have changed: ask it again
        self._moving_keys: frozenset[str] = frozenset()
        self._world_thread: threading.Thread | None = None
        if cfg.foxglove_views and cfg.world_objects and self._records(world.mirror_key(self.bus.robot)):
            self._moving_keys = world.moving_keys(self.bus.robot)
            self._world_thread = threading.Thread(target=self._ask_world, name="record:world", daemon=True)
            self._world_thread.start()
        self._writer_thread = threading.Thread(target=self._write_loop, name="record:writer", daemon=True)
        self._writer_thread.start()
        self.log.info("recording %s to %s", cfg.key_expr, cfg.output)

    def _records(self, key: str) -> bool:
        """Whether ``key_expr`` takes messages on ``key``."""
        return zenoh.KeyExpr(self.config.key_expr).intersects(zenoh.KeyExpr(key))

    def _ask_world(self) -> None:
        """``sim/ground_truth`` until the sim answers once (the world as the log begins), then after
        each motion, gripper or reset; the sim's copy of the reply is recorded like any message, and
        its view is ``/world/objects``."""
        robot = self.bus.robot
        while not world.ask(self.session, robot, GROUND_TRUTH, timeout_s=WORLD_TIMEOUT_S):
            if self._stopping.wait(WORLD_RETRY_S):
                return
        while True:
            self._moved.wait()  # set by the writer after a motion, and by stop()
            if self._stopping.is_set():
                return
            self._moved.clear()  # before asking: a motion ending meanwhile asks once more
            world.ask(self.session, robot, GROUND_TRUTH, timeout_s=WORLD_TIMEOUT_S)

    def _write_loop(self) -> None:
        channel = self._subscriber.handler
        every = self.config.state_every
        seen: dict[str, int] = {}
        while True:
            try:
                sample = channel.recv()  # no GIL while waiting; ZError when undeclared and drained
            except zenoh.ZError:
                return
            if sample.kind != zenoh.SampleKind.PUT:
                continue
            key = str(sample.key_expr)
            if every > 1 and key.endswith(STATE_TOPICS):
                seen[key] = seen.get(key, -1) + 1
                if seen[key] % every:
                    continue
            sequence = request_id_from(sample.attachment) or 0
            data = sample.payload.to_bytes()
            with self._lock:
                if self.writer.closed:
                    return
                try:
                    self.writer.write(key, data, time.time_ns(), sequence & 0xFFFF_FFFF)
                    self.recorded += 1
                    self._per_key[key] = self._per_key.get(key, 0) + 1
                except Exception:  # a full disk must not stop the service from answering
                    self.log.exception("could not record a message on %s", key)
            if key in self._moving_keys:
                self._moved.set()

    @handles(STATUS)
    def status(self, _request: StatusRequest) -> StatusReply:
        """What is written so far (see the module doc)."""
        with self._lock:
            return StatusReply(output=self.config.output, recorded=self.recorded, per_key=dict(self._per_key))

    def stop(self) -> None:
        self._stopping.set()
        self._moved.set()  # wakes the world's thread, which then returns
        with contextlib.suppress(zenoh.ZError):
            self._subscriber.undeclare()
        self._writer_thread.join(timeout=0.5)
        with self._lock:
            self.writer.close()
        self.log.info("wrote %d messages to %s", self.recorded, self.config.output)
        if self._world_thread is not None:  # the log is closed: a request under way ends in its timeout
            self._world_thread.join(timeout=WORLD_TIMEOUT_S + 0.2)


def main(argv: list[str] | None = None, **kwargs: Any) -> int:
    return run_service(RecorderService, argv, **kwargs)


if __name__ == "__main__":
    raise SystemExit(main())
