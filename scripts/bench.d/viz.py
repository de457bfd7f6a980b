"""Foxglove benchmark: the demo's log, and what the live view costs the fetch.

1. A nominal fetch (``scripts/demo``'s run) recorded by the default recorder to an MCAP log:
   ``demo_log_mb``; ``channels_total`` and ``channels_foxglove_ok`` by Foxglove's own published code
   (``scripts/foxglove_check``: @mcap/core with CRCs, every message of every channel decoded; needs
   node and npm), ``channels_schema_rules_ok`` by the rules of Foxglove's JSON-schema reader
   (:func:`services.bus.foxglove.schema_problems`), and the largest channels.
2. On a second stack (not recording) with an idle subscriber to the sim's state topics
   (``hrp/<robot>/sim/*``) in this process throughout (the sim's wall time depends on whether
   anything subscribes: README, "the sim without subscribers"), after a warm-up fetch: ``--pairs``
   alternations of the nominal fetch without the live view, then with the viz service running and a
   Foxglove WebSocket client subscribed to every channel. Per fetch: wall time, CPU seconds of the
   stack's processes (every descendant of this process: services, viz; ``stack_cpu_s``), of this
   process (the supervisor, and the client and latency probe when the view is on;
   ``bench_process_cpu_s``) and the load average. ``fetch_wall_ratio`` and ``fetch_cpu_ratio``
   (medians of ``stack_cpu_s``, with / without; goal <= 1.05), ``viz_cpu_share`` (the viz process's
   CPU over the fetch's wall time, in cores), ``live_latency_ms_p50/p95`` (a ``sim/joint_state``
   received by this process -> the transform made of it received by the client, matched by the base
   position).

Writes ``bench/out/viz.json``. Usage: scripts/bench viz [--log-dir DIR] [--pairs N]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import statistics
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
    """Channels of a log: which ones Foxglove's own code decodes (every message), which JSON schemas
    pass the rules of its JSON-schema reader, and the largest channels."""
    from mcap.reader import make_reader

    from services.bus.foxglove import schema_problems
    from services.viz import nodecheck

    rules_ok, rules_bad, seen = 0, [], set()
    sizes: dict[str, int] = {}
    with open(path, "rb") as stream:
        for schema, channel, message in make_reader(stream, validate_crcs=True).iter_messages():
            sizes[channel.topic] = sizes.get(channel.topic, 0) + len(message.data)
            if channel.id in seen:
                continue
            seen.add(channel.id)
            if channel.message_encoding == "json" and schema is not None:
                problems = schema_problems(json.loads(schema.data), channel.topic)
                rules_bad.extend(problems)
                rules_ok += not problems
            else:
                rules_ok += channel.message_encoding == "protobuf"
    largest = sorted(sizes.items(), key=lambda kv: -kv[1])[:8]
    report = {
        "channels_total": len(seen),
        "channels_foxglove_ok": None,
        "channels_schema_rules_ok": rules_ok,
        "channels_rejected": rules_bad,
        "largest_channels_mb_uncompressed": {k: round(v / 1e6, 2) for k, v in largest},
    }
    reason = nodecheck.unavailable()
    if reason:
        report["foxglove_check"] = f"not run: {reason}"
        return report
    node = nodecheck.check_log(path)
    report["channels_foxglove_ok"] = node["channels_ok"]
    report["foxglove_check"] = {
        "reader": node["reader"],
        "messages_decoded": sum(ch["decoded"] for ch in node["channels"]),
        "messages": node["messages"],
        "summary_message_count": node["summary_message_count"],
        "failed": {ch["topic"]: ch["errors"] for ch in node["channels"] if not ch["ok"]},
    }
    return report


def _tree_cpu_s(root: int) -> float:
    """CPU seconds (user + system) of every live descendant process of ``root`` (not ``root``)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    total, todo = 0.0, list(children.get(root, []))
    while todo:
        pid = todo.pop()
        try:
            total += _cpu_s(pid)
        except (OSError, IndexError):
            continue
        todo.extend(children.get(pid, []))
    return total


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


