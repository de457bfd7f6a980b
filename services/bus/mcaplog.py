"""MCAP logs of the bus: what the recorder writes and what replay and ``log-info`` read.

Layout of a log (one MCAP file):

* **originals**, one channel per key expression (topic = the zenoh key), holding the exact bytes
  that were published, so replay republishes exactly what was sent. The message encoding is the
  frame kind (:mod:`services.bus.frames`): ``json`` (plain JSON, which Foxglove shows directly),
  ``hrpb`` (the binary frame of :mod:`services.bus.codec`) or ``octets`` (anything else, e.g. a
  malformed request). A key whose messages change kind gets one channel per kind.
* **views** of binary frames, for Foxglove: ``<key>/view`` is the frame as JSON (arrays as lists,
  large ones summarised), and every image-like array becomes ``<key>/view/<field>`` as a
  ``foxglove.RawImage`` (protobuf, raw pixels).

Schemas: the JSON schema of the message type when the key is known to the spec registry
(:mod:`services.bus.schemas`), for originals and views alike. Channel metadata ``hrp.key`` is the
zenoh key and ``hrp.role`` is ``original`` or ``view``. The request id attachment of the
``<endpoint>/request|reply|error`` mirrors is the MCAP message ``sequence``.

Chunks are lz4-compressed (or not at all: never zstd, which costs 5x the time on images for 2 %)
and closed both by size and every ``chunk_period_s``, and the file is flushed after each chunk: a
recorder killed with SIGKILL loses at most its last chunk, and :class:`LogReader` reads the rest.
"""

from __future__ import annotations

import functools
import json
import struct
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from services.bus import foxglove, keys
from services.bus.frames import ArrayRef, frame_kind, parse_frame, replace_arrays
from services.errors import InvalidRequestError, NotFoundError

ROLE_ORIGINAL = "original"
ROLE_VIEW = "view"
_COMPRESSIONS = {"lz4": CompressionType.LZ4, "none": CompressionType.NONE}
_MIRRORS = ("request", "reply", "error")


# ---------------------------------------------------------------------------------------------------
# Which message type a key carries
# ---------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=4096)
def message_type_for_key(key: str) -> type | None:
    """The msgspec type published on ``key`` according to the spec registry, or None."""
    from services.bus import schemas
    from services.bus.schemas.common import ErrorInfo, Heartbeat

    try:
        _robot, service, rest = keys.parse(key)
    except ValueError:
        return None
    parts = rest.split("/")
    if parts == ["heartbeat"]:
        return Heartbeat
    if len(parts) == 1:
        topic = schemas.topics().get(f"{service}/{parts[0]}")
        return topic.message if topic is not None else None
    if len(parts) == 2 and parts[1] in _MIRRORS:
        if parts[1] == "error":
            return ErrorInfo
        endpoint = schemas.endpoints().get(f"{service}/{parts[0]}")
        if endpoint is None:
            return None
        return endpoint.request if parts[1] == "request" else endpoint.reply
    return None


def schema_name(type_: type) -> str:
    """``hrp.<schema module>.<Type>``, e.g. ``hrp.diag.EchoRequest``."""
    module = type_.__module__.removeprefix("services.bus.schemas.")
    return f"hrp.{module}.{type_.__qualname__}"


