"""Ball-fetch benchmark: the whole fetch script over seeded random layouts of the demo scene.

Starts every service once (the launcher of ``humanoid up``, on a private hub port), then for each seed
``0..n-1`` resets the sim to ``ball_fetch`` with that seed (random box, ball, table and chair
placement within the scene file's ranges) and runs ``supervisor/scripts/fetch.txt``.

A run succeeds when the script succeeds **and** the sim's ground truth (benchmarks may read it; the
supervisor never does) has the orange ball resting on the yellow table: not held, its centre within the
table top's rectangle and 0 to 6 cm above the top plus its radius.

Writes ``bench/out/fetch.json`` (``--out``; rewritten after every layout, ``"partial": true`` until the
last): ``n``, ``success_rate``, ``median_wall_s``, ``median_sim_s`` (over all runs), ``retries`` (total),
``real_time_factor`` (median sim / wall), ``median_think_s`` (median wall time from an action attempt's
start to its first ``sim/execute`` chunk, over every attempt that moved the robot: how long the robot
stands still thinking), ``footsteps_plan_calls`` (median calls to ``footsteps/plan`` per fetch, counted
in the recorded log: the recorder of the stack writes every ``footsteps/**`` message to an MCAP file,
``--record``, and each fetch's ``footsteps/plan`` requests are those logged between its start and end),
the load average before and after, and per run: seed, ok, script_ok, on_table, wall_s, sim_s, retries,
think_s (median), footsteps_plan_calls, failure.
Goals (issues 10, 15): success >= 95 %, wall time <= sim time, median think <= 1 s, >= 2 footstep
plans per fetch.

Usage: scripts/bench fetch [--n N] [--seed0 S] [--log-dir DIR] [--out FILE] [--record FILE]
       scripts/bench fetch --count-log FILE.mcap --out FILE   (recount a cut-off run's calls)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import statistics
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "fetch.json"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class CallWatch:
    """Per fetch: the wall time from each action attempt's start (the runner's ``started`` event) to
    its first ``sim/execute`` request (the supervisor's bus hook)."""

    def __init__(self, sup: Any) -> None:  # supervisor.core.Supervisor
        self.think_s: list[float] = []
        self._started: float | None = None
        self._forward = sup.runner.on_event
        sup.runner.on_event = self._on_event
        sup.bus.on_call = self._on_call

    def reset(self) -> None:
        self.think_s, self._started = [], None

    def _on_event(self, event: Any) -> None:  # supervisor.runner.Event
        self._forward(event)
        if event.kind == "started":
            self._started = time.monotonic()

    def _on_call(self, spec: Any) -> None:  # services.bus.spec.EndpointSpec
        if spec.path == "sim/execute" and self._started is not None:
            self.think_s.append(time.monotonic() - self._started)
            self._started = None


def summarize(runs: list[dict[str, Any]], load_before: tuple[float, ...], partial: bool) -> dict[str, Any]:
    """The benchmark's JSON: figures over ``runs``, the goals, the machine."""
    n = len(runs)
    calls = [r["footsteps_plan_calls"] for r in runs if r["footsteps_plan_calls"] is not None]
    return {
        "n": n,
        "seeds": [runs[0]["seed"], runs[-1]["seed"]] if runs else [],
        "partial": partial,
        "success_rate": sum(r["ok"] for r in runs) / max(n, 1),
        "median_wall_s": statistics.median(r["wall_s"] for r in runs) if runs else None,
        "median_sim_s": statistics.median(r["sim_s"] for r in runs) if runs else None,
        "retries": sum(r["retries"] for r in runs),
        "real_time_factor": statistics.median(r["sim_s"] / max(r["wall_s"], 1e-9) for r in runs)
        if runs
        else None,
        "median_think_s": statistics.median(t for r in runs for t in r["think_samples_s"])
        if any(r["think_samples_s"] for r in runs)
        else None,
        "footsteps_plan_calls": statistics.median(calls) if calls else None,
        "footsteps_plan_calls_min": min(calls) if calls else None,
        "goals": {
            "success_rate": 0.95,
            "real_time_factor": 1.0,
            "median_think_s": 1.0,
            "footsteps_plan_calls": 2,
        },
        "runs": runs,
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "load_avg_before": load_before,
            "load_avg": os.getloadavg(),
        },
        "when": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }


def _write(out: Path, result: dict[str, Any]) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")


