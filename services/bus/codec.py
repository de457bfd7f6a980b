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


def _dec_hook(type_: type, obj: Any) -> Any:
    if type_ is np.ndarray:
        blob: memoryview | None = getattr(_local, "blob", None)
        if isinstance(obj, list):  # arrays written as JSON lists (e.g. typed by hand on the CLI)
            return np.asarray(obj, dtype=float)
        if not isinstance(obj, dict) or _ND_KEY not in obj:
            raise ValueError("expected an array (a JSON list or a binary array reference)")
        if blob is None:
            raise ValueError("array reference in a plain JSON message")
        offset, nbytes = obj[_ND_KEY]
        if offset < 0 or offset + nbytes > len(blob):
            raise ValueError("array reference points outside the message")
        arr = np.frombuffer(blob[offset : offset + nbytes], dtype=np.dtype(obj["dtype"]))
        return arr.reshape(obj["shape"])
    raise NotImplementedError(f"cannot decode type {type_!r}")


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


def decode(buf: bytes | bytearray | memoryview, type_: type[T]) -> T:
    """Decode one frame as ``type_``; raise InvalidRequestError saying what is wrong and where."""
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
        raise InvalidRequestError(f"malformed payload for {_type_name(type_)}: {exc}") from None


def from_builtins(obj: Any, type_: type[T]) -> T:
    """Build a message from JSON-like values (arrays as nested lists); InvalidRequestError if wrong."""
    try:
        return msgspec.convert(obj, type_, dec_hook=_dec_hook)
    except msgspec.ValidationError as exc:
        raise InvalidRequestError(f"invalid {_type_name(type_)}: {exc}") from None


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
