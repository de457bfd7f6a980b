"""Plan walks with the ZMP preview-control pattern generator and plot them as PNG files under out/.

For each walk: the planned ZMP, the multibody ZMP of the whole-body motion and the support polygon
over time in x and in y (the support polygon projected on each axis, shaded, as in Fig. 8 of the
reaching paper), the CoM against the ZMP, and a top view of the footsteps with the CoM and ZMP paths.

With ``--sim`` each walk is also planned from the state of the simulated robot (sim.world.World,
pybullet), executed there open loop, and the soles measured every 5 ms are plotted against the plan
(``walking_<robot>_<walk>_sim.png``, final errors in the title).

Usage: python examples/walking_plots.py [--robot hrp2_like|talos] [--walk straight|turn|side|arc|all]
       [--sim] [--out out]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Polygon

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from services.model import load_robot  # noqa: E402
from services.walking.footsteps import (  # noqa: E402
    FootstepBounds,
    SolePose,
    arc_walk,
    side_steps,
    sole_corners,
    straight_walk,
    turn_in_place,
)
from services.walking.pattern import PatternOptions, WalkPattern, plan_pattern  # noqa: E402
from services.walking.support_polygon import support_hull  # noqa: E402
from services.walking.timing import LEFT, RIGHT, WalkTiming  # noqa: E402
from services.walking.wholebody import WholeBodyPlanner, WholeBodyResult  # noqa: E402
from sim.world import World  # noqa: E402

WALKS = ("straight", "turn", "side", "arc")


def _sole(robot, q: np.ndarray, side: str) -> SolePose:
    T = robot.sole_pose(q, side)
    return SolePose(
        float(T.translation[0]), float(T.translation[1]), math.atan2(T.rotation[1, 0], T.rotation[0, 0])
    )


def make_walk(robot, name: str, q0: np.ndarray | None = None):
    """The issue's walks from the soles of ``q0`` (default: half-sitting)."""
    q0 = robot.q_half_sitting if q0 is None else q0
    kw = {"left_start": _sole(robot, q0, "left"), "right_start": _sole(robot, q0, "right")}
    if name == "straight":
        return straight_walk(10, 0.2, **kw)
    if name == "turn":
        return turn_in_place(math.pi / 2, 4, sole_size_m=robot.sole_size_m, **kw)
    if name == "side":
        return side_steps(6, 0.05, **kw)
    if name == "arc":
        return arc_walk(1.0, math.pi / 2, 18, **kw)
    raise SystemExit(f"unknown walk {name!r}; choose from {WALKS} or all")


def polygon_extent(pattern: WalkPattern, length_m: float, width_m: float) -> np.ndarray:
    """(n, 4) = x_min, x_max, y_min, y_max of the support polygon at every sample."""
    out = np.empty((pattern.n_samples, 4))
    cache: dict[tuple, np.ndarray] = {}
    L, R = pattern.left_sole[:, [0, 1, 3]], pattern.right_sole[:, [0, 1, 3]]
    for k in range(pattern.n_samples):
        ph = int(pattern.phase[k])
        key = (
            (ph, *np.round(L[k], 9))
            if ph == LEFT
            else (ph, *np.round(R[k], 9))
            if ph == RIGHT
            else (ph, *np.round(L[k], 9), *np.round(R[k], 9))
        )
        if key not in cache:
            hull = support_hull(ph, L[k], R[k], length_m, width_m)
            cache[key] = np.array([hull[:, 0].min(), hull[:, 0].max(), hull[:, 1].min(), hull[:, 1].max()])
        out[k] = cache[key]
    return out


