"""Service calls of the supervisor: health-checked, tagged with the service, sim time remembered."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from services.bus.schemas.supervisor import REASON_WORLD_LOST
from services.bus.session import Client
from services.bus.spec import EndpointSpec
from services.errors import HumanoidError, RequestTimeoutError, StoppedError, UnavailableError
from supervisor.health import HealthMonitor

#: The service whose process holds the world (scene, objects, robot): its restart loses them (issue 16).
WORLD_SERVICE = "sim"
WORLD_RESET = "sim/reset"


class ServiceCaller:
    """``call(spec, request, timeout_s)`` for the actions.

    Before a call, the service must have its liveliness token and a recent heartbeat
    (:meth:`HealthMonitor.check`); an error of any call carries ``details["service"]`` so that the
    ``wait_service`` remedy knows which service to wait for. ``sim_time_s`` is the latest sim time seen
    in a reply [s].
    """

    def __init__(self, client: Client, health: HealthMonitor, stop: threading.Event | None = None) -> None:
        self.client = client
        self.health = health
        self.stop = stop or threading.Event()
        self.sim_time_s = 0.0
        self.calls: dict[str, int] = {}
        #: The sim's (token comebacks, heartbeat pid) when its world was last set up.
        self._world: tuple[int, int] | None = None
        #: Called with the spec before each call (tracing; tests use it to kill a service mid-request).
        self.on_call: Callable[[EndpointSpec], None] | None = None

    def call(self, spec: EndpointSpec, request: Any, timeout_s: float) -> Any:
        """The reply; the typed error of the service; StoppedError once stop is set."""
        if self.stop.is_set():
            raise StoppedError(f"stopped by the operator before calling {spec.path}")
        if self.on_call is not None:
            self.on_call(spec)
        started = time.monotonic()
        try:
            self.health.check(spec.service)
            if spec.service == WORLD_SERVICE:
                self._check_world(spec)
            try:
                reply = self.client.call(spec, request, timeout_s)
            except RequestTimeoutError:
                if time.monotonic() - started < 0.9 * timeout_s and self._went_away(spec.service):
                    raise UnavailableError(
                        f"service {spec.service!r} went away while serving {spec.path} (its process died?); "
                        "`humanoid up` restarts it",
                        {"service": spec.service},
                    ) from None
                raise
        except HumanoidError as exc:
            exc.details.setdefault("service", spec.service)
            exc.details.setdefault("endpoint", spec.path)
            raise
        self.calls[spec.path] = self.calls.get(spec.path, 0) + 1
        if spec.path == WORLD_RESET:
            state = self.health.health(WORLD_SERVICE)
            self._world = (state.comebacks, state.pid)
        sim_time = getattr(reply, "sim_time_s", None)
        if isinstance(sim_time, float) and sim_time > 0.0:
            self.sim_time_s = sim_time
        return reply

    def _check_world(self, spec: EndpointSpec) -> None:
        """UnavailableError (``details.reason`` ``REASON_WORLD_LOST``, final: not retried) when the sim
        restarted since its world was set up (its last sim/reset, or the first call): the launcher brings
        a fresh sim back, but the scene, the objects and the robot's place died with the old process."""
        state = self.health.health(WORLD_SERVICE)
        if self._world is None or (self._world[1] == 0 and state.comebacks == self._world[0]):
            self._world = (state.comebacks, state.pid)  # (the pid, once the first heartbeat came)
            return
        comebacks, pid = self._world
        # its token came back, from another process (or one not heard from yet): a new sim
        restarted = state.comebacks != comebacks and (state.pid == 0 or state.pid != pid)
        if restarted and spec.path != WORLD_RESET:
            raise UnavailableError(
                "the simulation is gone: the sim process died and was restarted, and the world it held "
                "(the scene, its objects, the robot's place and what it carried) was lost with it; reset "
                "the scene (sim/reset) and start again",
                {"service": WORLD_SERVICE, "reason": REASON_WORLD_LOST},
            )

    def _went_away(self, service: str, within_s: float = 1.0) -> bool:
        """Whether ``service``'s liveliness token disappears within ``within_s`` (a query that ended
        early without a reply: its queryable vanished with its process)."""
        deadline = time.monotonic() + within_s
        while time.monotonic() < deadline:
            if not self.health.health(service).alive:
                return True
            time.sleep(0.02)
        return False
