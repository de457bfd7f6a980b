"""The form a bus frame takes in a log: one JSON document Foxglove decodes, and back, byte for byte.

A frame (:mod:`services.bus.frames`) becomes, in the log:

* ``json``: the same bytes, unless its type has lists of lists (Foxglove's JSON-schema reader has no
  arrays of arrays): then each inner list there becomes ``{"values": [...]}``
  (:func:`services.bus.foxglove.nested_list_paths`);
* ``hrpb``: the JSON header, each array reference ``{"__nd__": [offset, nbytes], "dtype", "shape"}``
  replaced by ``{"dtype", "shape", "data": <base64 of the bytes>}`` (plus the nested-list rewrite);
* ``octets`` (or a frame that does not parse): ``{"data": <base64>}``.

:func:`from_log_form` rebuilds the exact frame (msgspec writes the same bytes for the parsed document
as for the message it came from: same key order, shortest float repr), so replay republishes what
was sent and ``replay --requests`` compares replies byte for byte.
"""

from __future__ import annotations

import base64
import struct
from typing import Any

import msgspec

from services.bus.codec import MAGIC, split
from services.bus.foxglove import NESTED_KEY, nested_list_paths
from services.bus.frames import frame_kind
from services.errors import HumanoidError

_ND_KEY = "__nd__"
_HEADER = struct.Struct("<4sI")
#: Schema of an ``octets`` message in a log.
OCTETS_SCHEMA: dict[str, Any] = {
    "title": "Octets",
    "description": "a payload that is neither JSON nor a binary frame (e.g. a malformed request), base64",
    "type": "object",
    "properties": {"data": {"type": "string", "contentEncoding": "base64"}},
}
_encoder = msgspec.json.Encoder()


def to_log_form(data: bytes, type_: type | None) -> tuple[str, bytes]:
    """``(kind, JSON bytes)``: the frame's kind (json, hrpb, octets) and its form in the log."""
    kind = frame_kind(data)
    nested = nested_list_paths(type_) if type_ is not None else ()
    if kind == "json" and not nested:
        return kind, bytes(data)
    try:
        if kind == "json":
            stored = _encoder.encode(_map_nested(msgspec.json.decode(data), nested, _wrap))
        elif kind == "hrpb":
            header, blob = split(data)
            doc = _arrays_out(msgspec.json.decode(header), blob)
            stored = _encoder.encode(_map_nested(doc, nested, _wrap) if nested else doc)
        else:
            stored = b""
        # Only a form that gives the frame back is kept (a frame with stray bytes is kept as octets).
        if stored and from_log_form(kind, stored, type_) == data:
            return kind, stored
    except (msgspec.DecodeError, ValueError, TypeError, KeyError, HumanoidError):
        pass  # not what its first bytes said: kept as octets
    return "octets", _encoder.encode({"data": base64.b64encode(bytes(data)).decode()})


def from_log_form(kind: str, stored: bytes, type_: type | None) -> bytes:
    """The exact frame that :func:`to_log_form` turned into ``stored``."""
    if kind == "octets":
        return base64.b64decode(msgspec.json.decode(stored)["data"])
    nested = nested_list_paths(type_) if type_ is not None else ()
    if kind == "json":
        if not nested:
            return bytes(stored)
        return _encoder.encode(_map_nested(msgspec.json.decode(stored), nested, _unwrap))
    if kind == "hrpb":
        doc = msgspec.json.decode(stored)
        if nested:
            doc = _map_nested(doc, nested, _unwrap)
        blobs: list[bytes] = []
        header = _encoder.encode(_arrays_in(doc, blobs, [0]))
        return b"".join([_HEADER.pack(MAGIC, len(header)), header, *blobs])
    raise ValueError(f"unknown frame kind {kind!r} (json, hrpb, octets)")


# ---------------------------------------------------------------------------------------------------
def _arrays_out(node: Any, blob: memoryview | None) -> Any:
    if isinstance(node, dict):
        if _ND_KEY in node and "dtype" in node and "shape" in node:
            if blob is None:
                raise ValueError("array reference in a plain JSON frame")
            offset, nbytes = node[_ND_KEY]
            if offset < 0 or offset + nbytes > len(blob):
                raise ValueError("array reference outside the frame")
            raw = base64.b64encode(blob[offset : offset + nbytes]).decode()
            return {"dtype": node["dtype"], "shape": node["shape"], "data": raw}
        return {k: _arrays_out(v, blob) for k, v in node.items()}
    if isinstance(node, list):
        return [_arrays_out(v, blob) for v in node]
    return node


def _is_array(node: dict[str, Any]) -> bool:
    return len(node) == 3 and isinstance(node.get("data"), str) and "dtype" in node and "shape" in node


def _arrays_in(node: Any, blobs: list[bytes], offset: list[int]) -> Any:
    """Array objects back to references, in document order (the order the codec laid out the blobs)."""
    if isinstance(node, dict):
        if _is_array(node):
            raw = base64.b64decode(node["data"])
            ref = {_ND_KEY: [offset[0], len(raw)], "dtype": node["dtype"], "shape": node["shape"]}
            blobs.append(raw)
            offset[0] += len(raw)
            return ref
        return {k: _arrays_in(v, blobs, offset) for k, v in node.items()}
    if isinstance(node, list):
        return [_arrays_in(v, blobs, offset) for v in node]
    return node


def _wrap(value: Any) -> Any:
    if not isinstance(value, list):
        return value
    return [{NESTED_KEY: v} if isinstance(v, list) else v for v in value]


def _unwrap(value: Any) -> Any:
    if not isinstance(value, list):
        return value
    return [v[NESTED_KEY] if isinstance(v, dict) and list(v) == [NESTED_KEY] else v for v in value]


def _map_nested(doc: Any, paths: tuple[tuple[str, ...], ...], fn: Any) -> Any:
    for path in paths:
        doc = _apply(doc, path, fn)
    return doc


def _apply(node: Any, path: tuple[str, ...], fn: Any) -> Any:
    if not path:
        return fn(node)
    step, rest = path[0], path[1:]
    if step == "[]":
        return [_apply(v, rest, fn) for v in node] if isinstance(node, list) else node
    if isinstance(node, dict) and step in node:
        return {**node, step: _apply(node[step], rest, fn)}
    return node
