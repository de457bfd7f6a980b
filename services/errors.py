"""The typed exception tree shared by every package of the stack.

Pure algorithm packages raise these; the bus layer turns them into error replies with the same code,
and the client turns error replies back into the same exception types. No zenoh here.
"""

from __future__ import annotations

from typing import Any, ClassVar

ERROR_CODES = ("invalid_request", "infeasible", "not_found", "timeout", "unavailable", "internal")


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


_BY_CODE: dict[str, type[HumanoidError]] = {
    cls.code: cls
    for cls in (
        InvalidRequestError,
        InfeasibleError,
        NotFoundError,
        RequestTimeoutError,
        UnavailableError,
        InternalError,
    )
}


def error_from_code(code: str, message: str, details: dict[str, Any] | None = None) -> HumanoidError:
    """Rebuild the typed exception for an error ``code`` received on the bus."""
    cls = _BY_CODE.get(code, InternalError)
    if cls is InternalError and code != "internal":
        message = f"[unknown error code {code!r}] {message}"
    return cls(message, details)
