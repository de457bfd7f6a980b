"""Plot the reaching paper's Figs. 6, 7 and 8 for a reach beyond the arm's reach, as PNG files under out/.

For the settings asked (``--settings``): ``paper``, the defaults, which are the paper's experiment (its
two criteria, the manipulability of the arm's Jacobian and the end-effector error, S = I; TALOS adds
its joint torque); ``position``, the manipulability of the translation rows only (then the end-effector
error fires instead); ``joint_speed``, the extension criterion (an arm joint beyond 50 % of its limit):

* ``reaching_<robot>_<settings>_snapshots.png`` (Fig. 6): the robot at five instants of the kept motion
  (start, weight on the support foot, mid-swing, landing, goal reached), side and top views;
* ``reaching_<robot>_<settings>_criteria.png`` (Fig. 7): the two criteria of the paper's experiment,
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
import pinocchio as pin
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
# Beyond the left arm's reach on the initial support polygon, one step away (left hand). (0.2, 0.75, 0.9)
# is within hrp2_like's whole-body reach with S = I: reached without a step, nothing triggers.
DEFAULT_TARGETS = {"hrp2_like": (0.60, 0.60, 1.10), "talos": (0.50, 0.65, 1.10)}


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


def snapshot_times(result) -> list[tuple[str, float]]:
    """Fig. 6's instants: start, weight on the support foot (end of the first double support), mid-swing,
    landing, goal reached (end of the hand's motion)."""
    t = result.times_s
    single = np.flatnonzero(result.phase != result.phase[0])
    if single.size == 0:
        instants = np.linspace(0.0, result.reach_end_s, 5)
        return [(f"({c})", float(x)) for c, x in zip("abcde", instants, strict=True)]
    first, last = int(single[0]), int(single[-1])
    return [
        ("(a) start", 0.0),
        ("(b) weight on the support foot", float(t[first])),
        ("(c) swing", float(t[(first + last) // 2])),
        ("(d) landing", float(t[last])),
        ("(e) goal reached", float(result.reach_end_s)),
    ]


def _segments(robot, q: np.ndarray) -> list[np.ndarray]:
    """Lines [m] from each joint to its parent joint and from the hands' joints to the grasp frames."""
    model, data = robot.model, robot.new_data()
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    lines = [
        np.array([data.oMi[model.parents[j]].translation, data.oMi[j].translation])
        for j in range(2, model.njoints)
    ]
    for side in ("left", "right"):
        fid = robot.frame_id(robot.frames.grasp(side))
        parent = model.frames[fid].parentJoint
        lines.append(np.array([data.oMi[parent].translation, data.oMf[fid].translation]))
    return lines


def plot_snapshots(path: Path, result, robot, label: str) -> None:
    """Fig. 6: the robot (its joints as a stick figure) at five instants, side view (x-z) above, top view
    (x-y) below, with the soles and the target."""
    instants = snapshot_times(result)
    fig, axes = plt.subplots(2, len(instants), figsize=(3.0 * len(instants), 6.0))
    length, width = robot.sole_size_m
    for c, (name, t_s) in enumerate(instants):
        k = min(round(t_s / result.dt_s), result.q.shape[0] - 1)
        lines = _segments(robot, result.q[k])
        for row, (i, j) in enumerate(((0, 2), (0, 1))):
            ax = axes[row, c]
            for line in lines:
                ax.plot(line[:, i], line[:, j], color="tab:blue", lw=1.2)
            ax.plot(result.target_world_m[i], result.target_world_m[j], "r*", ms=9)
            if row == 1:
                for sole in (result.left_sole[k], result.right_sole[k]):
                    hull = support_hull(1, sole[[0, 1, 3]], sole[[0, 1, 3]], length, width)
                    ax.add_patch(Polygon(hull, closed=True, fill=False, ec="0.4", lw=0.8))
            ax.set_aspect("equal")
            ax.set_xlim(-0.4, 1.0)
            ax.set_ylim((0.0, 1.6) if row == 0 else (-0.5, 0.9))
            ax.tick_params(labelsize=6)
        axes[0, c].set_title(f"{name}\nt = {t_s:.2f} s", fontsize=8)
    axes[0, 0].set_ylabel("z [m] (side view)")
    axes[1, 0].set_ylabel("y [m] (top view)")
    fig.suptitle(f"Fig. 6 — {robot.name} ({label}): reaching with support polygon reshaping", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_criteria(path: Path, result, monitors_without, robot_name: str) -> None:
    """Fig. 7: the two monitored criteria of the paper's experiment over time, on the initial support
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
            (violation.time_s, 0.55),
            xycoords=("data", "axes fraction"),
            xytext=(6, 0),
            textcoords="offset points",
            fontsize=8,
            color="tab:red",
        )
    axes[1].set_xlabel("time [s]")
    axes[0].legend(fontsize=8, loc="lower left")
    axes[0].set_title(
        f"Fig. 7 — {robot_name}\nthe monitored criteria with and without support polygon reshaping",
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
    "paper": ("defaults = the paper's experiment (2 criteria, S = I)", ReachingOptions()),
    "position": (
        "manipulability of the translation rows only",
        ReachingOptions(manipulability_of="position"),
    ),
    "joint_speed": (
        "with the joint-speed criterion (extension)",
        ReachingOptions(criteria=("manipulability", "ee_error", "joint_speed")),
    ),
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
        default=["paper"],
        help="planner settings to plot (default: paper, the defaults)",
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
        plot_snapshots(out / f"{stem}_snapshots.png", result, robot, label)
        plot_criteria(out / f"{stem}_criteria.png", result, without, f"{robot.name}, {label}")
        plot_zmp(out / f"{stem}_zmp.png", result, robot, cop, label)
        print(f"wrote {out}/{stem}_snapshots.png, {stem}_criteria.png and {stem}_zmp.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
