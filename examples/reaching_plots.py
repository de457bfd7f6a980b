"""Plot the reaching paper's Figs. 6-7 and 8 for a reach beyond the arm's reach, as PNG files under out/.

Each for the paper's experiment (``paper``: its two criteria, S = I) and the stack's defaults (``stack``):

* ``reaching_<robot>_<settings>_criteria.png`` (Figs. 6-7): the two criteria of the paper's experiment,
  the arm's manipulability (eq. 5) and the end-effector error, over time on the initial support polygon
  (computed to its end: "without reshaping"; the planner discards it at the first criterion out of
  range, marked) and in the motion with support polygon reshaping, against their thresholds.
* ``reaching_<robot>_<settings>_zmp.png`` (Fig. 8): the ZMP in x and in y over time against the support
  polygon projected on each axis (shaded): planned (dotted: the pattern generator's, dashed: multibody
  ZMP of the whole-body trajectory) and measured in the sim (solid: centre of pressure of the floor
  contacts), plus a top view of the footsteps, the ZMP and the target.

Usage: python examples/reaching_plots.py [--robot hrp2_like|talos] [--target X Y Z] [--hand left|right]
       [--no-sim] [--settings paper stack] [--out out]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
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
from services.reaching import ReachRequest  # noqa: E402
from services.reaching.options import ReachingOptions  # noqa: E402
from services.reaching.planner import planner_for  # noqa: E402
from services.walking.support_polygon import support_hull  # noqa: E402

MEASURED_WINDOW = 20  # samples (0.1 s) of the moving mean of the measured centre of pressure
# Beyond the left arm's reach on the initial support polygon (left hand).
DEFAULT_TARGETS = {"hrp2_like": (0.90, 0.30, 0.90), "talos": (0.20, 0.80, 1.00)}


def polygon_extents(result, robot) -> np.ndarray:
    """(n, 4) x_min, x_max, y_min, y_max of the support polygon at every sample [m]."""
    length, width = robot.sole_size_m
    out = np.empty((result.times_s.shape[0], 4))
    cache: dict[tuple, np.ndarray] = {}
    for k in range(out.shape[0]):
        left, right = result.left_sole[k, [0, 1, 3]], result.right_sole[k, [0, 1, 3]]
        key = (int(result.phase[k]), *np.round(left, 6), *np.round(right, 6))
        if key not in cache:
            hull = support_hull(int(result.phase[k]), left, right, length, width)
            cache[key] = np.array([hull[:, 0].min(), hull[:, 0].max(), hull[:, 1].min(), hull[:, 1].max()])
        out[k] = cache[key]
    return out


def measured_zmp(robot, result) -> np.ndarray | None:
    """Execute the motion in the sim and record the centre of pressure of the floor contacts (n, 2)."""
    import pybullet as pb

    from sim.world import World

    cop: list[np.ndarray] = []
    with World(robot, "empty") as world:

        def record(w: World) -> None:
            points = pb.getContactPoints(bodyA=w.robot_id, bodyB=w.floor_id, physicsClientId=w.client)
            forces = np.array([c[9] for c in points])
            if forces.sum() <= 0.0:
                cop.append(np.full(2, np.nan))
                return
            positions = np.array([c[6][:2] for c in points])
            cop.append(forces @ positions / forces.sum())

        world.on_tick = record
        execution = world.execute(result.q)
        world.on_tick = None
        print(f"sim: {execution.outcome}, {execution.message}")
    return np.array(cop) if cop else None


def smooth(x: np.ndarray, window: int = MEASURED_WINDOW) -> np.ndarray:
    """Centred moving mean (pybullet's contact forces alternate between sole corners at every step)."""
    kernel = np.ones(window) / window
    padded = np.pad(x, (window // 2, window - 1 - window // 2), mode="edge")
    return np.convolve(padded, kernel, mode="valid")


def plot_criteria(path: Path, result, monitors_without, robot_name: str) -> None:
    """Figs. 6-7: the two monitored criteria of the paper's experiment over time, on the initial support
    polygon (computed to its end: "without reshaping") and in the kept motion, with the threshold and
    the trigger (the first criterion out of range: where the motion on the initial polygon is
    discarded and reshaping starts) marked."""
    fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    violation = result.attempts[0].violation
    series = (
        ("manipulability", "manipulability w = sqrt(det(J J^T))", result.thresholds.manipulability, "1.5e-4"),
        ("ee_error_m", "end-effector error [m]", result.thresholds.ee_error_m, "4e-5 m"),
    )
    for ax, (field, label, threshold, text) in zip(axes, series, strict=True):
        ax.plot(
            monitors_without.times_s,
            getattr(monitors_without, field),
            "--",
            color="tab:red",
            label="without reshaping (initial support polygon)",
        )
        ax.plot(
            result.monitors.times_s, getattr(result.monitors, field), color="tab:blue", label="with reshaping"
        )
        ax.axhline(threshold, color="k", lw=0.8, label=f"threshold ({text})")
        ax.set_yscale("log")
        ax.set_ylabel(label)
        if violation is not None:
            ax.axvline(violation.time_s, color="tab:red", lw=0.8, ls=":")
    if violation is not None:
        axes[0].annotate(
            f"'{violation.criterion}' fails at t = {violation.time_s:.2f} s:\nmotion discarded, reshaping "
            f"({len(result.footsteps)} step{'s' if len(result.footsteps) != 1 else ''})",
            (violation.time_s, axes[0].get_ylim()[1] * 0.3),
            fontsize=8,
            color="tab:red",
        )
    axes[1].set_xlabel("time [s]")
    axes[0].legend(fontsize=8, loc="lower left")
    axes[0].set_title(
        f"Figs. 6-7 — {robot_name}\nthe monitored criteria with and without support polygon reshaping",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_zmp(path: Path, result, robot, cop: np.ndarray | None, label: str = "") -> None:
    t = result.times_s
    ext = polygon_extents(result, robot)
    fig = plt.figure(figsize=(12, 4.5))
    for i, axis in enumerate("xy"):
        ax = fig.add_subplot(1, 3, i + 1)
        ax.fill_between(t, ext[:, 2 * i], ext[:, 2 * i + 1], color="0.85", label="support polygon")
        ax.plot(t, result.zmp_planned_m[:, i], ":", color="k", label="planned (pattern generator)")
        ax.plot(t, result.zmp_multibody_m[:, i], "--", color="tab:blue", label="planned (multibody)")
        if cop is not None:
            n = min(len(cop), len(t) - 1)
            ax.plot(
                t[1 : n + 1],
                smooth(cop[:n, i]),
                color="tab:red",
                lw=1.0,
                label="measured in the sim (0.1 s mean)",
            )
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"ZMP {axis} [m]")
        if i == 0:
            ax.legend(fontsize=7, loc="upper left")
    ax = fig.add_subplot(1, 3, 3)
    length, width = robot.sole_size_m
    for k in sorted({0, *np.flatnonzero(np.diff(result.phase) != 0), len(t) - 1}):
        for sole, colour in ((result.left_sole[k], "tab:green"), (result.right_sole[k], "tab:orange")):
            hull = support_hull(1, sole[[0, 1, 3]], sole[[0, 1, 3]], length, width)
            ax.add_patch(Polygon(hull, closed=True, fill=False, ec=colour, lw=0.8))
    ax.plot(result.zmp_multibody_m[:, 0], result.zmp_multibody_m[:, 1], color="tab:blue", lw=0.8, label="ZMP")
    ax.plot(result.com_m[:, 0], result.com_m[:, 1], color="k", lw=0.8, label="CoM")
    ax.plot(*result.target_world_m[:2], "r*", ms=10, label="target")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7)
    ax.set_title("top view (soles: left green, right orange)", fontsize=8)
    fig.suptitle(
        f"Fig. 8 — {robot.name} ({label}): ZMP against the support polygon, {len(result.footsteps)} step(s), "
        f"min margin {1e3 * result.min_zmp_margin_m:.0f} mm",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


SETTINGS = {
    "stack": ("the stack's defaults", ReachingOptions()),
    "paper": ("the paper's experiment (2 criteria, S = I)", ReachingOptions.paper_experiment()),
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robot", default="hrp2_like", choices=("hrp2_like", "talos"))
    parser.add_argument("--target", type=float, nargs=3, metavar=("X", "Y", "Z"), help="target [m]")
    parser.add_argument("--hand", choices=("left", "right"), help="default: the target's side")
    parser.add_argument("--no-sim", action="store_true", help="do not execute in the sim (no measured ZMP)")
    parser.add_argument(
        "--settings",
        nargs="+",
        choices=sorted(SETTINGS),
        default=["paper", "stack"],
        help="planner settings to plot: the paper's experiment and/or the stack's defaults (default both)",
    )
    parser.add_argument("--out", default=str(ROOT / "out"), help="output directory (default out/)")
    args = parser.parse_args(argv)

    robot = load_robot(args.robot)
    target = np.array(args.target or DEFAULT_TARGETS[robot.name])
    hand = args.hand or ("left" if target[1] >= 0 else "right")
    request = ReachRequest(hand, target, robot.q_half_sitting)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in args.settings:
        label, options = SETTINGS[name]
        planner = planner_for(robot.name, options)
        result = planner.plan(request)
        _, without = planner.without_reshaping(request)
        print(
            f"{robot.name}, {label}: {len(result.footsteps)} step(s), {result.duration_s:.1f} s motion "
            f"planned in {result.wall_time_s:.2f} s; attempts: "
            + ", ".join(
                f"{a.kind}"
                + (f" ({a.violation.criterion} at {a.violation.time_s:.2f} s)" if a.violation else "")
                for a in result.attempts
            )
        )
        cop = None if args.no_sim else measured_zmp(robot, result)
        stem = f"reaching_{robot.name}_{name}"
        plot_criteria(out / f"{stem}_criteria.png", result, without, f"{robot.name}, {label}")
        plot_zmp(out / f"{stem}_zmp.png", result, robot, cop, label)
        print(f"wrote {out}/{stem}_criteria.png and {stem}_zmp.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
