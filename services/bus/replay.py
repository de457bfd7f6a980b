"""Replaying MCAP logs: republish messages with their timing, or re-send requests and diff the replies.

``replay`` republishes the exact recorded bytes of every original message (see
:mod:`services.bus.mcaplog`) on its key, keeping the original relative timing (divided by
``speed``); the request id of request/reply/error mirrors goes back as the attachment. Heartbeats
are left out unless asked for: they describe processes of the past, and ``humanoid status`` would
mistake them for live ones.

``replay_requests`` re-sends every recorded request (``<endpoint>/request``) to the running service,
one at a time and in order, and compares each answer with the recorded one (``/reply`` or
``/error`` with the same request id). Planners are stateless, so none should differ: this is
regression testing from logs.
"""

from __future__ import annotations

import fnmatch
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import msgspec
import numpy as np
import zenoh

from services.bus import encodings, keys
from services.bus.codec import decode
from services.bus.mcaplog import LogMessage, LogReader, message_type_for_key
from services.bus.schemas.common import ErrorInfo
from services.bus.session import request_id_bytes
from services.errors import HumanoidError, InvalidRequestError


def key_filter(
    patterns: list[str] | None, *, heartbeats: bool = False, views: bool = False
) -> Callable[[str], bool]:
    """Shell-style globs on keys (``*`` also matches ``/``): ``hrp/*/sim/*``; None: everything.
    ``views``: a log's Foxglove views (their topics not under ``hrp/``: ``/tf``, the robot, the
    cameras) pass whatever the globs say."""

    def accept(key: str) -> bool:
        if views and not key.startswith(f"{keys.PREFIX}/"):
            return True
        if not heartbeats and key.endswith("/heartbeat"):
            return False
        return patterns is None or any(fnmatch.fnmatchcase(key, p) for p in patterns)

    return accept


@dataclass
class ReplayStats:
    published: int = 0
    skipped: int = 0
    duration_s: float = 0.0
    per_key: Counter[str] = field(default_factory=Counter)


def replay(
    session: zenoh.Session,
    reader: LogReader,
    *,
    speed: float = 1.0,
    accept: Callable[[str], bool] | None = None,
    on_message: Callable[[LogMessage], None] | None = None,
    start_s: float = 0.0,
    stop: threading.Event | None = None,
) -> ReplayStats:
    """Republish the log's original messages with their relative timing (``speed`` 2 = twice as fast),
    from ``start_s`` seconds after the log's first message (the earlier ones are skipped). ``stop``, once
    set (e.g. by a Ctrl-C handler), ends the playback before the next message: the publishers are
    undeclared in order, never from inside a zenoh call."""
    if not speed > 0:
        raise InvalidRequestError(f"speed={speed} must be > 0 (2 plays twice as fast)")
    if start_s < 0:
        raise InvalidRequestError(f"start={start_s} s must be >= 0 (seconds into the log)")
    log_first_ns: int | None = None
    accept = accept or key_filter(None)
    stats = ReplayStats()
    publishers: dict[str, Any] = {}
    first_ns: int | None = None
    started = time.monotonic()
    try:
        for msg in reader.messages():
            if log_first_ns is None:
                log_first_ns = msg.log_time_ns
            if not accept(msg.key) or msg.log_time_ns - log_first_ns < start_s * 1e9:
                stats.skipped += 1
                continue
            if first_ns is None:
                first_ns = msg.log_time_ns
            due = started + (msg.log_time_ns - first_ns) / 1e9 / speed
            delay = due - time.monotonic()
            if stop is not None:
                if stop.wait(max(delay, 0.0)):
                    break
            elif delay > 0:
                time.sleep(delay)
            pub = publishers.get(msg.key)
            if pub is None:
                pub = publishers[msg.key] = session.declare_publisher(msg.key)
            attachment = request_id_bytes(msg.sequence) if msg.sequence and _is_mirror(msg.key) else None
            pub.put(msg.data, attachment=attachment, encoding=encodings.of_kind(msg.encoding))
            stats.published += 1
            stats.per_key[msg.key] += 1
            if on_message is not None:
                on_message(msg)
    finally:
        for pub in publishers.values():
            pub.undeclare()
    stats.duration_s = time.monotonic() - started
    return stats


def _is_mirror(key: str) -> bool:
    return key.rsplit("/", 1)[-1] in ("request", "reply", "error")


# ---------------------------------------------------------------------------------------------------
# Requests
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RequestOutcome:
    """One re-sent request: ``status`` is same, differs, no_record (no recorded answer) or failed."""

    endpoint: str  # the zenoh key of the endpoint
    request_id: int
    status: str
    detail: str = ""


