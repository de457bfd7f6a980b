"""Walking benchmark: our ZMP preview-control pattern generator against placo's WalkPatternGenerator.

The walk (issue 5): 10 straight steps of 0.20 m on ``hrp2_like`` from half-sitting, 0.8 s single
support, 0.1 s double support between steps (placo's ``double_support_ratio`` 0.125 of the single
support), 1.0 s first and last weight transfers (placo ``startend_double_support_ratio`` 1.25). Ours
also stands 0.8 s before the first transfer and 1.0 s after the last one (the preview controller's
lead-in and settling), so its trajectory is 1.8 s longer than placo's.

Figures, all from one run:
- ``ours_plan_ms``: CoM/ZMP/feet pattern at 5 ms (median of repeats, preview gains cached);
- ``placo_plan_ms_5ms`` / ``placo_plan_ms_50ms``: placo's ``WalkPatternGenerator.plan`` on a 5 ms and a
  50 ms planning grid (in the placo peer venv ``.venv-peers/placo``, made by
  ``scripts/peers/setup_placo.sh``; the same footsteps; a plan under 1 s is the median of 5);
- ``ours_wholebody_rtf``: trajectory duration / time of our whole-body stage (prioritized IK at 5 ms,
  multibody ZMP, second preview stage where needed);
- ``*_cpu`` variants: the same with process CPU time instead of wall time (the machine is shared: under
  load, wall times grow and CPU times do not);
- ``ours_zmp_outside_mm`` / ``placo_zmp_outside_mm``: worst distance of the multibody ZMP (pinocchio
  centroidal dynamics of the 5 ms joint trajectory, our model) outside the support polygon, 0 when it
  never leaves it. placo's joint trajectory is its own walk tasks + kinematics solver at 5 ms along its
  5 ms plan (``placo_zmp_outside_mm_50ms``: along its 50 ms plan).

Usage: scripts/bench walking [--robot hrp2_like] [--repeats N] [--no-placo] [--help]
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
OUT = ROOT / "bench" / "out" / "walking.json"
PLACO_PYTHON = ROOT / ".venv-peers" / "placo" / "bin" / "python"
PLACO_SETUP = ROOT / "scripts" / "peers" / "setup_placo.sh"
PLACO_WORKER = ROOT / "scripts" / "peers" / "placo_walk_worker.py"

N_STEPS = 10
STEP_LENGTH_M = 0.20
SINGLE_SUPPORT_S = 0.8
DOUBLE_SUPPORT_RATIO = 0.125  # of the single support, placo's convention
STARTEND_DS_S = 1.0
PLACO_ZMP_MARGIN_M = 0.025  # placo's default margin of its ZMP constraint


def _walk(robot):
    from services.walking.footsteps import SolePose, straight_walk

    q0 = robot.q_half_sitting
    left = robot.sole_pose(q0, "left").translation
    right = robot.sole_pose(q0, "right").translation
    return straight_walk(
        N_STEPS,
        STEP_LENGTH_M,
        left_start=SolePose(float(left[0]), float(left[1]), 0.0),
        right_start=SolePose(float(right[0]), float(right[1]), 0.0),
    )


def bench_ours(robot, repeats: int) -> dict:
    from services.walking.footsteps import FootstepBounds
    from services.walking.pattern import PatternOptions, plan_pattern
    from services.walking.preview_control import preview_gains
    from services.walking.timing import WalkTiming
    from services.walking.wholebody import WholeBodyPlanner

    seq = _walk(robot)
    timing = WalkTiming(
        single_support_s=SINGLE_SUPPORT_S,
        double_support_s=DOUBLE_SUPPORT_RATIO * SINGLE_SUPPORT_S,
        initial_double_support_s=STARTEND_DS_S,
        final_double_support_s=STARTEND_DS_S,
    )
    q0 = robot.q_half_sitting
    c0 = robot.com(q0)
    bounds = FootstepBounds.from_robot(robot)
    preview_gains.cache_clear()
    t0 = time.perf_counter()
    pattern = plan_pattern(seq, timing, PatternOptions(), initial_com_m=c0, bounds=bounds)
    cold_ms = 1e3 * (time.perf_counter() - t0)
    times, cpu = [], []
    for _ in range(repeats):
        t0, c0_cpu = time.perf_counter(), time.process_time()
        pattern = plan_pattern(seq, timing, PatternOptions(), initial_com_m=c0, bounds=bounds)
        times.append(1e3 * (time.perf_counter() - t0))
        cpu.append(1e3 * (time.process_time() - c0_cpu))
    planner = WholeBodyPlanner(robot)
    results, wb_cpu = [], []
    for _ in range(3):
        c0_cpu = time.process_time()
        results.append(planner.solve(pattern, q0))
        wb_cpu.append(time.process_time() - c0_cpu)
    order = np.argsort([r.wall_time_s for r in results])
    res = results[int(order[1])]  # the median run
    return {
        "ours_plan_ms": float(np.median(times)),
        "ours_plan_ms_cpu": float(np.median(cpu)),
        "ours_wholebody_rtf_cpu": pattern.duration_s / float(np.median(wb_cpu)),
        "ours_plan_ms_cold": cold_ms,
        "ours_duration_s": pattern.duration_s,
        "ours_samples": pattern.n_samples,
        "ours_wholebody_rtf": res.real_time_factor,
        "ours_wholebody_s": res.wall_time_s,
        "ours_zmp_outside_mm": 1e3 * res.worst_zmp_outside_m,
        "ours_zmp_min_margin_mm": 1e3 * res.min_zmp_margin_m,
        "ours_corrections": res.corrections,
        "ours_max_sole_error_mm": 1e3 * res.max_sole_error_m,
        "ours_max_com_error_mm": 1e3 * res.max_com_error_m,
    }


def _placo_urdf(robot, directory: Path) -> Path:
    """The robot's URDF plus the frames placo's HumanoidRobot looks up (left_foot, right_foot, trunk)."""
    text = Path(robot.urdf_path).read_text(encoding="utf-8")
    links = {
        "left_foot": robot.frames.left_sole,
        "right_foot": robot.frames.right_sole,
        "trunk": robot.frames.base,
    }
    extra = "".join(
        f'  <link name="{name}"/>\n'
        f'  <joint name="{name}_placo_frame" type="fixed"><parent link="{parent}"/><child link="{name}"/>'
        '<origin xyz="0 0 0" rpy="0 0 0"/></joint>\n'
        for name, parent in links.items()
    )
    path = directory / f"{robot.name}_placo.urdf"
    path.write_text(text.replace("</robot>", extra + "</robot>"), encoding="utf-8")
    return path


def bench_placo(robot) -> tuple[dict, str]:
    """placo figures, or ({}, reason) when placo cannot run here."""
    from services.walking.multibody_zmp import multibody_zmp
    from services.walking.support_polygon import distances_to_support

    setup = subprocess.run(["bash", str(PLACO_SETUP)], capture_output=True, text=True)
    if setup.returncode != 0 or not PLACO_PYTHON.exists():
        return {}, f"placo venv setup failed: {setup.stderr.strip()[-400:]}"
    q0 = robot.q_half_sitting
    with tempfile.TemporaryDirectory() as tmp:
        tmpdir = Path(tmp)
        request = {
            "urdf": str(_placo_urdf(robot, tmpdir)),
            "joint_names": list(robot.joint_names),
            "q_start": [float(v) for v in q0],
            "footsteps": _walk(robot).to_dict(),
            "single_support_s": SINGLE_SUPPORT_S,
            "double_support_ratio": DOUBLE_SUPPORT_RATIO,
            "startend_double_support_ratio": STARTEND_DS_S / SINGLE_SUPPORT_S,
            "com_height_m": float(robot.com(q0)[2]),
            "step_height_m": float(robot.params.step_height_m),
            "sole_length_m": float(robot.sole_size_m[0]),
            "sole_width_m": float(robot.sole_size_m[1]),
            "zmp_margin_m": PLACO_ZMP_MARGIN_M,
            "plan_dts": [0.005, 0.05],
            "wholebody_plan_dts": [0.005, 0.05],
            "sample_dt_s": 0.005,
        }
        req_path = tmpdir / "request.json"
        reply_path = tmpdir / "reply.json"
        req_path.write_text(json.dumps(request), encoding="utf-8")
        run = subprocess.run(
            [str(PLACO_PYTHON), str(PLACO_WORKER), str(req_path), "--out", str(reply_path)],
            capture_output=True,
            text=True,
            timeout=1800,
        )
        if run.returncode != 0:
            return {}, f"placo worker failed: {run.stderr.strip()[-600:]}"
        reply = json.loads(reply_path.read_text(encoding="utf-8"))
        out = {
            "placo_plan_ms_5ms": reply["plan_ms"]["0.005"],
            "placo_plan_ms_50ms": reply["plan_ms"]["0.05"],
            "placo_plan_ms_5ms_cpu": reply["plan_cpu_ms"]["0.005"],
            "placo_plan_ms_50ms_cpu": reply["plan_cpu_ms"]["0.05"],
            "placo_duration_s": reply["duration_s"]["0.005"],
        }
        for dt, suffix in (("0.005", ""), ("0.05", "_50ms")):
            arrays = np.load(reply["npz"][dt])
            mb = multibody_zmp(robot.model, arrays["q"], 0.005)
            dist = distances_to_support(
                mb.zmp_m, arrays["phase"], arrays["left_sole"], arrays["right_sole"], *robot.sole_size_m
            )
            planned = distances_to_support(
                arrays["zmp_planned"],
                arrays["phase"],
                arrays["left_sole"],
                arrays["right_sole"],
                *robot.sole_size_m,
            )
            out[f"placo_zmp_outside_mm{suffix}"] = 1e3 * max(0.0, float(dist.max()))
            out[f"placo_zmp_worst_time_s{suffix}"] = float(arrays["t"][int(np.argmax(dist))])
            out[f"placo_planned_zmp_outside_mm{suffix}"] = 1e3 * max(0.0, float(planned.max()))
            out[f"placo_wholebody_rtf{suffix}"] = float(arrays["t"][-1]) / reply["wholebody_s"][dt]
        return out, ""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench walking", description=__doc__.split("\n")[0])
    parser.add_argument("--robot", default="hrp2_like", help="robot model (default hrp2_like)")
    parser.add_argument("--repeats", type=int, default=20, help="repeats of our pattern planning")
    parser.add_argument("--no-placo", action="store_true", help="skip the placo peer")
    args = parser.parse_args(argv)

    from services.model import load_robot

    robot = load_robot(args.robot)
    results: dict = {
        "robot": args.robot,
        "walk": f"{N_STEPS} straight steps of {STEP_LENGTH_M} m, single support {SINGLE_SUPPORT_S} s, "
        f"double support {DOUBLE_SUPPORT_RATIO * SINGLE_SUPPORT_S:.3f} s, "
        f"first/last transfer {STARTEND_DS_S} s",
        "machine": f"{platform.machine()} {platform.python_version()}",
    }
    results.update(bench_ours(robot, args.repeats))
    note = "skipped (--no-placo)"
    if not args.no_placo:
        placo, note = bench_placo(robot)
        results.update(placo)
    if note:
        results["placo_note"] = note

    rows = [
        ("pattern plan at 5 ms [ms]", "ours_plan_ms", "placo_plan_ms_5ms"),
        ("  CPU time [ms]", "ours_plan_ms_cpu", "placo_plan_ms_5ms_cpu"),
        ("pattern plan at 50 ms [ms]", None, "placo_plan_ms_50ms"),
        ("  CPU time [ms]", None, "placo_plan_ms_50ms_cpu"),
        ("whole body real-time factor", "ours_wholebody_rtf", "placo_wholebody_rtf"),
        ("  on CPU time", "ours_wholebody_rtf_cpu", None),
        ("multibody ZMP outside polygon [mm]", "ours_zmp_outside_mm", "placo_zmp_outside_mm"),
        ("  (placo along its 50 ms plan)", None, "placo_zmp_outside_mm_50ms"),
        ("multibody ZMP min margin inside [mm]", "ours_zmp_min_margin_mm", None),
        ("trajectory duration [s]", "ours_duration_s", "placo_duration_s"),
    ]

    def cell(key: str | None) -> str:
        if key is None or key not in results:
            return "-"
        return f"{results[key]:.2f}"

    print(f"walking benchmark on {args.robot}: {results['walk']}")
    print(f"{'figure':40s} {'ours':>12s} {'placo':>12s}")
    for label, ours, theirs in rows:
        print(f"{label:40s} {cell(ours):>12s} {cell(theirs):>12s}")
    if note:
        print(f"placo: {note}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
