"""Ball-fetch benchmark: the whole fetch script over seeded random layouts of the demo scene.

Starts every service once (the launcher of ``humanoid up``, on a private hub port), then for each seed
``0..n-1`` resets the sim to ``ball_fetch`` with that seed (random box, ball, table and chair
placement within the scene file's ranges) and runs ``supervisor/scripts/fetch.txt``.

A run succeeds when the script succeeds **and** the sim's ground truth (benchmarks may read it; the
supervisor never does) has the orange ball resting on the yellow table: not held, its centre within the
table top's rectangle and 0 to 6 cm above the top plus its radius.

Writes ``bench/out/fetch.json``: ``n``, ``success_rate``, ``median_wall_s``, ``median_sim_s`` (over all
runs), ``retries`` (total), ``real_time_factor`` (median sim / wall), and per run: seed, ok, script_ok,
on_table, wall_s, sim_s, retries, failure. Goals (issue 10): success >= 95 %, wall time <= sim time.

Usage: scripts/bench fetch [--n N] [--seed0 S] [--log-dir DIR]
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

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "fetch.json"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench fetch", description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=20, help="number of seeded layouts (20)")
    parser.add_argument("--seed0", type=int, default=0, help="first seed (0)")
    parser.add_argument("--log-dir", default="bench/out/fetch-logs", help="services' output")
    parser.add_argument("--out", default=str(OUT), help="JSON output file")
    args = parser.parse_args(argv)

    from services.bus.config import BusConfig
    from services.bus.schemas import sim as sim_msg
    from supervisor.core import Supervisor
    from supervisor.evaluate import ball_on_table
    from supervisor.fetch import fetch, running_stack

    bus = BusConfig().with_hub_port(_free_port())
    runs = []
    with running_stack(bus, log_dir=args.log_dir), Supervisor.connect(bus) as sup:
        missing = sup.wait_for_services(30.0)
        if missing:
            print(f"services missing: {', '.join(missing)}", file=sys.stderr)
        for seed in range(args.seed0, args.seed0 + args.n):
            summary, _report = fetch(sup, seed=seed)
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
                "failure": summary.failure or why,
            }
            runs.append(run)
            print(
                f"seed {seed:3d}  {'ok  ' if run['ok'] else 'FAIL'}  wall {run['wall_s']:6.1f} s  "
                f"sim {run['sim_s']:6.1f} s  retries {run['retries']}  {run['failure']}",
                flush=True,
            )
    n = len(runs)
    result = {
        "n": n,
        "success_rate": sum(r["ok"] for r in runs) / max(n, 1),
        "median_wall_s": statistics.median(r["wall_s"] for r in runs) if runs else None,
        "median_sim_s": statistics.median(r["sim_s"] for r in runs) if runs else None,
        "retries": sum(r["retries"] for r in runs),
        "real_time_factor": statistics.median(r["sim_s"] / max(r["wall_s"], 1e-9) for r in runs)
        if runs
        else None,
        "goals": {"success_rate": 0.95, "real_time_factor": 1.0},
        "runs": runs,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "load_avg": os.getloadavg()},
        "when": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }
    print()
    print(
        f"{'n':>4} {'success':>8} {'median wall [s]':>16} {'median sim [s]':>15} "
        f"{'retries':>8} {'sim/wall':>9}"
    )
    print(
        f"{n:>4} {result['success_rate']:>8.0%} {result['median_wall_s']:>16.1f} "
        f"{result['median_sim_s']:>15.1f} "
        f"{result['retries']:>8} {result['real_time_factor']:>9.2f}"
    )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out}")
    return 0
