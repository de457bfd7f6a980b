"""The recorder (``services/bus/recorder.py``, service ``record``): what it has written so far."""

from __future__ import annotations

import msgspec

from services.bus.spec import EndpointSpec


class StatusRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """What the recorder has written so far (no fields)."""


class StatusReply(msgspec.Struct, kw_only=True, frozen=True):
    """``output``: the MCAP file being written; ``recorded``: messages written so far (one copy each,
    Foxglove's views not counted); ``per_key``: of them, how many on each key (``hrp/<robot>/...``).

    A message is in the log once counted here (the stop closes the log with it): a client that must
    know a message is recorded before it stops the recorder asks this, as a message published a few
    milliseconds before a stop may not have reached the recorder yet."""

    output: str
    recorded: int
    per_key: dict[str, int] = {}


STATUS = EndpointSpec(
    "record", "status", StatusRequest, StatusReply, "what the recorder has written so far, in all and per key"
)
