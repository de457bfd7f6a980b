"""Benchmark of footstep planning as inverse kinematics (services/footsteps).

The paper's three scenarios (section 4) beside the paper's solve times (HRP-2 model, 2.13 GHz Core 2:
3.2 s for the 9-step reach, 0.9 s for the pick-up, 0.3 s for the 4-step posture recovery), and seeded
random layouts (``services.footsteps.scenarios.random_layout``: a target 1-3 m away in any direction
at 0.1-1.2 m height, 0-2 disk obstacles). Both start feet are solved (section 5.2) in every timing.

Writes ``bench/out/footsteps.json``::

    {"scenarios": [{name, solve_s, cpu_s, steps, paper_s, paper_steps, solved}, ...],
     "random": {n, success_rate, median_s, median_cpu_s, p90_s, max_s, failures: [...]}, ...}

``solve_s`` is the best wall time of ``--repeat`` runs (the machine is shared), ``cpu_s`` the process
CPU time of that run, ``first_s`` the wall time of the first run: the planner keeps its chain models
and solvers (with their pinocchio data) per chain structure, so the first request of a structure
also pays for building them (the random layouts share one stance: after the first ones they reuse
them, as a running service does).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from services.errors import InfeasibleError  # noqa: E402
from services.footsteps import scenarios  # noqa: E402
from services.footsteps.planner import plan_footsteps  # noqa: E402
from services.model import load_robot  # noqa: E402

GOAL_SPEEDUP = 10.0
GOAL_SUCCESS = 0.95


def _timed(request, robot):
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    try:
        result = plan_footsteps(request, robot)
        error = None
    except InfeasibleError as exc:
        result, error = None, exc
    return result, error, time.perf_counter() - t_wall, time.process_time() - t_cpu


def bench_scenarios(robot, repeat: int) -> list[dict]:
    rows = []
    for name in ("reach", "pickup", "posture"):
        scenario = scenarios.SCENARIOS[name](robot.name)
        runs = [_timed(scenario.request, robot) for _ in range(repeat)]
        result, error, wall, cpu = min(runs, key=lambda r: r[2])
        rows.append(
            {
                "name": name,
                "solved": error is None,
                "solve_s": wall,
                "cpu_s": cpu,
                "first_s": runs[0][2],
                "steps": None if result is None else result.n_steps,
                "iterations": None if result is None else result.iterations,
                "paper_s": scenario.paper_solve_s,
                "paper_steps": scenario.paper_steps,
                "speedup_vs_paper": scenario.paper_solve_s / wall,
                "error": None if error is None else error.message,
            }
        )
    return rows


def bench_random(robot, n: int, seed0: int) -> dict:
    walls, cpus, steps, failures = [], [], [], []
    for seed in range(seed0, seed0 + n):
        request = scenarios.random_layout(seed, robot.name)
        result, error, wall, cpu = _timed(request, robot)
        walls.append(wall)
        cpus.append(cpu)
        if error is None:
            steps.append(result.n_steps)
        else:
            failures.append({"seed": seed, "reason": error.details.get("reason"), "message": error.message})
    ordered = sorted(walls)
    return {
        "n": n,
        "seed0": seed0,
        "success_rate": (n - len(failures)) / n,
        "median_s": statistics.median(walls),
        "median_cpu_s": statistics.median(cpus),
        "p90_s": ordered[min(n - 1, int(0.9 * n))],
        "max_s": ordered[-1],
        "median_steps": statistics.median(steps) if steps else None,
        "failures": failures,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="scripts/bench footsteps",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--n", type=int, default=100, help="random layouts (default 100)")
    parser.add_argument("--seed0", type=int, default=0, help="first seed of the random layouts")
    parser.add_argument("--repeat", type=int, default=3, help="runs per scenario, best wall time kept")
    parser.add_argument("--robot", default="hrp2_like")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "footsteps.json")
    args = parser.parse_args(argv)
    robot = load_robot(args.robot)
    plan_footsteps(scenarios.posture(robot.name).request, robot)  # warm caches (imports, awkward start)

    rows = bench_scenarios(robot, max(1, args.repeat))
    print(
        f"{'scenario':10s} {'solved':>6s} {'steps':>5s} {'paper':>5s} {'wall s':>8s} {'cpu s':>8s} "
        f"{'first s':>8s} {'paper s':>8s} {'speedup':>8s}"
    )
    for r in rows:
        print(
            f"{r['name']:10s} {r['solved']!s:>6s} {r['steps']!s:>5s} {r['paper_steps'] or '-'!s:>5s} "
            f"{r['solve_s']:8.3f} {r['cpu_s']:8.3f} {r['first_s']:8.3f} {r['paper_s']:8.2f} "
            f"{r['speedup_vs_paper']:7.1f}x"
        )
    rand = bench_random(robot, args.n, args.seed0)
    print(
        f"random layouts: {rand['n']}, success {100 * rand['success_rate']:.1f} %, "
        f"median {rand['median_s']:.3f} s "
        f"wall ({rand['median_cpu_s']:.3f} s CPU), p90 {rand['p90_s']:.3f} s, max {rand['max_s']:.3f} s, "
        f"median steps {rand['median_steps']}"
    )
    for f in rand["failures"]:
        print(f"  seed {f['seed']}: {f['message']}")
    goals = {
        "speedup_10x": all(r["solved"] and r["speedup_vs_paper"] >= GOAL_SPEEDUP for r in rows),
        "success_95": rand["success_rate"] >= GOAL_SUCCESS,
    }
    print(
        f"goals: 10x faster than the paper on every scenario: {goals['speedup_10x']}; "
        f">= 95 % random success: {goals['success_95']}"
    )
    out = {
        "robot": robot.name,
        "machine": {
            "python": platform.python_version(),
            "processor": platform.processor() or platform.machine(),
        },
        "scenarios": rows,
        "random": rand,
        "goals": goals,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
