"""Foxglove benchmark: the demo's log, and what the live view costs the fetch.

1. A nominal fetch (``scripts/demo``'s run) recorded to an MCAP log: ``demo_log_mb``, ``channels_total``
   and ``channels_foxglove_ok`` (protobuf channels with a ``foxglove.*`` schema whose first message
   decodes, JSON channels whose schema passes the rules of Foxglove's JSON-schema reader and whose
   first message parses: :func:`services.bus.foxglove.schema_problems`), and the largest channels.
2. On a second stack (not recording), after a warm-up fetch (a stack's first fetch is slower), the
   nominal fetch without the live view, then with the viz
   service running and a Foxglove WebSocket client subscribed to every channel:
   ``fetch_wall_ratio`` (with / without; goal <= 1.05), ``viz_cpu_share`` (the viz process's CPU time
   over the fetch's wall time, in cores), ``live_latency_ms_p50/p95`` (a ``sim/joint_state`` received
   by this process -> the transform made of it received by the client, matched by the base position).

Writes ``bench/out/viz.json``. Usage: scripts/bench viz [--log-dir DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "viz.json"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def channels_report(path: Path) -> dict:
    """Channels of a log and which of them Foxglove loads (the rules of the tests)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    from mcap.reader import make_reader

    from services.bus.foxglove import schema_problems

    first: dict[int, tuple] = {}
    sizes: dict[str, int] = {}
    with open(path, "rb") as stream:
        for schema, channel, message in make_reader(stream, validate_crcs=True).iter_messages():
            first.setdefault(channel.id, (schema, channel, bytes(message.data)))
            sizes[channel.topic] = sizes.get(channel.topic, 0) + len(message.data)
    ok, bad = 0, []
    for schema, channel, data in first.values():
        try:
            if channel.message_encoding == "protobuf":
                assert schema is not None and schema.name.startswith("foxglove.")
                files = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
                pool = descriptor_pool.DescriptorPool()
                for f in files.file:
                    pool.Add(f)
                message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name)).FromString(data)
            else:
                assert channel.message_encoding == "json" and schema is not None
                problems = schema_problems(json.loads(schema.data))
                assert not problems, problems
                json.loads(data)
            ok += 1
        except Exception as exc:
            bad.append(f"{channel.topic}: {exc}")
    largest = sorted(sizes.items(), key=lambda kv: -kv[1])[:8]
    return {
        "channels_total": len(first),
        "channels_foxglove_ok": ok,
        "channels_rejected": bad,
        "largest_channels_mb": {k: round(v / 1e6, 2) for k, v in largest},
    }


class LatencyProbe:
    """Joint states seen on the bus and transforms seen by a Foxglove client, matched by base position."""

    def __init__(self, session, robot: str, url: str) -> None:
        from services.bus import keys
        from services.viz.wsclient import FoxgloveClient

        self.seen: dict[tuple[float, float, float], int] = {}
        self.latencies_ms: list[float] = []
        self.messages = 0
        self._stop = threading.Event()
        self._sub = session.declare_subscriber(keys.key(robot, "sim", "joint_state"), self._on_joint_state)
        self.client = FoxgloveClient(url)
        self.client.wait_for_topics(["/tf", "/robot"], timeout_s=10.0)
        self.client.subscribe(list(self.client.topics()))
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _on_joint_state(self, sample) -> None:  # zenoh thread: decode and store only
        from services.bus.codec import decode
        from services.bus.schemas.sim import JointState

        arrived = time.time_ns()
        q = decode(sample.payload.to_bytes(), JointState).q
        self.seen[(float(q[0]), float(q[1]), float(q[2]))] = arrived

    def _read(self) -> None:
        from foxglove.messages import FrameTransforms
        from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

        files = descriptor_pb2.FileDescriptorSet.FromString(bytes(FrameTransforms.get_schema().data))
        pool = descriptor_pool.DescriptorPool()
        for f in files.file:
            pool.Add(f)
        cls = message_factory.GetMessageClass(pool.FindMessageTypeByName("foxglove.FrameTransforms"))
        while not self._stop.is_set():
            got = self.client.receive(0.2)
            if got is None:
                continue
            self.messages += 1
            if got.topic != "/tf":
                continue
            base = next(t for t in cls.FromString(got.data).transforms if t.parent_frame_id == "world")
            sent = self.seen.get((base.translation.x, base.translation.y, base.translation.z))
            if sent is not None:
                self.latencies_ms.append((got.received_ns - sent) / 1e6)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._sub.undeclare()
        self.client.close()


def _percentile(values: list[float], p: float) -> float | None:
    if not values:
        return None
    ordered = sorted(values)
    return round(ordered[min(len(ordered) - 1, int(p / 100 * len(ordered)))], 2)