def plot_zmp(res: WholeBodyResult, robot, path: Path, title: str) -> None:
    p = res.pattern
    ext = polygon_extent(p, *robot.sole_size_m)
    t = p.times_s
    fig, axes = plt.subplots(2, 1, figsize=(11, 7), sharex=True)
    for ax, axis, (lo, hi) in ((axes[0], 0, (0, 1)), (axes[1], 1, (2, 3))):
        ax.fill_between(t, ext[:, lo], ext[:, hi], color="0.85", step="post", label="support polygon")
        ax.plot(t, p.zmp_ref_m[:, axis], color="0.45", lw=0.8, label="ZMP reference")
        ax.plot(t, p.zmp_planned_m[:, axis], "b:", lw=1.6, label="planned ZMP (cart-table)")
        ax.plot(t, res.zmp_multibody_m[:, axis], "r-", lw=1.0, label="multibody ZMP (whole body)")
        ax.set_ylabel(f"{'xy'[axis]} [m]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=8)
    axes[1].set_xlabel("time [s]")
    margin = 1e3 * res.min_zmp_margin_m
    axes[0].set_title(
        f"{title}: ZMP and support polygon (min multibody ZMP margin {margin:.1f} mm, "
        f"{res.corrections} second-stage corrections)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_com(res: WholeBodyResult, path: Path, title: str) -> None:
    p = res.pattern
    t = p.times_s
    fig, axes = plt.subplots(3, 1, figsize=(11, 7.5), sharex=True)
    for axis, ax in enumerate(axes[:2]):
        ax.plot(t, p.zmp_planned_m[:, axis], "b:", lw=1.4, label="planned ZMP")
        ax.plot(t, p.com_m[:, axis], "k-", lw=1.4, label="CoM (pattern)")
        ax.plot(t, res.com_m[:, axis], "g--", lw=1.0, label="CoM (whole body)")
        ax.set_ylabel(f"{'xy'[axis]} [m]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=8)
    axes[2].plot(t, res.com_m[:, 2], "g-", lw=1.0, label="CoM height (whole body)")
    axes[2].plot(t, p.left_sole[:, 2], color="tab:blue", lw=1.0, label="left sole z")
    axes[2].plot(t, p.right_sole[:, 2], color="tab:orange", lw=1.0, label="right sole z")
    axes[2].set_ylabel("z [m]")
    axes[2].set_xlabel("time [s]")
    axes[2].legend(loc="center right", fontsize=8)
    axes[2].grid(alpha=0.3)
    axes[0].set_title(f"{title}: CoM, ZMP and sole heights", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_footsteps(res: WholeBodyResult, robot, path: Path, title: str) -> None:
    p = res.pattern
    seq = p.footsteps
    length, width = robot.sole_size_m
    pts = np.vstack([p.left_sole[:, :2], p.right_sole[:, :2]])
    span = np.ptp(pts, axis=0) + 2 * length
    aspect = float(np.clip(span[1] / span[0], 0.25, 1.5))
    fig, ax = plt.subplots(figsize=(10, 10 * aspect + 2.0))
    colours = {"left": "tab:blue", "right": "tab:orange"}
    for side, pose in (("left", seq.left_start), ("right", seq.right_start)):
        ax.add_patch(
            Polygon(
                sole_corners(pose, length, width), closed=True, fill=False, ec=colours[side], lw=1.5, ls="--"
            )
        )
    for i, step in enumerate(seq.steps):
        corners = sole_corners(step.pose, length, width)
        ax.add_patch(Polygon(corners, closed=True, fc=colours[step.side], alpha=0.25, ec=colours[step.side]))
        ax.annotate(str(i), (step.pose.x_m, step.pose.y_m), ha="center", va="center", fontsize=8)
    ax.plot(p.zmp_ref_m[:, 0], p.zmp_ref_m[:, 1], color="0.5", lw=0.8, label="ZMP reference")
    ax.plot(res.zmp_multibody_m[:, 0], res.zmp_multibody_m[:, 1], "r-", lw=0.6, label="multibody ZMP")
    ax.plot(p.com_m[:, 0], p.com_m[:, 1], "k-", lw=1.4, label="CoM")
    ax.plot([], [], color=colours["left"], lw=6, alpha=0.4, label="left footsteps (dashed: start)")
    ax.plot([], [], color=colours["right"], lw=6, alpha=0.4, label="right footsteps")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.margins(0.1)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3)
    ax.set_title(f"{title}: footsteps (numbered in order), CoM and ZMP, top view", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_in_sim(robot, name: str) -> tuple[WholeBodyResult, np.ndarray, np.ndarray, str]:
    """Plan ``name`` from the sim's state, execute it; (plan, measured soles (n, 2, 4), times, outcome)."""
    from services.walking.wholebody import plan_walk
    from sim.config import SimConfig

    # TALOS needs more constraint-solver iterations than the sim's default (README of services/walking).
    config = SimConfig(solver_iterations=50) if robot.name == "talos" else SimConfig()
    with World(robot.name, "empty", config=config) as world:
        q0 = world.state().q
        res = plan_walk(world.robot, make_walk(world.robot, name, q0), q0)
        samples: list[np.ndarray] = []
        t0 = world.sim_time_s

        def record(w: World) -> None:
            q = w.pyrobot.read_q()
            row = []
            for side in ("left", "right"):
                s = _sole(robot, q, side)
                row.append([s.x_m, s.y_m, float(robot.sole_pose(q, side).translation[2]), s.yaw_rad])
            samples.append(np.array([w.sim_time_s - t0, *np.ravel(row)]))

        world.on_tick = record
        outcome = world.execute(res.q, hold_s=0.5)
        world.on_tick = None
    data = np.array(samples)
    return (
        res,
        data[:, 1:].reshape(-1, 2, 4),
        data[:, 0],
        outcome.message if outcome.outcome != "completed" else "completed",
    )


def plot_sim(
    res: WholeBodyResult, measured: np.ndarray, times: np.ndarray, outcome: str, path: Path, title: str
) -> None:
    p = res.pattern
    left, right = p.footsteps.final_stance()
    errors = []
    for i, pose in enumerate((left, right)):
        x, y, _, yaw = measured[-1, i]
        errors.append(
            (
                1e3 * math.hypot(x - pose.x_m, y - pose.y_m),
                math.degrees(abs(math.remainder(yaw - pose.yaw_rad, 2 * math.pi))),
            )
        )
    fig, axes = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
    colours = {"left": "tab:blue", "right": "tab:orange"}
    for row, (ax, label) in enumerate(zip(axes, ("x [m]", "y [m]", "z [m]"), strict=True)):
        for i, side in enumerate(("left", "right")):
            ax.plot(
                p.times_s,
                p.sole(side)[:, row],
                "--",
                color=colours[side],
                lw=1.0,
                label=f"{side} sole planned",
            )
            ax.plot(
                times,
                measured[:, i, row],
                "-",
                color=colours[side],
                lw=0.8,
                alpha=0.7,
                label=f"{side} sole in the sim",
            )
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper left", ncol=2)
    axes[2].set_xlabel("time [s]")
    axes[0].set_title(
        f"{title} in the sim: {outcome[:80]}; final sole errors left {errors[0][0]:.1f} mm / "
        f"{errors[0][1]:.2f} deg, right {errors[1][0]:.1f} mm / {errors[1][1]:.2f} deg",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robot", default="hrp2_like", choices=["hrp2_like", "talos"])
    parser.add_argument("--walk", default="all", help=f"one of {', '.join(WALKS)} or all")
    parser.add_argument("--out", default=str(ROOT / "out"), help="output directory")
    parser.add_argument(
        "--sim", action="store_true", help="also execute each walk in the pybullet sim and plot it"
    )
    args = parser.parse_args(argv)
    robot = load_robot(args.robot)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    planner = WholeBodyPlanner(robot)
    q0 = robot.q_half_sitting
    for name in WALKS if args.walk == "all" else (args.walk,):
        seq = make_walk(robot, name)
        pattern = plan_pattern(
            seq,
            WalkTiming(),
            PatternOptions(),
            initial_com_m=robot.com(q0),
            bounds=FootstepBounds.from_robot(robot),
        )
        res = planner.solve(pattern, q0)
        title = f"{robot.name} {name}"
        stem = out / f"walking_{robot.name}_{name}"
        plot_zmp(res, robot, Path(f"{stem}_zmp.png"), title)
        plot_com(res, Path(f"{stem}_com.png"), title)
        plot_footsteps(res, robot, Path(f"{stem}_footsteps.png"), title)
        f = res.figures()
        print(
            f"{title}: {pattern.duration_s:.1f} s, whole body x{f['real_time_factor']:.0f} real time, "
            f"multibody ZMP min margin {f['min_zmp_margin_mm']:.1f} mm, "
            f"wrote {stem}_{{zmp,com,footsteps}}.png"
        )
        if args.sim:
            sim_res, measured, times, outcome = run_in_sim(robot, name)
            plot_sim(sim_res, measured, times, outcome, Path(f"{stem}_sim.png"), title)
            print(f"{title} in the sim: {outcome}; wrote {stem}_sim.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
