"""The typed exception tree shared by every package of the stack.

Pure algorithm packages raise these; the bus layer turns them into error replies with the same code,
and the client turns error replies back into the same exception types. No zenoh here.
"""

from __future__ import annotations

from typing import Any, ClassVar

ERROR_CODES = ("invalid_request", "infeasible", "not_found", "timeout", "unavailable", "internal")
#: Outcomes in the world (the sim reports them; the supervisor fails an action with them): not bus codes.
WORLD_CODES = ("fell", "collision", "not_grasped", "stopped")
#: Every failure reason of a supervisor action: a bus error code or a world outcome.
REASONS = ERROR_CODES + WORLD_CODES


class HumanoidError(Exception):
    """Base of every error of the stack. ``code`` is one of :data:`ERROR_CODES`.

    ``details`` carries machine-readable context (residuals, the field at fault, valid options) and
    travels on the bus with the message.
    """

    code: ClassVar[str] = "internal"

    def __init__(self, message: str, details: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.details: dict[str, Any] = dict(details or {})

    def __str__(self) -> str:
        return f"{self.code}: {self.message}"


class InvalidRequestError(HumanoidError):
    """The request is malformed or out of its documented domain (names the field and what was expected)."""

    code = "invalid_request"


class InfeasibleError(HumanoidError):
    """The request is well formed but no solution exists within bounds/budget; ``details`` has residuals."""

    code = "infeasible"


class NotFoundError(HumanoidError):
    """A named thing (object, service, file) does not exist or was not detected."""

    code = "not_found"


class RequestTimeoutError(HumanoidError):
    """No reply within the time budget."""

    code = "timeout"


class UnavailableError(HumanoidError):
    """The service needed is not running (no liveliness token) or refused to serve."""

    code = "unavailable"


class InternalError(HumanoidError):
    """A bug or unexpected failure inside a service; the service keeps serving."""

    code = "internal"


class WorldOutcomeError(HumanoidError):
    """An action failed in the world (the robot fell, touched something, grasped nothing, was stopped):
    the request was fine, the execution was not. ``details`` says where and what (collisions: a list
    of :class:`services.bus.schemas.sim.Contact`-like dicts)."""

    code = "collision"  # overridden by every subclass


class FellError(WorldOutcomeError):
    """The robot fell."""

    code = "fell"


class CollisionError(WorldOutcomeError):
    """A motion was stopped by a contact it was not allowed."""

    code = "collision"


class NotGraspedError(WorldOutcomeError):
    """A hand closed on nothing, or lost what it held."""

    code = "not_grasped"


class StoppedError(WorldOutcomeError):
    """The operator said stop."""

    code = "stopped"


_BY_CODE: dict[str, type[HumanoidError]] = {
    cls.code: cls
    for cls in (
        InvalidRequestError,
        InfeasibleError,
        NotFoundError,
        RequestTimeoutError,
        UnavailableError,
        InternalError,
        FellError,
        CollisionError,
        NotGraspedError,
        StoppedError,
    )
}


def error_from_code(code: str, message: str, details: dict[str, Any] | None = None) -> HumanoidError:
    """The typed exception of an error ``code`` (one of :data:`REASONS`: received on the bus, or a
    world outcome)."""
    cls = _BY_CODE.get(code, InternalError)
    if cls is InternalError and code != "internal":
        message = f"[unknown error code {code!r}] {message}"
    return cls(message, details)