def replay_requests(
    session: zenoh.Session,
    reader: LogReader,
    *,
    timeout_s: float = 30.0,
    accept: Callable[[str], bool] | None = None,
    on_outcome: Callable[[RequestOutcome], None] | None = None,
) -> list[RequestOutcome]:
    """Re-send every recorded request in order and compare the answers with the recorded ones."""
    requests: list[LogMessage] = []
    answers: dict[tuple[str, int], LogMessage] = {}
    for msg in reader.messages():
        head, _, tail = msg.key.rpartition("/")
        if tail == "request" and (accept is None or accept(head)):
            requests.append(msg)
        elif tail in ("reply", "error") and msg.sequence:
            answers[(head, msg.sequence)] = msg
    outcomes = []
    for request in requests:
        endpoint = request.key.rpartition("/")[0]
        recorded = answers.get((endpoint, request.sequence))
        outcome = _resend(session, endpoint, request, recorded, timeout_s)
        outcomes.append(outcome)
        if on_outcome is not None:
            on_outcome(outcome)
    return outcomes


def _resend(
    session: zenoh.Session, endpoint: str, request: LogMessage, recorded: LogMessage | None, timeout_s: float
) -> RequestOutcome:
    rid = request.sequence
    label = encodings.of_kind(request.encoding)
    replies = list(session.get(endpoint, payload=request.data, encoding=label, timeout=timeout_s))
    if not replies:
        service = _service_of(endpoint)
        return RequestOutcome(
            endpoint, rid, "failed", f"no answer within {timeout_s:.0f} s (is {service} running?)"
        )
    reply = replies[0]
    got_ok = reply.ok is not None
    got = (reply.ok if got_ok else reply.err).payload.to_bytes()
    if recorded is None:
        return RequestOutcome(endpoint, rid, "no_record", "the log has no answer to this request")
    was_ok = recorded.key.endswith("/reply")
    if got_ok != was_ok:
        return RequestOutcome(
            endpoint, rid, "differs",
            f"recorded {_outcome_text(recorded.data, was_ok)}, now {_outcome_text(got, got_ok)}",
        )  # fmt: skip
    if got == recorded.data:
        return RequestOutcome(endpoint, rid, "same")
    if not got_ok:
        return RequestOutcome(
            endpoint, rid, "differs",
            f"recorded {_outcome_text(recorded.data, False)}, now {_outcome_text(got, False)}",
        )  # fmt: skip
    return RequestOutcome(endpoint, rid, "differs", _diff_replies(recorded.key, recorded.data, got))


def _service_of(endpoint: str) -> str:
    try:
        return keys.parse(endpoint)[1]
    except ValueError:
        return endpoint


def _outcome_text(data: bytes, ok: bool) -> str:
    if ok:
        return "an ok reply"
    try:
        info = decode(data, ErrorInfo)
        return f"error {info.code} ({info.message})"
    except HumanoidError:
        return "an error"


def _diff_replies(reply_key: str, old: bytes, new: bytes) -> str:
    """Where two replies differ: the first field path and the values (or an array's largest change)."""
    type_ = message_type_for_key(reply_key)
    if type_ is None:
        return f"the bytes differ ({len(old)} recorded, {len(new)} now)"
    try:
        a, b = decode(old, type_), decode(new, type_)
    except HumanoidError as exc:
        return f"a reply does not decode: {exc.message}"
    return _first_difference(to_builtins_arrays(a), to_builtins_arrays(b), "") or "only the encoding differs"


def to_builtins_arrays(msg: Any) -> Any:
    """Like codec.to_builtins, but arrays stay numpy arrays (to compare them numerically)."""
    if isinstance(msg, msgspec.Struct):
        return {name: to_builtins_arrays(getattr(msg, name)) for name in msg.__struct_fields__}
    if isinstance(msg, dict):
        return {k: to_builtins_arrays(v) for k, v in msg.items()}
    if isinstance(msg, list | tuple):
        return [to_builtins_arrays(v) for v in msg]
    return msg


def _first_difference(a: Any, b: Any, path: str) -> str:
    where = path or "(the message)"
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a_arr, b_arr = np.asarray(a), np.asarray(b)
        if a_arr.shape != b_arr.shape:
            return f"{where}: shape {a_arr.shape} recorded, {b_arr.shape} now"
        if a_arr.dtype.kind in "biuf" and b_arr.dtype.kind in "biuf":
            diff = np.abs(a_arr.astype(float) - b_arr.astype(float))
            if np.any(diff > 0) or np.any(np.isnan(a_arr) != np.isnan(b_arr)):
                return f"{where}: largest change {np.nanmax(diff):.6g} over {int(np.sum(diff > 0))} elements"
            return ""
        return "" if np.array_equal(a_arr, b_arr) else f"{where}: arrays differ"
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                return f"{path}.{k}: present only {'now' if k in b else 'in the log'}"
            found = _first_difference(a[k], b[k], f"{path}.{k}")
            if found:
                return found
        return ""
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{where}: {len(a)} items recorded, {len(b)} now"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            found = _first_difference(x, y, f"{path}[{i}]")
            if found:
                return found
        return ""
    return "" if a == b else f"{where}: {a!r} recorded, {b!r} now"