def _recount(log: str, out: Path) -> int:
    """``--count-log``: fill a (cut-off) run's ``footsteps_plan_calls`` from its log."""
    result = json.loads(out.read_text())
    runs = result["runs"]
    from services.bus.schemas import footsteps as fs_msg
    from supervisor.evaluate import requests_in_log

    counts = requests_in_log(log, fs_msg.PLAN, [(r["start_ns"], r["end_ns"]) for r in runs])
    for run, count in zip(runs, counts, strict=True):
        run["footsteps_plan_calls"] = count
    calls = [r["footsteps_plan_calls"] for r in runs]
    result["footsteps_plan_calls"] = statistics.median(calls) if calls else None
    result["footsteps_plan_calls_min"] = min(calls) if calls else None
    _write(out, result)
    print(f"footsteps/plan calls per fetch from {log}: {counts}; wrote {out}")
    return 0


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench fetch", description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=20, help="number of seeded layouts (20)")
    parser.add_argument("--seed0", type=int, default=0, help="first seed (0)")
    parser.add_argument("--log-dir", default="bench/out/fetch-logs", help="services' output")
    parser.add_argument("--out", default=str(OUT), help="JSON output file")
    parser.add_argument(
        "--record", help="MCAP log of the footstep planner's messages (default: beside --out, .mcap)"
    )
    parser.add_argument("--count-log", metavar="MCAP", help="only recount the calls of --out from this log")
    args = parser.parse_args(argv)
    out = Path(args.out)
    if args.count_log:
        return _recount(args.count_log, out)
    record = args.record or str(out.with_suffix(".mcap"))

    from services.bus.config import BusConfig
    from services.bus.schemas import footsteps as fs_msg
    from services.bus.schemas import sim as sim_msg
    from supervisor.core import Supervisor
    from supervisor.evaluate import ball_on_table, record_config, requests_in_log
    from supervisor.fetch import fetch, running_stack

    bus = BusConfig().with_hub_port(_free_port())
    load_before = os.getloadavg()
    runs: list[dict[str, Any]] = []
    Path(args.log_dir).mkdir(parents=True, exist_ok=True)
    config_path = record_config(Path(args.log_dir) / "record.yaml")
    with (
        running_stack(bus, log_dir=args.log_dir, record=record, config_path=config_path),
        Supervisor.connect(bus) as sup,
    ):
        missing = sup.wait_for_services(30.0)
        if missing:
            print(f"services missing: {', '.join(missing)}", file=sys.stderr)
        watch = CallWatch(sup)
        for seed in range(args.seed0, args.seed0 + args.n):
            watch.reset()
            start_ns = time.time_ns()
            summary, _report = fetch(sup, seed=seed)
            end_ns = time.time_ns()
            gt = sup.bus.call(sim_msg.GROUND_TRUTH, sim_msg.GroundTruthRequest(), 10.0)
            on_table, why = ball_on_table(gt)
            run = {
                "seed": seed,
                "ok": summary.ok and on_table,
                "script_ok": summary.ok,
                "on_table": on_table,
                "wall_s": round(summary.wall_s, 2),
                "sim_s": round(summary.sim_s, 2),
                "retries": summary.retries,
                "think_s": round(statistics.median(watch.think_s), 2) if watch.think_s else None,
                "think_samples_s": [round(t, 2) for t in watch.think_s],
                "footsteps_plan_calls": None,  # from the log, once the recorder has closed it
                "failure": summary.failure or why,
                "start_ns": start_ns,
                "end_ns": end_ns,
                "load_avg": [round(v, 2) for v in os.getloadavg()],
            }
            runs.append(run)
            _write(out, summarize(runs, load_before, partial=True))
            print(
                f"seed {seed:3d}  {'ok  ' if run['ok'] else 'FAIL'}  wall {run['wall_s']:6.1f} s  "
                f"sim {run['sim_s']:6.1f} s  retries {run['retries']}  think {run['think_s']} s  "
                f"load {run['load_avg'][0]:.1f}  {run['failure']}",
                flush=True,
            )
    counts = requests_in_log(record, fs_msg.PLAN, [(r["start_ns"], r["end_ns"]) for r in runs])
    for run, count in zip(runs, counts, strict=True):
        run["footsteps_plan_calls"] = count
    result = summarize(runs, load_before, partial=False)
    n = len(runs)
    print(f"footsteps/plan calls per fetch (from {record}): {counts}")
    print()
    print(
        f"{'n':>4} {'success':>8} {'median wall [s]':>16} {'median sim [s]':>15} "
        f"{'retries':>8} {'sim/wall':>9} {'think [s]':>10} {'footsteps/plan':>15}"
    )
    print(
        f"{n:>4} {result['success_rate']:>8.0%} {result['median_wall_s']:>16.1f} "
        f"{result['median_sim_s']:>15.1f} "
        f"{result['retries']:>8} {result['real_time_factor']:>9.2f} "
        f"{result['median_think_s'] or 0.0:>10.2f} {result['footsteps_plan_calls'] or 0:>15}"
    )
    _write(out, result)
    print(f"wrote {out}")
    return 0
