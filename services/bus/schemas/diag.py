"""The diagnostics service: round trips for health checks, tests and the bus benchmark."""

from __future__ import annotations

import msgspec
import numpy as np

from services.bus.spec import EndpointSpec


class EchoRequest(msgspec.Struct, kw_only=True, frozen=True):
    """Anything to send back. ``blob`` travels as raw bytes (binary frame)."""

    text: str = ""
    blob: np.ndarray | None = None


class EchoReply(msgspec.Struct, kw_only=True, frozen=True):
    text: str = ""
    blob: np.ndarray | None = None
    pid: int = 0  # process id of the diag service that answered


ECHO = EndpointSpec("diag", "echo", EchoRequest, EchoReply, "returns the request (round-trip checks)")
