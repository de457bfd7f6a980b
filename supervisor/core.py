"""The supervisor: a bus session, health watching, the actions, the runner, events and progress output.

::

    with Supervisor.connect(bus_config, out=sys.stdout) as sup:
        report = sup.run(load_script("supervisor/scripts/fetch.txt"), run_id="fetch")

Events go to ``hrp/<robot>/supervisor/events`` (:mod:`services.bus.schemas.supervisor`) and, as
one line each, to ``out`` (the progress a person sees while an action runs).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterable, Iterator
from typing import IO

import zenoh

from services.bus.config import BusConfig
from services.bus.schemas import perception as perception_msg
from services.bus.schemas.supervisor import EVENTS, SupervisorEvent
from services.bus.session import Client, TypedPublisher, close_session, open_session
from services.errors import HumanoidError
from supervisor.actions import Actions
from supervisor.calls import ServiceCaller
from supervisor.config import SupervisorConfig
from supervisor.health import HealthMonitor
from supervisor.retry import DEFAULT_POLICY, RetryPolicy
from supervisor.runner import Event, Runner, RunReport
from supervisor.script import Step

#: Services the actions use.
SERVICES = ("sim", "perception", "navigation", "footsteps", "walking", "reaching")


class Supervisor:
    """Runs steps over the services; see the module docstring."""

    def __init__(
        self,
        session: zenoh.Session,
        robot: str,
        *,
        out: IO[str] | None = None,
        policy: RetryPolicy = DEFAULT_POLICY,
        config: SupervisorConfig | None = None,
        owns_session: bool = False,
    ) -> None:
        self.session = session
        self.robot = robot
        self.out = out
        self.stop = threading.Event()
        self.health = HealthMonitor(session, robot)
        self.client = Client(session, robot)
        self.bus = ServiceCaller(self.client, self.health, self.stop)
        self.actions = Actions(self.bus, self.health, stop=self.stop, progress=self._progress, config=config)
        self.runner = Runner(
            self.actions.table(),
            policy=policy,
            remedies=self.actions.remedies(),
            on_event=self._on_event,
            stop=self.stop,
        )
        self._events = TypedPublisher(session, robot, EVENTS)
        self._owns_session = owns_session
        self._run_id = ""
        self._step = ""
        self._line = 0
        self._attempt = 0
        self._started = time.monotonic()
        self.events: list[SupervisorEvent] = []

    @classmethod
    @contextlib.contextmanager
    def connect(cls, bus: BusConfig, **kwargs) -> Iterator[Supervisor]:
        """A supervisor on its own session (closed on exit)."""
        session = open_session(bus)
        sup = cls(session, bus.robot, owns_session=True, **kwargs)
        try:
            yield sup
        finally:
            sup.close()

    def close(self) -> None:
        self.stop.set()
        self._events.undeclare()
        self.health.close()
        if self._owns_session:
            close_session(self.session)

    # Running ------------------------------------------------------------------------------------------
    def wait_for_services(self, timeout_s: float = 30.0, services: Iterable[str] = SERVICES) -> list[str]:
        """Wait until the services are alive; the names still missing."""
        return self.health.wait_all(tuple(services), timeout_s)

    def known_objects(self) -> list[str]:
        """The objects perception knows (its learned models)."""
        return list(self.bus.call(perception_msg.MODELS, perception_msg.ModelsRequest(), 10.0).names)

    def run(self, steps: Iterable[Step], run_id: str = "") -> RunReport:
        """Run the steps (one script, or one console command); events published and printed."""
        steps = list(steps)
        self.stop.clear()
        self._run_id = run_id or f"run@{time.time():.0f}"
        self._started = time.monotonic()
        self._publish(
            SupervisorEvent(kind="run_started", run_id=self._run_id, message=f"{len(steps)} step(s)")
        )
        try:
            report = self.runner.run(steps)
        except HumanoidError as exc:  # e.g. a step naming an action without implementation
            self._publish(
                SupervisorEvent(
                    kind="run_finished", run_id=self._run_id, ok=False, reason=exc.code, message=exc.message
                )
            )
            raise
        failure = report.failure
        self._publish(
            SupervisorEvent(
                kind="run_finished",
                run_id=self._run_id,
                ok=report.ok,
                retries=report.retries,
                reason=failure.reason if failure else "",
                message=failure.summary() if failure else f"{len(report.reports)} step(s) done",
            )
        )
        return report

    def request_stop(self) -> None:
        """Abort the running action at its next service call or trajectory chunk ("stop")."""
        self.stop.set()

    # Events -------------------------------------------------------------------------------------------
    def _on_event(self, event: Event) -> None:
        self._step, self._line, self._attempt = event.step, event.line, event.attempt
        self._publish(
            SupervisorEvent(
                kind=event.kind,
                run_id=self._run_id,
                step=event.step,
                line=event.line,
                attempt=event.attempt,
                reason=event.reason,
                message=event.message,
            )
        )

    def _progress(self, text: str) -> None:
        self._publish(
            SupervisorEvent(
                kind="progress",
                run_id=self._run_id,
                step=self._step,
                line=self._line,
                attempt=self._attempt,
                message=text,
            )
        )

    def _publish(self, event: SupervisorEvent) -> None:
        event = SupervisorEvent(
            **{
                **{f: getattr(event, f) for f in event.__struct_fields__},
                "sim_time_s": self.bus.sim_time_s,
                "wall_time_s": time.time(),
            }
        )
        self.events.append(event)
        with contextlib.suppress(zenoh.ZError):
            self._events.put(event)
        if self.out is not None:
            self.out.write(format_event(event, time.monotonic() - self._started) + "\n")
            self.out.flush()


def format_event(event: SupervisorEvent, elapsed_s: float) -> str:
    """One line of progress for a person."""
    stamp = f"[{elapsed_s:6.1f} s]"
    attempt = f" (attempt {event.attempt})" if event.attempt > 1 else ""
    if event.kind == "run_started":
        return f"{stamp} run {event.run_id}: {event.message}"
    if event.kind == "run_finished":
        verdict = "SUCCESS" if event.ok else "FAILED"
        return f"{stamp} {verdict}: {event.message} ({event.retries} retries)"
    if event.kind == "started":
        return f"{stamp} > {event.step}{attempt}"
    if event.kind == "progress":
        return f"{stamp}   . {event.message}"
    if event.kind == "finished":
        return f"{stamp}   ok: {event.message}"
    if event.kind == "failed":
        return f"{stamp}   failed [{event.reason}]: {event.message}"
    if event.kind == "retried":
        return f"{stamp}   retrying {event.step}{attempt}: after {event.reason}, {event.message}"
    if event.kind == "stopped":
        return f"{stamp}   stopped: {event.message}"
    return f"{stamp} {event.kind}: {event.message}"
