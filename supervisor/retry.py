"""Retry policies: what the supervisor does when an action reports a failure of a given kind.

Following the motion-autonomy paper ("Each action can report failures ... it is thus possible to
implement error recovery strategies by analyzing the reports of the actions"), each failure reason
maps to a bounded number of retries and a remedy run before the retry.
"""

from __future__ import annotations

from dataclasses import dataclass

from services.bus.schemas.supervisor import REASON_OUT_OF_REACH, REASON_WORLD_LOST
from services.bus.schemas.walking import REASON_LEANING
from supervisor.report import REASONS

REMEDIES = ("none", "relocalize", "replan", "wait_service")


@dataclass(frozen=True)
class RetryRule:
    """``retries`` more attempts after the first, each preceded by ``remedy``, ``backoff_s`` apart."""

    retries: int
    remedy: str = "none"
    backoff_s: float = 0.0

    def __post_init__(self) -> None:
        if self.remedy not in REMEDIES:
            raise ValueError(f"unknown remedy {self.remedy!r}; known: {', '.join(REMEDIES)}")
        if self.retries < 0:
            raise ValueError("retries must be >= 0")


@dataclass(frozen=True)
class RetryPolicy:
    """A rule per failure reason; reasons without a rule are not retried, nor are the failures whose
    sub-reason (``details["reason"]``) is ``final`` (no retry can help: the world they acted in is gone;
    the object rests below the reach of a standing robot, seen from near; the robot leans on what it
    touched and cannot settle its feet). A remedy failing with a ``final`` sub-reason ends the retries
    too (the runner)."""

    rules: tuple[tuple[str, RetryRule], ...]
    final: tuple[str, ...] = (REASON_WORLD_LOST, REASON_OUT_OF_REACH, REASON_LEANING)

    def rule(self, reason: str, sub_reason: str = "") -> RetryRule:
        if sub_reason and sub_reason in self.final:
            return RetryRule(0)
        for name, rule in self.rules:
            if name == reason:
                return rule
        return RetryRule(0)

    def __post_init__(self) -> None:
        unknown = [name for name, _ in self.rules if name not in REASONS]
        if unknown:
            raise ValueError(f"retry rules for unknown reasons {unknown}; known: {', '.join(REASONS)}")


DEFAULT_POLICY = RetryPolicy(
    rules=(
        # A missed grasp: the object moved or was localized badly; look again, reach again.
        ("not_grasped", RetryRule(2, "relocalize")),
        # The plan hit something: plan again from the state the robot is in now.
        ("collision", RetryRule(2, "replan")),
        # A planner found no solution: a fresh localization may move the goal into reach.
        ("infeasible", RetryRule(1, "relocalize")),
        # A service died or is restarting: wait for its liveliness token, then retry (not the sim: its
        # restart lost the world, REASON_WORLD_LOST is final).
        ("unavailable", RetryRule(3, "wait_service", backoff_s=0.5)),
        ("timeout", RetryRule(2, "wait_service", backoff_s=0.5)),
        ("internal", RetryRule(1, "none", backoff_s=0.5)),
    )
)
