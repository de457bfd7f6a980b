"""The form a bus frame takes in a log: one JSON document Foxglove decodes, and back.

A frame (:mod:`services.bus.frames`) becomes, in the log:

* ``json``: the same bytes, unless its type has lists of lists (Foxglove's JSON-schema reader has no
  arrays of arrays): then each inner list there becomes ``{"values": [...]}``
  (:func:`services.bus.foxglove.nested_list_paths`);
* ``hrpb``: the JSON header, each array reference ``{"__nd__": [offset, nbytes], "dtype", "shape"}``
  replaced by the array object of :func:`pack_array` (plus the nested-list rewrite);
* ``octets`` (or a frame that does not parse): ``{"data": <base64>}``.

By default :func:`from_log_form` rebuilds the exact frame (msgspec writes the same bytes for the
parsed document as for the message it came from: same key order, shortest float repr), so replay
republishes what was sent and ``replay --requests`` compares replies byte for byte. Arrays are
stored losslessly, float ones of 64+ elements in the ``delta-planes`` byte layout (:func:`pack_array`),
which zstd compresses 25-30 % better than the plain bytes for the stack's trajectories.

A sensor stream may instead be written with ``decimals`` (the recorder does so for the sim's 200 Hz
joint state and base pose, 6 decimals: 1 um, 1 urad): every float rounded to that many decimals and
its arrays as JSON numbers (``values``, plottable in Foxglove). That form is not exact by design
(replay republishes the rounded values) and is 2.6x smaller after compression than the float64 bytes.
"""

from __future__ import annotations

import base64
import struct
from typing import Any

import msgspec
import numpy as np

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
#: Byte layout of a float array's ``data`` (lossless, see :func:`pack_array`).
DELTA_PLANES = "delta-planes"
#: Float arrays with fewer elements keep their plain C-order bytes.
DELTA_MIN_SIZE = 64
_DELTA_DTYPES = {"<f8": "<i8", "<f4": "<i4"}


def to_log_form(data: bytes, type_: type | None, decimals: int | None = None) -> tuple[str, bytes]:
    """``(kind, JSON bytes)``: the frame's kind (json, hrpb, octets) and its form in the log; with
    ``decimals``, floats rounded to that many decimals and arrays as numbers (not exact)."""
    kind = frame_kind(data)
    nested = nested_list_paths(type_) if type_ is not None else ()
    if kind == "json" and not nested and decimals is None:
        return kind, bytes(data)
    try:
        if kind == "json":
            doc = msgspec.json.decode(data)
            if decimals is not None:
                doc = _rounded(doc, decimals)
            stored = _encoder.encode(_map_nested(doc, nested, _wrap))
        elif kind == "hrpb":
            header, blob = split(data)
            doc = _arrays_out(msgspec.json.decode(header), blob, decimals)
            if decimals is not None:
                doc = _rounded(doc, decimals)
            stored = _encoder.encode(_map_nested(doc, nested, _wrap) if nested else doc)
        else:
            stored = b""
        # Only a form that gives the frame back is kept (a frame with stray bytes is kept as octets);
        # a rounded form must at least rebuild a frame.
        if stored and decimals is not None and from_log_form(kind, stored, type_):
            return kind, stored
        if stored and from_log_form(kind, stored, type_) == data:
            return kind, stored
    except (msgspec.DecodeError, ValueError, TypeError, KeyError, HumanoidError):
        pass  # not what its first bytes said: kept as octets
    return "octets", _encoder.encode({"data": base64.b64encode(bytes(data)).decode()})


