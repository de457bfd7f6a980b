"""Service log lines on the bus (services.bus.buslog) and their Foxglove form, in one process."""

from __future__ import annotations

import logging
import threading
import time

import pytest

from services.bus import buslog
from services.bus.codec import decode
from services.bus.config import BusConfig
from services.bus.schemas.common import LogLine
from services.bus.session import bus_session
from services.viz import common as c
from services.viz.converter import Converter
from tests.conftest import free_port
from tests.test_viz_live import _schema_data, protobuf_class


def test_level_names_and_off(monkeypatch):
    assert buslog.level_from("warning") == logging.WARNING and buslog.level_from("OFF") is None
    monkeypatch.setenv(buslog.ENV_LEVEL, "error")
    assert buslog.level_from(None) == logging.ERROR
    with pytest.raises(ValueError, match="DEBUG, INFO, WARNING, ERROR, CRITICAL, OFF"):
        buslog.level_from("loud")


def test_warnings_and_up_are_published_and_shown_as_foxglove_logs():
    bus = BusConfig().with_hub_port(free_port())
    with bus_session(bus, as_hub=True) as session:
        got: list[tuple[str, bytes]] = []
        arrived = threading.Event()

        def on_sample(sample) -> None:
            got.append((str(sample.key_expr), sample.payload.to_bytes()))
            arrived.set()

        sub = session.declare_subscriber(f"hrp/{bus.robot}/**/log", on_sample)
        assert buslog.attach(session, bus.robot, "walking", "OFF") is None
        handler = buslog.attach(session, bus.robot, "walking")
        log = logging.getLogger("humanoid.walking.test")
        log.setLevel(logging.DEBUG)
        try:
            time.sleep(0.2)
            log.info("not on the bus")
            try:
                raise RuntimeError("boom")
            except RuntimeError:
                log.exception("plan %d failed", 7)
            assert arrived.wait(5.0)
            # A burst never blocks the caller: at most QUEUE_CAPACITY wait, the oldest are dropped.
            for i in range(20 * buslog.QUEUE_CAPACITY):
                log.warning("burst %d", i)
            assert len(handler._queue) <= buslog.QUEUE_CAPACITY
        finally:
            handler.close()
            sub.undeclare()
        assert handler not in logging.getLogger().handlers
    key, frame = got[0]
    line = decode(frame, LogLine)
    assert key == f"hrp/{bus.robot}/walking/log" and line.level == "ERROR" and line.service == "walking"
    assert line.message.startswith("plan 7 failed") and "RuntimeError: boom" in line.message
    assert line.logger == "humanoid.walking.test" and line.file.endswith("test_viz_buslog.py")
    assert not any(b"not on the bus" in f for _k, f in got)
    assert handler.published + handler.dropped >= 1 + 20 * buslog.QUEUE_CAPACITY - buslog.QUEUE_CAPACITY

    (view,) = Converter().views(key, frame, time.time_ns())
    assert view.topic == c.LOG and view.schema_name == "foxglove.Log"
    msg = protobuf_class("foxglove.Log", _schema_data("foxglove.Log")).FromString(view.data)
    assert msg.level == 4 and msg.name == "walking (humanoid.walking.test)"  # 4: ERROR
    assert msg.line == line.line and msg.timestamp.seconds == int(line.wall_time_s)