# ---------------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------------
class LogWriter:
    """Writes bus messages to an MCAP file (see the module docstring). Not thread-safe."""

    def __init__(
        self,
        path: str | Path,
        *,
        compression: str = "lz4",
        chunk_size_bytes: int = 4 << 20,
        image_views: bool = True,
        max_view_elements: int = 100_000,
        metadata: dict[str, str] | None = None,
    ) -> None:
        if compression not in _COMPRESSIONS:
            raise InvalidRequestError(
                f"compression {compression!r} is not one of: {', '.join(_COMPRESSIONS)} (zstd is too slow)"
            )
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file, chunk_size=chunk_size_bytes, compression=_COMPRESSIONS[compression])
        # mcap 1.x closes chunks only by size; closing them by time needs its private method.
        self._finalize_chunk = getattr(self._writer, "_Writer__finalize_chunk", None)
        if self._finalize_chunk is None:
            raise RuntimeError("this mcap version has no Writer.__finalize_chunk: pin mcap>=1.6,<2")
        self._writer.start(profile="", library="humanoid-autonomy recorder")
        if metadata:
            self._writer.add_metadata("recording", dict(metadata))
        self._image_views = image_views
        self._max_view_elements = max_view_elements
        self._channels: dict[tuple[str, str], int] = {}
        self._schemas: dict[str, int] = {}
        self.message_counts: Counter[str] = Counter()
        self.closed = False

    # Public -------------------------------------------------------------------------------------------
    def write(self, key: str, data: bytes, log_time_ns: int, sequence: int = 0) -> None:
        """Log one message published on ``key`` (its exact bytes, plus Foxglove views if binary)."""
        kind = frame_kind(data)
        type_ = message_type_for_key(key)
        # Bytes that are neither JSON nor a binary frame (a malformed request) match no schema.
        channel = self._channel(key, kind, type_ if kind != "octets" else None, ROLE_ORIGINAL, kind)
        self._writer.add_message(channel, log_time_ns, data, log_time_ns, sequence)
        self.message_counts[key] += 1
        if kind == "hrpb":
            self._write_views(key, data, type_, log_time_ns, sequence)
        self._file.flush()  # a chunk closed by size reaches the OS now

    def flush_chunk(self) -> None:
        """Close the open chunk and push it to the OS (bounds what a SIGKILL can lose)."""
        self._finalize_chunk()
        self._file.flush()

    def close(self) -> None:
        """Write the summary (indexes, statistics) and close the file."""
        if self.closed:
            return
        self.closed = True
        self._writer.finish()
        self._file.close()

    # Internals ----------------------------------------------------------------------------------------
    def _schema_id(self, type_: type | None) -> int:
        if type_ is None:
            return 0
        name = schema_name(type_)
        sid = self._schemas.get(name)
        if sid is None:
            from services.bus.spec import json_schema

            data = json.dumps(json_schema(type_)).encode()
            sid = self._schemas[name] = self._writer.register_schema(name, "jsonschema", data)
        return sid

    def _image_schema_id(self) -> int:
        sid = self._schemas.get(foxglove.SCHEMA_NAME)
        if sid is None:
            sid = self._schemas[foxglove.SCHEMA_NAME] = self._writer.register_schema(
                foxglove.SCHEMA_NAME, foxglove.SCHEMA_ENCODING, foxglove.raw_image_schema()
            )
        return sid

    def _channel(
        self, topic: str, slot: str, type_: type | None, role: str, encoding: str, key: str = ""
    ) -> int:
        cid = self._channels.get((topic, slot))
        if cid is None:
            schema = (
                self._image_schema_id() if encoding == foxglove.MESSAGE_ENCODING else self._schema_id(type_)
            )
            meta = {"hrp.key": key or topic, "hrp.role": role}
            cid = self._channels[(topic, slot)] = self._writer.register_channel(topic, encoding, schema, meta)
        return cid

    def _write_views(
        self, key: str, data: bytes, type_: type | None, log_time_ns: int, sequence: int
    ) -> None:
        try:
            doc, refs = parse_frame(data)
        except (msgspec.DecodeError, ValueError):
            return  # a malformed binary frame: the original is kept, there is nothing to view
        by_path = {ref.path: ref for ref in refs}

        def view_of(path: str, _ref: dict[str, Any]) -> Any:
            ref = by_path[path]
            array = ref.array()
            encoding = foxglove.image_encoding(array) if self._image_views else None
            if encoding is not None:
                topic = f"{key}/view/{path}"
                frame_id = _frame_id(doc, path)
                image = foxglove.encode_raw_image(
                    ref.data,
                    shape=array.shape,
                    encoding=encoding,
                    itemsize=array.dtype.itemsize,
                    stamp_ns=log_time_ns,
                    frame_id=frame_id,
                )
                cid = self._channel(topic, "image", None, ROLE_VIEW, foxglove.MESSAGE_ENCODING, key)
                self._writer.add_message(cid, log_time_ns, image, log_time_ns, sequence)
                return {"image_topic": topic, "dtype": str(array.dtype), "shape": list(array.shape)}
            return _array_view(ref, self._max_view_elements)

        view = replace_arrays(doc, view_of)
        cid = self._channel(f"{key}/view", "json", type_, ROLE_VIEW, "json", key)
        self._writer.add_message(cid, log_time_ns, msgspec.json.encode(view), log_time_ns, sequence)


def _frame_id(doc: Any, path: str) -> str:
    """An image's frame: a ``frame_id`` or ``name`` beside the array (innermost first), else its path."""
    nodes = [doc]
    for part in path.split("/")[:-1]:
        node = nodes[-1]
        try:
            nodes.append(node[int(part)] if isinstance(node, list) else node[part])
        except (KeyError, IndexError, ValueError, TypeError):
            break
    for node in reversed(nodes):
        if isinstance(node, dict):
            for name in ("frame_id", "name"):
                if isinstance(node.get(name), str):
                    return node[name]
    return path


def _array_view(ref: ArrayRef, max_elements: int) -> Any:
    array = ref.array()
    if array.size <= max_elements:
        return array.tolist()  # msgspec writes NaN and inf as null
    summary: dict[str, Any] = {
        "dtype": str(array.dtype),
        "shape": list(array.shape),
        "elements": int(array.size),
    }
    if array.dtype.kind in "biuf" and array.size:
        summary.update(min=float(np.nanmin(array)), max=float(np.nanmax(array)))
    return summary


