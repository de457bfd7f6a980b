"""Recorder, replay and log-info over real zenoh sessions, with the recorder in its own process."""

from __future__ import annotations

import os
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from services.bus import keys
from services.bus.codec import decode, encode
from services.bus.mcaplog import LogReader, LogWriter
from services.bus.replay import key_filter, replay, replay_requests
from services.bus.schemas.diag import (
    ECHO,
    PING,
    STREAM,
    EchoReply,
    EchoRequest,
    Ping,
    StereoFrame,
    StreamRequest,
)
from services.bus.session import TypedPublisher, request_id_from

REPO = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.integration


def _start_recorder(harness, path, *args):
    return harness.spawn_service("services.bus.recorder", "--output", str(path), *args, name="record")


def _collect(session, key_expr):
    """Every (key, bytes, request id) published on ``key_expr`` from now on, in arrival order."""
    got: list[tuple[str, bytes, int | None]] = []
    lock = threading.Lock()

    def on_sample(sample):
        with lock:
            got.append((str(sample.key_expr), sample.payload.to_bytes(), request_id_from(sample.attachment)))

    return session.declare_subscriber(key_expr, on_sample), got


def _wait_for(predicate, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.02)
    return predicate()


def test_record_then_replay_reproduces_messages_in_order(bus_harness, tmp_path):
    path = tmp_path / "session.mcap"
    h = bus_harness
    h.spawn_service("services.bus.diag")
    recorder = _start_recorder(h, path)
    pub = TypedPublisher(h.session, h.bus.robot, PING)
    time.sleep(0.5)  # the recorder's and diag's subscriptions reach this session
    for seq in range(20):
        pub.put(Ping(seq=seq, text=f"ping {seq}"))
        time.sleep(0.01)
    blob = np.linspace(0.0, 1.0, 7)
    assert np.array_equal(h.client.call(ECHO, EchoRequest(text="a", blob=blob), 5.0).blob, blob)
    h.client.call(STREAM, StreamRequest(count=2, width=64, height=48), 5.0)
    time.sleep(0.3)
    assert h.stop(recorder) == 0
    pub.undeclare()

    recorded = [m for m in LogReader(path).messages() if not m.key.endswith("/heartbeat")]
    robot = h.bus.robot
    pings = [decode(m.data, Ping).seq for m in recorded if m.key == keys.key(robot, "diag", "ping")]
    assert pings == list(range(20))
    pongs = [decode(m.data, Ping).seq for m in recorded if m.key == keys.key(robot, "diag", "pong")]
    assert pongs == list(range(20))
    request = next(m for m in recorded if m.key == keys.request_mirror(robot, "diag", "echo"))
    reply = next(m for m in recorded if m.key == keys.reply_mirror(robot, "diag", "echo"))
    assert request.sequence == reply.sequence != 0
    assert request.encoding == "hrpb"
    assert np.array_equal(decode(reply.data, EchoReply).blob, blob)

    # Replay into a bus without diag (else it would answer the replayed pings too).
    for proc in h.procs:
        h.stop(proc)
    h.wait_gone("diag")
    sub, got = _collect(h.session, keys.everything(robot))
    time.sleep(0.3)
    stats = replay(h.session, LogReader(path), speed=2.0, accept=key_filter(None))
    assert _wait_for(lambda: len(got) >= len(recorded))
    sub.undeclare()
    assert stats.published == len(recorded)
    assert [(k, d) for k, d, _ in got] == [(m.key, m.data) for m in recorded]
    rids = {k: rid for k, _, rid in got if k.endswith(("/request", "/reply"))}
    assert rids[request.key] == request.sequence and rids[reply.key] == reply.sequence
    span_s = (recorded[-1].log_time_ns - recorded[0].log_time_ns) / 1e9
    assert stats.duration_s >= 0.99 * span_s / 2.0  # the relative timing was kept (a lower bound)


def test_replay_requests_reports_same_and_different_replies(bus_harness, tmp_path):
    h = bus_harness
    h.spawn_service("services.bus.diag")
    robot = h.bus.robot
    path = tmp_path / "requests.mcap"
    writer = LogWriter(path)
    endpoint = keys.key(robot, "diag", "echo")
    t = time.time_ns()
    same = encode(EchoRequest(text="same", blob=np.arange(3.0)))
    writer.write(endpoint + "/request", same, t, sequence=1)
    writer.write(endpoint + "/reply", encode(EchoReply(text="same", blob=np.arange(3.0))), t + 1, sequence=1)
    writer.write(endpoint + "/request", encode(EchoRequest(text="new")), t + 2, sequence=2)
    writer.write(endpoint + "/reply", encode(EchoReply(text="old")), t + 3, sequence=2)
    writer.write(endpoint + "/request", encode(EchoRequest(blob=np.ones(4))), t + 4, sequence=3)
    writer.write(
        endpoint + "/reply", encode(EchoReply(blob=np.array([1.0, 1.0, 1.5, 1.0]))), t + 5, sequence=3
    )
    writer.write(endpoint + "/request", b"garbage", t + 6, sequence=4)
    writer.write(endpoint + "/reply", encode(EchoReply()), t + 7, sequence=4)
    writer.close()

    outcomes = {o.request_id: o for o in replay_requests(h.session, LogReader(path), timeout_s=5.0)}
    assert outcomes[1].status == "same"
    assert outcomes[2].status == "differs" and ".text: 'old' recorded, 'new' now" in outcomes[2].detail
    assert outcomes[3].status == "differs" and "largest change 0.5 over 1 elements" in outcomes[3].detail
    assert outcomes[4].status == "differs" and "now error invalid_request" in outcomes[4].detail

    cli = subprocess.run(
        [sys.executable, "-m", "services.cli", "replay", str(path), "--requests", "--hub", h.hub],
        capture_output=True, text=True, timeout=60, cwd=REPO,
    )  # fmt: skip
    assert cli.returncode == 1, cli.stderr
    assert "4 requests re-sent, 3 with a different or missing reply" in cli.stdout


