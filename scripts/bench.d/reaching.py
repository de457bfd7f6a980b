"""Reaching benchmark: whole-body reaching with task-driven support polygon reshaping, planned and
executed in the pybullet world.

Figures (issue 7), all from one run:
- ``plan_no_step_ms``: median planning time of targets within reach (no step), and the duration of
  those motions; ``plan_with_step_ms``: the same for targets just beyond reach (the planner steps);
  ``*_speedup``: motion duration / planning time (goal: >= 10);
- ``random``: ``n`` seeded random targets around the robot, 0.3-1.0 m beyond the arm's reach
  (horizontal distance from the reaching shoulder minus the arm length), heights 0.3-1.4 m, any
  direction; the reaching hand is the one on the target's side. Each is planned from the sim's state
  and executed in ``sim.world.World`` (scene ``empty``); a success is a completed execution, the robot
  standing and the hand within 1 cm of the target (goal: >= 95 %). Planning times are wall times on
  this shared machine (CPU times alongside).
- ``trigger``: over the random targets (executed with the defaults, which are the paper's experiment:
  its two criteria, S = I; TALOS adds ``joint_torque``), how many reshapings each criterion triggered
  (the first attempt's violation, on the initial support polygon: the paper's ``manipulability``
  (< 1.5e-4) and ``ee_error`` (> 4e-5 m), ``joint_torque``, and ``multibody_zmp``: a motion whose ZMP
  does not exist or leaves the polygon, discarded); ``single_step_share``: the share of the reshaped
  reaches done with one step (the paper's Fig. 6 makes one step);
- ``one_step``: ``n`` seeded targets in front of the reaching shoulder (within 0.6 rad), 0-0.15 m beyond
  the whole-body reach on the initial polygon (the reach envelope), planned (not executed) with the
  defaults: the targets of the paper's one step (Fig. 5); the same trigger counts,
  ``single_step_share`` of the reshaped ones, and the single steps tried and discarded (the planner
  then walks);
- ``just_beyond``: ``n`` other seeded targets only 0.05-0.3 m beyond the arm's length, in every
  direction, planned (not executed) with the defaults: the same figures (most are beside or behind
  the robot: the stance must turn, one step cannot);
- ``extension_joint_speed``: the random targets planned (not executed) with the extension criterion
  ``joint_speed`` (an arm joint beyond 50 % of its velocity limit) added: trigger counts, steps.

The envelopes of reach (measured once per hand, see ``services/reaching/envelope.py``) are computed
before the timings.

Usage: scripts/bench reaching [--robot hrp2_like|talos] [--n 50] [--seed 0] [--help]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: small dense problems

import argparse
import json
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
OUT = ROOT / "bench" / "out" / "reaching.json"

SUCCESS_HAND_ERROR_M = 0.01
HOLD_S = 1.0  # standing still after the motion, still monitored by the sim [s]
# Fixed targets for the timings, in the frame of the robot standing at the origin [m].
NO_STEP_TARGETS = {
    "hrp2_like": [(0.45, 0.30, 0.90), (0.40, 0.35, 0.50), (0.35, -0.30, 1.10), (0.55, 0.25, 0.80)],
    "talos": [(0.45, 0.30, 1.00), (0.40, 0.35, 0.60), (0.35, -0.30, 1.20), (0.55, 0.25, 0.90)],
}
STEP_TARGETS = {
    # (0.2, 0.75, 0.9) is within hrp2_like's whole-body reach with S = I (no step): (0.3, 0.85, 0.9) instead
    "hrp2_like": [(0.90, 0.30, 0.90), (0.30, 0.85, 0.90), (0.85, -0.30, 0.60), (0.60, 0.60, 1.10)],
    "talos": [(0.90, 0.30, 1.00), (0.20, 0.80, 1.00), (0.85, -0.30, 0.70), (0.60, 0.60, 1.20)],
}


def random_targets(
    robot, n: int, seed: int, beyond_m: tuple[float, float] = (0.3, 1.0)
) -> list[tuple[str, np.ndarray, float]]:
    """(hand, target [m], distance beyond the arm's reach [m], within ``beyond_m``) around the robot at
    the origin."""
    from services.reaching import SupportPolygonPlanner

    support = SupportPolygonPlanner(robot)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        bearing = rng.uniform(-math.pi, math.pi)
        height = rng.uniform(0.3, 1.4)
        beyond = rng.uniform(*beyond_m)
        hand = "left" if math.sin(bearing) >= 0 else "right"
        s = support.shoulder_in_mid[hand]
        u = np.array([math.cos(bearing), math.sin(bearing)])
        radius = support.arm_length_m[hand] + beyond
        su = float(s @ u)
        rho = su + math.sqrt(su * su - float(s @ s) + radius * radius)
        xy = rho * u
        out.append((hand, np.array([xy[0], xy[1], height]), beyond))
    return out


def one_step_targets(robot, n: int, seed: int, beyond_m: tuple[float, float] = (0.0, 0.15)):
    """(hand, target [m], distance beyond the reach envelope [m]) in front of the reaching shoulder
    (within 0.6 rad of straight ahead), heights 0.6-1.4 m, ``beyond_m`` beyond the whole-body reach on
    the initial support polygon (``services.reaching.envelope``, measured straight ahead): the targets
    the paper's one step (Fig. 5) is for; one step suffices for many of them, not all (a target
    outwards of the shoulder is harder to reach)."""
    from services.reaching.options import ReachingOptions
    from services.reaching.planner import planner_for

    planner = planner_for(robot.name, ReachingOptions())
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        hand = "left" if rng.uniform() < 0.5 else "right"
        bearing = rng.uniform(-0.6, 0.6)
        height = rng.uniform(0.6, 1.4)
        beyond = rng.uniform(*beyond_m)
        distance = planner.envelope(hand).at(height) + beyond
        sx, sy = planner.support.shoulder_in_mid[hand]
        target = np.array([sx + distance * math.cos(bearing), sy + distance * math.sin(bearing), height])
        out.append((hand, target, beyond))
    return out


def run_one(world, robot, hand: str, target: np.ndarray) -> dict:
    """Plan from the sim's state, execute, measure the hand."""
    from services.errors import HumanoidError
    from services.reaching import ReachRequest, plan_reach

    world.reset()
    q0 = world.state().q
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        result = plan_reach(robot, ReachRequest(hand, target, q0))
    except HumanoidError as exc:
        return {
            "outcome": exc.code,
            "message": exc.message,
            "planning_s": time.perf_counter() - t0,
            "trigger": (exc.details or {}).get("criterion"),
        }
    plan_s, plan_cpu_s = time.perf_counter() - t0, time.process_time() - c0
    ex = world.execute(result.q, hold_s=HOLD_S)
    q = world.state().q
    hand_error = float(np.linalg.norm(robot.frame_pose(q, robot.frames.grasp(hand)).translation - target))
    standing = ex.outcome == "completed" and not world.fallen()
    return {
        "outcome": "reached" if standing and hand_error <= SUCCESS_HAND_ERROR_M else ex.outcome,
        "message": ex.message,
        "steps": len(result.footsteps),
        "duration_s": result.duration_s,
        "planning_s": plan_s,
        "planning_cpu_s": plan_cpu_s,
        "speedup": result.duration_s / plan_s,
        "hand_error_mm": 1e3 * hand_error,
        "planned_hand_error_mm": 1e3 * result.hand_error_m,
        "min_zmp_margin_mm": 1e3 * result.min_zmp_margin_m,
        "foot_slip_mm": 1e3 * ex.foot_slip_m,
        "attempts": [
            a.kind + ("" if a.violation is None else f":{a.violation.criterion}") for a in result.attempts
        ],
        "trigger": None if result.attempts[0].violation is None else result.attempts[0].violation.criterion,
    }


