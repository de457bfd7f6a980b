"""The diagnostics service: round trips for health checks, tests and the bus benchmark."""

from __future__ import annotations

from typing import Annotated

import msgspec
import numpy as np
from msgspec import Meta

from services.bus.limits import Budget, ImageSide, Name
from services.bus.spec import EndpointSpec, TopicSpec


class EchoRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Anything to send back. ``blob`` travels as raw bytes (binary frame)."""

    text: str = ""
    blob: np.ndarray | None = None


class EchoReply(msgspec.Struct, kw_only=True, frozen=True):
    """The request's content, unchanged (a deterministic reply: replay finds no difference)."""

    text: str = ""
    blob: np.ndarray | None = None


class RaiseRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Ask for an error reply, to check a client's error handling end to end.

    ``code`` is one of services.errors.ERROR_CODES, or ``bug`` for an unexpected exception in the
    handler (which the service reports as ``internal`` and survives).
    """

    code: Name  # at most 128 characters (a known code is a short word)
    message: str


class RaiseReply(msgspec.Struct, kw_only=True, frozen=True):
    """Never sent: the endpoint always answers with an error."""


class Ping(msgspec.Struct, kw_only=True, frozen=True):
    """A message the diag service republishes unchanged on ``diag/pong`` (pub/sub round trips)."""

    seq: int
    text: str = ""
    blob: np.ndarray | None = None


class StreamRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Publish ``count`` stereo pairs of ``width`` x ``height`` RGB images on ``diag/frames``."""

    count: Annotated[int, Meta(ge=1, le=100_000)] = 100
    width: ImageSide = 640  # [px]
    height: ImageSide = 480  # [px]
    time_budget_s: Budget = 10.0  # stop publishing after this long and reply timeout [s]


class StreamReply(msgspec.Struct, kw_only=True, frozen=True):
    sent: int
    elapsed_s: float  # time spent publishing [s]


class StereoFrame(msgspec.Struct, kw_only=True, frozen=True):
    """A synthetic stereo pair (throughput tests): two HxWx3 uint8 RGB images."""

    seq: int
    stamp_s: float  # time.time() at publication [s]
    left: np.ndarray
    right: np.ndarray


ECHO = EndpointSpec("diag", "echo", EchoRequest, EchoReply, "returns the request (round-trip checks)")
ECHO_WORKER = EndpointSpec(
    "diag",
    "echo_worker",
    EchoRequest,
    EchoReply,
    "diag/echo served by a worker thread (measures the hand-off)",
)
RAISE = EndpointSpec("diag", "raise", RaiseRequest, RaiseReply, "answers with the error asked for")
STREAM = EndpointSpec("diag", "stream", StreamRequest, StreamReply, "publishes stereo pairs on diag/frames")
PING = TopicSpec("diag", "ping", Ping, "republished unchanged on diag/pong")
PONG = TopicSpec("diag", "pong", Ping, "the messages received on diag/ping")
FRAMES = TopicSpec("diag", "frames", StereoFrame, "synthetic stereo pairs published by diag/stream")
