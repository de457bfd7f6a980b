"""Figures of the two-stage navigation planner ("Manipulating While Walking", `001_771c0ce3779b0683.txt`).

``out/navigation_topview.png`` (stage 1): left, the demo room (6 x 6 m), a path from the south-west
corner to "in front of the yellow table, facing it, at 0.4 m", its footprint rectangles and footsteps;
right, the bar-carrying scene (Figure 2 (a)): the bar held at 0.9 m along the path meets the box on the
table; colliding bar positions in red, the anticipating and regaining limits marked.

``out/navigation_bar_reshaping.png`` (stage 2, Figures 2 and 3): the whole two-stage plan of the bar
scenario from the robot holding the bar on its stands: top view of the path, the footsteps and the bar
as the whole-body motion carries it (coloured by height); the bar's height over time before reshaping
(first whole-body solution) and after (key frames at the anticipating, colliding and regaining times,
quintic interpolation, the reshaped whole-body motion); the bar's distance to the box before and after.

    .venv/bin/python examples/navigation_plots.py            # writes both PNGs under out/
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib import cm
from matplotlib.axes import Axes
from matplotlib.colors import Normalize
from matplotlib.patches import Circle, Polygon

from services.model import load_robot
from services.navigation.body_extents import with_arms_of
from services.navigation.demo_scenes import (
    BAR_BOX_TOP_M,
    BAR_TABLE_TOP_M,
    bar_scenario,
    bar_scenario_start,
    demo_room,
)
from services.navigation.footsteps_along_path import FootstepOptions, footsteps_along_path
from services.navigation.geometry import BodyModel, BoxObstacle, Scene, body_model
from services.navigation.goals import ObjectGoal
from services.navigation.goto import GotoOptions, GotoResult, plan_goto
from services.navigation.path import PlannerConfig, SampledPath, plan_path
from services.navigation.stage2 import Stage2Options
from services.navigation.upper_body import CarriedBar, sweep_carried_object

REPO = Path(__file__).resolve().parents[1]


def _rect(cx: float, cy: float, hx: float, hy: float, yaw: float) -> list[tuple[float, float]]:
    c, s = math.cos(yaw), math.sin(yaw)
    return [(cx + c * x - s * y, cy + s * x + c * y) for x, y in ((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy))]


def draw_scene(ax: Axes, scene: Scene) -> None:
    """Obstacles coloured by their top height (walls grey), lowest first so objects on tables show."""
    tops = [o.z_range_m[1] for o in scene.obstacles if not o.name.startswith("wall")]
    norm = Normalize(vmin=0.0, vmax=max(tops, default=1.0))
    for o in sorted(scene.obstacles, key=lambda o: o.z_range_m[1]):
        wall = o.name.startswith("wall")
        if isinstance(o, BoxObstacle):
            patch = Polygon(_rect(*o.center_xyz_m[:2], *(0.5 * v for v in o.size_xyz_m[:2]), o.yaw_rad))
        else:
            patch = Circle(o.center_xyz_m[:2], o.radius_m)
        patch.set_facecolor("dimgray" if wall else cm.viridis(norm(o.z_range_m[1])))
        patch.set_edgecolor("black")
        patch.set_alpha(0.85)
        ax.add_patch(patch)
        if not wall:
            z0, z1 = o.z_range_m
            x, y = o.center_xyz_m[:2]
            ax.annotate(
                f"{o.name}\nz {z0:.2f}-{z1:.2f}", (x, y), ha="center", va="center", fontsize=7, color="white"
            )
    ax.figure.colorbar(
        cm.ScalarMappable(norm=norm, cmap="viridis"), ax=ax, shrink=0.6, label="obstacle top z [m]"
    )
    xmin, xmax, ymin, ymax = scene.bounds_xy_m
    ax.set_xlim(xmin - 0.2, xmax + 0.2)
    ax.set_ylim(ymin - 0.2, ymax + 0.2)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def draw_path(ax: Axes, path: SampledPath, body: BodyModel, every_m: float = 0.6) -> None:
    ax.plot(
        path.xy_m[:, 0], path.xy_m[:, 1], "-", color="tab:green", lw=2, label=f"path {path.length_m:.2f} m"
    )
    back = ~path.forward
    if back.any():
        ax.plot(
            path.xy_m[back, 0], path.xy_m[back, 1], ".", color="tab:orange", ms=3, label="walking backward"
        )
    hx, hy = body.half_extents_m
    s = 0.0
    while s <= path.length_m:
        p = path.pose_at(s)
        ax.add_patch(
            Polygon(_rect(p.x_m, p.y_m, hx, hy, p.theta_rad), fill=False, ec="tab:green", lw=0.6, alpha=0.6)
        )
        s += every_m
    for pose, label in ((path.start, "start"), (path.goal, "goal")):
        ax.annotate(
            label,
            (pose.x_m, pose.y_m),
            xytext=(pose.x_m + 0.4 * math.cos(pose.theta_rad), pose.y_m + 0.4 * math.sin(pose.theta_rad)),
            arrowprops={"arrowstyle": "<-", "color": "black"},
            fontsize=8,
        )


def draw_footsteps(ax: Axes, path: SampledPath, body: BodyModel) -> int:
    steps = footsteps_along_path(path, options=FootstepOptions.for_body(body)).sequence
    for k, step in enumerate(steps.steps):
        colour = "tab:blue" if step.side == "left" else "tab:red"
        p = step.pose
        ax.add_patch(Polygon(_rect(p.x_m, p.y_m, 0.12, 0.07, p.yaw_rad), fill=False, ec=colour, lw=0.8))
        if k % 5 == 0:
            ax.annotate(str(k), (p.x_m, p.y_m), fontsize=5, ha="center", va="center", color=colour)
    return len(steps.steps)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=REPO / "out" / "navigation_topview.png", help="PNG path")
    parser.add_argument(
        "--bar-out", type=Path, default=REPO / "out" / "navigation_bar_reshaping.png", help="PNG of stage 2"
    )
    parser.add_argument("--robot", default="hrp2_like", help="body model (hrp2_like, talos)")
    parser.add_argument("--turning-radius", type=float, default=0.5, help="minimum turning radius [m]")
    args = parser.parse_args(argv)
    body = body_model(args.robot)
    config = PlannerConfig(turning_radius_m=args.turning_radius)
    fig, (ax_room, ax_bar) = plt.subplots(1, 2, figsize=(15, 7.5))

    scene, start, _ = demo_room()
    path = plan_path(scene, body, start, ObjectGoal("yellow_table", 0.4), config)
    draw_scene(ax_room, scene)
    draw_path(ax_room, path, body)
    n_steps = draw_footsteps(ax_room, path, body)
    ax_room.set_title(
        f"demo room: to 0.4 m in front of yellow_table ({path.curve}, {path.planner}, "
        f"{1e3 * path.plan_time_s:.0f} ms), {n_steps} footsteps"
    )
    ax_room.legend(loc="lower right", fontsize=8)

    scene, start, goal = bar_scenario()
    robot = load_robot(args.robot)
    holding = with_arms_of(body, robot, bar_scenario_start(robot))  # the arms ahead, holding the bar
    path = plan_path(scene, holding, start, goal, config)
    bar = CarriedBar(height_m=0.9)
    sweep = sweep_carried_object(scene, path, bar, holding)
    draw_scene(ax_bar, scene)
    draw_path(ax_bar, path, holding, every_m=1.0)
    draw_footsteps(ax_bar, path, holding)
    for k in range(0, len(path.s_m), 5):
        theta = path.theta_rad[k]
        cx = path.xy_m[k, 0] + bar.forward_m * math.cos(theta)
        cy = path.xy_m[k, 1] + bar.forward_m * math.sin(theta)
        dx, dy = -0.5 * bar.length_m * math.sin(theta), 0.5 * bar.length_m * math.cos(theta)
        hit = sweep.bar_distance_m[k] < 0.0
        ax_bar.plot(
            [cx - dx, cx + dx], [cy - dy, cy + dy], color="red" if hit else "silver", lw=0.8 if hit else 0.4
        )
    for seg in sweep.segments:
        limits = (
            (seg.s_anticipate_m, "anticipating", -0.3),
            (seg.s_collide_m, "colliding", -0.6),
            (seg.s_collide_end_m, "collision ends", -0.9),
            (seg.s_regain_m, "regaining", -0.3),
        )
        for s, label, dy in limits:
            p = path.pose_at(s)
            ax_bar.plot([p.x_m], [p.y_m], "k|", ms=14)
            ax_bar.annotate(f"{label}\ns={s:.2f} m", (p.x_m, p.y_m + dy), fontsize=7, ha="center", va="top")
    title = "; ".join(
        f"{seg.part} hits {list(seg.obstacles)}, clears at {seg.clear_height_m:.2f} m"
        for seg in sweep.segments
    )
    ax_bar.set_title(f"bar scenario, bar at {bar.height_m} m: {title or 'collision-free'}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    plot_bar_reshaping(args.robot, args.bar_out)
    print(f"wrote {args.bar_out}")
    return 0


def plan_bar_scenario(robot_name: str) -> GotoResult:
    """The two-stage plan of the bar scenario: from the robot holding the bar on its stands to the goal,
    the bar carried at 0.8 m."""
    robot = load_robot(robot_name)
    scene, _, goal = bar_scenario()
    options = GotoOptions(stage2=Stage2Options(carry_height_m=0.8))
    return plan_goto(robot, scene, bar_scenario_start(robot), goal, CarriedBar(), options)


def plot_bar_reshaping(robot_name: str, out: Path) -> None:
    """Top view, bar height and bar-box distance over time of the reshaped bar scenario."""
    scene, _, _ = bar_scenario()
    result = plan_bar_scenario(robot_name)
    motion = result.motion
    t = motion.times_s
    fig = plt.figure(figsize=(15, 9))
    grid = fig.add_gridspec(2, 2, height_ratios=(1.15, 1.0))
    ax_top = fig.add_subplot(grid[0, :])
    ax_h = fig.add_subplot(grid[1, 0])
    ax_d = fig.add_subplot(grid[1, 1], sharex=ax_h)

    body = body_model(robot_name)
    draw_scene(ax_top, scene)
    draw_path(ax_top, result.path, body, every_m=1.0)
    for step in result.footsteps.sequence.steps:
        colour = "tab:blue" if step.side == "left" else "tab:red"
        p = step.pose
        ax_top.add_patch(Polygon(_rect(p.x_m, p.y_m, 0.12, 0.07, p.yaw_rad), fill=False, ec=colour, lw=0.8))
    centre = motion.bar_centre_m
    half = 0.5 * CarriedBar().length_m
    norm = Normalize(vmin=float(centre[:, 2].min()), vmax=float(centre[:, 2].max()))
    q = motion.q
    for k in range(0, len(t), 60):
        yaw = float(
            np.arctan2(2 * (q[k, 6] * q[k, 5] + q[k, 3] * q[k, 4]), 1 - 2 * (q[k, 4] ** 2 + q[k, 5] ** 2))
        )
        dx, dy = -half * math.sin(yaw), half * math.cos(yaw)
        cx, cy = centre[k, 0], centre[k, 1]
        ax_top.plot([cx - dx, cx + dx], [cy - dy, cy + dy], color=cm.plasma(norm(centre[k, 2])), lw=0.9)
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap="plasma"), ax=ax_top, shrink=0.6, label="bar height [m]")
    ax_top.set_xlim(-0.6, 3.8)
    ax_top.set_ylim(-1.4, 1.4)
    report = motion.report()
    ax_top.set_title(
        f"stage 2: {len(result.footsteps.sequence.steps)} footsteps, {report['iterations']} whole-body "
        f"solutions, bar lifted over {[list(w.obstacles) for w in motion.windows]}; min clearance "
        f"{1e3 * report['min_clearance_m']:.0f} mm,\nmultibody ZMP margin "
        f"{1e3 * report['zmp_margin_m']:.0f} mm (bar included), "
        f"planned in {result.timings_s['total_s']:.1f} s"
    )

    ax_h.plot(t, motion.bar_height_nominal_m, ":", color="gray", label="nominal (task space)")
    ax_h.plot(
        t, motion.bar_height_first_m, "-", color="tab:red", lw=1.2, label="before reshaping (whole body)"
    )
    ax_h.plot(
        t, motion.bar_height_planned_m, "--", color="tab:blue", lw=1.2, label="key frames + quintics, 5 ms"
    )
    ax_h.plot(t, centre[:, 2], "-", color="tab:green", lw=1.0, label="after reshaping (whole body)")
    ax_h.axhline(BAR_BOX_TOP_M, color="tab:olive", lw=0.8)
    ax_h.annotate("box top", (t[-1], BAR_BOX_TOP_M), ha="right", va="bottom", fontsize=8)
    ax_h.axhline(BAR_TABLE_TOP_M, color="goldenrod", lw=0.8)
    ax_h.annotate("table top", (t[-1], BAR_TABLE_TOP_M), ha="right", va="bottom", fontsize=8)
    for w in motion.windows:
        for time_s, label in (
            (w.t_anticipate_s, "anticipating"),
            (w.t_collide_s, "colliding"),
            (w.t_collide_end_s, "collision ends"),
            (w.t_regain_s, "regaining"),
        ):
            ax_h.axvline(time_s, color="black", lw=0.5, ls="--")
            ax_h.annotate(label, (time_s, 0.74), rotation=90, fontsize=7, ha="right", va="bottom")
    ax_h.set_xlabel("time [s]")
    ax_h.set_ylabel("bar centre height [m]")
    ax_h.set_title("the bar's height before and after reshaping (Figure 2 (b)-(d))")
    ax_h.legend(fontsize=7, loc="upper left")

    before = motion.iterations[0]
    first = [e for e in before.events if e.group == "bar"]
    box = motion.check.obstacles.index("box")
    bar_g = motion.check.groups.index("bar")
    exact_within = 0.25  # MotionChecker: distances are exact below this, lower bounds above
    for check, colour, label in (
        (motion.first_check, "tab:red", "before reshaping"),
        (motion.check, "tab:green", "after reshaping"),
    ):
        if check is not None:
            d = check.distance_m[:, bar_g, box]
            ax_d.plot(t, np.where(d < exact_within, d, np.nan), color=colour, label=label)
    if first:
        ax_d.axvspan(
            first[0].t_start_s, first[-1].t_end_s, color="tab:red", alpha=0.2, label="colliding before"
        )
    ax_d.axhline(0.0, color="black", lw=0.6)
    ax_d.axhline(0.02, color="gray", lw=0.6, ls=":")
    ax_d.annotate("required clearance", (t[0], 0.02), fontsize=7, va="bottom")
    ax_d.set_ylim(-0.15, exact_within)
    ax_d.set_xlabel("time [s]")
    ax_d.set_ylabel("signed distance bar - box [m]")
    ax_d.set_title(f"bar to box; before reshaping: {1e3 * before.min_clearance_m:.0f} mm (penetration)")
    ax_d.legend(fontsize=7)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
