"""``humanoid model ...``: inspect the robot models, regenerate the URDF, check standing in pybullet."""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import Any

import numpy as np

from services.cli_common import examples

EXAMPLES = examples(
    "humanoid model info --robot talos          # joints, limits, frames, cameras, parameters",
    "humanoid model urdf --check                # exit 1 if the committed URDF is stale",
    "humanoid model stand --robot hrp2_like --seconds 10",
)


def add_cli(subparsers: Any) -> None:
    """Register ``humanoid model info|urdf|stand``."""
    parser = subparsers.add_parser(
        "model",
        help="robot models: info, URDF generation, standing check",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="model_command", metavar="ACTION", required=True)

    raw = {"epilog": EXAMPLES, "formatter_class": argparse.RawDescriptionHelpFormatter}
    info = sub.add_parser("info", help="joints, limits, frames, half-sitting, cameras and parameters", **raw)
    info.add_argument("--robot", default="hrp2_like", help="hrp2_like (default) or talos")
    info.set_defaults(func=_info)

    urdf = sub.add_parser("urdf", help="regenerate services/model/data/hrp2_like.urdf (or --check it)", **raw)
    urdf.add_argument("--check", action="store_true", help="exit 1 if the committed URDF is stale")
    urdf.set_defaults(func=_urdf)

    stand = sub.add_parser(
        "stand", help="stand in half-sitting in pybullet (DIRECT); report tilt, slip, steps/s", **raw
    )
    stand.add_argument("--robot", default="hrp2_like", help="hrp2_like (default) or talos")
    stand.add_argument("--seconds", type=float, default=10.0, help="simulated time [s] (default 10)")
    stand.add_argument("--dt", type=float, default=1e-3, help="physics step [s] (default 0.001)")
    stand.add_argument("--solver-iterations", type=int, default=50, help="pybullet solver iterations (50)")
    stand.set_defaults(func=_stand)


def _info(args: argparse.Namespace) -> int:
    from services.model import load_robot

    robot = load_robot(args.robot)
    q = robot.q_half_sitting
    print(f"{robot.name}: {robot.urdf_path}")
    print(
        f"  nq={robot.nq} nv={robot.nv} actuated={len(robot.joint_names)} mass={robot.total_mass_kg:.3f} kg"
    )
    print(
        f"  sole {robot.sole_size_m[0]} x {robot.sole_size_m[1]} m; "
        f"CoM in half-sitting {np.round(robot.com(q), 4)}"
    )
    print(f"  base in half-sitting {np.round(q[:7], 4)}")
    print("  joint                      q_half     lower     upper     v_max")
    for name in robot.joint_names:
        iq, iv = robot.joint_index(name)
        print(
            f"  {name:24s} {q[iq]:9.4f} {robot.q_lower[iq]:9.4f} {robot.q_upper[iq]:9.4f} "
            f"{robot.v_max[iv]:9.3f}"
        )
    print("  frames: " + ", ".join(f"{k}={v}" for k, v in vars(robot.frames).items()))
    for name, cam in sorted(robot.cameras.items()):
        print(
            f"  camera {name}: {cam.frame} {cam.width_px}x{cam.height_px} "
            f"fx={cam.fx:.2f} cx={cam.cx} cy={cam.cy}"
        )
    for name, pair in sorted(robot.stereo_pairs.items()):
        print(f"  stereo {name}: {pair.left} + {pair.right}, baseline {pair.baseline_m} m")
    print(f"  capsules: {len(robot.capsules)}, checked pairs: {len(robot.collision_pairs)}")
    print(f"  params: {robot.params}")
    return 0


def _urdf(args: argparse.Namespace) -> int:
    from services.model.generate_urdf import DEFAULT_URDF_PATH, urdf_text, write_urdf

    if args.check:
        if DEFAULT_URDF_PATH.read_text(encoding="utf-8") != urdf_text():
            print(f"{DEFAULT_URDF_PATH} is stale: run `humanoid model urdf`", file=sys.stderr)
            return 1
        print(f"{DEFAULT_URDF_PATH} is up to date")
        return 0
    print(f"wrote {write_urdf()}")
    return 0


def _stand(args: argparse.Namespace) -> int:
    import pinocchio as pin
    import pybullet as p

    from services.model import load_robot
    from services.model.pybullet_robot import PybulletRobot

    robot = load_robot(args.robot)
    client = p.connect(p.DIRECT)
    try:
        p.setGravity(0.0, 0.0, -9.81, physicsClientId=client)
        p.setTimeStep(args.dt, physicsClientId=client)
        p.setPhysicsEngineParameter(numSolverIterations=args.solver_iterations, physicsClientId=client)
        plane = p.createMultiBody(
            0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client), physicsClientId=client
        )
        p.changeDynamics(plane, -1, lateralFriction=1.0, physicsClientId=client)
        sim = PybulletRobot(robot, client)
        q0 = robot.q_half_sitting
        sim.set_position_targets(q0)
        soles0 = {side: robot.sole_pose(q0, side).translation for side in ("left", "right")}
        steps = max(1, round(args.seconds / args.dt))
        tilt_deg = slip_m = 0.0
        cpu_s = 0.0
        for i in range(steps):
            t0 = time.process_time()
            p.stepSimulation(physicsClientId=client)
            cpu_s += time.process_time() - t0
            if i % 100 == 99 or i == steps - 1:
                q = sim.read_q()
                R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
                tilt_deg = max(tilt_deg, math.degrees(math.acos(max(-1.0, min(1.0, R[2, 2])))))
                for side, p0 in soles0.items():
                    slip_m = max(
                        slip_m, float(np.linalg.norm(robot.sole_pose(q, side).translation[:2] - p0[:2]))
                    )
    finally:
        p.disconnect(client)
    print(
        f"{robot.name}: {args.seconds} s at dt={args.dt} s, {args.solver_iterations} solver iterations: "
        f"max tilt {tilt_deg:.3f} deg, max sole slip {slip_m * 1000:.3f} mm, "
        f"{steps / max(cpu_s, 1e-9):.0f} steps per CPU second"
    )
    return 0 if tilt_deg < 0.3 and slip_m < 1e-3 else 1
