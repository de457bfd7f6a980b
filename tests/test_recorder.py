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
    StreamRequest,
)
from services.bus.session import TypedPublisher, request_id_from

REPO = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.integration


def _start_recorder(harness, path, *args, **kwargs):
    return harness.spawn_service(
        "services.bus.recorder", "--output", str(path), *args, name="record", **kwargs
    )


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


def test_sigkilled_recorder_leaves_a_log_read_up_to_its_last_complete_chunk(bus_harness, tmp_path):
    h = bus_harness
    config = tmp_path / "stack.yaml"
    config.write_text("record:\n  chunk_size_bytes: 1024\n  foxglove_views: false\n")
    path = tmp_path / "killed.mcap"
    recorder = _start_recorder(h, path, "--config", str(config))
    pub = TypedPublisher(h.session, h.bus.robot, PING)
    time.sleep(0.5)
    stop = threading.Event()

    def publish() -> None:  # the recorder is killed while messages keep coming
        seq = 0
        while not stop.is_set():
            pub.put(Ping(seq=seq, text="x" * 40))
            seq += 1
            time.sleep(0.002)

    publisher = threading.Thread(target=publish)
    publisher.start()
    time.sleep(1.5)
    os.kill(recorder.pid, signal.SIGKILL)
    recorder.wait()
    stop.set()
    publisher.join()
    pub.undeclare()

    # The official reader, CRCs checked, reads every complete chunk and stops at the cut.
    from mcap.exceptions import McapError
    from mcap.stream_reader import StreamReader

    official = 0
    with open(path, "rb") as stream, pytest.raises((McapError, EOFError, struct.error, ValueError)):
        for record in StreamReader(stream, validate_crcs=True).records:
            official += type(record).__name__ == "Message"
    reader = LogReader(path)
    info = reader.info()
    assert not info.complete
    pings = [decode(m.data, Ping).seq for m in reader.messages() if m.key.endswith("/diag/ping")]
    assert len(pings) >= 100 and pings == list(range(len(pings)))  # a prefix, in order, none missing
    assert len(pings) + sum(1 for m in reader.messages() if not m.key.endswith("/diag/ping")) == official
    cli = subprocess.run(
        [sys.executable, "-m", "services.cli", "log-info", str(path)],
        capture_output=True, text=True, timeout=60, cwd=REPO,
    )  # fmt: skip
    assert cli.returncode == 0, cli.stderr
    assert "truncated" in cli.stdout and "read up to its last complete chunk" in cli.stdout
    assert f"hrp/{h.bus.robot}/diag/ping" in cli.stdout and "hrp.diag.Ping" in cli.stdout


def test_state_every_thins_out_the_200_hz_state_topics_only(bus_harness, tmp_path):
    from services.bus.schemas.sim import CLOCK, Clock

    h = bus_harness
    config = tmp_path / "stack.yaml"
    config.write_text("record:\n  state_every: 4\n")
    path = tmp_path / "thin.mcap"
    recorder = _start_recorder(h, path, "--config", str(config))
    clock = TypedPublisher(h.session, h.bus.robot, CLOCK)
    ping = TypedPublisher(h.session, h.bus.robot, PING)
    time.sleep(0.5)
    for i in range(40):
        clock.put(Clock(sim_time_s=0.005 * i))
        ping.put(Ping(seq=i))
        time.sleep(0.005)
    time.sleep(0.5)
    assert h.stop(recorder) == 0
    clock.undeclare()
    ping.undeclare()
    messages = list(LogReader(path).messages())
    clocks = [decode(m.data, Clock).sim_time_s for m in messages if m.key.endswith("/sim/clock")]
    assert clocks == [pytest.approx(0.005 * i) for i in range(0, 40, 4)]
    assert [decode(m.data, Ping).seq for m in messages if m.key.endswith("/diag/ping")] == list(range(40))


def test_status_says_what_is_written_so_the_recorder_is_stopped_after_it(bus_harness, tmp_path):
    """``record/status`` counts the messages written, per key: stopped once it counts them, the
    recorder has every message in its log, also when it runs behind (at the lowest CPU priority here;
    a SIGTERM right after a message may come before the message reaches the recorder)."""
    from services.bus.schemas.record import STATUS, StatusRequest

    path = tmp_path / "status.mcap"
    h = bus_harness
    recorder = _start_recorder(h, path, preexec_fn=lambda: os.nice(19))
    pub = TypedPublisher(h.session, h.bus.robot, PING, track_matching=True)
    assert _wait_for(lambda: pub.matching)  # the recorder's subscription has reached this session
    ping = keys.key(h.bus.robot, "diag", "ping")
    for seq in range(50):
        pub.put(Ping(seq=seq, text=f"ping {seq}"))
    assert _wait_for(lambda: h.client.call(STATUS, StatusRequest(), 10.0).per_key.get(ping) == 50, 60.0)
    status = h.client.call(STATUS, StatusRequest(), 10.0)
    assert status.output == str(path) and status.recorded >= 50
    assert h.stop(recorder) == 0
    pub.undeclare()
    pings = [decode(m.data, Ping).seq for m in LogReader(path).messages() if m.key == ping]
    assert pings == list(range(50))
