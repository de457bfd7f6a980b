"""A client written by a stranger: zenoh-python, the standard library and numpy, and the documentation.

Nothing of the stack is imported here (no ``services``, ``sim``, ``supervisor``): what this module
knows of the bus it read in ``services/bus/README.md`` and the top-level README ("Services and their
endpoints"):

* every session is a zenoh *peer* listening on a free loopback port and connecting to the hub, with
  multicast scouting off; an endpoint is the queryable ``hrp/<robot>/<service>/<name>``;
* a request is a JSON document (an empty payload counts as ``{}``), or a binary frame
  ``b"HRPB" | u32 header length (little endian) | header JSON | raw array bytes`` whose header has
  ``{"__nd__": [offset, nbytes], "dtype": "<f8", "shape": [...]}`` in place of each array (arrays may
  also be written as JSON lists); zenoh's encoding and attachment of a query are not read;
* the answer is one zenoh reply: an ok reply whose payload is a frame of the same two kinds, or an
  error reply whose payload is ``ErrorInfo`` JSON ``{"code", "message", "details"}``; the reply's zenoh
  encoding (and every published sample's) names the kind: ``application/json`` for plain JSON,
  ``application/octet-stream;hrpb`` for a binary frame.

Used by ``tests/test_fuzz.py`` (the stranger's tests share its stack).
"""

from __future__ import annotations

import json
import struct
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import zenoh

MAGIC = b"HRPB"
#: The zenoh encoding labels of the two frame kinds (services/bus/README "Calling an endpoint").
JSON_LABEL = "application/json"
HRPB_LABEL = "application/octet-stream;hrpb"
#: What zenoh itself puts in an error reply when a query's timeout passes without an answer.
ZENOH_TIMEOUT = b"Timeout"


def open_session(hub: str) -> zenoh.Session:
    """A peer session as the README describes the stack's own: listen on loopback, connect to ``hub``."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("peer"))
    config.insert_json5("connect/endpoints", json.dumps([hub]))
    config.insert_json5("listen/endpoints", json.dumps(["tcp/127.0.0.1:0"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def wait_alive(session: zenoh.Session, robot: str, services: set[str], timeout_s: float = 30.0) -> None:
    """Until each of ``services`` has its liveliness token ``hrp/<robot>/<service>/alive`` in view: a
    fresh session learns the peers' queryables over some milliseconds, and a query sent before finds
    none and ends at once without a reply (the README: wait for the token before the first call)."""
    deadline = time.monotonic() + timeout_s
    while True:
        seen = {
            str(r.ok.key_expr).split("/")[2] for r in session.liveliness().get(f"hrp/{robot}/*/alive") if r.ok
        }
        if services <= seen:
            return
        if time.monotonic() > deadline:
            raise TimeoutError(f"no liveliness token of {sorted(services - seen)} within {timeout_s} s")
        time.sleep(0.05)


def frame(doc: dict[str, Any], arrays: dict[str, np.ndarray] | None = None) -> bytes:
    """A request: plain JSON, or a binary frame with ``arrays`` (top-level fields) as raw bytes."""
    if not arrays:
        return json.dumps(doc).encode()
    header = dict(doc)
    blobs = []
    offset = 0
    for name, arr in arrays.items():
        arr = np.ascontiguousarray(arr)
        header[name] = {"__nd__": [offset, arr.nbytes], "dtype": arr.dtype.str, "shape": list(arr.shape)}
        blobs.append(arr.tobytes())
        offset += arr.nbytes
    head = json.dumps(header).encode()
    return MAGIC + struct.pack("<I", len(head)) + head + b"".join(blobs)


def label_of(raw: bytes) -> str:
    """The encoding label a frame of the bus carries (the README), from its first bytes."""
    return HRPB_LABEL if raw[:4] == MAGIC else JSON_LABEL


def unframe(raw: bytes) -> Any:
    """A reply frame as JSON values, each array reference replaced by its numpy array."""
    if raw[:4] != MAGIC:
        return json.loads(raw)
    (n,) = struct.unpack_from("<I", raw, 4)
    header = json.loads(raw[8 : 8 + n])
    blob = raw[8 + n :]

    def resolve(node: Any) -> Any:
        if isinstance(node, dict):
            if "__nd__" in node:
                offset, nbytes = node["__nd__"]
                data = np.frombuffer(blob[offset : offset + nbytes], dtype=np.dtype(node["dtype"]))
                return data.reshape(node["shape"])
            return {k: resolve(v) for k, v in node.items()}
        if isinstance(node, list):
            return [resolve(v) for v in node]
        return node

    return resolve(header)


@dataclass
class Answer:
    """What came back: ``kind`` "ok", "error" or "none" (no reply within the timeout)."""

    kind: str
    body: Any = None  # the ok reply, unframed
    error: dict[str, Any] = field(default_factory=dict)  # the ErrorInfo of an error reply
    raw: bytes = b""
    encoding: str = ""  # the reply's zenoh encoding label

    @property
    def code(self) -> str:
        return self.error.get("code", "") if self.kind == "error" else self.kind

    @property
    def message(self) -> str:
        return str(self.error.get("message", ""))

    def __str__(self) -> str:
        if self.kind == "error":
            return f"error {self.code}: {self.message}"
        return self.kind


def call(
    session: zenoh.Session,
    key: str,
    payload: bytes,
    timeout_s: float = 30.0,
    *,
    encoding: str | None = None,
    attachment: bytes | None = None,
) -> Answer:
    """One query to ``key``; the first reply (an endpoint has one queryable, which replies once)."""
    options: dict[str, Any] = {"payload": payload, "timeout": timeout_s}
    if encoding is not None:
        options["encoding"] = zenoh.Encoding(encoding)
    if attachment is not None:
        options["attachment"] = attachment
    for reply in session.get(key, **options):
        if reply.ok is not None:
            raw = reply.ok.payload.to_bytes()
            return Answer("ok", body=unframe(raw), raw=raw, encoding=str(reply.ok.encoding))
        raw = reply.err.payload.to_bytes()
        if raw == ZENOH_TIMEOUT:
            break
        return Answer("error", error=json.loads(raw), raw=raw, encoding=str(reply.err.encoding))
    return Answer("none")
