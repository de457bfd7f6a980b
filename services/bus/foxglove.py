"""Foxglove's well-known ``foxglove.RawImage`` schema, written by hand as protobuf.

Foxglove shows an MCAP channel as an image when its schema is ``foxglove.RawImage``. Of the
encodings Foxglove reads, protobuf keeps the pixels as raw bytes (JSON would need base64), and the
schema record is a serialized ``google.protobuf.FileDescriptorSet``. Both the descriptor and the
messages are small enough to encode here with a few lines of the protobuf wire format
(https://protobuf.dev/programming-guides/encoding/), so no protobuf package is needed.

The ``.proto`` it encodes (from foxglove/schemas, ``RawImage.proto``)::

    syntax = "proto3";
    import "google/protobuf/timestamp.proto";
    package foxglove;
    message RawImage {
      google.protobuf.Timestamp timestamp = 1;
      string frame_id = 7;
      fixed32 width = 2;
      fixed32 height = 3;
      string encoding = 4;   // rgb8, rgba8, mono8, 16UC1, 32FC1, ...
      fixed32 step = 5;      // bytes per row
      bytes data = 6;
    }
"""

from __future__ import annotations

import struct

import numpy as np

SCHEMA_NAME = "foxglove.RawImage"
SCHEMA_ENCODING = "protobuf"
MESSAGE_ENCODING = "protobuf"

_VARINT, _I64, _LEN, _I32 = 0, 1, 2, 5
# google.protobuf.FieldDescriptorProto enums
_LABEL_OPTIONAL = 1
_TYPE_INT64, _TYPE_INT32, _TYPE_FIXED32, _TYPE_STRING, _TYPE_MESSAGE, _TYPE_BYTES = 3, 5, 7, 9, 11, 12


def _varint(value: int) -> bytes:
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _tag(number: int, wire_type: int) -> bytes:
    return _varint((number << 3) | wire_type)


def _len_field(number: int, data: bytes) -> bytes:
    return _tag(number, _LEN) + _varint(len(data)) + data


def _str_field(number: int, text: str) -> bytes:
    return _len_field(number, text.encode())


def _int_field(number: int, value: int) -> bytes:
    return _tag(number, _VARINT) + _varint(value)


def _fixed32_field(number: int, value: int) -> bytes:
    return _tag(number, _I32) + struct.pack("<I", value)


def _field_descriptor(name: str, number: int, type_: int, type_name: str = "") -> bytes:
    body = _str_field(1, name) + _int_field(3, number) + _int_field(4, _LABEL_OPTIONAL) + _int_field(5, type_)
    return body + (_str_field(6, type_name) if type_name else b"")


def _message_descriptor(name: str, fields: list[bytes]) -> bytes:
    return _str_field(1, name) + b"".join(_len_field(2, f) for f in fields)


def _file_descriptor(name: str, package: str, messages: list[bytes], dependencies: tuple[str, ...]) -> bytes:
    body = _str_field(1, name) + _str_field(2, package)
    body += b"".join(_str_field(3, dep) for dep in dependencies)
    body += b"".join(_len_field(4, m) for m in messages)
    return body + _str_field(12, "proto3")


def raw_image_schema() -> bytes:
    """The serialized FileDescriptorSet of ``foxglove.RawImage`` (and its Timestamp dependency)."""
    timestamp = _file_descriptor(
        "google/protobuf/timestamp.proto",
        "google.protobuf",
        [
            _message_descriptor(
                "Timestamp",
                [_field_descriptor("seconds", 1, _TYPE_INT64), _field_descriptor("nanos", 2, _TYPE_INT32)],
            )
        ],
        (),
    )
    raw_image = _file_descriptor(
        "foxglove/RawImage.proto",
        "foxglove",
        [
            _message_descriptor(
                "RawImage",
                [
                    _field_descriptor("timestamp", 1, _TYPE_MESSAGE, ".google.protobuf.Timestamp"),
                    _field_descriptor("frame_id", 7, _TYPE_STRING),
                    _field_descriptor("width", 2, _TYPE_FIXED32),
                    _field_descriptor("height", 3, _TYPE_FIXED32),
                    _field_descriptor("encoding", 4, _TYPE_STRING),
                    _field_descriptor("step", 5, _TYPE_FIXED32),
                    _field_descriptor("data", 6, _TYPE_BYTES),
                ],
            )
        ],
        ("google/protobuf/timestamp.proto",),
    )
    return _len_field(1, timestamp) + _len_field(1, raw_image)


def image_encoding(array: np.ndarray) -> str | None:
    """The RawImage ``encoding`` of an array that can be shown as an image, else None.

    uint8 H x W (mono8), H x W x 1/3/4 (mono8/rgb8/rgba8); uint16 H x W (16UC1, depth in mm);
    float32 H x W (32FC1, depth in m). Both sides at least 8 px, so trajectories are not images.
    """
    if array.ndim not in (2, 3) or min(array.shape[:2]) < 8:
        return None
    channels = 1 if array.ndim == 2 else array.shape[2]
    if array.dtype == np.uint8:
        return {1: "mono8", 3: "rgb8", 4: "rgba8"}.get(channels)
    if channels == 1 and array.dtype == np.uint16:
        return "16UC1"
    if channels == 1 and array.dtype == np.float32:
        return "32FC1"
    return None


def encode_raw_image(
    data: bytes | memoryview,
    *,
    shape: tuple[int, ...],
    encoding: str,
    itemsize: int,
    stamp_ns: int,
    frame_id: str,
) -> bytes:
    """One ``foxglove.RawImage`` message (protobuf) around C-contiguous pixel bytes ``data``."""
    height, width = int(shape[0]), int(shape[1])
    channels = 1 if len(shape) == 2 else int(shape[2])
    seconds, nanos = divmod(int(stamp_ns), 1_000_000_000)
    timestamp = _int_field(1, seconds) + (_int_field(2, nanos) if nanos else b"")
    # Fields in number order, as protobuf serializers write them.
    head = (
        _len_field(1, timestamp)
        + _fixed32_field(2, width)
        + _fixed32_field(3, height)
        + _str_field(4, encoding)
        + _fixed32_field(5, width * channels * itemsize)
        + _tag(6, _LEN)
        + _varint(len(data))
    )
    return b"".join((head, data, _str_field(7, frame_id)))
