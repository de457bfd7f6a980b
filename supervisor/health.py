"""Which services are up: liveliness tokens and heartbeats, watched by the supervisor.

A service declares ``hrp/<robot>/<service>/alive`` when ready and publishes a heartbeat at 2 Hz
(services/bus/service.py). The token goes when the process dies (or its session closes); a token
whose heartbeats stopped means a process alive but stuck. The supervisor checks both before calling
a service and, after an ``unavailable`` or ``timeout`` failure, waits for the service's token to
come back (the launcher restarts dead services) before retrying.

zenoh callbacks only update dictionaries under a lock and notify a condition (no blocking, no zenoh
calls from them).
"""

from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import dataclass

import msgspec
import zenoh

from services.bus import keys
from services.bus.schemas.common import Heartbeat
from services.errors import UnavailableError

#: A heartbeat older than this while the token is present: the service is stuck [s] (2 Hz beats).
STALE_HEARTBEAT_S = 5.0


@dataclass(frozen=True)
class ServiceHealth:
    """What the supervisor knows of one service.

    alive: its liveliness token is present; since_s: monotonic time the token (re)appeared;
    heartbeat_age_s: seconds since its last heartbeat (None: none seen yet); pid: from the heartbeat;
    comebacks: how many times the token reappeared after disappearing (restarts seen).
    """

    name: str
    alive: bool
    since_s: float
    heartbeat_age_s: float | None
    pid: int
    comebacks: int


class HealthMonitor:
    """Tracks the liveliness tokens and heartbeats of every service of ``robot``."""

    def __init__(self, session: zenoh.Session, robot: str) -> None:
        self.robot = robot
        self._cond = threading.Condition()
        self._alive: dict[str, float] = {}
        self._seen: set[str] = set()
        self._comebacks: dict[str, int] = {}
        self._beats: dict[str, tuple[float, int]] = {}
        self._decoder = msgspec.json.Decoder(Heartbeat)
        self._tokens = session.liveliness().declare_subscriber(
            keys.all_alive(robot), self._on_token, history=True
        )
        self._heartbeats = session.declare_subscriber(keys.all_heartbeats(robot), self._on_heartbeat)

    # zenoh callbacks ---------------------------------------------------------------------------------
    def _on_token(self, sample: zenoh.Sample) -> None:
        try:
            service = keys.parse(str(sample.key_expr))[1]
        except ValueError:
            return
        with self._cond:
            if sample.kind == zenoh.SampleKind.PUT:
                if service not in self._alive:
                    self._alive[service] = time.monotonic()
                    if service in self._seen:
                        self._comebacks[service] = self._comebacks.get(service, 0) + 1
                    self._seen.add(service)
            else:
                self._alive.pop(service, None)
                self._beats.pop(service, None)
            self._cond.notify_all()

    def _on_heartbeat(self, sample: zenoh.Sample) -> None:
        try:
            beat = self._decoder.decode(sample.payload.to_bytes())
        except msgspec.DecodeError:
            return
        with self._cond:
            self._beats[beat.service] = (time.monotonic(), beat.pid)

    # queries -------------------------------------------------------------------------------------------
    def health(self, service: str) -> ServiceHealth:
        with self._cond:
            beat = self._beats.get(service)
            return ServiceHealth(
                name=service,
                alive=service in self._alive,
                since_s=self._alive.get(service, 0.0),
                heartbeat_age_s=None if beat is None else time.monotonic() - beat[0],
                pid=0 if beat is None else beat[1],
                comebacks=self._comebacks.get(service, 0),
            )

    def alive(self) -> set[str]:
        with self._cond:
            return set(self._alive)

    def check(self, service: str) -> None:
        """UnavailableError if ``service`` has no token, or a token but no heartbeat for a while."""
        state = self.health(service)
        if not state.alive:
            raise UnavailableError(
                f"service {service!r} is not running (no liveliness token at "
                f"{keys.alive(self.robot, service)}); `humanoid up` starts and restarts it",
                {"service": service},
            )
        if state.heartbeat_age_s is not None and state.heartbeat_age_s > STALE_HEARTBEAT_S:
            raise UnavailableError(
                f"service {service!r} (pid {state.pid}) has not sent a heartbeat for "
                f"{state.heartbeat_age_s:.1f} s: it is stuck",
                {"service": service},
            )

    def wait_alive(self, service: str, timeout_s: float, stop: threading.Event | None = None) -> bool:
        """Block until ``service`` has a token (True), ``timeout_s`` passes or ``stop`` is set (False)."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while service not in self._alive:
                remaining = deadline - time.monotonic()
                if remaining <= 0 or (stop is not None and stop.is_set()):
                    return False
                self._cond.wait(min(remaining, 0.1))
        return True

    def wait_all(self, services: tuple[str, ...] | list[str], timeout_s: float) -> list[str]:
        """Wait until every named service is alive; the names still missing after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        for service in services:
            self.wait_alive(service, max(0.0, deadline - time.monotonic()))
        return sorted(set(services) - self.alive())

    def close(self) -> None:
        for sub in (self._tokens, self._heartbeats):
            with contextlib.suppress(zenoh.ZError):
                sub.undeclare()
