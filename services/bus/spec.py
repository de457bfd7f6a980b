"""Typed descriptions of endpoints (request/reply) and topics (pub/sub).

Each service's schema module (``services/bus/schemas/<service>.py``) declares its specs next to its
message types; services, clients, the CLI (``humanoid call``) and the recorder all use the same specs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class EndpointSpec:
    """A request/reply endpoint ``hrp/<robot>/<service>/<name>``."""

    service: str
    name: str
    request: type
    reply: type
    doc: str = ""

    @property
    def path(self) -> str:
        """``service/name``, as typed on the command line."""
        return f"{self.service}/{self.name}"


@dataclass(frozen=True)
class TopicSpec:
    """A pub/sub topic ``hrp/<robot>/<service>/<name>`` carrying messages of type ``message``."""

    service: str
    name: str
    message: type
    doc: str = ""

    @property
    def path(self) -> str:
        return f"{self.service}/{self.name}"


def json_schema(type_: Any) -> dict[str, Any]:
    """The JSON schema of a message type (arrays shown as lists of numbers)."""
    import msgspec
    import numpy as np

    def hook(t: Any) -> dict[str, Any]:
        if t is np.ndarray:
            return {"type": "array", "items": {}, "description": "numpy array (binary on the bus)"}
        raise NotImplementedError(f"no JSON schema for {t!r}")

    return msgspec.json.schema(type_, schema_hook=hook)
