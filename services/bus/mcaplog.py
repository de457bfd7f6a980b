"""MCAP logs of the bus: what the recorder writes and what replay and ``log-info`` read.

Layout of a log (one MCAP file, every channel decodable by Foxglove):

* **originals**, one channel per key expression (topic = the zenoh key), one copy of each message in
  its log form (:mod:`services.bus.logform`): JSON, with arrays as ``{dtype, shape, data (base64)}``,
  under the JSON Schema Foxglove's reader accepts (:func:`services.bus.foxglove.message_schema`).
  Channel metadata: ``hrp.key`` (the zenoh key), ``hrp.role`` = ``original`` and ``hrp.frame`` (the
  frame kind on the bus: ``json``, ``hrpb`` or ``octets``), from which :class:`LogReader` rebuilds the
  exact bytes that were published. The request id attachment of the ``<endpoint>/request|reply|error``
  mirrors is the MCAP message ``sequence``. A channel written rounded (a sensor stream, see
  :mod:`services.bus.logform`) has ``hrp.decimals``: its floats are rounded to that many decimals.
* **views** (``hrp.role`` = ``view``): Foxglove's own messages (transforms, scene, images, logs),
  protobuf, made by a ``views`` callable (the recorder passes :mod:`services.viz`'s converters).

Chunks are zstd-compressed by default (lz4 or none on request) and closed by size (``chunk_size_bytes``
of messages, uncompressed); the file is flushed after each message, so a recorder killed with SIGKILL
leaves every closed chunk on disk and :class:`LogReader` (the official mcap stream reader, CRCs
checked) reads them up to the cut.
"""

from __future__ import annotations

import functools
import json
import struct
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from services.bus import keys
from services.bus.foxglove import message_schema
from services.bus.logform import OCTETS_SCHEMA, from_log_form, to_log_form
from services.errors import InvalidRequestError, NotFoundError

ROLE_ORIGINAL = "original"
ROLE_VIEW = "view"
COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
_MIRRORS = ("request", "reply", "error")


@dataclass(frozen=True)
class View:
    """A derived message for Foxglove (a transform, a scene update, an image...), already encoded."""

    topic: str
    schema_name: str  # e.g. foxglove.FrameTransforms
    schema_encoding: str  # protobuf or jsonschema
    schema_data: bytes
    message_encoding: str  # protobuf or json
    data: bytes
    log_time_ns: int


#: ``views(key, frame, log_time_ns)`` -> the Foxglove messages derived from one bus message.
Views = Callable[[str, bytes, int], Iterable[View]]


