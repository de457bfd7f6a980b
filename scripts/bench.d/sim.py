"""Simulation benchmark: physics steps per second, real-time factor of trajectory execution, render times.

- ``steps_per_s``: physics steps (1 ms) per wall-clock second, hrp2_like standing in the ball-fetching
  scene with every joint position controlled (median of ``--repeats`` runs of 2 s of sim time);
  ``steps_per_s_talos`` the same with talos_reduced.
- ``execute_rtf``: sim time / wall time of :meth:`World.execute` on a squat-and-rise (1.5 s down, 0.3 s
  pause, 1.5 s up), monitoring included (contacts, fall, tracking, slip), no bus;
  ``execute_rtf_service``: the same trajectory sent to a spawned ``sim`` service over zenoh (state
  published at 200 Hz of sim time; request/reply included).
- ``render_640_ms``, ``render_320_ms``: one head camera image (wide_left, RGB only) with pybullet's
  software renderer in the ball-fetching scene (median of ``--renders``); ``..._seg_depth_ms`` with
  depth and segmentation.

References (issue 3, measured on an idle machine): ~3500 steps/s for hrp2_like, ~2700 for talos;
~80 ms at 640x480 and ~20 ms at 320x240. Writes bench/out/sim.json.

``--subscriber`` runs only this instead (bench/out/sim_subscriber.json): ``sim/execute`` of a 12.3 s squat
over the bus with no subscriber and with an idle ``hrp/**`` subscriber, alternated ``--repeats`` times;
per run the wall time and the CPU time and runqueue wait of the sim's executing thread (Linux
schedstat), so a difference in wall time shows whether it is work or waiting for a core;
``--baseline DIR`` runs the sim of another source tree too (before/after a change, in one run).

Usage: scripts/bench sim [--repeats N] [--renders N] [--no-service] [--subscriber [--baseline DIR]]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "sim.json"
OUT_SUBSCRIBER = REPO / "bench" / "out" / "sim_subscriber.json"
REFERENCE = {"steps_per_s": 3500.0, "steps_per_s_talos": 2700.0, "render_640_ms": 80.0, "render_320_ms": 20.0}


def steps_per_s(model: str, repeats: int) -> float:
    from sim.world import World

    with World(model, "ball_fetch") as world:
        rates = []
        for _ in range(repeats):
            world.reset()
            started = time.perf_counter()
            world.hold(2.0)
            rates.append(2000.0 / (time.perf_counter() - started))
    return statistics.median(rates)


def squat(model: str, q_start, down_s: float = 1.5, pause_s: float = 0.3, up_s: float = 1.5):
    from services.model import load_robot
    from sim import motions

    return motions.squat_trajectory(
        load_robot(model), q_start, depth_m=0.06, down_s=down_s, pause_s=pause_s, up_s=up_s
    )


def execute_rtf() -> tuple[float, dict[str, float]]:
    from sim.world import World

    with World("hrp2_like", "ball_fetch") as world:
        traj = squat("hrp2_like", world.state().q)
        started = time.perf_counter()
        result = world.execute(traj)
        wall = time.perf_counter() - started
    quality = {
        "outcome": result.outcome,
        "base_error_m": result.base_error_m,
        "tracking_error_rad": result.tracking_error_rad,
        "foot_slip_m": result.foot_slip_m,
    }
    return result.duration_s / wall, quality


@contextlib.contextmanager
def spawned_sim(src: Path = REPO) -> Iterator[tuple[Any, Any, Any, subprocess.Popen]]:
    """A hub session here and a ``sim`` service (ball_fetch) run from the source tree ``src``:
    yields ``(client, session, bus, process)``."""
    from services.bus.config import BusConfig
    from services.bus.session import Client, close_session, open_session

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    bus = BusConfig(robot=f"simbench{os.getpid()}").with_hub_port(port)
    session = open_session(bus, as_hub=True)
    args = ["--hub", bus.hub, "--robot", bus.robot, "--scene", "ball_fetch", "--log-level", "WARNING"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sim.service", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        cwd=src,
        env={**os.environ, "PYTHONPATH": str(src)},
    )
    try:
        client = Client(session, bus.robot, default_timeout_s=300.0)
        client.wait_for(["sim"], timeout_s=60.0)
        yield client, session, bus, proc
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
        close_session(session)


def execute_rtf_service() -> float:
    from services.bus.schemas import sim as msg

    with spawned_sim() as (client, _, _, _):
        traj = squat("hrp2_like", client.call(msg.STATE, msg.StateRequest()).q)
        started = time.perf_counter()
        reply = client.call(msg.EXECUTE, msg.ExecuteRequest(q=traj))
        wall = time.perf_counter() - started
        if reply.outcome != "completed":
            raise RuntimeError(f"benchmark squat did not complete over the bus: {reply.message}")
        return reply.duration_s / wall


def thread_times(pid: int) -> dict[str, tuple[float, float]]:
    """``{tid: (cpu s, runqueue wait s)}`` of each thread of process ``pid`` (Linux schedstat)."""
    out = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(FileNotFoundError):
            run_ns, wait_ns, _ = (int(x) for x in (task / "schedstat").read_text().split())
            out[task.name] = (run_ns / 1e9, wait_ns / 1e9)
    return out


_SUB_NAMES = {False: "none", True: "idle hrp/**"}


def subscriber_ab(sources: dict[str, Path], repeats: int) -> list[dict[str, Any]]:
    """``sim/execute`` of a 12.3 s squat (5 s down, 2.3 s pause, 5 s up) with no subscriber on the bus
    and with an idle ``hrp/**`` subscriber in the calling process, alternated ``repeats`` times for
    each source tree; per run: wall time, and the CPU time and runqueue wait of the sim's busiest
    thread (the one executing)."""
    from services.bus.schemas import sim as msg

    runs: list[dict[str, Any]] = []
    for _ in range(repeats):
        for label, src in sources.items():
            with spawned_sim(src) as (client, session, bus, proc):
                q0 = client.call(msg.STATE, msg.StateRequest()).q
                traj = squat("hrp2_like", q0, down_s=5.0, pause_s=2.3, up_s=5.0)
                for subscriber in (False, True):
                    client.call(msg.RESET, msg.ResetRequest())
                    everything = f"hrp/{bus.robot}/**"
                    sub = session.declare_subscriber(everything, lambda _: None) if subscriber else None
                    time.sleep(0.5)  # let the subscription reach the sim
                    before = thread_times(proc.pid)
                    started = time.perf_counter()
                    reply = client.call(msg.EXECUTE, msg.ExecuteRequest(q=traj))
                    wall = time.perf_counter() - started
                    after = thread_times(proc.pid)
                    if sub is not None:
                        sub.undeclare()
                    if reply.outcome != "completed":
                        raise RuntimeError(f"benchmark squat did not complete: {reply.message}")
                    cpu, wait = max(
                        (after[t][0] - before[t][0], after[t][1] - before[t][1]) for t in after if t in before
                    )
                    runs.append(
                        {
                            "source": label,
                            "subscriber": subscriber,
                            "sim_s": reply.duration_s,
                            "wall_s": wall,
                            "cpu_s": cpu,
                            "runqueue_wait_s": wait,
                            "load_average_1min": os.getloadavg()[0],
                        }
                    )
                    print(
                        f"{label:8} {_SUB_NAMES[subscriber]:12} wall {wall:6.2f} s  cpu {cpu:5.2f} s  "
                        f"runqueue wait {wait:6.2f} s  sim/wall {reply.duration_s / wall:4.2f}  "
                        f"sim/cpu {reply.duration_s / cpu:4.2f}  (load {os.getloadavg()[0]:.1f})",
                        flush=True,
                    )
    return runs


def subscriber_main(baseline: Path | None, repeats: int) -> int:
    sources = {"this": REPO} if baseline is None else {"baseline": baseline, "this": REPO}
    runs = subscriber_ab(sources, repeats)
    header = f"{'source':8} {'subscriber':12} {'wall [s]':>9} {'cpu [s]':>8} {'wait [s]':>9} {'sim/cpu':>8}"
    print(f"\n{header}  (medians)")
    summary = []
    for label in sources:
        for subscriber in (False, True):
            rs = [r for r in runs if r["source"] == label and r["subscriber"] == subscriber]
            row = {
                "source": label,
                "subscriber": subscriber,
                **{k: statistics.median(r[k] for r in rs) for k in ("wall_s", "cpu_s", "runqueue_wait_s")},
            }
            row["sim_per_cpu"] = rs[0]["sim_s"] / row["cpu_s"]
            summary.append(row)
            print(
                f"{label:8} {_SUB_NAMES[subscriber]:12} {row['wall_s']:9.2f} {row['cpu_s']:8.2f} "
                f"{row['runqueue_wait_s']:9.2f} {row['sim_per_cpu']:8.2f}"
            )
    result = {
        "trajectory_sim_s": runs[0]["sim_s"],
        "sources": {k: str(v) for k, v in sources.items()},
        "summary": summary,
        "runs": runs,
        "machine": {"cpus": os.cpu_count(), "load_average_1min": os.getloadavg()[0]},
    }
    OUT_SUBSCRIBER.parent.mkdir(parents=True, exist_ok=True)
    OUT_SUBSCRIBER.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {OUT_SUBSCRIBER.relative_to(REPO)}")
    return 0


def render_ms(renders: int) -> dict[str, float]:
    from sim.world import World

    out = {}
    with World("hrp2_like", "ball_fetch") as world:
        for width, height in ((640, 480), (320, 240)):
            for extra, kwargs in (("", {}), ("_seg_depth", {"depth": True, "segmentation": True})):
                world.render("wide_left", width, height, **kwargs)  # warm-up
                times = []
                for _ in range(renders):
                    started = time.perf_counter()
                    world.render("wide_left", width, height, **kwargs)
                    times.append(1000.0 * (time.perf_counter() - started))
                out[f"render_{width}{extra}_ms"] = statistics.median(times)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench sim", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="runs of 2 s of sim time per steps/s figure (with --subscriber: alternations)",
    )
    parser.add_argument("--renders", type=int, default=10, help="images per render figure")
    parser.add_argument("--no-service", action="store_true", help="skip the execution over the bus")
    parser.add_argument(
        "--subscriber",
        action="store_true",
        help="only the execution over the bus with and without an idle subscriber (sim_subscriber.json)",
    )
    parser.add_argument(
        "--baseline", type=Path, help="with --subscriber: also run the sim from this source tree, alternated"
    )
    args = parser.parse_args(argv)
    sys.path.insert(0, str(REPO))
    if args.subscriber:
        return subscriber_main(args.baseline, args.repeats)

    results: dict[str, object] = {}
    results["steps_per_s"] = steps_per_s("hrp2_like", args.repeats)
    results["steps_per_s_talos"] = steps_per_s("talos", args.repeats)
    rtf, quality = execute_rtf()
    results["execute_rtf"] = rtf
    results["execute_squat"] = quality
    if not args.no_service:
        results["execute_rtf_service"] = execute_rtf_service()
    results.update(render_ms(args.renders))
    results["machine"] = {
        "python": platform.python_version(),
        "cpus": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
    }

    rows = [
        ("steps_per_s", "physics steps/s, hrp2_like + ball_fetch", "{:.0f}"),
        ("steps_per_s_talos", "physics steps/s, talos + ball_fetch", "{:.0f}"),
        ("execute_rtf", "sim/wall time executing a squat (World)", "{:.2f}"),
        ("execute_rtf_service", "same over zenoh (sim service)", "{:.2f}"),
        ("render_640_ms", "one 640x480 camera image [ms]", "{:.1f}"),
        ("render_320_ms", "one 320x240 camera image [ms]", "{:.1f}"),
        ("render_640_seg_depth_ms", "640x480 + depth + segmentation [ms]", "{:.1f}"),
        ("render_320_seg_depth_ms", "320x240 + depth + segmentation [ms]", "{:.1f}"),
    ]
    print(f"{'figure':26} {'value':>9} {'reference':>10}  description")
    for key, label, fmt in rows:
        if key not in results:
            continue
        ref = REFERENCE.get(key)
        print(f"{key:26} {fmt.format(results[key]):>9} {('' if ref is None else f'{ref:g}'):>10}  {label}")
    q = quality
    print(
        f"squat: {q['outcome']}, base error {1000 * q['base_error_m']:.2f} mm, joint error "
        f"{q['tracking_error_rad']:.4f} rad, foot slip {1000 * q['foot_slip_m']:.3f} mm "
        f"(load average {results['machine']['load_average_1min']:.1f} on {os.cpu_count()} CPUs)"
    )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {OUT.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
