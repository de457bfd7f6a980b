"""The wall-clock budget of the request being served, checked by the planners between their steps.

Issue 16: "every planner honours its time budget and replies ``timeout`` with what it has; no request
holds a service past its own budget plus a second". A service handler opens the request's budget
(:func:`within`); the planning code below it, however deep, calls :func:`check` between two bounded
steps of work (a knot of the whole-body IK, a view of a look-around, a sample of a reaching
trajectory, a reshaping iteration of navigation's stage 2). Past the budget, :func:`check` raises
:class:`~services.errors.RequestTimeoutError` naming where the work stopped, with what was done so
far in ``details`` (``budget_s``, ``elapsed_s``, ``stage`` and the caller's partial results); the
service base turns it into a typed ``timeout`` reply, and the endpoint serves the next request.

A step that cannot be stopped once started (one call into a C library) is checked *before* it starts
with :func:`check_fits` and its estimated cost: refused when it would end past the budget.

The budget is per thread (a :mod:`contextvars` variable): each endpoint of a service runs its
handler in its own worker thread, so two endpoints served at once keep their own budgets. Outside a
handler (scripts, tests of the pure packages) no budget is open and :func:`check` does nothing.

Pure Python, no zenoh: the algorithm packages import it.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from services.errors import InvalidRequestError, RequestTimeoutError


@dataclass(frozen=True)
class Deadline:
    """A wall-clock budget opened at ``started`` (``time.monotonic()`` [s]) for ``budget_s`` [s]."""

    budget_s: float
    started: float

    @property
    def at(self) -> float:
        """When the budget runs out (``time.monotonic()`` [s])."""
        return self.started + self.budget_s

    def elapsed(self) -> float:
        """Seconds since the budget was opened."""
        return time.monotonic() - self.started

    def remaining(self) -> float:
        """Seconds left (<= 0 once it ran out)."""
        return self.at - time.monotonic()

    def expired(self) -> bool:
        return time.monotonic() > self.at


_CURRENT: contextvars.ContextVar[Deadline | None] = contextvars.ContextVar("request_deadline", default=None)


@contextlib.contextmanager
def within(budget_s: float) -> Iterator[Deadline]:
    """Open a budget of ``budget_s`` [s] for the code run inside the ``with`` block (this thread)."""
    if not (math.isfinite(budget_s) and budget_s > 0):
        raise InvalidRequestError(f"time_budget_s must be > 0 s, got {budget_s}", {"field": "time_budget_s"})
    deadline = Deadline(float(budget_s), time.monotonic())
    token = _CURRENT.set(deadline)
    try:
        yield deadline
    finally:
        _CURRENT.reset(token)


def within_if(budget_s: float | None) -> contextlib.AbstractContextManager[Deadline | None]:
    """:func:`within` when a budget is given, else nothing (an optional ``time_budget_s`` field)."""
    return within(budget_s) if budget_s is not None else contextlib.nullcontext()


def current() -> Deadline | None:
    """The budget open in this thread, if any."""
    return _CURRENT.get()


def expired() -> bool:
    """Whether the budget open in this thread ran out (False when none is open): for loops that stop
    on their own and report what they have, rather than raise (:func:`check` raises)."""
    deadline = _CURRENT.get()
    return deadline is not None and deadline.expired()


def remaining(default_s: float) -> float:
    """Seconds left of the open budget, at most ``default_s`` (``default_s`` when none is open): the
    timeout to give a call made on the request's behalf (at least 1 ms)."""
    deadline = _CURRENT.get()
    if deadline is None:
        return default_s
    return max(min(default_s, deadline.remaining()), 1e-3)


def check(where: str, partial: dict[str, Any] | None = None) -> None:
    """Raise RequestTimeoutError when the open budget ran out.

    Args:
        where: the step reached, for the message (``"whole-body IK, knot 40 of 310"``).
        partial: what the work has so far, put in ``details`` (JSON-able values: counts, lists).
    """
    deadline = _CURRENT.get()
    if deadline is None or not deadline.expired():
        return
    raise RequestTimeoutError(
        f"the time budget of {deadline.budget_s:.3g} s ran out after {deadline.elapsed():.2f} s, at {where}: "
        "give a larger time_budget_s or a smaller request",
        {"budget_s": deadline.budget_s, "elapsed_s": deadline.elapsed(), "stage": where, **(partial or {})},
    )


def check_fits(cost_s: float, where: str, partial: dict[str, Any] | None = None) -> None:
    """Raise RequestTimeoutError, before a step that cannot be stopped once started (one call into a
    C library: a pybullet render), when its estimated ``cost_s`` [s] would end it past the open budget
    (nothing is done when no budget is open).

    Args:
        cost_s: the step's estimated wall time [s].
        where: the step, for the message (``"the render of a 2048 x 2048 px image"``).
        partial: what the work has so far, put in ``details``.
    """
    check(where, partial)
    deadline = _CURRENT.get()
    if deadline is None or cost_s <= deadline.remaining():
        return
    raise RequestTimeoutError(
        f"the time budget of {deadline.budget_s:.3g} s would run out during {where} (about {cost_s:.2f} s, "
        f"{max(deadline.remaining(), 0.0):.2f} s left after {deadline.elapsed():.2f} s): not started; "
        "give a larger time_budget_s or a smaller request",
        {
            "budget_s": deadline.budget_s,
            "elapsed_s": deadline.elapsed(),
            "stage": where,
            "estimated_s": cost_s,
            **(partial or {}),
        },
    )
