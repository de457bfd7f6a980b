"""Per-service log files of ``humanoid up``: ``<log_dir>/<service>.log``, rotated by size.

A service's stdout and stderr go through a pipe to a :class:`RotatingLog`, whose thread copies them
line by line into the file; when the file would pass ``max_bytes`` it becomes ``<service>.log.1``
(``.1`` becomes ``.2``, and so on up to ``backups``) and a new file starts. ``humanoid logs SERVICE``
reads them back (:func:`log_files`).
"""

from __future__ import annotations

import contextlib
import threading
from collections import deque
from pathlib import Path
from typing import IO

#: Where ``humanoid up`` writes the services' logs by default (relative to the current directory).
DEFAULT_LOG_DIR = "out/logs"
#: Defaults of the launcher's log rotation: 5 MB per file, 3 older files kept.
MAX_BYTES = 5_000_000
BACKUPS = 3


class RotatingLog:
    """One service's log file, written from the pipes of its successive processes (restarts append)."""

    def __init__(self, path: str | Path, max_bytes: int = MAX_BYTES, backups: int = BACKUPS) -> None:
        self.path = Path(path)
        self.max_bytes = max_bytes
        self.backups = backups
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._file: IO[bytes] = open(self.path, "ab")  # noqa: SIM115 (closed by close())
        self._threads: list[threading.Thread] = []
        self._last: deque[bytes] = deque(maxlen=20)  # what the launcher shows when the service dies

    def follow(self, pipe: IO[bytes]) -> None:
        """Copy ``pipe`` (a child's stdout) into the log until it closes, on a daemon thread."""
        thread = threading.Thread(target=self._pump, args=(pipe,), name=f"log-{self.path.stem}", daemon=True)
        self._threads = [t for t in self._threads if t.is_alive()] + [thread]
        thread.start()

    def write(self, data: bytes) -> None:
        with self._lock:
            if self._file.closed:
                return
            if (
                self.max_bytes > 0
                and self._file.tell() + len(data) > self.max_bytes
                and self._file.tell() > 0
            ):
                self._rotate()
            self._file.write(data)
            self._file.flush()
            self._last.append(data)

    def _rotate(self) -> None:
        self._file.close()
        for i in range(self.backups - 1, 0, -1):
            older = self.path.with_name(f"{self.path.name}.{i}")
            if older.exists():
                older.replace(self.path.with_name(f"{self.path.name}.{i + 1}"))
        if self.backups > 0:
            self.path.replace(self.path.with_name(f"{self.path.name}.1"))
        else:
            self.path.unlink(missing_ok=True)
        self._file = open(self.path, "ab")  # noqa: SIM115

    def _pump(self, pipe: IO[bytes]) -> None:
        with contextlib.suppress(OSError, ValueError):
            for line in iter(pipe.readline, b""):
                self.write(line)
        with contextlib.suppress(OSError):
            pipe.close()

    def tail(self, lines: int = 12, timeout_s: float = 0.5) -> list[str]:
        """The last lines written (after waiting up to ``timeout_s`` for a dead process's pipe to drain)."""
        for thread in self._threads:
            thread.join(timeout_s)
        with self._lock:
            last = list(self._last)[-lines:]
        return [line.decode(errors="replace").rstrip("\n") for line in last]

    def close(self, timeout_s: float = 0.5) -> None:
        """Wait a little for the pipes to drain (their processes are gone), then close the file."""
        for thread in self._threads:
            thread.join(timeout_s)
        with self._lock:
            self._file.close()


def log_files(log_dir: str | Path, service: str) -> list[Path]:
    """The files of a service's log, oldest first (``.3``, ``.2``, ``.1``, then the current one)."""
    base = Path(log_dir) / f"{service}.log"
    older = sorted(
        (p for p in base.parent.glob(f"{service}.log.*") if p.suffix[1:].isdigit()),
        key=lambda p: -int(p.suffix[1:]),
    )
    return [*older, base] if base.exists() else older
