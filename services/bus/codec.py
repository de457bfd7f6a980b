"""Wire codec: small messages as msgspec JSON, large arrays as raw bytes behind a small header.

Two frame kinds, told apart by their first byte:

* a plain JSON document (first byte ``{`` or ``[``) for messages with no :class:`numpy.ndarray`
  field: compact, human readable, and stored as-is in MCAP with a JSON schema;
* a binary frame ``b"HRPB" | u32 header_len (little endian) | header JSON | blob bytes`` for
  messages with arrays. In the header every array is replaced by
  ``{"__nd__": [offset, nbytes], "dtype": "<f8", "shape": [...]}`` pointing into the blob section,
  so images and trajectories travel as raw bytes, never base64.

Decoding is typed: ``decode(buf, T)`` validates against the msgspec type ``T`` and raises
:class:`~services.errors.InvalidRequestError` naming the field and the expected type.
"""

from __future__ import annotations

import re
import struct
import threading
from typing import Any, TypeVar

import msgspec
import numpy as np

from services.errors import InvalidRequestError

T = TypeVar("T")

MAGIC = b"HRPB"
_HEADER = struct.Struct("<4sI")
_ND_KEY = "__nd__"

_local = threading.local()


def _enc_hook(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        blobs: list[bytes | memoryview] | None = getattr(_local, "blobs", None)
        if blobs is None:
            raise TypeError("numpy arrays are only encodable through services.bus.codec.encode")
        arr = np.ascontiguousarray(obj)
        offset = _local.offset
        data = memoryview(arr).cast("B") if arr.size else b""
        blobs.append(data)
        _local.offset += arr.nbytes
        return {_ND_KEY: [offset, arr.nbytes], "dtype": arr.dtype.str, "shape": list(arr.shape)}
    if isinstance(obj, np.generic):
        return obj.item()
    raise NotImplementedError(f"cannot encode objects of type {type(obj).__name__}")


#: Array element kinds a message may carry: bool, signed and unsigned integers, floats (no strings,
#: objects, datetimes, complex numbers or void records).
ARRAY_KINDS = "biuf"
#: Most dimensions of an array in a message (a trajectory is 2-D, an image 3-D).
MAX_ARRAY_DIMS = 4
#: Largest magnitude of a value in a float array of a request: configurations are in m and rad,
#: camera matrices in px; 1e308 would overflow the first sum that uses it.
MAX_ARRAY_ABS = 1e9
_REF_KEYS = frozenset((_ND_KEY, "dtype", "shape"))


def _dec_hook(type_: type, obj: Any) -> Any:
    """Arrays from JSON lists of numbers or binary references; a ValueError names what is wrong
    (msgspec adds the field path)."""
    if type_ is np.ndarray:
        if isinstance(obj, list):  # arrays written as JSON lists (e.g. typed by hand on the CLI)
            return _array_from_list(obj)
        if not isinstance(obj, dict) or _ND_KEY not in obj:
            raise ValueError("expected an array (a JSON list of numbers or a binary array reference)")
        blob: memoryview | None = getattr(_local, "blob", None)
        if blob is None:
            raise ValueError("array reference in a plain JSON message")
        return _array_from_ref(obj, blob)
    raise NotImplementedError(f"cannot decode type {type_!r}")


def _array_from_list(obj: list[Any]) -> np.ndarray:
    # Converted to float64 directly: numpy's own guess of the element type turned a list holding one
    # 1 MB string among 740 numbers into a 3 GB array of strings (30 s, or a MemoryError); as floats,
    # the string fails at once. (msgspec's strict check was tried: it refuses numpy scalars, which
    # in-process callers put in lists.)
    try:
        arr = np.array(obj, dtype=np.float64)
    except (ValueError, TypeError, RecursionError, OverflowError):
        raise ValueError(
            "expected a rectangular array of numbers (rows of equal length, numbers only)"
        ) from None
    # numpy's float conversion also reads "0.5" as 0.5 and null as NaN: neither is a number in JSON
    leaf = _first_non_number(obj)
    if leaf is not None:
        raise ValueError(f"expected an array of numbers, found {leaf} among them")
    if arr.ndim > MAX_ARRAY_DIMS:
        raise ValueError(f"array has {arr.ndim} dimensions, at most {MAX_ARRAY_DIMS} allowed")
    _check_finite(arr)
    return arr


def _first_non_number(obj: list[Any]) -> str | None:
    """How the first string or null among a nested list's leaves reads in an error (None: only
    numbers). One pass over a list that numpy already converted (so no string in it is huge)."""
    stack: list[Any] = [obj]
    while stack:
        item = stack.pop()
        if isinstance(item, list):
            stack.extend(reversed(item))  # in reading order
        elif item is None:
            return "null"
        elif isinstance(item, str):
            return f"the string {item[:20]!r}"
    return None


def _array_from_ref(obj: dict[str, Any], blob: memoryview) -> np.ndarray:
    """A binary array reference ``{"__nd__": [offset, nbytes], "dtype": ..., "shape": [...]}``."""
    if set(obj) != _REF_KEYS:
        missing = sorted(_REF_KEYS - set(obj))
        extra = sorted(set(obj) - _REF_KEYS)
        raise ValueError(
            "binary array reference needs exactly the keys __nd__, dtype, shape"
            + (f"; missing {', '.join(missing)}" if missing else "")
            + (f"; unknown {', '.join(extra)}" if extra else "")
        )
    where, dtype_str, shape = obj[_ND_KEY], obj["dtype"], obj["shape"]
    if not (isinstance(where, list) and len(where) == 2 and all(_is_count(v) for v in where)):
        raise ValueError("__nd__ must be [offset, nbytes], two non-negative integers")
    if not (isinstance(shape, list) and len(shape) <= MAX_ARRAY_DIMS and all(_is_count(v) for v in shape)):
        raise ValueError(f"shape must be a list of at most {MAX_ARRAY_DIMS} non-negative integers")
    if not isinstance(dtype_str, str) or len(dtype_str) > 8:
        raise ValueError("dtype must be a short numpy type string such as '<f8' or '|u1'")
    try:
        dtype = np.dtype(dtype_str)
    except (TypeError, ValueError):
        raise ValueError(f"dtype {dtype_str!r} is not a numpy type string such as '<f8'") from None
    if dtype.kind not in ARRAY_KINDS or dtype.hasobject or dtype.fields is not None:
        raise ValueError(f"dtype {dtype_str!r}: only bool, integer and float arrays travel on the bus")
    offset, nbytes = where
    if offset + nbytes > len(blob):
        raise ValueError("array reference points outside the message")
    count = 1
    for n in shape:
        count *= n
    if count * dtype.itemsize != nbytes:
        raise ValueError(f"shape {shape} of {dtype_str} needs {count * dtype.itemsize} bytes, not {nbytes}")
    arr = np.frombuffer(blob[offset : offset + nbytes], dtype=dtype).reshape(shape)
    _check_finite(arr)
    return arr


def _is_count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value < 2**48


def _check_finite(arr: np.ndarray) -> None:
    """Requests only (``decode(..., finite=True)``): float arrays finite and within MAX_ARRAY_ABS."""
    if not getattr(_local, "finite", False):
        return
    if arr.dtype.kind == "f" and arr.size and not np.isfinite(arr).all():
        bad = int(np.flatnonzero(~np.isfinite(arr.reshape(-1)))[0])
        raise ValueError(f"array has a non-finite value (NaN or infinity) at flat index {bad}")
    if arr.dtype.kind == "f" and arr.size and float(np.abs(arr).max()) > MAX_ARRAY_ABS:
        bad = int(np.argmax(np.abs(arr).reshape(-1)))
        raise ValueError(
            f"array value {arr.reshape(-1)[bad]:g} at flat index {bad} is beyond +-{MAX_ARRAY_ABS:g}"
        )


_encoder = msgspec.json.Encoder(enc_hook=_enc_hook)


class _HasArraysError(Exception):
    """Raised by the plain encoder's hook on the first array: the message needs a binary frame."""


def _plain_enc_hook(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        raise _HasArraysError
    if isinstance(obj, np.generic):
        return obj.item()
    raise NotImplementedError(f"cannot encode objects of type {type(obj).__name__}")


_plain_encoder = msgspec.json.Encoder(enc_hook=_plain_enc_hook)


def encode(msg: Any) -> bytes:
    """Encode a msgspec Struct (or any msgspec-encodable value) into one frame."""
    try:  # most messages have no array: one msgspec call
        return _plain_encoder.encode(msg)
    except _HasArraysError:
        return _encode_binary(msg)


def _encode_binary(msg: Any) -> bytes:
    _local.blobs = []
    _local.offset = 0
    try:
        header = _encoder.encode(msg)
        blobs = _local.blobs
    finally:
        _local.blobs = None
    if not blobs:
        return header
    return b"".join([_HEADER.pack(MAGIC, len(header)), header, *blobs])


def split(buf: bytes | bytearray | memoryview) -> tuple[memoryview, memoryview | None]:
    """Split a frame into (JSON header, blob section or None for a plain JSON frame)."""
    view = memoryview(buf)
    if len(view) >= _HEADER.size and bytes(view[:4]) == MAGIC:
        _, n = _HEADER.unpack_from(view)
        if _HEADER.size + n > len(view):
            raise InvalidRequestError("truncated binary frame: header length exceeds the message size")
        return view[_HEADER.size : _HEADER.size + n], view[_HEADER.size + n :]
    return view, None


_decoders: dict[Any, msgspec.json.Decoder] = {}


def _decoder(type_: Any) -> msgspec.json.Decoder:
    dec = _decoders.get(type_)
    if dec is None:
        dec = _decoders[type_] = msgspec.json.Decoder(type_, dec_hook=_dec_hook)
    return dec


#: Largest request a service decodes [bytes] (a 60 s trajectory of 40 joints is 3.8 MB, a 640x480
#: stereo pair 1.8 MB); larger ones are refused before any parsing.
MAX_REQUEST_BYTES = 64 * 1024 * 1024


def decode(
    buf: bytes | bytearray | memoryview, type_: type[T], *, max_bytes: int | None = None, finite: bool = False
) -> T:
    """Decode one frame as ``type_``; raise InvalidRequestError saying what is wrong and where.

    Every way a payload can be wrong ends here as InvalidRequestError naming the field path (``$.a.b``)
    and the rule: types, the schema's ``Meta`` constraints (ranges, lengths), unknown fields of
    structs declared ``forbid_unknown_fields``, non-finite numbers, invalid UTF-8, nesting deeper than
    the decoder's recursion limit, malformed binary array references. ``max_bytes``: refuse larger
    frames; ``finite``: refuse NaN and infinities in float arrays too (JSON numbers are always
    finite). Services decode requests with both (:func:`decode_request`); replies may carry NaN.
    """
    if max_bytes is not None and len(buf) > max_bytes:
        raise InvalidRequestError(
            f"{_type_name(type_)} payload of {len(buf)} bytes exceeds the limit of {max_bytes} bytes"
        )
    _local.finite = finite
    try:
        if buf[:1] != b"H":  # not a binary frame (those start with MAGIC): plain JSON, one call
            return _decoder(type_).decode(buf)
        header, blob = split(buf)
        _local.blob = blob
        try:
            return _decoder(type_).decode(header)
        finally:
            _local.blob = None
    except msgspec.ValidationError as exc:
        raise InvalidRequestError(f"invalid {_type_name(type_)}: {exc}") from None
    except msgspec.DecodeError as exc:
        raise InvalidRequestError(
            f"malformed payload for {_type_name(type_)}: {exc}{_non_json_number(buf, exc)}"
        ) from None
    except UnicodeDecodeError as exc:
        raise InvalidRequestError(
            f"malformed payload for {_type_name(type_)}: a string is not valid UTF-8 ({exc.reason})"
            f"{_near_invalid_utf8(buf)}"
        ) from None
    except RecursionError:
        raise InvalidRequestError(
            f"malformed payload for {_type_name(type_)}: arrays or objects nested too deeply"
        ) from None


def decode_request(buf: bytes | bytearray | memoryview, type_: type[T]) -> T:
    """Decode a request as a service does: :data:`MAX_REQUEST_BYTES` and finite arrays enforced."""
    try:
        return decode(buf, type_, max_bytes=MAX_REQUEST_BYTES, finite=True)
    finally:
        _local.finite = False


def _near_invalid_utf8(buf: bytes | bytearray | memoryview) -> str:
    """``" (byte N, after "key")"``: where the first invalid UTF-8 byte is, for the error message."""
    raw = bytes(buf)
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        return f" (byte {exc.start}{_after_field(raw, exc.start)})"
    return ""


def _after_field(raw: bytes, at: int) -> str:
    """``', after field "key"'``: the last object key before byte ``at`` of a JSON text, or ""."""
    keys_before = re.findall(rb'"([A-Za-z_][A-Za-z0-9_]{0,63})"\s*:', raw[max(0, at - 4096) : at])
    return f', after field "{keys_before[-1].decode()}"' if keys_before else ""


_DECODE_AT = re.compile(r"\(byte (\d+)\)")
_NON_JSON_NUMBERS = (b"NaN", b"Infinity", b"-Infinity", b"+Infinity", b"inf", b"-inf", b"nan")


def _non_json_number(buf: bytes | bytearray | memoryview, exc: msgspec.DecodeError) -> str:
    """When the JSON text breaks at a ``NaN`` or ``Infinity`` literal (what Python's ``json.dumps``
    writes for non-finite floats): say so and where, for the error message; else ""."""
    match = _DECODE_AT.search(str(exc))
    if match is None:
        return ""
    at = int(match.group(1))
    raw = bytes(buf[: at + 16]) if buf[:1] != b"H" else bytes(split(buf)[0][: at + 16])
    for start in (at - 1, at):  # msgspec points at the literal's first letter, after any sign
        if start >= 0 and raw[start:].startswith(_NON_JSON_NUMBERS):
            return (
                f"; a non-finite number (NaN or Infinity) at byte {start}{_after_field(raw, start)}: "
                "not a JSON number, and requests take finite numbers only"
            )
    return ""


def from_builtins(obj: Any, type_: type[T]) -> T:
    """Build a message from JSON-like values (arrays as nested lists); InvalidRequestError if wrong."""
    try:
        return msgspec.convert(obj, type_, dec_hook=_dec_hook)
    except msgspec.ValidationError as exc:
        raise InvalidRequestError(f"invalid {_type_name(type_)}: {exc}") from None
    except RecursionError:
        raise InvalidRequestError(f"invalid {_type_name(type_)}: values nested too deeply") from None


def to_builtins(msg: Any) -> Any:
    """A JSON-friendly view of a message: arrays become nested lists (for the CLI and logs)."""
    return msgspec.to_builtins(msg, enc_hook=_to_builtins_hook)


def _to_builtins_hook(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise NotImplementedError(f"cannot convert objects of type {type(obj).__name__}")


def _type_name(type_: Any) -> str:
    return getattr(type_, "__name__", repr(type_))