def pack_array(raw: bytes | memoryview, dtype: str, shape: list[int], decimals: int | None = None) -> dict:
    """An array's object in a log: ``{dtype, shape, data}`` with ``data`` the base64 of

    * with ``decimals`` and a float dtype: no ``data`` but ``values``, the numbers (C order) rounded;
    * a little-endian float array of >= :data:`DELTA_MIN_SIZE` elements: its ``delta-planes`` bytes
      (``layout``): the array as rows along its first axis (time, for a trajectory), each element's
      bits read as a signed integer of the same width, every row minus the previous one (wrapping;
      the first row kept), columns laid out one after the other, then byte planes (all first bytes,
      all second bytes, ...). Smooth series give differences with equal high bytes, which zstd
      compresses; the bits are untouched, so :func:`unpack_array` gives back the same bytes;
    * otherwise the plain C-order bytes."""
    raw = memoryview(raw).cast("B")
    if decimals is not None and np.dtype(dtype).kind == "f":
        values = np.round(np.frombuffer(raw, dtype=dtype).astype(float), decimals)
        return {"dtype": dtype, "shape": shape, "values": values.tolist()}
    as_int = _DELTA_DTYPES.get(dtype)
    count = len(raw) // np.dtype(dtype).itemsize
    if as_int is None or count < DELTA_MIN_SIZE or not shape or shape[0] < 2:
        return {"dtype": dtype, "shape": shape, "data": base64.b64encode(raw).decode()}
    rows = np.frombuffer(raw, dtype=as_int).reshape(shape[0], -1)
    delta = rows.copy()
    delta[1:] -= rows[:-1]  # integer arithmetic wraps: exact inverse by a cumulative sum
    planes = np.ascontiguousarray(delta.T).view(np.uint8).reshape(-1, delta.itemsize).T
    data = base64.b64encode(planes.tobytes()).decode()
    return {"dtype": dtype, "shape": shape, "layout": DELTA_PLANES, "data": data}


def unpack_array(node: dict[str, Any]) -> bytes:
    """The C-order bytes of an array object written by :func:`pack_array`."""
    dtype = node["dtype"]
    if "values" in node:
        values = np.asarray([np.nan if v is None else v for v in node["values"]], dtype=float)
        return values.astype(dtype).tobytes()
    raw = base64.b64decode(node["data"])
    layout = node.get("layout", "")
    if not layout:
        return raw
    if layout != DELTA_PLANES or dtype not in _DELTA_DTYPES:
        raise ValueError(f"unknown array layout {layout!r} for dtype {dtype!r}")
    as_int = np.dtype(_DELTA_DTYPES[dtype])
    shape = node["shape"]
    rows = shape[0]
    planes = np.frombuffer(raw, dtype=np.uint8).reshape(as_int.itemsize, -1)
    if rows < 1 or planes.shape[1] % rows:
        raise ValueError(f"array bytes do not match its shape {shape}")
    delta = np.ascontiguousarray(planes.T).view(as_int).reshape(-1, rows).T
    return np.cumsum(delta, axis=0, dtype=as_int).tobytes()


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
def _arrays_out(node: Any, blob: memoryview | None, decimals: int | None) -> Any:
    if isinstance(node, dict):
        if _ND_KEY in node and "dtype" in node and "shape" in node:
            if blob is None:
                raise ValueError("array reference in a plain JSON frame")
            offset, nbytes = node[_ND_KEY]
            if offset < 0 or offset + nbytes > len(blob):
                raise ValueError("array reference outside the frame")
            return pack_array(blob[offset : offset + nbytes], node["dtype"], node["shape"], decimals)
        return {k: _arrays_out(v, blob, decimals) for k, v in node.items()}
    if isinstance(node, list):
        return [_arrays_out(v, blob, decimals) for v in node]
    return node


def _rounded(node: Any, decimals: int) -> Any:
    if isinstance(node, float):
        return round(node, decimals)
    if isinstance(node, dict):
        return {k: _rounded(v, decimals) for k, v in node.items()}
    if isinstance(node, list):
        return [_rounded(v, decimals) for v in node]
    return node


def _is_array(node: dict[str, Any]) -> bool:
    if "dtype" not in node or "shape" not in node:
        return False
    if isinstance(node.get("values"), list):
        return len(node) == 3
    return isinstance(node.get("data"), str) and (len(node) == 3 or (len(node) == 4 and "layout" in node))


def _arrays_in(node: Any, blobs: list[bytes], offset: list[int]) -> Any:
    """Array objects back to references, in document order (the order the codec laid out the blobs)."""
    if isinstance(node, dict):
        if _is_array(node):
            raw = unpack_array(node)
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
