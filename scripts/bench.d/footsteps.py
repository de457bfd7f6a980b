"""Benchmark of footstep planning as inverse kinematics (services/footsteps).

The paper's three scenarios (section 4) beside the paper's solve times (HRP-2 model, 2.13 GHz Core 2:
3.2 s for the 9-step reach, 0.9 s for the pick-up, 0.3 s for the 4-step posture recovery), and seeded
random layouts (``services.footsteps.scenarios.random_layout``: a target 1-3 m away in any direction
at 0.1-1.2 m height, 0-2 disk obstacles). Both start feet are solved (section 5.2) in every timing.

The scenarios run with the paper's task sets (section 4: the reach alone with its disks; gaze >
posture) and ``scenarios.PAPER_OPTIONS``; ``paper_tasks`` lists them beside the paper's steps and
times and beside the stack's variant (``posture_objective``: the rest posture as lowest objective, the
stack's default numerics). ``executed`` plays the reach and the pick-up (paper task sets and
settings, the CoM kept 3 cm inside the support polygon; both start at half-sitting, as the sim
does) in the sim: the footsteps walked with ``services.walking.two_stage.executable_walk`` (the CoM
lowered, then slower supports, until every joint stays within its speed limit), then the final reach
(outcome, fall, foot slip, hand error, the hands' lowest collision-box corner above the floor, planned
and executed); ``pickup_no_hand_floor`` is the pick-up with the hands-above-floor constraint off (the
gripper planned into the floor: the execution stops on that contact).
``epsilon_study`` is Fig. 10's threshold study (reach > gaze > posture,
every epsilon_i x0.1 / x1 / x5: steps, step additions, time). ``numerics`` runs the three paper
scenarios with each of Algorithm 1's numerics that differ from eqs. 2/15 switched to the paper's
form one at a time (saturated task rates off, the 0.25 per-coordinate cap on, LM damping off,
epsilon as written, no polish iterations), and all of them at once: which results depend on which.

Writes ``bench/out/footsteps.json``::

    {"scenarios": [{name, solve_s, cpu_s, steps, paper_s, paper_steps, solved}, ...],
     "paper_tasks": [...], "executed": [...], "epsilon_study": [...], "numerics": {variant: [...]},
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
import math
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from dataclasses import replace  # noqa: E402

from services.errors import InfeasibleError, RequestTimeoutError  # noqa: E402
from services.footsteps import scenarios  # noqa: E402
from services.footsteps.demo import run_epsilon_study  # noqa: E402
from services.footsteps.planner import plan_footsteps  # noqa: E402
from services.model import load_robot  # noqa: E402

GOAL_SPEEDUP = 10.0
GOAL_SUCCESS = 0.95


def _timed(request, robot):
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    try:
        result = plan_footsteps(request, robot)
        error = None
    except (InfeasibleError, RequestTimeoutError) as exc:
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


# Algorithm 1's numerics that differ from eqs. 2/15, each switched to the paper's form (README).
NUMERICS = {
    "as_run": {},
    "no_rate_saturation": {"max_rate_m": math.inf, "max_rate_rad": math.inf},
    "coordinate_cap_0.25": {"dq_max": 0.25},
    "no_lm_damping": {"damping": 0.0, "error_damping": 0.0},
    "epsilon_as_written": {"relative_epsilon": math.inf},
    "no_polish": {"polish_iterations": 0},
    "all_as_written": {
        "max_rate_m": math.inf,
        "max_rate_rad": math.inf,
        "damping": 0.0,
        "error_damping": 0.0,
        "relative_epsilon": math.inf,
        "polish_iterations": 0,
    },
}


def _row(name: str, scenario, result, error, wall: float, cpu: float) -> dict:
    return {
        "name": name,
        "solved": error is None,
        "steps": None if result is None else result.n_steps,
        "iterations": None if result is None else result.iterations,
        "solve_s": wall,
        "cpu_s": cpu,
        "paper_s": scenario.paper_solve_s,
        "paper_steps": scenario.paper_steps,
        "error": None if error is None else error.message,
    }


def bench_paper_tasks(robot) -> list[dict]:
    """The three scenarios with the paper's task sets beside the stack's posture-objective variant."""
    rows = []
    for name in ("reach", "pickup", "posture"):
        factory = scenarios.SCENARIOS[name]
        variants = [("paper", factory(robot.name))]
        if name != "posture":
            variants.append(("posture_objective", factory(robot.name, posture_objective=True)))
        for task_set, scenario in variants:
            result, error, wall, cpu = _timed(scenario.request, robot)
            row = _row(name, scenario, result, error, wall, cpu)
            row["task_set"] = task_set
            row["tasks"] = [t.name for t in scenario.request.tasks]
            rows.append(row)
    return rows


def bench_executed(robot, names: tuple[str, ...] = ("reach", "pickup", "pickup_no_hand_floor")) -> list[dict]:
    """The reach and the pick-up with the paper's task sets executed (the posture scenario starts from
    a configuration the sim does not start in): the footsteps walked
    (``services.walking.two_stage.executable_walk``: the CoM height and timing derived so that the
    joints stay within their speed limits), then the final reach, played open loop in the sim.
    ``pickup_no_hand_floor``: the pick-up with the hands-above-the-floor constraint off (planner and
    reach), the A/B of ``PlannerOptions.hand_floor``."""
    import numpy as np
    import pinocchio as pin

    from services.footsteps.execution import execute_plan
    from services.footsteps.hand_floor import hand_floor_task
    from sim.world import World

    floor = hand_floor_task(robot, robot.model, 0.0)
    rows = []
    for name in names:
        base = name.removesuffix("_no_hand_floor")
        scenario = scenarios.SCENARIOS[base](robot.name)
        request = scenario.request  # the paper's task set and settings (CoM margin d of eq. 11: 3 cm)
        if name != base:
            request = replace(request, options=replace(request.options, hand_floor=False))
        result = plan_footsteps(request, robot)
        data = robot.new_data()
        pin.framesForwardKinematics(robot.model, data, np.asarray(result.q_final))
        row: dict = {
            "name": name,
            "steps": len(result.footsteps),
            "com_margin_m": request.options.com_margin_m,
            "hand_floor": request.options.hand_floor,
            "planned_min_hand_floor_m": float(floor.heights(data).min()),
        }
        try:
            motion = execute_plan(robot, request, result)
        except InfeasibleError as exc:
            rows.append({**row, "executable": False, "message": exc.message})
            continue
        speed = np.abs(np.diff(motion.q[:, 7:], axis=0)) / motion.dt_s / robot.v_max[6:]
        adjustment = motion.walk_adjustment
        row.update(
            executable=True,
            com_lowering_m=None if adjustment is None else adjustment.com_lowering_m,
            slowdown=None if adjustment is None else adjustment.slowdown,
            duration_s=motion.duration_s,
            max_joint_speed_ratio=float(speed.max()),
            reach_min_hand_floor_m=motion.reach_min_hand_floor_m,
        )
        with World(robot, "empty") as world:
            execution = world.execute(motion.q, motion.dt_s, hold_s=1.0)
            q = world.state().q
            errors = {}
            for task in request.tasks:
                if task.kind == "reach":
                    hand = robot.frame_pose(q, robot.frames.grasp(task.hand)).translation
                    errors[task.name] = float(np.linalg.norm(hand - np.asarray(task.target_m)))
            row.update(
                outcome=execution.outcome,
                message=execution.message,
                fallen=world.fallen(),
                foot_slip_m=execution.foot_slip_m,
                hand_error_m=errors,
            )
        rows.append(row)
    return rows


def bench_numerics(robot) -> dict:
    """The paper scenarios with each numerical device switched to eqs. 2/15's form."""
    out = {}
    for variant, overrides in NUMERICS.items():
        rows = []
        for name in ("reach", "pickup", "posture"):
            scenario = scenarios.SCENARIOS[name](robot.name)
            request = replace(scenario.request, options=replace(scenario.request.options, **overrides))
            result, error, wall, cpu = _timed(request, robot)
            rows.append(_row(name, scenario, result, error, wall, cpu))
        out[variant] = rows
    return out


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
    parser.add_argument("--no-sim", action="store_true", help="skip executing the scenarios in the sim")
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
    paper = bench_paper_tasks(robot)
    print("paper_tasks (section 4 task sets; posture_objective: the stack's variant)")
    for r in paper:
        print(
            f"  {r['name']:8s} {r['task_set']:17s} solved {r['solved']!s:5s} steps {r['steps']!s:>3s} "
            f"(paper {r['paper_steps'] or '0-few'!s}) {r['solve_s']:.3f} s (paper {r['paper_s']} s)"
        )
    study = run_epsilon_study(robot.name, out_dir=None)
    print("epsilon_study (Fig. 10: reach > gaze > posture)")
    for r in study:
        print(
            f"  {r['label']:8s} x{r['epsilon_scale']:<4g} steps {r['steps']} "
            f"added after {r['steps_added_at']} {r['solve_s']:.3f} s wall, {r['cpu_s']:.3f} s CPU"
        )
    executed = [] if args.no_sim else bench_executed(robot)
    print("executed in the sim (paper task sets; walk derived by executable_walk)")
    for r in executed:
        if not r["executable"]:
            print(f"  {r['name']:8s} {r['steps']} steps NOT EXECUTABLE: {r['message']}")
            continue
        print(
            f"  {r['name']:8s} {r['steps']} steps, CoM lowered {100 * (r['com_lowering_m'] or 0):.0f} cm, "
            f"supports x{r['slowdown'] or 1:g}, joints <= {100 * r['max_joint_speed_ratio']:.0f} % of their "
            f"limits, {r['duration_s']:.1f} s: {r['outcome']}, fallen {r['fallen']}, foot slip "
            f"{1e3 * r['foot_slip_m']:.1f} mm, lowest hand corner {1e3 * r['reach_min_hand_floor_m']:.0f} mm "
            f"(planned {1e3 * r['planned_min_hand_floor_m']:.0f} mm), hand "
            + ", ".join(f"{k} {1e3 * v:.1f} mm" for k, v in r["hand_error_m"].items())
            + ("" if r["outcome"] == "completed" else f" ({r['message']})")
        )
    numerics = bench_numerics(robot)
    print("numerics (paper scenarios; each device switched to eqs. 2/15's form)")
    for variant, rows_v in numerics.items():
        cells = ", ".join(
            f"{r['name']} {'ok' if r['solved'] else 'FAIL'} {r['steps']} steps {r['solve_s']:.2f} s"
            for r in rows_v
        )
        print(f"  {variant:20s} {cells}")
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
        "paper_tasks": paper,
        "executed": executed,
        "epsilon_study": study,
        "numerics": numerics,
        "random": rand,
        "goals": goals,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
