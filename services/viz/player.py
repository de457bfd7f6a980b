"""``humanoid replay FILE --foxglove [PORT]``: serve a recorded log to Foxglove over its WebSocket protocol.

Every channel of the log (the originals in their JSON log form, and the Foxglove views: transforms,
scene, plans, cameras, log lines) is advertised with its schema and played with the recorded
relative timing (divided by ``speed``), like the live view (:mod:`services.viz.service`) but from a
file: nothing is published on the bus.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import foxglove
from foxglove.websocket import ServerListener

from services.bus.mcaplog import LogReader
from services.errors import InvalidRequestError
from services.viz.common import start_ws_server


@dataclass
class PlayStats:
    messages: int = 0
    channels: int = 0
    duration_s: float = 0.0


def serve_log(
    path: str,
    *,
    host: str = "127.0.0.1",
    port: int = 8765,
    speed: float = 1.0,
    stop: threading.Event | None = None,
    on_ready: Callable[[int], None] | None = None,
    wait_for_viewer_s: float = 0.0,
    linger_s: float = 1.0,
    start_s: float = 0.0,
    accept: Callable[[str], bool] | None = None,
    loop: bool = False,
) -> PlayStats:
    """Play the log at ``path`` to Foxglove viewers on ws://host:port until its end (or ``stop``).

    ``on_ready(port)`` is called once the server listens; ``wait_for_viewer_s`` > 0 holds the start
    that long (at most) until a viewer subscribes to something; after the end the server stays up
    ``linger_s`` (the last messages reach the viewers; the panels keep showing them). As ``humanoid
    replay`` on the bus: ``start_s`` [s] into the log, only the topics ``accept`` takes (None: all),
    ``loop`` plays it again and again until ``stop``."""
    if not speed > 0:
        raise InvalidRequestError(f"speed={speed} must be > 0 (2 plays twice as fast)")
    if not 0 <= port <= 65535:
        raise InvalidRequestError(f"port {port} is not a TCP port (0..65535)")
    if not start_s >= 0:
        raise InvalidRequestError(f"start={start_s} must be >= 0 s")
    stop = stop or threading.Event()
    reader = LogReader(path)
    context = foxglove.Context()
    subscribed = threading.Event()

    class Listener(ServerListener):
        def on_subscribe(self, client: object, channel: object) -> None:
            subscribed.set()

    # Channels are advertised up front, so a viewer sees every topic before the playback starts.
    channels: dict[int, foxglove.Channel] = {}
    first_ns = None
    for message, channel, schema in reader.records():
        first_ns = message.log_time if first_ns is None else min(first_ns, message.log_time)
        if channel.id not in channels and (accept is None or accept(channel.topic)):
            fx_schema = (
                foxglove.Schema(name=schema.name, encoding=schema.encoding, data=bytes(schema.data))
                if schema is not None
                else None
            )
            channels[channel.id] = foxglove.Channel(
                channel.topic, schema=fx_schema, message_encoding=channel.message_encoding, context=context
            )
    begin_ns = (first_ns or 0) + int(start_s * 1e9)
    server = start_ws_server(
        name=f"humanoid replay {path}", host=host, port=port, context=context, server_listener=Listener()
    )
    stats = PlayStats(channels=len(channels))
    try:
        if on_ready is not None:
            on_ready(server.port)
        if wait_for_viewer_s > 0:
            subscribed.wait(wait_for_viewer_s)
        started = time.monotonic()
        while not stop.is_set():
            played = _play_once(reader, channels, begin_ns, speed, stop)
            stats.messages += played
            if not loop or played == 0:
                break
        stats.duration_s = time.monotonic() - started
        stop.wait(linger_s)
    finally:
        server.stop()
    return stats


def _play_once(
    reader: LogReader,
    channels: dict[int, foxglove.Channel],
    begin_ns: int,
    speed: float,
    stop: threading.Event,
) -> int:
    """One pass over the log from ``begin_ns`` (log time [ns]) with its relative timing / ``speed``;
    the messages played."""
    started = time.monotonic()
    played = 0
    for message, channel, _schema in reader.records():
        if stop.is_set():
            break
        if message.log_time < begin_ns or channel.id not in channels:
            continue
        due = started + (message.log_time - begin_ns) / 1e9 / speed
        delay = due - time.monotonic()
        if delay > 0 and stop.wait(delay):
            break
        channels[channel.id].log(bytes(message.data), log_time=message.log_time)
        played += 1
    return played
