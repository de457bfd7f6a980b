"""The zenoh encoding label of every payload the stack puts on the bus, so a reader that does not know
the codec can tell a frame's kind from the sample (``sample.encoding``, ``reply.ok.encoding``,
``reply.err.encoding``) without looking at its bytes.

The labels (zenoh's MIME-like ``type/subtype[;schema]``) of the frame kinds of
:mod:`services.bus.frames`:

* ``application/json``: a plain JSON document (every message without arrays, every error reply's
  :class:`~services.bus.schemas.common.ErrorInfo`, heartbeats, log lines);
* ``application/octet-stream;hrpb``: a binary frame (``HRPB`` | header length | JSON header | raw
  array bytes, :mod:`services.bus.codec`);
* ``application/octet-stream``: anything else (the copy of a malformed request, replayed as it came).

The stack itself never reads the labels: a payload is decoded by its bytes (a query's label is not
read either, services/bus/README "Calling an endpoint").
"""

from __future__ import annotations

import zenoh

from services.bus.codec import MAGIC
from services.bus.frames import frame_kind

JSON = zenoh.Encoding.APPLICATION_JSON
HRPB = zenoh.Encoding.APPLICATION_OCTET_STREAM.with_schema("hrpb")
OCTETS = zenoh.Encoding.APPLICATION_OCTET_STREAM
_BY_KIND = {"json": JSON, "hrpb": HRPB, "octets": OCTETS}


def of_frame(frame: bytes | bytearray | memoryview) -> zenoh.Encoding:
    """The label of a frame :func:`services.bus.codec.encode` made (or one that decoded): a binary
    frame or plain JSON, told by the first four bytes."""
    return HRPB if bytes(frame[:4]) == MAGIC else JSON


def of_bytes(data: bytes | bytearray | memoryview) -> zenoh.Encoding:
    """The label of bytes nobody checked (the copy of a refused request, a message read from a log):
    their kind as :func:`services.bus.frames.frame_kind` tells it."""
    return _BY_KIND[frame_kind(data)]


def of_kind(kind: str) -> zenoh.Encoding:
    """The label of a frame kind (``json``, ``hrpb``, ``octets``: a log's ``LogMessage.encoding``)."""
    return _BY_KIND.get(kind, OCTETS)
