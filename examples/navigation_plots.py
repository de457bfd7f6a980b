"""Top view of stage 1 of the navigation planner: obstacles, the planned path, the footprint along it,
the footsteps, and the carried bar's sweep in the bar scenario.

Left: the demo room (6 x 6 m), a path from the south-west corner to "in front of the yellow table, facing
it, at 0.4 m", its footprint rectangles and footsteps. Right: the bar-carrying scene of "Manipulating
While Walking" (`001_771c0ce3779b0683.txt`, Figure 2 (a)): the bar held at 0.9 m meets the box on the
table; colliding bar positions in red, the anticipating and regaining limits marked.

    .venv/bin/python examples/navigation_plots.py            # writes out/navigation_topview.png
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib import cm
from matplotlib.axes import Axes
from matplotlib.colors import Normalize
from matplotlib.patches import Circle, Polygon

from services.navigation.demo_scenes import bar_scenario, demo_room
from services.navigation.footsteps_along_path import FootstepOptions, footsteps_along_path
from services.navigation.geometry import BodyModel, BoxObstacle, Scene, body_model
from services.navigation.goals import ObjectGoal
from services.navigation.path import PlannerConfig, SampledPath, plan_path
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
    path = plan_path(scene, body, start, goal, config)
    bar = CarriedBar(height_m=0.9)
    sweep = sweep_carried_object(scene, path, bar, body)
    draw_scene(ax_bar, scene)
    draw_path(ax_bar, path, body, every_m=1.0)
    draw_footsteps(ax_bar, path, body)
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
