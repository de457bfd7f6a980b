"""IK benchmark: our strict hierarchy (services.ik) against pink's weighted QP on the same problem.

The problem (issue 4): TALOS from half-sitting, feet fixed (level 1) > CoM over the support polygon
with a 2 cm margin (2) > right grasp frame 0.40 m in front of the chest at z = 1.00 m (3) > rest
posture (4). Ours solves it as the strict hierarchy; pink (``pin-pink`` with the daqp backend, in
its own venv ``.venv-peers/pink`` created by ``scripts/peers/setup_pink.sh``) solves the same
tasks as one weighted QP per iteration, on the very same serialized pinocchio model. Both run in
the same invocation. The same problem is solved by ours on ``hrp2_like``.

Figures: time per iteration [us] (median over repeats of the run time divided by its iterations,
kinematics and task evaluation included) and iterations until the hand is within 1 mm of its
target; the floor is pinocchio's kinematics + Jacobians + CoM alone. Writes bench/out/ik.json.

Usage: scripts/bench ik [--repeats N] [--rounds N] [--no-pink] [--help]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "bench" / "out" / "ik.json"
PINK_PYTHON = ROOT / ".venv-peers" / "pink" / "bin" / "python"
PINK_SETUP = ROOT / "scripts" / "peers" / "setup_pink.sh"
PINK_WORKER = ROOT / "scripts" / "peers" / "pink_ik_worker.py"

HAND_TOL_M = 1e-3
MARGIN_M = 0.02
HAND_AHEAD_OF_CHEST_M = 0.40
HAND_HEIGHT_M = 1.00
# Ours: the hand asks at most 0.2 m per iteration (Task.max_step), gains 1, alpha 1.
HAND_MAX_STEP_M = 0.2
MAX_ITERS = 100
# pink's weights: feet pose and CoM dominate, then the hand, a small posture regularization.
PINK_COSTS = {"feet": 10.0, "com": 1.0, "hand": 1.0, "posture": 1e-3}
PINK_DT_S = 1.0  # gains 1 and dt 1: Gauss-Newton steps, as ours (alpha = 1, lambda = 1)


def build_problem(robot_name: str):
    """(robot, levels, q0, hand target, context) of the benchmark problem on ``robot_name``."""
    from services.ik import ComSupportPolygonTask, FramePoseTask, FramePositionTask, Level, PostureTask
    from services.model import load_robot

    robot = load_robot(robot_name)
    model = robot.model
    q0 = np.array(robot.q_half_sitting)
    data = robot.new_data()
    pin.framesForwardKinematics(model, data, q0)
    frames = robot.frames
    T_left = pin.SE3(data.oMf[model.getFrameId(frames.left_sole)])
    T_right = pin.SE3(data.oMf[model.getFrameId(frames.right_sole)])
    chest = data.oMf[model.getFrameId(frames.torso)].translation
    hand0 = data.oMf[model.getFrameId(frames.right_grasp)].translation
    target = np.array([chest[0] + HAND_AHEAD_OF_CHEST_M, hand0[1], HAND_HEIGHT_M])
    polygon = robot.support_polygon(q0)
    levels = [
        Level(
            (
                FramePoseTask(model, frames.left_sole, T_left),
                FramePoseTask(model, frames.right_sole, T_right),
            ),
            name="feet",
        ),
        Level((ComSupportPolygonTask(model, MARGIN_M, polygon_world_xy=polygon),), name="com"),
        Level((FramePositionTask(model, frames.right_grasp, target, max_step=HAND_MAX_STEP_M),), name="hand"),
        Level((PostureTask(model, q0),), name="posture", tol=math.inf),
    ]
    context = {
        "T_left": T_left,
        "T_right": T_right,
        "polygon": polygon,
        "hand0": hand0,
    }
    return robot, levels, q0, target, context


def run_ours(robot_name: str, repeats: int) -> dict:
    """Time per iteration of every run and iterations to 1 mm of our solver on ``robot_name``."""
    from services.ik import HierarchicalSolver

    robot, levels, q0, target, _ = build_problem(robot_name)
    solver = HierarchicalSolver(robot.model, robot.q_lower, robot.q_upper)
    per_iter_us = []
    cpu_per_iter_us = []
    result = None
    for _ in range(repeats):
        start_cpu = time.process_time()
        result = solver.run(levels, q0, alpha=1.0, max_iters=MAX_ITERS, tol=HAND_TOL_M)
        if result.iterations:
            per_iter_us.append(result.wall_time_s / result.iterations * 1e6)
            cpu_per_iter_us.append((time.process_time() - start_cpu) / result.iterations * 1e6)
    if result is None:
        raise ValueError("repeats must be >= 1")
    hand_values = result.values[:, 2]
    reached = np.flatnonzero(hand_values <= HAND_TOL_M)
    return {
        "per_run_us_per_iter": per_iter_us,
        "cpu_us_per_iter": float(np.median(cpu_per_iter_us)),
        "iters": int(reached[0]) if reached.size else -1,
        "reason": result.reason,
        "hand_error_m": float(hand_values[-1]),
        "feet_error": float(result.values[-1, 0]),
        "com_violation_m": float(result.values[-1, 1]),
        "hand_target_m": target.tolist(),
        "values": result.values.tolist(),
    }


def kinematics_floor_us(robot_name: str, repeats: int = 2000) -> float:
    """pinocchio computeJointJacobians + updateFramePlacements + jacobianCenterOfMass [us]."""
    from services.model import load_robot

    robot = load_robot(robot_name)
    model, data = robot.model, robot.new_data()
    q = np.array(robot.q_half_sitting)
    samples = []
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(repeats):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            pin.jacobianCenterOfMass(model, data, False)
        samples.append((time.perf_counter() - start) / repeats * 1e6)
    return float(np.median(samples))


def run_pink(repeats: int) -> dict:
    """Solve the TALOS problem with pink in its venv; returns the worker's JSON."""
    if not PINK_PYTHON.exists():
        setup = subprocess.run(["bash", str(PINK_SETUP)], capture_output=True, text=True)
        if setup.returncode != 0:
            return {"error": f"pink venv setup failed: {setup.stderr.strip()[-500:]}"}
    robot, _, q0, target, context = build_problem("talos")
    com = np.array(robot.com(q0))
    polygon = context["polygon"]
    com_target = np.array([polygon[:, 0].mean(), polygon[:, 1].mean(), com[2]])
    with tempfile.TemporaryDirectory() as tmp:
        model_path = Path(tmp) / "talos.bin"
        robot.model.saveToBinary(str(model_path))
        problem = {
            "model_path": str(model_path),
            "q0": q0.tolist(),
            "left_sole": robot.frames.left_sole,
            "right_sole": robot.frames.right_sole,
            "T_left": context["T_left"].homogeneous.tolist(),
            "T_right": context["T_right"].homogeneous.tolist(),
            "hand": robot.frames.right_grasp,
            "hand_target": target.tolist(),
            "com_target": com_target.tolist(),
            "costs": PINK_COSTS,
            "dt": PINK_DT_S,
            "damping": 1e-12,
            "tol_m": HAND_TOL_M,
            "max_iters": MAX_ITERS,
            "repeats": repeats,
        }
        proc = subprocess.run(
            [str(PINK_PYTHON), str(PINK_WORKER)],
            input=json.dumps(problem),
            capture_output=True,
            text=True,
            env={**os.environ, "PYTHONPATH": ""},
        )
    if proc.returncode != 0:
        return {"error": f"pink worker failed: {proc.stderr.strip()[-800:]}"}
    return json.loads(proc.stdout)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench ik", description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=20, help="runs of each solver per round (default 20)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating ours/pink rounds (default 3)")
    parser.add_argument("--no-pink", action="store_true", help="skip the pink peer")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.rounds < 1:
        parser.error("--repeats and --rounds must be >= 1")

    # Ours and pink alternate, so that both see the same load on this shared machine.
    talos_runs: list[float] = []
    pink_runs: list[float] = []
    talos: dict = {}
    pink: dict = {}
    for _ in range(args.rounds):
        talos = run_ours("talos", args.repeats)
        talos_runs += talos["per_run_us_per_iter"]
        if not args.no_pink:
            pink = run_pink(args.repeats)
            pink_runs += pink.get("per_run_us_per_iter", [])
    hrp2 = run_ours("hrp2_like", args.repeats * args.rounds)
    floor = kinematics_floor_us("talos")
    ours_us = float(np.median(talos_runs))
    pink_us = float(np.median(pink_runs)) if pink_runs else None

    result = {
        "ours_us_per_iter": ours_us,
        "ours_iters": talos["iters"],
        "pink_us_per_iter": pink_us,
        "pink_iters": pink.get("iters"),
        "hrp2_like_us_per_iter": float(np.median(hrp2["per_run_us_per_iter"])),
        "hrp2_like_iters": hrp2["iters"],
        "kinematics_floor_us": floor,
        "hand_tol_m": HAND_TOL_M,
        "repeats": args.repeats,
        "rounds": args.rounds,
        "details": {
            "talos": {k: v for k, v in talos.items() if k not in ("values", "per_run_us_per_iter")},
            "talos_values_per_iteration": talos["values"],
            "hrp2_like": {k: v for k, v in hrp2.items() if k not in ("values", "per_run_us_per_iter")},
            "pink": {k: v for k, v in pink.items() if k != "per_run_us_per_iter"},
            "pink_costs": PINK_COSTS,
            "pink_dt_s": PINK_DT_S,
            "hand_max_step_m": HAND_MAX_STEP_M,
            "load_average": os.getloadavg(),
            "openblas_num_threads_env": os.environ.get("OPENBLAS_NUM_THREADS"),
            "python": sys.version.split()[0],
        },
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2))

    rows = [
        ("ours (strict hierarchy, proxsuite)", "talos", ours_us, talos["iters"]),
        ("pink + daqp (weighted QP)", "talos", pink_us, pink.get("iters", "-")),
        ("ours (strict hierarchy, proxsuite)", "hrp2_like", result["hrp2_like_us_per_iter"], hrp2["iters"]),
        ("pinocchio kinematics floor", "talos", floor, "-"),
    ]
    print(f"{'solver':38s} {'robot':10s} {'us/iter':>9s} {'iters to 1 mm':>14s}")
    for name, robot, us, iters in rows:
        us_text = f"{us:9.1f}" if isinstance(us, float) and math.isfinite(us) else f"{'-':>9s}"
        print(f"{name:38s} {robot:10s} {us_text} {iters!s:>14s}")
    if "error" in pink:
        print(f"pink: {pink['error']}", file=sys.stderr)
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0 if talos["iters"] >= 0 and hrp2["iters"] >= 0 else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