def test_sigkilled_recorder_leaves_a_readable_log(bus_harness, tmp_path):
    h = bus_harness
    config = tmp_path / "stack.yaml"
    config.write_text("record:\n  chunk_period_s: 0.2\n")
    path = tmp_path / "killed.mcap"
    recorder = _start_recorder(h, path, "--config", str(config))
    pub = TypedPublisher(h.session, h.bus.robot, PING)
    time.sleep(0.5)
    for seq in range(60):
        pub.put(Ping(seq=seq))
        time.sleep(0.01)
    time.sleep(0.6)  # a few chunk periods: the pings are on disk now
    os.kill(recorder.pid, signal.SIGKILL)
    recorder.wait()
    pub.undeclare()

    reader = LogReader(path)
    info = reader.info()
    assert not info.complete
    pings = [decode(m.data, Ping).seq for m in reader.messages() if m.key.endswith("/diag/ping")]
    assert pings == list(range(60))
    cli = subprocess.run(
        [sys.executable, "-m", "services.cli", "log-info", str(path)],
        capture_output=True, text=True, timeout=60, cwd=REPO,
    )  # fmt: skip
    assert cli.returncode == 0, cli.stderr
    assert "no summary (recorder stopped abruptly)" in cli.stdout
    assert f"hrp/{h.bus.robot}/diag/ping" in cli.stdout and "hrp.diag.Ping" in cli.stdout


def _protobuf_fields(data: bytes) -> dict[int, object]:
    """A minimal protobuf reader (varint, fixed32, length-delimited), independent of the writer's code."""
    fields: dict[int, object] = {}
    i = 0

    def varint() -> int:
        nonlocal i
        shift = value = 0
        while True:
            byte = data[i]
            i += 1
            value |= (byte & 0x7F) << shift
            shift += 7
            if not byte & 0x80:
                return value

    while i < len(data):
        tag = varint()
        number, wire = tag >> 3, tag & 7
        if wire == 0:
            fields[number] = varint()
        elif wire == 5:
            fields[number] = struct.unpack_from("<I", data, i)[0]
            i += 4
        elif wire == 2:
            n = varint()
            fields[number] = data[i : i + n]
            i += n
        else:
            raise ValueError(f"unexpected wire type {wire}")
    return fields


def test_images_get_foxglove_raw_image_views(tmp_path):
    path = tmp_path / "views.mcap"
    writer = LogWriter(path)
    left = np.random.default_rng(1).integers(0, 255, (48, 64, 3), dtype=np.uint8)
    frame = StereoFrame(seq=3, stamp_s=1.5, left=left, right=left[::-1].copy())
    key = "hrp/hrp2/diag/frames"
    writer.write(key, encode(frame), 2_000_000_123)
    writer.write(
        "hrp/hrp2/diag/echo/reply", encode(EchoReply(blob=np.arange(5.0))), 2_000_000_200, sequence=9
    )
    writer.close()

    records = {ch.topic: (msg, ch, schema) for msg, ch, schema in LogReader(path).records()}
    msg, channel, schema = records[f"{key}/view/left"]
    assert schema.name == "foxglove.RawImage" and schema.encoding == "protobuf"
    assert channel.message_encoding == "protobuf" and channel.metadata["hrp.role"] == "view"
    image = _protobuf_fields(msg.data)
    stamp = _protobuf_fields(image[1])
    assert (stamp[1], stamp.get(2, 0)) == (2, 123)
    assert (image[2], image[3], image[4], image[5]) == (64, 48, b"rgb8", 64 * 3)
    assert np.array_equal(np.frombuffer(image[6], np.uint8).reshape(48, 64, 3), left)
    assert image[7] == b"left"
    json_view = records[f"{key}/view"][0]
    import json

    view = json.loads(json_view.data)
    assert view["seq"] == 3 and view["left"]["image_topic"] == f"{key}/view/left"
    original = records[key]
    assert original[1].message_encoding == "hrpb" and decode(original[0].data, StereoFrame).seq == 3
    reply_view = json.loads(records["hrp/hrp2/diag/echo/reply/view"][0].data)
    assert reply_view["blob"] == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert records["hrp/hrp2/diag/echo/reply/view"][0].sequence == 9
    assert records[key][2].name == "hrp.diag.StereoFrame"
