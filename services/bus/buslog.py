"""A service's Python log lines on the bus: ``hrp/<robot>/<service>/log`` (:class:`LogLine`).

:func:`attach` adds a handler to the root logger of a service process (so the lines of the algorithm
packages it runs are included), for records at ``level`` and above (WARNING by default: the
``--bus-log-level`` option of every service, or ``HUMANOID_BUS_LOG_LEVEL``; ``OFF`` publishes
nothing). The recorder logs them and the viz converters turn them into ``foxglove.Log``.

Never blocks the service: ``emit`` formats the record and appends it to a bounded queue; one daemon
thread publishes. When lines come faster than they are published the oldest are dropped (counted in
``dropped``); records made by the publishing thread itself are ignored (no feedback loop).
"""

from __future__ import annotations

import collections
import contextlib
import logging
import os
import threading

import zenoh

from services.bus import encodings, keys
from services.bus.codec import encode
from services.bus.schemas.common import LogLine

#: Environment variable giving the default of ``--bus-log-level``.
ENV_LEVEL = "HUMANOID_BUS_LOG_LEVEL"
DEFAULT_LEVEL = "WARNING"
#: Lines waiting to be published; more are dropped, oldest first.
QUEUE_CAPACITY = 256
_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")


def level_from(name: str | None) -> int | None:
    """The logging level of ``name`` (DEBUG..CRITICAL, any case), None for OFF; None given: the
    environment's :data:`ENV_LEVEL` or WARNING. A ValueError names the valid values."""
    text = (name if name is not None else os.environ.get(ENV_LEVEL, DEFAULT_LEVEL)).strip().upper()
    if text == "OFF":
        return None
    if text not in _LEVELS:
        raise ValueError(f"bus log level {text!r} is not one of: {', '.join(_LEVELS)}, OFF")
    return getattr(logging, text)


class BusLogHandler(logging.Handler):
    """Publishes log records as :class:`LogLine` on the service's ``log`` key (see the module doc)."""

    def __init__(self, session: zenoh.Session, robot: str, service: str, level: int) -> None:
        super().__init__(level)
        self.service = service
        self.dropped = 0
        self.published = 0
        self._pid = os.getpid()
        self._queue: collections.deque[LogLine] = collections.deque(maxlen=QUEUE_CAPACITY)
        self._wake = threading.Event()
        self._closing = False
        self._publisher = session.declare_publisher(keys.key(robot, service, "log"))
        self._thread = threading.Thread(target=self._publish_loop, name=f"{service}:buslog", daemon=True)
        self._thread.start()

    def emit(self, record: logging.LogRecord) -> None:
        if self._closing or threading.current_thread() is self._thread:
            return
        try:
            message = record.getMessage()
            if record.exc_info:
                message += "\n" + logging.Formatter().formatException(record.exc_info)
            line = LogLine(
                service=self.service, pid=self._pid, level=record.levelname, logger=record.name,
                message=message, file=record.pathname, line=record.lineno, wall_time_s=record.created,
            )  # fmt: skip
        except Exception:
            self.handleError(record)
            return
        if len(self._queue) == QUEUE_CAPACITY:
            self.dropped += 1
        self._queue.append(line)  # deque append is atomic; maxlen drops the oldest
        self._wake.set()

    def _publish_loop(self) -> None:
        while True:
            self._wake.wait()
            self._wake.clear()
            while self._queue:
                line = self._queue.popleft()
                try:
                    self._publisher.put(encode(line), encoding=encodings.JSON)
                    self.published += 1
                except zenoh.ZError:
                    return
            if self._closing:
                return

    def close(self) -> None:
        """Publish what is queued (up to 1 s), then undeclare; the handler is removed from logging."""
        self._closing = True
        self._wake.set()
        self._thread.join(timeout=1.0)
        with contextlib.suppress(zenoh.ZError):
            self._publisher.undeclare()
        logging.getLogger().removeHandler(self)
        super().close()


def attach(
    session: zenoh.Session, robot: str, service: str, level: str | None = None
) -> BusLogHandler | None:
    """Publish this process's log records at ``level`` and above (see :func:`level_from`) on the
    service's ``log`` key; None when the level is OFF. ``close()`` the handler before the session."""
    threshold = level_from(level)
    if threshold is None:
        return None
    handler = BusLogHandler(session, robot, service, threshold)
    logging.getLogger().addHandler(handler)
    return handler