# ---------------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LogMessage:
    """One original message of a log."""

    key: str
    data: bytes
    log_time_ns: int
    sequence: int  # request id of a request/reply/error mirror, else 0
    encoding: str  # json, hrpb or octets


@dataclass(frozen=True)
class ChannelInfo:
    topic: str
    role: str
    message_encoding: str
    schema_name: str
    messages: int


@dataclass(frozen=True)
class LogInfo:
    path: str
    size_bytes: int
    messages: int
    start_ns: int
    end_ns: int
    channels: tuple[ChannelInfo, ...]
    complete: bool  # False: no summary (recorder killed); counted by reading every chunk
    unreadable_tail: bool = False  # the last chunk was cut off
    metadata: dict[str, str] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return max(0, self.end_ns - self.start_ns) / 1e9


class LogReader:
    """Reads a log written by :class:`LogWriter`, including one whose recorder was killed."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise NotFoundError(f"log file {self.path} does not exist")
        self.unreadable_tail = False

    def records(self) -> Iterator[tuple[Message, Channel, Schema | None]]:
        """Every message record with its channel and schema, in file order; stops at a cut-off tail."""
        channels: dict[int, Channel] = {}
        schemas: dict[int, Schema] = {}
        self.unreadable_tail = False
        with open(self.path, "rb") as stream:
            reader = StreamReader(stream, skip_magic=False)
            try:
                for record in reader.records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        channels[record.id] = record
                    elif isinstance(record, Message):
                        channel = channels.get(record.channel_id)
                        if channel is not None:
                            yield record, channel, schemas.get(channel.schema_id)
            except (McapError, struct.error, EOFError, ValueError, RuntimeError, OSError) as exc:
                # A recorder killed mid-chunk leaves a partial record (lz4 raises RuntimeError).
                if isinstance(exc, McapError) and "invalid magic" in str(exc) and not channels:
                    raise InvalidRequestError(f"{self.path} is not an MCAP file") from None
                self.unreadable_tail = True

    def messages(self) -> Iterator[LogMessage]:
        """The original messages, in the order they were recorded."""
        for message, channel, _schema in self.records():
            if channel.metadata.get("hrp.role", ROLE_ORIGINAL) != ROLE_ORIGINAL:
                continue
            yield LogMessage(
                key=channel.metadata.get("hrp.key", channel.topic),
                data=bytes(message.data),
                log_time_ns=message.log_time,
                sequence=message.sequence,
                encoding=channel.message_encoding,
            )

    def info(self) -> LogInfo:
        """Channels, counts, duration, schema names: from the summary, or by reading every chunk."""
        summary = None
        metadata: dict[str, str] = {}
        try:
            with open(self.path, "rb") as stream:
                reader = make_reader(stream)
                summary = reader.get_summary()
                if summary is not None:
                    for item in reader.iter_metadata():
                        metadata.update(item.metadata)
        except (McapError, struct.error, EOFError, ValueError, RuntimeError, OSError):
            summary = None
        size = self.path.stat().st_size
        if summary is not None and summary.statistics is not None:
            stats = summary.statistics
            channels = tuple(
                _channel_info(ch, summary.schemas.get(ch.schema_id), stats.channel_message_counts.get(cid, 0))
                for cid, ch in sorted(summary.channels.items())
            )
            return LogInfo(
                str(self.path), size, stats.message_count, stats.message_start_time,
                stats.message_end_time, channels, complete=True, metadata=metadata,
            )  # fmt: skip
        counts: Counter[int] = Counter()
        seen: dict[int, tuple[Channel, Schema | None]] = {}
        start, end, total = 0, 0, 0
        for message, channel, schema in self.records():
            counts[channel.id] += 1
            seen.setdefault(channel.id, (channel, schema))
            start = message.log_time if total == 0 else min(start, message.log_time)
            end = max(end, message.log_time)
            total += 1
        channels = tuple(_channel_info(ch, sc, counts[cid]) for cid, (ch, sc) in sorted(seen.items()))
        return LogInfo(
            str(self.path), size, total, start, end, channels, complete=False,
            unreadable_tail=self.unreadable_tail,
        )  # fmt: skip


def _channel_info(channel: Channel, schema: Schema | None, count: int) -> ChannelInfo:
    return ChannelInfo(
        topic=channel.topic,
        role=channel.metadata.get("hrp.role", ROLE_ORIGINAL),
        message_encoding=channel.message_encoding,
        schema_name=schema.name if schema is not None else "",
        messages=count,
    )


def now_ns() -> int:
    return time.time_ns()
