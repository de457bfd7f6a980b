"""Plan a walk with placo's WalkPatternGenerator (and optionally its whole-body walk tasks).

Runs inside the placo peer venv (``scripts/peers/setup_placo.sh``), which has placo and its own
pinocchio 3.8: it imports nothing from the project. The walking benchmark (scripts/bench.d/walking.py)
writes a JSON request, runs this script, and reads back a JSON reply and an ``.npz`` of arrays.

Request (JSON): ``urdf`` (a URDF with the frames ``left_foot``, ``right_foot`` and ``trunk`` placo needs),
``joint_names`` and ``q_start`` (the starting configuration in the project's joint order),
``footsteps`` (``{"left_start": [x, y, yaw], "right_start": [...], "steps": [{"side", "pose"}]}``, feet
alternating), ``single_support_s``, ``double_support_ratio``, ``startend_double_support_ratio``,
``com_height_m``, ``step_height_m``, ``sole_length_m``, ``sole_width_m``, ``zmp_margin_m``,
``plan_dts`` (planning grids [s]), ``wholebody_plan_dts`` (the plans to execute in whole body) and
``sample_dt_s`` (the whole-body sampling period). A plan that takes less than 1 s is repeated up to 5
times and the median kept.

Reply (JSON on the path given by ``--out``): ``plan_ms`` per grid, and per whole-body grid an ``npz``
with ``q`` (n, nq, project joint order), ``t``, ``phase`` (0 double, 1 left, 2 right), ``left_sole`` and
``right_sole`` (n, 4: x, y, z, yaw), ``com_planned`` (n, 3), ``zmp_planned`` (n, 2).

Usage: placo_walk_worker.py REQUEST.json --out REPLY.json
"""

from __future__ import annotations

import argparse
import json
import math
import time
import warnings

import numpy as np
import placo

warnings.filterwarnings("ignore")


def _frame(x: float, y: float, yaw: float) -> np.ndarray:
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = [x, y]
    return T


def _parameters(req: dict, dt: float) -> placo.HumanoidParameters:
    p = placo.HumanoidParameters()
    p.single_support_duration = req["single_support_s"]
    p.single_support_timesteps = round(req["single_support_s"] / dt)
    p.double_support_ratio = req["double_support_ratio"]
    p.startend_double_support_ratio = req["startend_double_support_ratio"]
    p.walk_com_height = req["com_height_m"]
    p.walk_foot_height = req["step_height_m"]
    p.walk_trunk_pitch = 0.0
    p.foot_length = req["sole_length_m"]
    p.foot_width = req["sole_width_m"]
    p.zmp_margin = req["zmp_margin_m"]
    return p


def _side(name: str):
    return placo.HumanoidRobot_Side.left if name == "left" else placo.HumanoidRobot_Side.right


def _footsteps(req: dict, p: placo.HumanoidParameters) -> list:
    """placo's list: first moving foot's start, the other start, then every landing (feet alternate)."""
    fs = req["footsteps"]
    first = fs["steps"][0]["side"]
    start = {"left": fs["left_start"], "right": fs["right_start"]}
    order = [
        (first, start[first]),
        ("right" if first == "left" else "left", start["right" if first == "left" else "left"]),
    ]
    order += [(s["side"], s["pose"]) for s in fs["steps"]]
    out = []
    for side, pose in order:
        f = placo.Footstep(p.foot_width, p.foot_length)
        f.side = _side(side)
        f.frame = _frame(*pose)
        out.append(f)
    return out


def _set_start(robot: placo.HumanoidRobot, req: dict) -> None:
    """Put the project's starting configuration into placo's robot, left sole where the request says."""
    q = np.array(robot.state.q)
    names = req["joint_names"]
    q_start = np.asarray(req["q_start"], dtype=float)
    q[:7] = q_start[:7]
    for i, name in enumerate(names):
        q[robot.get_joint_offset(name)] = q_start[7 + i]
    robot.state.q = q
    robot.update_kinematics()
    robot.update_support_side("left")
    robot.set_T_world_support(_frame(*req["footsteps"]["left_start"]))
    robot.ensure_on_floor()


