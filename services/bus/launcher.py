"""``humanoid up``: start the services, watch them, restart the ones that die, stop them all cleanly.

* The launcher's own zenoh session listens on the hub endpoint; every service connects to it.
* Each service is ``python -m <module>`` in its own process group (``start_new_session``): Ctrl-C in
  the terminal reaches only the launcher, which signals the services itself. A service also gets
  ``--parent-pid`` and stops by itself if the launcher disappears (killed with SIGKILL).
* Readiness is the service's liveliness token. Until every service is ready a service that exits
  fails the start-up; afterwards one that dies is restarted after a backoff, at most
  ``max_restarts`` times within ``restart_window_s``. Every step is logged and published as a
  :class:`~services.bus.schemas.common.LauncherEvent` on ``hrp/<robot>/launcher/events``.
* SIGINT/SIGTERM: SIGTERM to the services, SIGKILL to any still there after ``stop_grace_s``,
  then the recorder last (so it logs the others' last words), then the zenoh shared-memory files
  in ``/dev/shm`` that no living process holds are removed. All within 2 s.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import zenoh

from services.bus import keys
from services.bus.config import BusConfig
from services.bus.discovery import RECORDER, VIZ, ServiceEntry
from services.bus.logfiles import BACKUPS, MAX_BYTES, RotatingLog
from services.bus.schemas.common import LAUNCHER_EVENTS, LauncherEvent
from services.bus.session import TypedPublisher, close_session, open_session
from services.errors import InvalidRequestError, UnavailableError

log = logging.getLogger("humanoid.launcher")


@dataclass(frozen=True)
class LauncherConfig:
    """Options of ``humanoid up`` (YAML section ``launcher``).

    Attributes:
        ready_timeout_s: how long every service may take to declare its liveliness token [s].
        max_restarts: restarts of one service allowed within ``restart_window_s``; then it is given up.
        restart_window_s: the window over which restarts are counted [s].
        backoff_initial_s: delay before the first restart; doubles with each recent restart [s].
        backoff_max_s: longest delay before a restart [s].
        stop_grace_s: time between SIGTERM and SIGKILL when stopping [s].
        log_dir: if set, each service's output goes to ``<log_dir>/<service>.log`` instead of the
            launcher's terminal, rotated past ``log_max_bytes`` (``services.bus.logfiles``).
        log_max_bytes: size of a log file before it is rotated [B].
        log_backups: rotated files kept per service (``<service>.log.1`` ... ``.N``).
    """

    ready_timeout_s: float = 30.0
    max_restarts: int = 5
    restart_window_s: float = 60.0
    backoff_initial_s: float = 0.5
    backoff_max_s: float = 8.0
    stop_grace_s: float = 1.0
    log_dir: str = ""
    log_max_bytes: int = MAX_BYTES
    log_backups: int = BACKUPS

    def __post_init__(self) -> None:
        if self.stop_grace_s > 1.2:
            raise InvalidRequestError("stop_grace_s must be at most 1.2 s: `up` stops everything within 2 s")
        if min(self.ready_timeout_s, self.backoff_initial_s, self.backoff_max_s) <= 0:
            raise InvalidRequestError("ready_timeout_s, backoff_initial_s and backoff_max_s must be > 0")


@dataclass
class _Child:
    entry: ServiceEntry
    proc: subprocess.Popen[bytes] | None = None
    state: str = "pending"  # pending, starting, ready, backoff, failed, stopped
    attempt: int = 0
    restarts: deque[float] = field(default_factory=deque)
    restart_at: float = 0.0
    started_at: float = 0.0
    log_file: RotatingLog | None = None

    @property
    def pid(self) -> int:
        return self.proc.pid if self.proc is not None else 0


class Launcher:
    """Runs a set of services until :meth:`request_stop` (or a signal, via :func:`run_up`)."""

    def __init__(
        self,
        bus: BusConfig,
        entries: list[ServiceEntry],
        config: LauncherConfig | None = None,
        *,
        config_path: str | None = None,
        record: str | None = None,
        duration_s: float | None = None,
        out: IO[str] | None = None,
        foxglove_port: int | None = None,
    ) -> None:
        """``duration_s``: stop by itself this long after every service is ready (demos, CI);
        ``foxglove_port``: the WebSocket port of the viz service (when it is among ``entries``)."""
        self.bus = bus
        self.config = config or LauncherConfig()
        self.config_path = str(Path(config_path).resolve()) if config_path else None
        self.record = str(Path(record).resolve()) if record else None
        self.out = out or sys.stdout
        self.duration_s = duration_s
        self.foxglove_port = foxglove_port
        self.children = {e.name: _Child(e) for e in entries if e.name != RECORDER}
        self.recorder = _Child(next(e for e in entries if e.name == RECORDER)) if record else None
        self._alive: set[str] = set()
        self._alive_lock = threading.Lock()
        self._stop = threading.Event()
        self._session: zenoh.Session | None = None
        self._events: TypedPublisher | None = None

    # Lifecycle ------------------------------------------------------------------------------------------
    def request_stop(self) -> None:
        self._stop.set()

    def run(self) -> int:
        """Start, wait until ready, supervise, stop. 0 when stopped on request, 1 if start-up failed."""
        self._session = open_session(self.bus, as_hub=True)
        try:
            self._events = TypedPublisher(self._session, self.bus.robot, LAUNCHER_EVENTS)
            tracker = self._session.liveliness().declare_subscriber(
                keys.all_alive(self.bus.robot), self._on_liveliness, history=True
            )
            try:
                try:
                    if self.recorder is not None:
                        self._start_all([self.recorder])
                    self._start_all(list(self.children.values()))
                except UnavailableError as exc:
                    log.error("%s", exc.message)
                    print(f"error: {exc.message}", file=sys.stderr)
                    return 1
                self.print_table()
                if self.record:
                    print(f"recording to {self.record}", file=self.out, flush=True)
                self._supervise()
                return 0
            finally:
                self._stop_all()
                with contextlib.suppress(zenoh.ZError):
                    tracker.undeclare()
        finally:
            self._events = None
            close_session(self._session)
            for child in self._all_children():
                if child.log_file is not None:
                    child.log_file.close()
            if self.record:
                print(f"log written to {self.record}", file=self.out, flush=True)

    def _all_children(self) -> list[_Child]:
        return list(self.children.values()) + ([self.recorder] if self.recorder is not None else [])

    # Liveliness ------------------------------------------------------------------------------------------
    def _on_liveliness(self, sample: zenoh.Sample) -> None:  # zenoh thread: only touch a set
        try:
            service = keys.parse(str(sample.key_expr))[1]
        except ValueError:
            return
        with self._alive_lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._alive.add(service)
            else:
                self._alive.discard(service)

    def is_alive(self, service: str) -> bool:
        with self._alive_lock:
            return service in self._alive

    # Starting ----------------------------------------------------------------------------------------------
    def _command(self, child: _Child) -> list[str]:
        cmd = [sys.executable, "-m", child.entry.module, "--hub", self.bus.hub, "--robot", self.bus.robot]
        cmd += ["--parent-pid", str(os.getpid())]
        if self.config_path:
            cmd += ["--config", self.config_path]
        if child.entry.name == RECORDER and self.record:
            cmd += ["--output", self.record]
        if child.entry.name == VIZ and self.foxglove_port is not None:
            cmd += ["--port", str(self.foxglove_port)]
        return cmd

    def _spawn(self, child: _Child) -> None:
        output: Any = None
        if self.config.log_dir:
            if child.log_file is None:
                path = Path(self.config.log_dir) / f"{child.entry.name}.log"
                child.log_file = RotatingLog(path, self.config.log_max_bytes, self.config.log_backups)
            output = subprocess.PIPE
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        # exec of a fresh interpreter (spawn semantics), own process group: signals come from us only.
        child.proc = subprocess.Popen(
            self._command(child),
            stdin=subprocess.DEVNULL,
            stdout=output,
            stderr=subprocess.STDOUT if output is not None else None,
            env=env,
            start_new_session=True,
        )
        if child.log_file is not None and child.proc.stdout is not None:
            child.log_file.follow(child.proc.stdout)
        child.attempt += 1
        child.state = "starting"
        child.started_at = time.monotonic()
        self._event(child, "started")

    def _start_all(self, children: list[_Child]) -> None:
        for child in children:
            self._spawn(child)
        deadline = time.monotonic() + self.config.ready_timeout_s
        waiting = {c.entry.name: c for c in children}
        while waiting:
            for name, child in list(waiting.items()):
                code = child.proc.poll() if child.proc is not None else None
                if code is not None:
                    child.state = "failed"
                    self._event(child, "died", exit_code=code, message="exited before becoming ready")
                    raise UnavailableError(
                        f"service {name!r} ({child.entry.module}) exited with {_describe_exit(code)} "
                        f"before becoming ready; {self._log_tail(child)}"
                    )
                if self.is_alive(name):
                    child.state = "ready"
                    self._event(child, "ready")
                    del waiting[name]
            if not waiting:
                return
            if time.monotonic() > deadline:
                names = ", ".join(sorted(waiting))
                for child in waiting.values():
                    self._event(child, "timeout", message="no liveliness token in time")
                raise UnavailableError(
                    f"service(s) {names} did not declare a liveliness token "
                    f"(hrp/{self.bus.robot}/<service>/alive) within {self.config.ready_timeout_s:.0f} s"
                )
            if self._stop.wait(0.05):
                raise UnavailableError("stopped before every service was ready")

    # Supervising ----------------------------------------------------------------------------------------
    def _supervise(self) -> None:
        cfg = self.config
        end = None if self.duration_s is None else time.monotonic() + self.duration_s
        while not self._stop.wait(0.05):
            now = time.monotonic()
            if end is not None and now >= end:
                log.info("ran for %.1f s as asked: stopping", self.duration_s)
                return
            for child in self._all_children():
                if child.state in ("starting", "ready"):
                    code = child.proc.poll() if child.proc is not None else None
                    if code is not None:
                        self._on_death(child, code, now)
                    elif child.state == "starting" and self.is_alive(child.entry.name):
                        child.state = "ready"
                        self._event(child, "ready", message=f"restarted (attempt {child.attempt})")
                    elif child.state == "starting" and now - child.started_at > cfg.ready_timeout_s:
                        self._event(child, "timeout", message="no liveliness token in time: killing it")
                        self._kill_group(child, signal.SIGKILL)
                elif child.state == "backoff" and now >= child.restart_at:
                    self._spawn(child)

    def _on_death(self, child: _Child, code: int, now: float) -> None:
        cfg = self.config
        self._kill_group(child, signal.SIGKILL)  # whatever it started goes with it
        self._event(child, "died", exit_code=code, message=_describe_exit(code))
        if child.log_file is not None:
            print(f"{child.entry.name}: {self._log_tail(child)}", file=sys.stderr, flush=True)
        while child.restarts and now - child.restarts[0] > cfg.restart_window_s:
            child.restarts.popleft()
        if len(child.restarts) >= cfg.max_restarts:
            child.state = "failed"
            self._event(
                child,
                "gave_up",
                exit_code=code,
                message=f"died {len(child.restarts) + 1} times within {cfg.restart_window_s:.0f} s",
            )
            return
        delay = min(cfg.backoff_max_s, cfg.backoff_initial_s * 2 ** len(child.restarts))
        child.restarts.append(now)
        child.state = "backoff"
        child.restart_at = now + delay
        self._event(child, "restarting", exit_code=code, message=f"in {delay:.1f} s")

    def _log_tail(self, child: _Child) -> str:
        """Where to read why a service stopped: its last log lines, or the terminal above."""
        if child.log_file is None:
            return "its log above says why"
        lines = child.log_file.tail()
        shown = "\n".join(f"  | {line}" for line in lines) if lines else "  (nothing)"
        return f"the end of its log {child.log_file.path}:\n{shown}"

    # Stopping ---------------------------------------------------------------------------------------------
    def _stop_all(self) -> None:
        self._stop_group([c for c in self.children.values()], self.config.stop_grace_s)
        if self.recorder is not None:
            self._stop_group([self.recorder], max(0.3, 1.7 - self.config.stop_grace_s))

    def _stop_group(self, children: list[_Child], grace_s: float) -> None:
        running = [c for c in children if c.proc is not None and c.proc.poll() is None]
        for child in running:
            self._kill_group(child, signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        for child in running:
            with contextlib.suppress(subprocess.TimeoutExpired):
                child.proc.wait(timeout=max(0.0, deadline - time.monotonic()))  # type: ignore[union-attr]
        for child in children:
            if child.proc is None:
                continue
            if child.proc.poll() is None:
                log.warning("%s did not stop within %.1f s: killing it", child.entry.name, grace_s)
            self._kill_group(child, signal.SIGKILL)  # also any process it left in its group
            child.proc.wait()
            if child.state != "stopped":
                child.state = "stopped"
                self._event(child, "stopped", exit_code=child.proc.returncode)

    @staticmethod
    def _kill_group(child: _Child, sig: int) -> None:
        if child.proc is None:
            return
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(child.proc.pid, sig)

    # Reporting ----------------------------------------------------------------------------------------------
    def _event(self, child: _Child, event: str, *, exit_code: int | None = None, message: str = "") -> None:
        name = child.entry.name
        text = (
            f"{name}: {event}"
            + (f" (pid {child.pid})" if child.pid else "")
            + (f": {message}" if message else "")
        )
        (log.warning if event in ("died", "gave_up", "timeout") else log.info)("%s", text)
        if self._events is not None:
            with contextlib.suppress(zenoh.ZError):
                self._events.put(
                    LauncherEvent(
                        service=name,
                        event=event,
                        pid=child.pid,
                        attempt=child.attempt,
                        exit_code=exit_code,
                        message=message,
                        wall_time_s=time.time(),
                    )
                )

    def status_rows(self) -> list[tuple[str, str, str, str, str]]:
        rows = []
        for child in self._all_children():
            restarts = str(max(0, child.attempt - 1))
            rows.append((child.entry.name, child.state, str(child.pid or "-"), restarts, child.entry.module))
        return rows

    def print_table(self) -> None:
        print(f"hub {self.bus.hub}, robot {self.bus.robot}", file=self.out)
        print(
            format_table(("SERVICE", "STATE", "PID", "RESTARTS", "MODULE"), self.status_rows()), file=self.out
        )
        self.out.flush()


def format_table(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    """A plain left-aligned text table."""
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    lines = [
        "  ".join(str(v).ljust(w) for v, w in zip(row, widths, strict=True)).rstrip()
        for row in [header, *rows]
    ]
    return "\n".join(lines)


def _describe_exit(code: int) -> str:
    if code < 0:
        try:
            return f"signal {signal.Signals(-code).name}"
        except ValueError:
            return f"signal {-code}"
    return f"exit code {code}"


def run_up(launcher: Launcher) -> int:
    """Run ``launcher`` in the foreground until SIGINT/SIGTERM."""

    def on_signal(signum: int, _frame: Any) -> None:
        launcher.request_stop()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        return launcher.run()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