# ---------------------------------------------------------------------------------------------------
# Which message type a key carries
# ---------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=4096)
def message_type_for_key(key: str) -> type | None:
    """The msgspec type published on ``key`` according to the spec registry, or None."""
    from services.bus import schemas
    from services.bus.schemas.common import ErrorInfo, Heartbeat, LogLine

    try:
        _robot, service, rest = keys.parse(key)
    except ValueError:
        return None
    parts = rest.split("/")
    if parts == ["heartbeat"]:
        return Heartbeat
    if parts == ["log"]:
        return LogLine
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
        compression: str = "zstd",
        chunk_size_bytes: int = 1 << 20,
        views: Views | None = None,
        metadata: dict[str, str] | None = None,
        decimals: Mapping[str, int] | None = None,
    ) -> None:
        """``decimals``: topics (``service/topic``, e.g. ``sim/joint_state``) written rounded to that
        many decimals (:mod:`services.bus.logform`); every other message is written exactly."""
        if compression not in COMPRESSIONS:
            raise InvalidRequestError(f"compression {compression!r} is not one of: {', '.join(COMPRESSIONS)}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file, chunk_size=chunk_size_bytes, compression=COMPRESSIONS[compression])
        self._writer.start(profile="", library="humanoid-autonomy recorder")
        if metadata:
            self._writer.add_metadata("recording", dict(metadata))
        self._views = views
        self._decimals = dict(decimals or {})
        self._rounding: dict[str, int | None] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._schemas: dict[str, int] = {}
        self.message_counts: Counter[str] = Counter()
        self.view_errors = 0
        self.closed = False

    # Public -------------------------------------------------------------------------------------------
    def write(self, key: str, data: bytes, log_time_ns: int, sequence: int = 0) -> None:
        """Log one message published on ``key`` (one copy, in its log form), then its Foxglove views."""
        type_ = message_type_for_key(key)
        decimals = self._decimals_of(key)
        kind, stored = to_log_form(data, type_, decimals)
        channel = self._original_channel(key, kind, type_, decimals)
        self._writer.add_message(channel, log_time_ns, stored, log_time_ns, sequence)
        self.message_counts[key] += 1
        if self._views is not None:
            try:
                views = list(self._views(key, data, log_time_ns))
            except Exception:  # a converter bug must not lose the originals
                self.view_errors += 1
                views = []
            for view in views:
                cid = self._view_channel(view, key)
                self._writer.add_message(cid, view.log_time_ns, view.data, view.log_time_ns, 0)
        self._file.flush()  # a chunk closed by size reaches the OS now

    def close(self) -> None:
        """Write the summary (indexes, statistics) and close the file."""
        if self.closed:
            return
        self.closed = True
        self._writer.finish()
        self._file.close()

    # Internals ----------------------------------------------------------------------------------------
    def _schema_id(self, name: str, encoding: str, data: bytes) -> int:
        sid = self._schemas.get(name)
        if sid is None:
            sid = self._schemas[name] = self._writer.register_schema(name, encoding, data)
        return sid

    def _decimals_of(self, key: str) -> int | None:
        if key not in self._rounding:
            try:
                _robot, service, rest = keys.parse(key)
                self._rounding[key] = self._decimals.get(f"{service}/{rest}")
            except ValueError:
                self._rounding[key] = None
        return self._rounding[key]

    def _original_channel(self, key: str, kind: str, type_: type | None, decimals: int | None) -> int:
        cid = self._channels.get((key, kind))
        if cid is None:
            if kind == "octets":
                schema = self._schema_id("hrp.Octets", "jsonschema", json.dumps(OCTETS_SCHEMA).encode())
            elif type_ is not None:
                data = json.dumps(message_schema(type_)).encode()
                schema = self._schema_id(schema_name(type_), "jsonschema", data)
            else:
                schema = 0  # JSON of an unknown key: Foxglove shows schemaless JSON as it is
            meta = {"hrp.key": key, "hrp.role": ROLE_ORIGINAL, "hrp.frame": kind}
            if decimals is not None and kind != "octets":
                meta["hrp.decimals"] = str(decimals)
            topic = key if kind != "octets" else f"{key}#octets"  # json and hrpb share the schema
            cid = self._channels[(key, kind)] = self._writer.register_channel(topic, "json", schema, meta)
        return cid

    def _view_channel(self, view: View, key: str) -> int:
        cid = self._channels.get((view.topic, "view"))
        if cid is None:
            schema = self._schema_id(view.schema_name, view.schema_encoding, view.schema_data)
            meta = {"hrp.key": key, "hrp.role": ROLE_VIEW}
            cid = self._channels[(view.topic, "view")] = self._writer.register_channel(
                view.topic, view.message_encoding, schema, meta
            )
        return cid


# ---------------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LogMessage:
    """One original message of a log, as it was published."""

    key: str
    data: bytes
    log_time_ns: int
    sequence: int  # request id of a request/reply/error mirror, else 0
    encoding: str  # the frame kind: json, hrpb or octets


@dataclass(frozen=True)
class ChannelInfo:
    topic: str
    role: str
    message_encoding: str
    schema_name: str
    messages: int
    bytes: int = 0  # message bytes as stored (before chunk compression)
    rate_hz: float = 0.0  # messages per second between the channel's first and last message


@dataclass(frozen=True)
class LogInfo:
    path: str
    size_bytes: int
    messages: int
    start_ns: int
    end_ns: int
    channels: tuple[ChannelInfo, ...]
    complete: bool  # False: no summary (recorder killed): what was read up to the cut
    unreadable_tail: bool = False  # the file ends in a cut-off record (a recorder killed mid-chunk)
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
        """Every message record with its channel and schema, in file order, read by the official mcap
        stream reader with CRC validation; stops at a cut-off tail (``unreadable_tail`` is then set)."""
        channels: dict[int, Channel] = {}
        schemas: dict[int, Schema] = {}
        self.unreadable_tail = False
        with open(self.path, "rb") as stream:
            reader = StreamReader(stream, skip_magic=False, validate_crcs=True)
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
                # A recorder killed mid-chunk leaves a partial record (the reader raises at the cut).
                if isinstance(exc, McapError) and "magic" in str(exc).lower() and not channels:
                    raise InvalidRequestError(f"{self.path} is not an MCAP file") from None
                self.unreadable_tail = True

    def messages(self) -> Iterator[LogMessage]:
        """The original messages, as published (exact bytes), in the order they were recorded."""
        for message, channel, _schema in self.records():
            meta = channel.metadata
            if meta.get("hrp.role", ROLE_ORIGINAL) != ROLE_ORIGINAL:
                continue
            key = meta.get("hrp.key", channel.topic)
            frame = meta.get("hrp.frame")
            if frame is None:  # a log of the first format: the frame itself, its kind as the encoding
                data, kind = bytes(message.data), channel.message_encoding
            else:
                kind = frame
                data = from_log_form(frame, bytes(message.data), message_type_for_key(key))
            yield LogMessage(
                key=key, data=data, log_time_ns=message.log_time, sequence=message.sequence, encoding=kind
            )

    def info(self) -> LogInfo:
        """Channels with messages, bytes and rate; duration; schema names. Every chunk is read (bytes
        and rates are not in the summary); ``complete`` says whether the summary was there."""
        metadata: dict[str, str] = {}
        complete = False
        try:
            with open(self.path, "rb") as stream:
                reader = make_reader(stream)
                complete = reader.get_summary() is not None
                if complete:
                    for item in reader.iter_metadata():
                        metadata.update(item.metadata)
        except (McapError, struct.error, EOFError, ValueError, RuntimeError, OSError):
            complete = False
        counts: Counter[int] = Counter()
        sizes: Counter[int] = Counter()
        first: dict[int, int] = {}
        last: dict[int, int] = {}
        seen: dict[int, tuple[Channel, Schema | None]] = {}
        for message, channel, schema in self.records():
            cid = channel.id
            counts[cid] += 1
            sizes[cid] += len(message.data)
            seen.setdefault(cid, (channel, schema))
            first.setdefault(cid, message.log_time)
            first[cid] = min(first[cid], message.log_time)
            last[cid] = max(last.get(cid, 0), message.log_time)
        channels = tuple(
            _channel_info(ch, sc, counts[cid], sizes[cid], first[cid], last[cid])
            for cid, (ch, sc) in sorted(seen.items())
        )
        start = min(first.values(), default=0)
        end = max(last.values(), default=0)
        return LogInfo(
            str(self.path), self.path.stat().st_size, sum(counts.values()), start, end, channels,
            complete=complete and not self.unreadable_tail, unreadable_tail=self.unreadable_tail,
            metadata=metadata,
        )  # fmt: skip


def _channel_info(
    channel: Channel, schema: Schema | None, count: int, size: int, first_ns: int, last_ns: int
) -> ChannelInfo:
    span_s = (last_ns - first_ns) / 1e9
    return ChannelInfo(
        topic=channel.topic,
        role=channel.metadata.get("hrp.role", ROLE_ORIGINAL),
        message_encoding=channel.message_encoding,
        schema_name=schema.name if schema is not None else "",
        messages=count,
        bytes=size,
        rate_hz=(count - 1) / span_s if count > 1 and span_s > 0 else 0.0,
    )


def now_ns() -> int:
    return time.time_ns()
