"""Bus benchmark: the service framework against raw zenoh, in the same run, between separate processes.

- ``reqrep_p50_us`` / ``reqrep_p99_us``: a 64-byte request/reply round trip through the framework
  (``Client.call`` -> the ``diag`` service's ``diag/echo``, a ``blocking=False`` handler: codec,
  typed validation and reply envelope, run in zenoh's callback); ``reqrep_raw_*``: the same 64 bytes
  with ``session.get`` to a raw zenoh queryable that replies from its callback;
  ``reqrep_worker_*``: ``diag/echo_worker``, the same handler on a worker thread (the default, for
  planners), to show what the hand-off costs.
- ``pubsub_p50_us`` / ``pubsub_p99_us``: a 64-byte message published on ``diag/ping`` (TypedPublisher),
  republished by ``diag`` on ``diag/pong`` (a ``blocking=False`` typed subscription), received with
  a TypedSubscriber; ``pubsub_raw_*``: the same with raw zenoh publishers and a callback relay.
- ``stereo_fps``: 640x480 RGB stereo pairs (1.8 MB, binary frames) published by ``diag/stream``
  and received by a second service (``bench_sink``, running in this process), pairs per second
  at the receiver; nothing is dropped (the stream publisher blocks on congestion).

Framework and raw samples are interleaved one by one in a shuffled order, so machine load affects
both alike. Reference (issue 2,
this kind of machine): raw zenoh ~88 us pub/sub and ~112 us query/reply; goal: framework within 1.2x.
Writes bench/out/bus.json.

Usage: scripts/bench bus [--samples N] [--frames N] [--help]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "bus.json"
RAW_QUERY = "hrp/bench/raw/echo"
RAW_PING = "hrp/bench/raw/ping"
RAW_PONG = "hrp/bench/raw/pong"
RAW_ALIVE = "hrp/bench/raw/alive"
PAYLOAD_BYTES = 64


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def raw_peer(hub: str) -> int:
    """The raw zenoh side: a queryable replying from its callback and a ping -> pong relay."""
    import zenoh

    from services.bus.config import BusConfig
    from services.bus.session import close_session, open_session

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    session = open_session(BusConfig(hub=hub))
    pong = session.declare_publisher(RAW_PONG)
    queryable = session.declare_queryable(RAW_QUERY, lambda q: q.reply(q.key_expr, q.payload.to_bytes()))
    subscriber = session.declare_subscriber(RAW_PING, lambda s: pong.put(s.payload.to_bytes()))
    token = session.liveliness().declare_token(RAW_ALIVE)
    stop.wait()
    for entity in (token, subscriber, queryable, pong):
        entity.undeclare()
    close_session(session)
    _ = zenoh
    return 0


def percentile(values: list[float], q: float) -> float:
    import numpy as np

    return float(np.percentile(np.asarray(values), q))


def measure_latency(hub_session, bus, samples: int) -> dict[str, float]:
    import zenoh

    from services.bus.codec import encode
    from services.bus.schemas.diag import ECHO, ECHO_WORKER, PING, PONG, EchoRequest, Ping
    from services.bus.session import Client, TypedPublisher, TypedSubscriber

    client = Client(hub_session, bus.robot)
    # A request whose frame is 64 bytes, like the raw payload.
    text = "x" * (PAYLOAD_BYTES - len(encode(EchoRequest(text=""))))
    request = EchoRequest(text=text)
    assert len(encode(request)) == PAYLOAD_BYTES
    ping_text = "x" * (PAYLOAD_BYTES - len(encode(Ping(seq=100000, text=""))))
    raw_payload = b"x" * PAYLOAD_BYTES

    ping_pub = TypedPublisher(hub_session, bus.robot, PING)
    pong_sub = TypedSubscriber(hub_session, bus.robot, PONG)
    raw_ping = hub_session.declare_publisher(RAW_PING)
    raw_pong = hub_session.declare_subscriber(RAW_PONG, zenoh.handlers.FifoChannel(256))
    raw_pong_channel = raw_pong.handler
    time.sleep(0.5)  # subscriptions reach the peers

    def fw_reqrep() -> float:
        t0 = time.perf_counter()
        client.call(ECHO, request, 5.0)
        return time.perf_counter() - t0

    def worker_reqrep() -> float:
        t0 = time.perf_counter()
        client.call(ECHO_WORKER, request, 5.0)
        return time.perf_counter() - t0

    def raw_reqrep() -> float:
        t0 = time.perf_counter()
        for reply in hub_session.get(RAW_QUERY, payload=raw_payload, timeout=5.0):
            reply.ok.payload.to_bytes()
        return time.perf_counter() - t0

    seq = [100000]

    def fw_pubsub() -> float:
        seq[0] += 1
        t0 = time.perf_counter()
        ping_pub.put(Ping(seq=seq[0], text=ping_text))
        pong = pong_sub.recv()
        elapsed = time.perf_counter() - t0
        assert pong.seq == seq[0], "pong out of order"
        return elapsed

    def raw_pubsub() -> float:
        t0 = time.perf_counter()
        raw_ping.put(raw_payload)
        raw_pong_channel.recv().payload.to_bytes()
        return time.perf_counter() - t0

    funcs = {
        "reqrep_raw": raw_reqrep,
        "reqrep": fw_reqrep,
        "reqrep_worker": worker_reqrep,
        "pubsub_raw": raw_pubsub,
        "pubsub": fw_pubsub,
    }
    results: dict[str, list[float]] = {name: [] for name in funcs}
    for func in funcs.values():  # warm up
        for _ in range(200):
            func()
    # One sample of each per round, in a shuffled order: load drifts and the tail of the previous
    # exchange (the peer finishing its callback) weigh on framework and raw alike.
    rng = random.Random(0)
    order = list(funcs)
    for _ in range(samples):
        rng.shuffle(order)
        for name in order:
            results[name].append(funcs[name]() * 1e6)
    ping_pub.undeclare()
    pong_sub.undeclare()
    raw_ping.undeclare()
    raw_pong.undeclare()
    out = {}
    for name, values in results.items():
        out[f"{name}_p50_us"] = round(percentile(values, 50), 1)
        out[f"{name}_p99_us"] = round(percentile(values, 99), 1)
    out["reqrep_ratio"] = round(out["reqrep_p50_us"] / out["reqrep_raw_p50_us"], 3)
    out["pubsub_ratio"] = round(out["pubsub_p50_us"] / out["pubsub_raw_p50_us"], 3)
    out["reqrep_worker_ratio"] = round(out["reqrep_worker_p50_us"] / out["reqrep_raw_p50_us"], 3)
    out["samples"] = len(results["reqrep"])
    return out


def measure_stereo(bus, frames: int) -> dict[str, float]:
    """diag streams stereo pairs; a sink service in this process counts them."""
    from services.bus.schemas.diag import FRAMES, STREAM, StereoFrame, StreamRequest
    from services.bus.service import Service, serve, subscribes
    from services.bus.session import Client, bus_session

    received: list[float] = []
    done = threading.Event()
    bad: list[str] = []

    class BenchSink(Service):
        """Counts the stereo pairs of diag/frames."""

        name = "bench_sink"

        @subscribes(FRAMES)
        def on_frame(self, frame: StereoFrame) -> None:
            if frame.left.shape != (480, 640, 3) or frame.right.shape != (480, 640, 3):
                bad.append(f"frame {frame.seq} has shapes {frame.left.shape}, {frame.right.shape}")
            received.append(time.perf_counter())
            if len(received) >= frames:
                done.set()

    stop = threading.Event()
    ready = threading.Event()
    thread = threading.Thread(
        target=serve, args=(BenchSink, BenchSink.Config(), bus, stop, lambda _s: ready.set())
    )
    thread.start()
    try:
        ready.wait(10.0)
        with bus_session(bus) as session:
            client = Client(session, bus.robot)
            client.wait_for(["diag", "bench_sink"], timeout_s=10.0)
            time.sleep(0.5)
            reply = client.call(STREAM, StreamRequest(count=frames, width=640, height=480), timeout_s=120.0)
            done.wait(30.0)
    finally:
        stop.set()
        thread.join(5.0)
    if bad:
        raise RuntimeError(bad[0])
    n = len(received)
    fps = (n - 1) / (received[-1] - received[0]) if n > 1 else 0.0
    return {
        "stereo_fps": round(fps, 1),
        "stereo_pairs_sent": reply.sent,
        "stereo_pairs_received": n,
        "stereo_publish_fps": round(reply.sent / reply.elapsed_s, 1),
        "stereo_pair_mb": round(2 * 640 * 480 * 3 / 1e6, 2),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench bus", description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=3000, help="round trips per measurement (3000)")
    parser.add_argument("--frames", type=int, default=300, help="stereo pairs to stream (300)")
    parser.add_argument("--raw-peer", metavar="HUB", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.raw_peer:
        return raw_peer(args.raw_peer)

    from services.bus.config import BusConfig
    from services.bus.session import Client, alive_services, bus_session

    bus = BusConfig().with_hub_port(free_port())
    children: list[subprocess.Popen[bytes]] = []
    try:
        with bus_session(bus, as_hub=True) as hub:
            children.append(
                subprocess.Popen(
                    [sys.executable, "-m", "services.bus.diag", "--hub", bus.hub, "--log-level", "WARNING"],
                    start_new_session=True,
                )
            )
            children.append(
                subprocess.Popen([sys.executable, __file__, "--raw-peer", bus.hub], start_new_session=True)
            )
            Client(hub, bus.robot).wait_for(["diag"], timeout_s=20.0)
            deadline = time.monotonic() + 20.0
            while not any(r.ok is not None for r in hub.liveliness().get(RAW_ALIVE, timeout=0.5)):
                if time.monotonic() > deadline:
                    raise RuntimeError("the raw zenoh peer did not start")
                time.sleep(0.05)
            _ = alive_services
            result = measure_latency(hub, bus, args.samples)
            result.update(measure_stereo(bus, args.frames))
    finally:
        for child in children:
            child.send_signal(signal.SIGTERM)
        for child in children:
            try:
                child.wait(5.0)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()

    result.update(
        {
            "payload_bytes": PAYLOAD_BYTES,
            "host": platform.node(),
            "cpus": os.cpu_count(),
            "load_avg_1min": round(os.getloadavg()[0], 2),
            "unix_time": int(time.time()),
        }
    )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2) + "\n")
    suffixes = ("_p50_us", "_p99_us", "_raw_p50_us", "_raw_p99_us", "_ratio")
    rows = [
        (label, *(result[kind + suffix] for suffix in suffixes))
        for label, kind in (("request/reply 64 B", "reqrep"), ("pub/sub round trip 64 B", "pubsub"))
    ]
    print(f"{'round trip':26s} {'fw p50':>9s} {'fw p99':>9s} {'raw p50':>9s} {'raw p99':>9s} {'ratio':>6s}")
    for name, a, b, c, d, r in rows:
        print(f"{name:26s} {a:7.1f}us {b:7.1f}us {c:7.1f}us {d:7.1f}us {r:6.2f}")
    print(
        f"{'  same, on a worker thread':26s} {result['reqrep_worker_p50_us']:7.1f}us "
        f"{result['reqrep_worker_p99_us']:7.1f}us {'':9s} {'':9s} {result['reqrep_worker_ratio']:6.2f}"
    )
    print(
        f"stereo 640x480 RGB pairs: {result['stereo_fps']:.1f} pairs/s received "
        f"({result['stereo_pairs_received']}/{result['stereo_pairs_sent']}, "
        f"{result['stereo_fps'] * result['stereo_pair_mb']:.0f} MB/s)"
    )
    print(f"(load average {result['load_avg_1min']} on {result['cpus']} cpus) -> {OUT.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    raise SystemExit(main(sys.argv[1:]))
