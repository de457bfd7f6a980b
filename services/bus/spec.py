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
    """The JSON schema of a message type, with ``$ref`` definitions inlined (Foxglove reads these).

    Array fields (binary on the bus) accept anything here: in JSON views they are nested lists, or a
    summary (shape, dtype) when too large, or a reference to an image channel.
    """
    import msgspec
    import numpy as np

    def hook(t: Any) -> dict[str, Any]:
        if t is np.ndarray:
            return {"description": "numpy array (raw bytes on the bus)"}
        raise NotImplementedError(f"no JSON schema for {t!r}")

    schema = msgspec.json.schema(type_, schema_hook=hook)
    defs = schema.pop("$defs", {})
    return _inline(schema, defs, ())


def _inline(node: Any, defs: dict[str, Any], seen: tuple[str, ...]) -> Any:
    if isinstance(node, list):
        return [_inline(item, defs, seen) for item in node]
    if not isinstance(node, dict):
        return node
    ref = node.get("$ref")
    if isinstance(ref, str) and ref.startswith("#/$defs/"):
        name = ref.removeprefix("#/$defs/")
        if name in seen or name not in defs:  # a recursive type: leave it open
            return {"type": "object", "title": name}
        return _inline(defs[name], defs, (*seen, name))
    return {k: _inline(v, defs, seen) for k, v in node.items()}
