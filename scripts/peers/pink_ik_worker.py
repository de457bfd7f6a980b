"""Run the IK benchmark problem with pink (weighted tasks, one QP per iteration) and print JSON.

Runs inside the pink peer venv (scripts/peers/setup_pink.sh), started by scripts/bench.d/ik.py,
which writes the problem as JSON on stdin: the serialized pinocchio model (the very model our
solver uses), the initial configuration, frames and targets. Prints one JSON object on stdout:
the median time per iteration over the repeats [us], the iterations to reach the hand tolerance,
the final errors and the versions used.

Usage: .venv-peers/pink/bin/python scripts/peers/pink_ik_worker.py < problem.json
       (--help prints this text)
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def main() -> int:
    if "--help" in sys.argv or "-h" in sys.argv:
        print(__doc__)
        return 0
    import daqp  # noqa: F401  (fail early when the backend is missing)
    import pink
    import pinocchio as pin
    from pink.tasks import ComTask, FrameTask, PostureTask

    problem = json.load(sys.stdin)
    model = pin.Model()
    model.loadFromBinary(problem["model_path"])
    data = model.createData()
    q0 = np.array(problem["q0"], dtype=float)
    costs = problem["costs"]
    feet = []
    for frame, T in ((problem["left_sole"], problem["T_left"]), (problem["right_sole"], problem["T_right"])):
        task = FrameTask(frame, position_cost=costs["feet"], orientation_cost=costs["feet"])
        task.set_target(pin.SE3(np.array(T, dtype=float)))
        feet.append(task)
    com = ComTask(cost=[costs["com"], costs["com"], 0.0])
    com.set_target(np.array(problem["com_target"], dtype=float))
    hand = FrameTask(problem["hand"], position_cost=costs["hand"], orientation_cost=0.0)
    hand_target = np.array(problem["hand_target"], dtype=float)
    T_hand = pin.SE3(np.eye(3), hand_target)
    hand.set_target(T_hand)
    posture = PostureTask(cost=costs["posture"])
    posture.set_target(q0)
    tasks = [*feet, com, hand, posture]
    hand_id = model.getFrameId(problem["hand"])
    dt = float(problem["dt"])
    tol_m = float(problem["tol_m"])
    max_iters = int(problem["max_iters"])

    per_iter_us: list[float] = []
    cpu_per_iter_us: list[float] = []
    iterations = -1
    hand_error = float("nan")
    for _ in range(int(problem["repeats"])):
        configuration = pink.Configuration(model, data, q0.copy())
        start = time.perf_counter()
        start_cpu = time.process_time()
        count = 0
        while True:
            hand_error = float(np.linalg.norm(configuration.data.oMf[hand_id].translation - hand_target))
            if hand_error <= tol_m or count >= max_iters:
                break
            velocity = pink.solve_ik(configuration, tasks, dt, solver="daqp", damping=problem["damping"])
            configuration.integrate_inplace(velocity, dt)
            count += 1
        elapsed = time.perf_counter() - start
        elapsed_cpu = time.process_time() - start_cpu
        if count:
            per_iter_us.append(elapsed / count * 1e6)
            cpu_per_iter_us.append(elapsed_cpu / count * 1e6)
        iterations = count
    result = {
        "us_per_iter": float(np.median(per_iter_us)) if per_iter_us else float("nan"),
        "cpu_us_per_iter": float(np.median(cpu_per_iter_us)) if cpu_per_iter_us else float("nan"),
        "per_run_us_per_iter": per_iter_us,
        "iters": iterations,
        "reached": hand_error <= tol_m,
        "hand_error_m": hand_error,
        "pink_version": pink.__version__,
        "pinocchio_version": pin.__version__,
        "qp_solver": "daqp",
    }
    json.dump(result, sys.stdout)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