def timings(robot, targets: list[tuple[float, float, float]], expect_step: bool) -> dict:
    from services.reaching import ReachRequest, plan_reach

    q0 = robot.q_half_sitting
    wall, cpu, durations = [], [], []
    for target in targets:
        hand = "left" if target[1] >= 0 else "right"
        t0, c0 = time.perf_counter(), time.process_time()
        result = plan_reach(robot, ReachRequest(hand, np.array(target), q0))
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        durations.append(result.duration_s)
        if result.stepped != expect_step:
            print(f"  note: target {target} {'stepped' if result.stepped else 'did not step'}")
    return {
        "ms": 1e3 * float(np.median(wall)),
        "cpu_ms": 1e3 * float(np.median(cpu)),
        "motion_s": float(np.median(durations)),
        "speedup": float(np.median(np.array(durations) / np.array(wall))),
        "min_speedup": float(np.min(np.array(durations) / np.array(wall))),
    }


def planned_only(robot, targets: list[tuple[str, np.ndarray, float]], options) -> dict:
    """Plan (no execution) every target with ``options``: triggers and steps."""
    from services.errors import HumanoidError
    from services.reaching import ReachRequest
    from services.reaching.planner import ReachPlanner

    planner = ReachPlanner(robot, options)
    triggers: dict[str, int] = {}
    steps, failures, single_tried, single_discarded = [], 0, 0, 0
    for hand, target, _ in targets:
        try:
            result = planner.plan(ReachRequest(hand, target, robot.q_half_sitting))
        except HumanoidError as exc:
            failures += 1
            criterion = (exc.details or {}).get("criterion")
            if criterion:
                triggers[criterion] = triggers.get(criterion, 0) + 1
            continue
        first = result.attempts[0].violation
        if first is not None:
            triggers[first.criterion] = triggers.get(first.criterion, 0) + 1
        singles = [a for a in result.attempts if a.kind == "single"]
        single_tried += len(singles)
        single_discarded += sum(a.violation is not None for a in singles)
        steps.append(len(result.footsteps))
    reshaped = [n for n in steps if n > 0]
    return {
        "n": len(targets),
        "planned": len(steps),
        "infeasible": failures,
        "trigger": triggers,
        "reshaped": len(reshaped),
        "single_step_share": sum(n == 1 for n in reshaped) / len(reshaped) if reshaped else None,
        "single_tried": single_tried,
        "single_discarded": single_discarded,
        "median_steps": float(np.median(steps)) if steps else None,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench reaching", description=__doc__.split("\n")[0])
    parser.add_argument("--robot", default="hrp2_like", help="robot model (default hrp2_like)")
    parser.add_argument("--n", type=int, default=50, help="random targets planned and executed (default 50)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random targets (default 0)")
    args = parser.parse_args(argv)
    if args.n < 0:
        parser.error("--n must be >= 0")

    from services.model import load_robot
    from services.reaching.options import ReachingOptions
    from services.reaching.planner import planner_for
    from sim.world import World

    robot = load_robot(args.robot)
    planner = planner_for(robot.name, ReachingOptions())
    t0 = time.perf_counter()
    for hand in ("left", "right"):
        planner.envelope(hand)
    envelope_s = time.perf_counter() - t0

    no_step = timings(robot, NO_STEP_TARGETS[robot.name], expect_step=False)
    with_step = timings(robot, STEP_TARGETS[robot.name], expect_step=True)
    results: dict = {
        "robot": robot.name,
        "machine": f"{platform.machine()} {platform.python_version()}",
        "envelope_s": envelope_s,
        "plan_no_step_ms": no_step["ms"],
        "plan_no_step_cpu_ms": no_step["cpu_ms"],
        "no_step_motion_s": no_step["motion_s"],
        "no_step_speedup": no_step["speedup"],
        "plan_with_step_ms": with_step["ms"],
        "plan_with_step_cpu_ms": with_step["cpu_ms"],
        "with_step_motion_s": with_step["motion_s"],
        "with_step_speedup": with_step["speedup"],
    }

    runs = []
    world = World(robot, "empty")
    try:
        for i, (hand, target, beyond) in enumerate(random_targets(robot, args.n, args.seed)):
            run = run_one(world, robot, hand, target)
            run.update({"hand": hand, "target": [round(float(v), 4) for v in target], "beyond_m": beyond})
            runs.append(run)
            print(
                f"  {i + 1:3d}/{args.n} {hand:5s} "
                f"target ({target[0]:+.2f}, {target[1]:+.2f}, {target[2]:.2f}) "
                f"+{beyond:.2f} m: {run['outcome']:9s} steps {run.get('steps', '-')!s:>2s} "
                f"hand {run.get('hand_error_mm', float('nan')):6.1f} mm  plan {run['planning_s']:.2f} s "
                f"motion {run.get('duration_s', float('nan')):5.1f} s",
                flush=True,
            )
    finally:
        world.close()
    reached = [r for r in runs if r["outcome"] == "reached"]
    planned = [r for r in runs if "speedup" in r]
    outcomes: dict[str, int] = {}
    for r in runs:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    triggers: dict[str, int] = {}
    for r in runs:
        if r.get("trigger"):
            triggers[r["trigger"]] = triggers.get(r["trigger"], 0) + 1
    reshaped = [r for r in planned if r.get("steps", 0) > 0]
    results["trigger"] = triggers
    results["single_step_share"] = (
        sum(r["steps"] == 1 for r in reshaped) / len(reshaped) if reshaped else None
    )
    results["paper_single_step"] = "Fig. 6: one step"
    results["one_step"] = planned_only(
        robot, one_step_targets(robot, args.n, args.seed + 2), ReachingOptions()
    )
    results["just_beyond"] = planned_only(
        robot, random_targets(robot, args.n, args.seed + 1, beyond_m=(0.05, 0.3)), ReachingOptions()
    )
    results["extension_joint_speed"] = planned_only(
        robot,
        random_targets(robot, args.n, args.seed),
        ReachingOptions(criteria=(*ReachingOptions().criteria_for(robot), "joint_speed")),
    )
    results["random"] = {
        "n": len(runs),
        "seed": args.seed,
        "success_rate": len(reached) / len(runs) if runs else 0.0,
        "outcomes": outcomes,
        "median_hand_error_mm": float(np.median([r["hand_error_mm"] for r in reached])) if reached else None,
        "median_steps": float(np.median([r["steps"] for r in planned])) if planned else None,
        "median_speedup": float(np.median([r["speedup"] for r in planned])) if planned else None,
        "min_speedup": float(np.min([r["speedup"] for r in planned])) if planned else None,
        "runs": runs,
    }

    rnd = results["random"]
    print(f"reaching benchmark on {robot.name} (envelopes measured in {envelope_s:.2f} s)")
    print(f"{'figure':44s} {'value':>10s}")
    for label, value in (
        ("plan, target within reach [ms]", results["plan_no_step_ms"]),
        ("  motion / planning time", results["no_step_speedup"]),
        ("plan, target beyond reach (steps) [ms]", results["plan_with_step_ms"]),
        ("  motion / planning time", results["with_step_speedup"]),
        (f"random targets: success rate (n={rnd['n']})", rnd["success_rate"]),
        ("  median motion / planning time", rnd["median_speedup"] or float("nan")),
        ("  lowest motion / planning time", rnd["min_speedup"] or float("nan")),
        ("  median steps", rnd["median_steps"] or float("nan")),
        ("  median hand error when reached [mm]", rnd["median_hand_error_mm"] or float("nan")),
    ):
        print(f"{label:44s} {value:10.2f}")
    print(f"  outcomes: {rnd['outcomes']}")
    share = results["single_step_share"]
    print(f"  trigger (first violation) by criterion: {results['trigger']}")
    print(
        "  single_step_share (reshapings with one step; paper Fig. 6: one step): "
        + ("-" if share is None else f"{share:.2f} of {len(reshaped)}")
    )
    for key, label in (
        ("one_step", "targets in front 0-0.15 m beyond the reach envelope (planned only)"),
        ("just_beyond", "targets 0.05-0.3 m beyond the arm's length (defaults; planned only)"),
        ("extension_joint_speed", "random targets with joint_speed added (planned only)"),
    ):
        pe = results[key]
        print(
            f"{label}: {pe['planned']}/{pe['n']} planned, trigger {pe['trigger']}, single_step_share "
            f"{pe['single_step_share']} of {pe['reshaped']} (single steps tried {pe['single_tried']}, "
            f"discarded {pe['single_discarded']}; paper: one step), median steps {pe['median_steps']}"
        )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