def _measured_fetch(sup, bus, port: int | None) -> dict:
    """One nominal fetch; with ``port``, the viz service runs and a Foxglove client watches everything."""
    from supervisor.fetch import fetch

    viz = probe = None
    if port is not None:
        viz = subprocess.Popen(
            [sys.executable, "-m", "services.viz.service", "--hub", bus.hub, "--robot", bus.robot,
             "--port", str(port), "--log-level", "WARNING"],
            cwd=REPO, start_new_session=True,
        )  # fmt: skip
    try:
        if viz is not None:
            deadline = time.monotonic() + 60
            while "viz" not in sup.client.alive_services() and time.monotonic() < deadline:
                time.sleep(0.1)
            probe = LatencyProbe(sup.session, bus.robot, f"ws://127.0.0.1:{port}")
            time.sleep(1.0)  # the body, the calibrations: what a viewer gets on connecting
        me = os.getpid()
        cpu0, me0, viz0 = _tree_cpu_s(me), _cpu_s(me), _cpu_s(viz.pid) if viz is not None else 0.0
        summary, _ = fetch(sup)
        cpu1, me1, viz1 = _tree_cpu_s(me), _cpu_s(me), _cpu_s(viz.pid) if viz is not None else 0.0
        run = {
            "view": viz is not None,
            "ok": summary.ok,
            "retries": summary.retries,
            "wall_s": round(summary.wall_s, 2),
            "stack_cpu_s": round(cpu1 - cpu0, 2),
            "bench_process_cpu_s": round(me1 - me0, 2),
            "viz_cpu_s": round(viz1 - viz0, 2),
            "load_avg_1min": os.getloadavg()[0],
        }
        if probe is not None:
            probe.close()
            run["latencies_ms"] = probe.latencies_ms
            run["messages_received"] = probe.messages
        return run
    finally:
        if viz is not None:
            viz.terminate()
            viz.wait(10)


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
    parser.add_argument("--pairs", type=int, default=2, help="fetches without / with the live view (2)")
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

    # 2. The live view's cost: without / with alternated on one stack, an idle hrp/** subscriber throughout.
    from services.bus import keys

    bus = BusConfig().with_hub_port(_free_port())
    port = _free_port()
    runs: list[dict] = []
    latencies: list[float] = []
    received = 0
    with running_stack(bus, log_dir=str(log_dir / "b")), Supervisor.connect(bus) as sup:
        sup.wait_for_services(30.0)
        # The sim's state topics (joint_state, base_pose, clock) watched in both conditions.
        idle = sup.session.declare_subscriber(f"{keys.PREFIX}/{bus.robot}/sim/*", lambda _sample: None)
        warm_up, _ = fetch(sup)  # a stack's first fetch is slower (first plans, caches): not compared
        print(f"warm-up fetch: ok={warm_up.ok} wall {warm_up.wall_s:.1f} s")
        for pair in range(args.pairs):
            for view in (False, True):
                run = _measured_fetch(sup, bus, port if view else None)
                runs.append(run)
                latencies += run.pop("latencies_ms", [])
                received += run.pop("messages_received", 0)
                print(f"pair {pair + 1}, live view {'on ' if view else 'off'}: {run}")
        idle.undeclare()
    without = [r for r in runs if not r["view"]]
    with_view = [r for r in runs if r["view"]]

    def median(values: list[float]) -> float:
        return float(statistics.median(values)) if values else float("nan")

    result = {
        "demo_log_mb": round(log.stat().st_size / 1e6, 2),
        **report,
        "live_latency_ms_p50": _percentile(latencies, 50),
        "live_latency_ms_p95": _percentile(latencies, 95),
        "live_transforms_matched": len(latencies),
        "live_messages_received": received,
        "viz_cpu_share": round(median([r["viz_cpu_s"] / r["wall_s"] for r in with_view]), 3),
        "fetch_wall_ratio": round(
            median([r["wall_s"] for r in with_view]) / median([r["wall_s"] for r in without]), 3
        ),
        "fetch_cpu_ratio": round(
            median([r["stack_cpu_s"] for r in with_view]) / median([r["stack_cpu_s"] for r in without]), 3
        ),
        "fetches": {"recorded": {"wall_s": round(recorded.wall_s, 1), "ok": recorded.ok},
                    "warm_up": {"wall_s": round(warm_up.wall_s, 1), "ok": warm_up.ok}, "compared": runs},
        "goals": {"demo_log_mb": 30, "fetch_wall_ratio": 1.05},
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "load_avg_start": load_start,
            "load_avg_end": os.getloadavg(),
        },
        "when": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }  # fmt: skip
    for key in ("demo_log_mb", "channels_total", "channels_foxglove_ok", "channels_schema_rules_ok",
                "live_latency_ms_p50", "live_latency_ms_p95", "viz_cpu_share", "fetch_wall_ratio",
                "fetch_cpu_ratio"):  # fmt: skip
        print(f"{key:>24}: {result[key]}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out}")
    return 0
