"""What an action reports: success, or a failure with a reason code a retry policy can act on."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from services.errors import REASONS as ERROR_REASONS

# Reason codes of failed actions (services/errors.py): the bus error codes, then outcomes in the world.
REASONS = ERROR_REASONS


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
