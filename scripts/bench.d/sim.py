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

Usage: scripts/bench sim [--repeats N] [--renders N] [--no-service] [--help]
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
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "sim.json"
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


def squat(model: str, q_start):
    from services.model import load_robot
    from sim import motions

    return motions.squat_trajectory(
        load_robot(model), q_start, depth_m=0.06, down_s=1.5, pause_s=0.3, up_s=1.5
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


def execute_rtf_service() -> float:
    from services.bus.config import BusConfig
    from services.bus.schemas import sim as msg
    from services.bus.session import Client, close_session, open_session

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    bus = BusConfig(robot=f"simbench{os.getpid()}").with_hub_port(port)
    session = open_session(bus, as_hub=True)
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "sim.service",
            "--hub",
            bus.hub,
            "--robot",
            bus.robot,
            "--scene",
            "ball_fetch",
            "--log-level",
            "WARNING",
        ],
        stdout=subprocess.DEVNULL,
        cwd=REPO,
    )
    try:
        client = Client(session, bus.robot, default_timeout_s=120.0)
        client.wait_for(["sim"], timeout_s=60.0)
        traj = squat("hrp2_like", client.call(msg.STATE, msg.StateRequest()).q)
        started = time.perf_counter()
        reply = client.call(msg.EXECUTE, msg.ExecuteRequest(q=traj))
        wall = time.perf_counter() - started
        if reply.outcome != "completed":
            raise RuntimeError(f"benchmark squat did not complete over the bus: {reply.message}")
        return reply.duration_s / wall
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
        close_session(session)


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
    parser.add_argument("--repeats", type=int, default=3, help="runs of 2 s of sim time per steps/s figure")
    parser.add_argument("--renders", type=int, default=10, help="images per render figure")
    parser.add_argument("--no-service", action="store_true", help="skip the execution over the bus")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(REPO))

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
