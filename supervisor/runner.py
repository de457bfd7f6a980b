"""Runs parsed steps: resolves names, calls actions, applies the retry policy, emits events.

The runner knows nothing of the bus: actions, remedies and the event sink are given to it, so the
same runner drives the real services (``supervisor/actions.py``) and is testable on its own.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from services.errors import HumanoidError, InvalidRequestError
from supervisor.report import ActionReport
from supervisor.retry import DEFAULT_POLICY, RetryPolicy
from supervisor.script import Step

Action = Callable[[Step], ActionReport]
Remedy = Callable[[Step, ActionReport], None]


@dataclass(frozen=True)
class Event:
    """A supervisor event: ``kind`` in started | finished | failed | retried | stopped."""

    kind: str
    step: str
    line: int
    attempt: int
    reason: str = ""
    message: str = ""


@dataclass(frozen=True)
class RunReport:
    """The outcome of a whole script."""

    ok: bool
    reports: tuple[ActionReport, ...]
    retries: int
    wall_time_s: float
    bindings: dict[str, Any] = field(default_factory=dict)

    @property
    def failure(self) -> ActionReport | None:
        return next((r for r in self.reports if not r.ok), None)


class Runner:
    """Execute steps one after the other; stop at the first failure the policy cannot recover."""

    def __init__(
        self,
        actions: Mapping[str, Action],
        *,
        policy: RetryPolicy = DEFAULT_POLICY,
        remedies: Mapping[str, Remedy] | None = None,
        on_event: Callable[[Event], None] | None = None,
        stop: threading.Event | None = None,
    ) -> None:
        self.actions = actions
        self.policy = policy
        self.remedies = dict(remedies or {})
        self.on_event = on_event or (lambda _event: None)
        self.stop = stop or threading.Event()
        self.bindings: dict[str, Any] = {}

    def resolve(self, step: Step) -> Step:
        """Replace names bound by earlier ``as NAME`` with what they stand for."""
        args = tuple(str(self.bindings.get(a, a)) for a in step.args)
        kwargs = {k: str(self.bindings.get(v, v)) for k, v in step.kwargs.items()}
        return dataclasses.replace(step, args=args, kwargs=kwargs)

    def run(self, steps: Iterable[Step]) -> RunReport:
        started = time.monotonic()
        reports: list[ActionReport] = []
        retries = 0
        for step in steps:
            report = self.run_step(step)
            retries += report.attempts - 1
            reports.append(report)
            if not report.ok:
                break
        ok = bool(reports) and all(r.ok for r in reports)
        return RunReport(ok, tuple(reports), retries, time.monotonic() - started, dict(self.bindings))

    def run_step(self, step: Step) -> ActionReport:
        action = self.actions.get(step.action)
        if action is None:
            raise InvalidRequestError(f"no implementation of action '{step.action}'")
        attempt = 0
        while True:
            attempt += 1
            if self.stop.is_set():
                self._emit("stopped", step, attempt, "stopped", "stopped by the operator")
                return ActionReport(
                    step.action,
                    step.args,
                    ok=False,
                    reason="stopped",
                    message="stopped by the operator",
                    attempts=attempt,
                )
            resolved = self.resolve(step)
            self._emit("started", step, attempt)
            began = time.monotonic()
            try:
                report = action(resolved)
            except HumanoidError as exc:
                report = ActionReport(
                    step.action,
                    resolved.args,
                    ok=False,
                    reason=exc.code,
                    message=exc.message,
                    details=exc.details,
                )
            report = dataclasses.replace(report, attempts=attempt, wall_time_s=time.monotonic() - began)
            if report.ok:
                if step.bind:
                    self.bindings[step.bind] = report.details.get("object", report.details.get("value"))
                self._emit("finished", step, attempt, message=report.message)
                return report
            if report.reason == "stopped":
                self._emit("stopped", step, attempt, "stopped", report.message)
                return report
            self._emit("failed", step, attempt, report.reason, report.message)
            rule = self.policy.rule(report.reason, str(report.details.get("reason", "")))
            if attempt > rule.retries or self.stop.is_set():
                return report
            self._emit("retried", step, attempt + 1, report.reason, f"remedy: {rule.remedy}")
            if rule.backoff_s:
                self.stop.wait(rule.backoff_s * attempt)
            remedy = self.remedies.get(rule.remedy)
            if remedy is not None:
                try:
                    remedy(resolved, report)
                except HumanoidError as exc:
                    message = f"remedy {rule.remedy} failed: {exc.message}"
                    self._emit("failed", step, attempt, exc.code, message)
                    # no retry can succeed from here: a final sub-reason (a robot leaning on what it
                    # touched), or the robot fell during the remedy (on the ground: reset the sim)
                    if exc.code == "fell" or exc.details.get("reason") in self.policy.final:
                        details = {**report.details, **exc.details}
                        return dataclasses.replace(report, reason=exc.code, message=message, details=details)

    def _emit(self, kind: str, step: Step, attempt: int, reason: str = "", message: str = "") -> None:
        self.on_event(Event(kind, step.text(), step.line, attempt, reason, message))
