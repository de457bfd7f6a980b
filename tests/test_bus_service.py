"""The service framework over real zenoh sessions, each service in its own spawned process.

``diag`` (services/bus/diag.py) and ``probe`` (defined below, run as a script) talk to each other:
the probe calls diag/echo from its own handler (request/reply between two services) and receives
diag/pong (pub/sub between two services). Malformed payloads and handler exceptions get typed error
replies and the services keep serving.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time

import msgspec
import numpy as np
import pytest

from services.bus.codec import encode
from services.bus.schemas.diag import (
    ECHO,
    PING,
    PONG,
    RAISE,
    EchoRequest,
    Ping,
    RaiseRequest,
    StreamRequest,
)
from services.bus.schemas.sim import CLOCK
from services.bus.service import Service, handles, run_service, subscribes
from services.bus.session import TypedPublisher, TypedSubscriber, close_session, open_session
from services.bus.spec import EndpointSpec
from services.errors import (
    InfeasibleError,
    InternalError,
    InvalidRequestError,
    NotFoundError,
    RequestTimeoutError,
    UnavailableError,
)

pytestmark = pytest.mark.integration


# --- the probe service (runs in its own process: python tests/test_bus_service.py) -----------------
class RelayRequest(msgspec.Struct, kw_only=True, frozen=True):
    text: str


class RelayReply(msgspec.Struct, kw_only=True, frozen=True):
    echoed: str
    pongs: list[int]  # seq of every diag/pong received so far


RELAY = EndpointSpec("probe", "relay", RelayRequest, RelayReply, "calls diag/echo, reports pongs received")


class SleepRequest(msgspec.Struct, kw_only=True, frozen=True):
    seconds: float


SLEEP = EndpointSpec("probe", "sleep", SleepRequest, SleepRequest, "answers after `seconds` [s]")


class ProbeService(Service):
    """Test peer: calls diag from a handler and listens to diag/pong."""

    name = "probe"

    def start(self) -> None:
        self.pongs: list[int] = []

    @subscribes(PONG)
    def on_pong(self, ping: Ping) -> None:
        self.pongs.append(ping.seq)

    @handles(RELAY)
    def relay(self, request: RelayRequest) -> RelayReply:
        reply = self.client.call(ECHO, EchoRequest(text=request.text), timeout_s=5.0)
        return RelayReply(echoed=reply.text, pongs=list(self.pongs))

    @handles(SLEEP)
    def sleep(self, request: SleepRequest) -> SleepRequest:
        time.sleep(request.seconds)
        return request


# --- tests -------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def bus(module_bus_harness):
    module_bus_harness.spawn_service("services.bus.diag")
    module_bus_harness.spawn_script(__file__, name="probe")
    return module_bus_harness


def test_request_reply_with_arrays(bus):
    blob = np.arange(12, dtype=np.float32).reshape(3, 4)
    reply = bus.client.call(ECHO, EchoRequest(text="héllo", blob=blob), timeout_s=5.0)
    assert reply.text == "héllo"
    assert reply.blob.dtype == np.float32 and np.array_equal(reply.blob, blob)


def test_request_reply_and_pub_sub_between_two_services(bus):
    pub = TypedPublisher(bus.session, bus.bus.robot, PING)
    time.sleep(0.3)  # the probe's and diag's subscriptions reach this session
    for seq in range(5):
        pub.put(Ping(seq=seq, text="x"))
    deadline = time.monotonic() + 10.0
    while True:  # probe -> diag/echo (request/reply), diag/ping -> diag -> diag/pong -> probe (pub/sub)
        reply = bus.client.call(RELAY, RelayRequest(text="via probe"), timeout_s=10.0)
        if len(reply.pongs) >= 5 or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    pub.undeclare()
    assert reply.echoed == "via probe"
    assert reply.pongs[-5:] == [0, 1, 2, 3, 4]


def test_a_publisher_knows_whether_anyone_subscribes(bus):
    pub = TypedPublisher(bus.session, bus.bus.robot, CLOCK, track_matching=True)  # no sim here
    other = open_session(bus.bus)  # another peer, as a recorder or a viewer would be

    def becomes(expected: bool) -> bool:
        deadline = time.monotonic() + 5.0
        while pub.matching != expected and time.monotonic() < deadline:
            time.sleep(0.01)
        return pub.matching == expected

    try:
        assert becomes(False)
        sub = TypedSubscriber(other, bus.bus.robot, CLOCK)
        assert becomes(True)
        sub.undeclare()
        assert becomes(False)
    finally:
        pub.undeclare()
        close_session(other)


@pytest.mark.parametrize(
    ("payload", "expected"),
    [
        # garbage that cannot start a JSON value (random bytes starting with a digit decode a number first)
        (b"\xff" + os.urandom(255), "malformed payload for EchoRequest"),
        (b"HRPB\xff\xff\xff\xff{}", "truncated binary frame"),
        (b'{"text": 42}', "Expected `str`, got `int` - at `$.text`"),
        (b'{"blob": "not an array"}', "$.blob"),
        (b"[1, 2, 3]", "Expected `object`, got `array`"),
    ],
)
def test_malformed_payloads_get_invalid_request(bus, payload, expected):
    with pytest.raises(InvalidRequestError) as info:
        bus.client.call_raw("diag", "echo", payload, timeout_s=5.0)
    assert expected in info.value.message
    assert bus.client.call(ECHO, EchoRequest(text="still here"), timeout_s=5.0).text == "still here"


def test_missing_field_is_named(bus):
    with pytest.raises(InvalidRequestError, match="missing required field `message`"):
        bus.client.call_raw("diag", "raise", b'{"code": "infeasible"}', timeout_s=5.0)


def test_fifty_megabyte_garbage_gets_invalid_request(bus):
    payload = b"{" + os.urandom(50 * 1024 * 1024)
    with pytest.raises(InvalidRequestError, match="malformed payload"):
        bus.client.call_raw("diag", "echo", payload, timeout_s=60.0)
    assert bus.client.call(ECHO, EchoRequest(text="ok"), timeout_s=5.0).text == "ok"


@pytest.mark.parametrize(
    ("code", "error"),
    [("infeasible", InfeasibleError), ("not_found", NotFoundError), ("bug", InternalError)],
)
def test_handler_errors_become_typed_replies_and_service_keeps_serving(bus, code, error):
    with pytest.raises(error) as info:
        bus.client.call(RAISE, RaiseRequest(code=code, message="on purpose"), timeout_s=5.0)
    assert "on purpose" in info.value.message
    if code == "bug":
        assert "RuntimeError" in info.value.message
    assert bus.client.call(ECHO, EchoRequest(text="alive"), timeout_s=5.0).text == "alive"


def test_a_reply_too_late_is_a_timeout_and_the_service_keeps_serving(bus):
    """zenoh ends a query that outlives its timeout with an error reply of its own ("Timeout"): the
    client reports it as ``timeout`` (retried by the supervisor), not as an ``internal`` error."""
    with pytest.raises(RequestTimeoutError, match=r"probe/sleep gave no reply within 0\.5 s"):
        bus.client.call(SLEEP, SleepRequest(seconds=2.0), timeout_s=0.5)
    assert bus.client.call(SLEEP, SleepRequest(seconds=0.0), timeout_s=5.0).seconds == 0.0


def test_unknown_service_is_unavailable(bus):
    with pytest.raises(UnavailableError, match="'nobody' is not running"):
        bus.client.call_raw("nobody", "nothing", encode(EchoRequest()), timeout_s=3.0)


def test_heartbeat_counts_requests(bus):
    from services.bus import keys
    from services.bus.codec import decode
    from services.bus.schemas.common import Heartbeat

    beats = []
    sub = bus.session.declare_subscriber(
        keys.heartbeat(bus.bus.robot, "diag"), lambda s: beats.append(decode(s.payload.to_bytes(), Heartbeat))
    )
    deadline = time.monotonic() + 5.0
    while len(beats) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    sub.undeclare()
    assert len(beats) >= 2
    assert beats[-1].seq > beats[0].seq
    assert beats[-1].requests_served >= 1 and beats[-1].requests_failed >= 1


def test_large_requests_still_arrive_after_another_session_of_this_process_closed(bus_harness):
    """zenoh keeps one shared-memory pool per process for all its sessions: closing one session must not
    unlink it, or a service started afterwards cannot map it and never receives a large request (the
    CI failure of the supervisor tests: sim/execute "gave no reply" once an earlier test module closed
    its session)."""
    blob = np.random.default_rng(0).random((400, 400))  # 1.3 MB: through shared memory
    first = bus_harness.spawn_service("services.bus.diag")
    assert np.array_equal(bus_harness.client.call(ECHO, EchoRequest(blob=blob), timeout_s=10.0).blob, blob)
    close_session(open_session(bus_harness.bus))
    bus_harness.stop(first)
    bus_harness.wait_gone("diag")
    bus_harness.spawn_service("services.bus.diag")  # a process that has never mapped the pool
    assert np.array_equal(bus_harness.client.call(ECHO, EchoRequest(blob=blob), timeout_s=10.0).blob, blob)


def test_sigterm_stops_a_service_even_with_a_busy_handler(bus_harness):
    proc = bus_harness.spawn_service("services.bus.diag")
    # Keep diag/stream's worker busy for a long time, then ask the service to stop.
    bus_harness.session.get(
        "hrp/hrp2/diag/stream",
        payload=encode(StreamRequest(count=100_000, width=640, height=480)),
        timeout=30,
    )
    time.sleep(0.3)
    # more requests queued behind it: each still gets its one reply when the service stops
    queued = [
        bus_harness.session.get(
            "hrp/hrp2/diag/stream", payload=encode(StreamRequest(count=1, width=8, height=8)), timeout=30
        )
        for _ in range(3)
    ]
    time.sleep(0.3)
    started = time.monotonic()
    os.kill(proc.pid, signal.SIGTERM)
    proc.wait(timeout=10.0)
    print(f"diag exited {time.monotonic() - started:.2f} s after SIGTERM")
    assert proc.returncode == 0
    for replies in queued:
        errors = [json.loads(bytes(r.err.payload.to_bytes())) for r in replies if r.err is not None]
        assert [e["code"] for e in errors] == ["unavailable"], errors
        assert errors[0]["details"]["reason"] == "stopping" and "is stopping" in errors[0]["message"]
    bus_harness.wait_gone("diag")


def test_sigint_stops_an_idle_service(bus_harness):
    proc = bus_harness.spawn_service("services.bus.diag")
    os.kill(proc.pid, signal.SIGINT)
    proc.wait(timeout=10.0)
    assert proc.returncode == 0


if __name__ == "__main__":
    raise SystemExit(run_service(ProbeService, sys.argv[1:]))