def thinned_log_mb(every: int, log_dir: Path) -> float:
    """The demo's run recorded by a recorder with ``state_every = every`` (its own process) [MB]."""
    from services.bus.config import BusConfig
    from supervisor.core import Supervisor
    from supervisor.fetch import fetch, running_stack

    config = log_dir / "thinned.yaml"
    config.write_text(f"record:\n  state_every: {every}\n")
    log = (log_dir / f"demo-state-every-{every}.mcap").resolve()
    bus = BusConfig().with_hub_port(_free_port())
    with running_stack(bus, log_dir=str(log_dir / "c")), Supervisor.connect(bus) as sup:
        sup.wait_for_services(30.0)
        recorder = subprocess.Popen(
            [sys.executable, "-m", "services.bus.recorder", "--hub", bus.hub, "--robot", bus.robot,
             "--config", str(config), "--output", str(log), "--log-level", "WARNING"],
            cwd=REPO, start_new_session=True,
        )  # fmt: skip
        try:
            deadline = time.monotonic() + 60
            while "record" not in sup.client.alive_services() and time.monotonic() < deadline:
                time.sleep(0.1)
            summary, _ = fetch(sup)
        finally:
            recorder.terminate()
            recorder.wait(30)
    print(f"fetch recorded with state_every={every}: ok={summary.ok}, log {log.stat().st_size / 1e6:.1f} MB")
    return round(log.stat().st_size / 1e6, 2)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench viz", description=__doc__.split("\n\n")[0])
    parser.add_argument("--log-dir", default="bench/out/viz-logs", help="services' output and the demo log")
    parser.add_argument("--out", default=str(OUT), help="JSON output file")
    parser.add_argument(
        "--state-every",
        type=int,
        default=0,
        help="also record the fetch with the recorder's state_every = N (demo_log_mb_state_every)",
    )
    args = parser.parse_args(argv)

    from services.bus.config import BusConfig
    from supervisor.core import Supervisor
    from supervisor.fetch import fetch, running_stack

    log_dir = Path(args.log_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    load_start = os.getloadavg()

    # 1. The demo's run, recorded.
    log = (log_dir / "demo.mcap").resolve()
    bus = BusConfig().with_hub_port(_free_port())
    with running_stack(bus, record=str(log), log_dir=str(log_dir / "a")), Supervisor.connect(bus) as sup:
        sup.wait_for_services(30.0)
        recorded, _ = fetch(sup, snapshot=log_dir / "demo.png")
    size_mb = log.stat().st_size / 1e6
    print(f"recorded fetch: ok={recorded.ok} wall {recorded.wall_s:.1f} s; log {size_mb:.1f} MB")
    report = channels_report(log)
    if args.state_every:
        report["demo_log_mb_state_every"] = {str(args.state_every): thinned_log_mb(args.state_every, log_dir)}

    # 2. Without, then with the live view and a connected client.
    bus = BusConfig().with_hub_port(_free_port())
    port = _free_port()
    with running_stack(bus, log_dir=str(log_dir / "b")), Supervisor.connect(bus) as sup:
        sup.wait_for_services(30.0)
        warm_up, _ = fetch(sup)  # a stack's first fetch is slower (first plans, caches): not compared
        print(f"warm-up fetch: ok={warm_up.ok} wall {warm_up.wall_s:.1f} s")
        without, _ = fetch(sup)
        print(f"fetch without the live view: ok={without.ok} wall {without.wall_s:.1f} s")
        viz = subprocess.Popen(
            [sys.executable, "-m", "services.viz.service", "--hub", bus.hub, "--robot", bus.robot,
             "--port", str(port), "--log-level", "WARNING"],
            cwd=REPO, start_new_session=True,
        )  # fmt: skip
        try:
            deadline = time.monotonic() + 60
            while "viz" not in sup.client.alive_services() and time.monotonic() < deadline:
                time.sleep(0.1)
            probe = LatencyProbe(sup.session, bus.robot, f"ws://127.0.0.1:{port}")
            cpu0 = _cpu_s(viz.pid)
            with_view, _ = fetch(sup)
            cpu1 = _cpu_s(viz.pid)
            probe.close()
        finally:
            viz.terminate()
            viz.wait(10)
        print(f"fetch with the live view and a client: ok={with_view.ok} wall {with_view.wall_s:.1f} s")

    result = {
        "demo_log_mb": round(log.stat().st_size / 1e6, 2),
        **report,
        "live_latency_ms_p50": _percentile(probe.latencies_ms, 50),
        "live_latency_ms_p95": _percentile(probe.latencies_ms, 95),
        "live_transforms_matched": len(probe.latencies_ms),
        "live_messages_received": probe.messages,
        "viz_cpu_share": round((cpu1 - cpu0) / max(with_view.wall_s, 1e-9), 3),
        "fetch_wall_ratio": round(with_view.wall_s / max(without.wall_s, 1e-9), 3),
        "fetch_wall_s": {
            "recorded": round(recorded.wall_s, 1),
            "warm_up": round(warm_up.wall_s, 1),
            "without_view": round(without.wall_s, 1),
            "with_view": round(with_view.wall_s, 1),
        },
        "fetch_ok": {"recorded": recorded.ok, "without_view": without.ok, "with_view": with_view.ok},
        "fetch_retries": {"without_view": without.retries, "with_view": with_view.retries},
        "goals": {"demo_log_mb": 30, "fetch_wall_ratio": 1.05},
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "load_avg_start": load_start,
            "load_avg_end": os.getloadavg(),
        },
        "when": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }
    for key in ("demo_log_mb", "channels_total", "channels_foxglove_ok", "live_latency_ms_p50",
                "live_latency_ms_p95", "viz_cpu_share", "fetch_wall_ratio"):  # fmt: skip
        print(f"{key:>24}: {result[key]}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out}")
    return 0
