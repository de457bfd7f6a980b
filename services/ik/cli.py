"""``humanoid ik reach``: the prioritized IK on a reach-and-look problem, its task values per
iteration (printed, and plotted like Fig. 10 of the footstep paper)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from services.cli_common import examples

EXAMPLES = examples(
    "humanoid ik reach                               # 0.35 m ahead of the chest, 0.1 m below it",
    "humanoid ik reach --robot talos --target 0.4 -0.2 1.0 --plot out/ik_reach.png",
)


def add_cli(subparsers: Any) -> None:
    """Register ``humanoid ik reach``."""
    raw = {"epilog": EXAMPLES, "formatter_class": argparse.RawDescriptionHelpFormatter}
    parser = subparsers.add_parser("ik", help="prioritized inverse kinematics (hierarchical QP)", **raw)
    sub = parser.add_subparsers(dest="ik_command", metavar="ACTION", required=True)
    reach = sub.add_parser(
        "reach",
        help="feet fixed > CoM in the support polygon > right hand on a point > gaze at it > rest posture",
        **raw,
    )
    reach.add_argument("--robot", default="hrp2_like", help="hrp2_like (default) or talos")
    reach.add_argument(
        "--target",
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        help="hand target in the world [m] (default: 0.35 m ahead of the chest, 0.1 m below it)",
    )
    reach.add_argument("--tol", type=float, default=1e-4, help="task value tolerance (default 1e-4)")
    reach.add_argument("--max-iters", type=int, default=100, help="iteration budget (default 100)")
    reach.add_argument(
        "--plot", type=Path, default=None, help="write the task values per iteration to this PNG"
    )
    reach.set_defaults(func=_reach)


def _reach(args: argparse.Namespace) -> int:
    import pinocchio as pin

    from services.ik import (
        ComSupportPolygonTask,
        FramePoseTask,
        FramePositionTask,
        GazeTask,
        HierarchicalSolver,
        Level,
        PostureTask,
    )
    from services.model import load_robot

    robot = load_robot(args.robot)
    model = robot.model
    q0 = np.array(robot.q_half_sitting)
    data = robot.forward(q0, robot.new_data())
    frames = robot.frames
    if args.target is None:
        chest = data.oMf[model.getFrameId(frames.torso)].translation
        hand = data.oMf[model.getFrameId(frames.right_grasp)].translation
        target = np.array([chest[0] + 0.35, hand[1], chest[2] - 0.1])
    else:
        target = np.array(args.target, dtype=float)
    soles = [pin.SE3(data.oMf[model.getFrameId(f)]) for f in (frames.left_sole, frames.right_sole)]
    levels = [
        Level(
            (
                FramePoseTask(model, frames.left_sole, soles[0]),
                FramePoseTask(model, frames.right_sole, soles[1]),
            ),
            name="feet",
        ),
        Level((ComSupportPolygonTask(model, 0.02, polygon_world_xy=robot.support_polygon(q0)),), name="com"),
        Level((FramePositionTask(model, frames.right_grasp, target, max_step=0.2),), name="hand"),
        Level(
            (GazeTask(model, frames.gaze, target, axis_in_camera=(1.0, 0.0, 0.0), max_step=0.2),),
            name="gaze",
        ),
        Level((PostureTask(model, q0, gain=0.5),), name="posture", tol=math.inf),
    ]
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    result = solver.run(levels, q0, tol=args.tol, max_iters=args.max_iters)
    print(f"{robot.name}: hand target {np.round(target, 3)} m")
    print("iter " + " ".join(f"{name:>10s}" for name in result.level_names))
    for k, row in enumerate(result.values):
        print(f"{k:4d} " + " ".join(f"{v:10.2e}" for v in row))
    per_iter_us = result.wall_time_s / max(result.iterations, 1) * 1e6
    print(f"{result.reason} after {result.iterations} iterations, {per_iter_us:.0f} us per iteration")
    if args.plot is not None:
        _plot(result, args.plot, f"{robot.name}: reach and look")
        print(f"wrote {args.plot}")
    return 0 if result.converged else 1


def _plot(result: Any, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for k, name in enumerate(result.level_names):
        values = np.maximum(result.values[:, k], 1e-12)
        ax.semilogy(np.arange(values.shape[0]), values, marker="o", markersize=3, label=f"{k + 1}: {name}")
    ax.set_xlabel("iteration")
    ax.set_ylabel("task value (eqs. 5-6)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
