"""``record``: the recorder service, every message on ``hrp/**`` into an MCAP log.

Started by ``humanoid record FILE`` (in the foreground) or ``humanoid up --record FILE`` (as a
service process of the launcher), or directly: ``python -m services.bus.recorder --output FILE``.
The log layout (exact originals for replay, Foxglove views, schemas) is described in
:mod:`services.bus.mcaplog`.

Threads: zenoh pushes samples into a FIFO channel (no GIL on its side); one writer thread takes
them in order and writes; a flusher closes the open chunk every ``chunk_period_s`` so a SIGKILL
loses at most that much.
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

from services.bus.config import from_mapping
from services.bus.mcaplog import LogWriter
from services.bus.service import Service, run_service
from services.bus.session import request_id_from
from services.errors import InvalidRequestError


@dataclass(frozen=True)
class RecorderConfig:
    """Options of the recorder (YAML section ``record``).

    Attributes:
        output: the MCAP file to write (its directory is created).
        key_expr: what to record.
        compression: ``lz4`` or ``none`` (zstd is refused: on images 2 % smaller, 5x slower).
        chunk_size_bytes: a chunk is closed when it reaches this size [bytes].
        chunk_period_s: ... or when it is this old [s]: at most this much is lost to a SIGKILL.
        queue_capacity: samples waiting for the writer; when full, zenoh holds back further ones.
        image_views: write ``foxglove.RawImage`` views of image arrays.
        max_view_elements: larger non-image arrays are summarised (shape, min, max) in JSON views.
    """

    output: str = "humanoid.mcap"
    key_expr: str = "hrp/**"
    compression: str = "lz4"
    chunk_size_bytes: int = 4 << 20
    chunk_period_s: float = 1.0
    queue_capacity: int = 1024
    image_views: bool = True
    max_view_elements: int = 100_000

    def __post_init__(self) -> None:
        if self.chunk_period_s <= 0 or self.chunk_size_bytes <= 0 or self.queue_capacity <= 0:
            raise InvalidRequestError("chunk_period_s, chunk_size_bytes and queue_capacity must be > 0")


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
        self.writer = LogWriter(
            cfg.output,
            compression=cfg.compression,
            chunk_size_bytes=cfg.chunk_size_bytes,
            image_views=cfg.image_views,
            max_view_elements=cfg.max_view_elements,
            metadata={
                "robot": self.bus.robot,
                "hub": self.bus.hub,
                "host": socket.gethostname(),
                "started_unix_s": f"{time.time():.3f}",
                "key_expr": cfg.key_expr,
            },
        )
        self._lock = threading.Lock()
        self._done = threading.Event()
        self.recorded = 0
        self._subscriber = self.session.declare_subscriber(
            cfg.key_expr, zenoh.handlers.FifoChannel(cfg.queue_capacity)
        )
        self._writer_thread = threading.Thread(target=self._write_loop, name="record:writer", daemon=True)
        self._flusher = threading.Thread(target=self._flush_loop, name="record:flusher", daemon=True)
        self._writer_thread.start()
        self._flusher.start()
        self.log.info("recording %s to %s", cfg.key_expr, cfg.output)

    def _write_loop(self) -> None:
        channel = self._subscriber.handler
        while True:
            try:
                sample = channel.recv()  # no GIL while waiting; ZError when undeclared and drained
            except zenoh.ZError:
                return
            if sample.kind != zenoh.SampleKind.PUT:
                continue
            sequence = request_id_from(sample.attachment) or 0
            data = sample.payload.to_bytes()
            with self._lock:
                if self.writer.closed:
                    return
                try:
                    self.writer.write(str(sample.key_expr), data, time.time_ns(), sequence & 0xFFFF_FFFF)
                    self.recorded += 1
                except Exception:  # a full disk must not stop the service from answering
                    self.log.exception("could not record a message on %s", sample.key_expr)

    def _flush_loop(self) -> None:
        period = self.config.chunk_period_s
        while not self._done.wait(period):
            with self._lock:
                if self.writer.closed:
                    return
                try:
                    self.writer.flush_chunk()
                except Exception:
                    self.log.exception("could not flush the log")

    def stop(self) -> None:
        self._done.set()
        with contextlib.suppress(zenoh.ZError):
            self._subscriber.undeclare()
        self._writer_thread.join(timeout=0.5)
        with self._lock:
            self.writer.close()
        self.log.info("wrote %d messages to %s", self.recorded, self.config.output)


def main(argv: list[str] | None = None, **kwargs: Any) -> int:
    return run_service(RecorderService, argv, **kwargs)


if __name__ == "__main__":
    raise SystemExit(main())