def plan_once(req: dict, dt: float):
    robot = placo.HumanoidRobot(req["urdf"])
    _set_start(robot, req)
    p = _parameters(req, dt)
    supports = placo.FootstepsPlanner.make_supports(
        _footsteps(req, p), 0.0, True, p.has_double_support(), True
    )
    wpg = placo.WalkPatternGenerator(robot, p)
    com0 = np.array(robot.com_world())
    t0, c0 = time.perf_counter(), time.process_time()
    traj = wpg.plan(supports, com0, 0.0)
    plan_ms = 1e3 * (time.perf_counter() - t0)
    cpu_ms = 1e3 * (time.process_time() - c0)
    return robot, p, traj, plan_ms, cpu_ms


def _yaw(T: np.ndarray) -> float:
    return math.atan2(T[1, 0], T[0, 0])


def wholebody(req: dict, robot, p, traj) -> dict[str, np.ndarray]:
    """placo's walk tasks + kinematics solver along the trajectory, as in placo's walk example."""
    dt = req["sample_dt_s"]
    solver = placo.KinematicsSolver(robot)
    solver.enable_velocity_limits(True)
    solver.dt = dt
    tasks = placo.WalkTasks()
    tasks.initialize_tasks(solver, robot)
    # Upper body held at the starting posture (as the example's joints task does).
    names = req["joint_names"]
    legs = [n for n in names if "LEG" in n or "leg" in n]
    upper = {n: float(robot.get_joint(n)) for n in names if n not in legs}
    if upper:
        joints_task = solver.add_joints_task()
        joints_task.set_joints(upper)
        joints_task.configure("joints", "soft", 1.0)
    t_end = float(traj.t_end)
    ts = np.arange(0.0, t_end + 1e-9, dt)
    nq = len(names) + 7
    out = {k: [] for k in ("q", "phase", "left_sole", "right_sole", "com_planned", "zmp_planned")}
    omega = math.sqrt(9.81 / p.walk_com_height)
    for t in ts:
        tasks.update_tasks_from_trajectory(traj, t)
        robot.update_kinematics()
        solver.solve(True)
        if not traj.support_is_both(t):
            robot.update_support_side(str(traj.support_side(t)))
            robot.ensure_on_floor()
        robot.update_kinematics()
        q = np.array(robot.state.q)
        q_ours = np.empty(nq)
        q_ours[:7] = q[:7]
        for i, name in enumerate(names):
            q_ours[7 + i] = q[robot.get_joint_offset(name)]
        out["q"].append(q_ours)
        if traj.support_is_both(t):
            out["phase"].append(0)
        else:
            out["phase"].append(1 if str(traj.support_side(t)) == "left" else 2)
        for side, getter in (("left_sole", traj.get_T_world_left), ("right_sole", traj.get_T_world_right)):
            T = np.array(getter(t))
            out[side].append([T[0, 3], T[1, 3], T[2, 3], _yaw(T)])
        out["com_planned"].append(np.array(traj.get_p_world_CoM(t)))
        out["zmp_planned"].append(np.array(traj.get_p_world_ZMP(t, omega)))
    arrays = {k: np.asarray(v) for k, v in out.items()}
    arrays["t"] = ts
    return arrays


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("request", help="request JSON path")
    ap.add_argument("--out", required=True, help="reply JSON path (arrays go next to it as .npz)")
    args = ap.parse_args(argv)
    with open(args.request, encoding="utf-8") as f:
        req = json.load(f)
    reply: dict = {"plan_ms": {}, "plan_cpu_ms": {}, "duration_s": {}, "wholebody_s": {}, "npz": {}}
    base = args.out.rsplit(".", 1)[0]
    for dt in req["plan_dts"]:
        robot, p, traj, ms, cpu = plan_once(req, dt)
        times, cpus = [ms], [cpu]
        while ms < 1000.0 and len(times) < 5:
            robot, p, traj, ms, cpu = plan_once(req, dt)
            times.append(ms)
            cpus.append(cpu)
        reply["plan_ms"][str(dt)] = float(np.median(times))
        reply["plan_cpu_ms"][str(dt)] = float(np.median(cpus))
        reply["duration_s"][str(dt)] = float(traj.t_end)
        if any(abs(dt - w) < 1e-12 for w in req.get("wholebody_plan_dts", [])):
            t0 = time.perf_counter()
            arrays = wholebody(req, robot, p, traj)
            reply["wholebody_s"][str(dt)] = time.perf_counter() - t0
            npz = f"{base}_{dt}.npz"
            np.savez(npz, **arrays)
            reply["npz"][str(dt)] = npz
    with open(args.out, "w", encoding="utf-8") as f:
        json.dump(reply, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
