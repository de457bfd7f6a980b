"""A small client of Foxglove's WebSocket protocol, for tests, benchmarks and ``humanoid view --check``.

What Foxglove itself does when it connects (https://github.com/foxglove/ws-protocol, ``v1``): read
the server's ``advertise`` of channels (JSON text frames), send ``subscribe`` with a subscription id
per channel, and receive binary ``MessageData`` frames: opcode 0x01, u32 subscription id, u64
timestamp [ns], then the message bytes (protobuf or JSON, as the channel says).
"""

from __future__ import annotations

import json
import struct
import time
from dataclasses import dataclass
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
_MESSAGE_DATA = 0x01


@dataclass(frozen=True)
class ChannelAd:
    """A channel the server advertised."""

    id: int
    topic: str
    encoding: str
    schema_name: str


@dataclass(frozen=True)
class Received:
    topic: str
    log_time_ns: int
    data: bytes
    received_ns: int  # time.time_ns() when it arrived


class FoxgloveClient:
    """Connects, learns the channels, subscribes by topic, receives messages (blocking, with timeouts)."""

    def __init__(self, url: str = "ws://127.0.0.1:8765", open_timeout_s: float = 5.0) -> None:
        self.url = url
        self.ws: ClientConnection = connect(
            url,
            subprotocols=list(SUBPROTOCOLS),
            open_timeout=open_timeout_s,
            max_size=None,  # type: ignore[arg-type]
        )
        self.channels: dict[int, ChannelAd] = {}
        self._subscriptions: dict[int, str] = {}
        self._next_sub = 1
        self.server_info: dict[str, Any] = {}

    def close(self) -> None:
        self.ws.close()

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def topics(self) -> dict[str, ChannelAd]:
        return {ad.topic: ad for ad in self.channels.values()}

    def wait_for_topics(self, topics: list[str], timeout_s: float = 5.0) -> bool:
        """Read control frames until every topic of ``topics`` is advertised (or the time is out)."""
        deadline = time.monotonic() + timeout_s
        while not set(topics) <= set(self.topics()) and time.monotonic() < deadline:
            self._receive(max(0.01, deadline - time.monotonic()))
        return set(topics) <= set(self.topics())

    def subscribe(self, topics: list[str]) -> list[str]:
        """Subscribe to the advertised ``topics`` (others are still asked for, by unknown channel ids
        when ``raw_ids`` is used); returns the topics subscribed."""
        by_topic = self.topics()
        subs = []
        done = []
        for topic in topics:
            ad = by_topic.get(topic)
            if ad is None:
                continue
            sid = self._next_sub
            self._next_sub += 1
            self._subscriptions[sid] = topic
            subs.append({"id": sid, "channelId": ad.id})
            done.append(topic)
        if subs:
            self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        return done

    def subscribe_channel_ids(self, channel_ids: list[int]) -> None:
        """Subscribe to channel ids as given, advertised or not (a misbehaving viewer)."""
        subs = []
        for cid in channel_ids:
            sid = self._next_sub
            self._next_sub += 1
            self._subscriptions[sid] = f"#{cid}"
            subs.append({"id": sid, "channelId": cid})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def receive(self, timeout_s: float) -> Received | None:
        """The next message of a subscription within ``timeout_s``, else None."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            got = self._receive(max(0.001, deadline - time.monotonic()))
            if got is not None:
                return got
        return None

    def _receive(self, timeout_s: float) -> Received | None:
        try:
            frame = self.ws.recv(timeout=timeout_s)
        except TimeoutError:
            return None
        except ConnectionClosed:
            raise
        if isinstance(frame, str):
            self._control(json.loads(frame))
            return None
        if len(frame) >= 13 and frame[0] == _MESSAGE_DATA:
            sid, stamp = struct.unpack_from("<IQ", frame, 1)
            topic = self._subscriptions.get(sid, "")
            return Received(topic, stamp, bytes(frame[13:]), time.time_ns())
        return None

    def _control(self, msg: dict[str, Any]) -> None:
        op = msg.get("op")
        if op == "serverInfo":
            self.server_info = msg
        elif op == "advertise":
            for ch in msg.get("channels", []):
                self.channels[int(ch["id"])] = ChannelAd(
                    int(ch["id"]), ch["topic"], ch.get("encoding", ""), ch.get("schemaName", "")
                )
        elif op == "unadvertise":
            for cid in msg.get("channelIds", []):
                self.channels.pop(int(cid), None)
