"""What an action reports: success, or a failure with a reason code a retry policy can act on."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

# Reason codes of failed actions. The first six are the bus error codes (services.errors); the others
# are outcomes of execution in the world.
REASONS = (
    "invalid_request",
    "infeasible",
    "not_found",
    "timeout",
    "unavailable",
    "internal",
    "fell",
    "collision",
    "not_grasped",
    "stopped",
)


@dataclass(frozen=True)
class ActionReport:
    """The outcome of one action.

    Attributes:
        action: the action's name (``localize``, ``goto``...).
        args: the arguments it ran with, as written in the script.
        ok: whether it succeeded.
        reason: a code of :data:`REASONS` when it failed, ``""`` on success.
        message: what happened, for a person.
        details: machine-readable results (positions, residuals, the object held...).
        attempts: how many times it ran (1 + retries).
        sim_time_s: simulated time it took [s]; wall_time_s: wall-clock time [s].
    """

    action: str
    args: tuple[str, ...] = ()
    ok: bool = True
    reason: str = ""
    message: str = ""
    details: dict[str, Any] = field(default_factory=dict)
    attempts: int = 1
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0

    def __post_init__(self) -> None:
        if not self.ok and self.reason not in REASONS:
            raise ValueError(f"unknown failure reason {self.reason!r}; known: {', '.join(REASONS)}")

    def summary(self) -> str:
        call = " ".join((self.action, *self.args))
        if self.ok:
            return f"{call}: ok ({self.attempts} attempt(s)) {self.message}".rstrip()
        return f"{call}: FAILED [{self.reason}] {self.message} ({self.attempts} attempt(s))"


class ActionError(Exception):
    """Raised inside an action for a failure in the world (``fell``, ``collision``, ``not_grasped``,
    ``stopped``...); the runner turns it into a failed :class:`ActionReport` like a bus error."""

    def __init__(self, reason: str, message: str, details: dict[str, Any] | None = None) -> None:
        if reason not in REASONS:
            raise ValueError(f"unknown failure reason {reason!r}; known: {', '.join(REASONS)}")
        super().__init__(message)
        self.reason = reason
        self.message = message
        self.details: dict[str, Any] = dict(details or {})

    def __str__(self) -> str:
        return f"{self.reason}: {self.message}"
