"""Figures of the footstep planner: the states of the virtual chain seen from above at several
iterations and the final footprints (like Figs. 6, 7 and 11 of the footstep paper), and the task
values against the iterations with the step additions marked (like Fig. 10). Matplotlib (Agg), PNG."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pinocchio as pin
from matplotlib.patches import Circle, Polygon

from services.errors import InvalidRequestError
from services.footsteps.request import FootstepPlanRequest, FootstepPlanResult
from services.model import RobotModel
from services.model.ground import sole_corners
from services.walking.footsteps import SolePose

_SIDE_COLOUR = {"left": "tab:blue", "right": "tab:red"}


def _draw_footprint(ax, side: str, x: float, y: float, yaw: float, size: tuple[float, float], **kw) -> None:
    corners = sole_corners(SolePose(x, y, yaw), *size)
    ax.add_patch(Polygon(corners, closed=True, edgecolor=_SIDE_COLOUR[side], **kw))


def _draw_robot_top(ax, robot: RobotModel, q: Sequence[float]) -> None:
    """The robot's capsules projected on the ground (a top view of the body)."""
    data = robot.new_data()
    q = np.asarray(q, dtype=float)
    pin.framesForwardKinematics(robot.model, data, q)
    for c in robot.capsules:
        T = data.oMf[robot.frame_id(c.frame)]
        p0, p1 = T.act(np.asarray(c.p0_local)), T.act(np.asarray(c.p1_local))
        ax.plot(
            [p0[0], p1[0]],
            [p0[1], p1[1]],
            color="0.35",
            lw=max(1.0, 60 * c.radius_m),
            alpha=0.25,
            solid_capstyle="round",
        )
    com = pin.centerOfMass(robot.model, data, q)
    ax.plot(com[0], com[1], "k+", ms=8)


def _draw_targets(ax, request: FootstepPlanRequest) -> None:
    for disk in request.disks:
        ax.add_patch(Circle((disk.x_m, disk.y_m), disk.radius_m, color="0.6", alpha=0.5, lw=0))
    for task in request.tasks:
        if task.target_m is not None:
            marker = "o" if task.kind == "reach" else "*"
            ax.plot(task.target_m[0], task.target_m[1], marker, color="tab:green", ms=10, mec="k")


def chain_states_figure(
    robot: RobotModel,
    request: FootstepPlanRequest,
    result: FootstepPlanResult,
    path: Path,
    n_panels: int = 5,
    title: str = "",
) -> Path:
    """Top views of the chain at ``n_panels - 1`` iterations spread over the solve, then the retained
    footsteps with the final posture (needs a result planned with ``record_trace``)."""
    trace = result.trace
    if trace is None:
        raise InvalidRequestError("the result has no trace: plan with record_trace=True")
    n_iter = len(trace.footprints)
    picks = sorted({round(float(k)) for k in np.linspace(0, n_iter - 1, max(2, n_panels - 1))})
    # frame all panels alike
    pts = [np.array([f[1], f[2]]) for state in trace.footprints for f in state]
    pts += [np.array(t.target_m[:2]) for t in request.tasks if t.target_m is not None]
    pts += [np.array([d.x_m, d.y_m]) for d in request.disks]
    pts_a = np.array(pts)
    lo, hi = pts_a.min(0) - 0.35, pts_a.max(0) + 0.35
    size = robot.sole_size_m
    n_axes = len(picks) + 1
    aspect = float((hi[0] - lo[0]) / (hi[1] - lo[1]))

    # panel grid whose overall shape is closest to 16:10, preferring full rows
    def grid_cost(c: int) -> float:
        rows = math.ceil(n_axes / c)
        return abs(math.log(c * aspect / rows / 1.6)) + 0.3 * (rows * c - n_axes)

    ncols = min(range(1, n_axes + 1), key=grid_cost)
    nrows = math.ceil(n_axes / ncols)
    panel_w = 3.4 if aspect <= 1.5 else min(7.5, 2.6 * aspect)
    fig, grid = plt.subplots(
        nrows, ncols, figsize=(panel_w * ncols, panel_w / aspect * nrows + 0.7 * nrows), squeeze=False
    )
    axes_list = list(grid.ravel())
    for ax in axes_list[n_axes:]:
        ax.set_visible(False)
    axes = [axes_list[:n_axes]]
    for ax, k in zip(axes[0], picks, strict=False):
        state = trace.footprints[k]
        _draw_targets(ax, request)
        xs = [f[1] for f in state]
        ys = [f[2] for f in state]
        ax.plot(xs, ys, "-", color="0.5", lw=0.8)  # the virtual chain F_0 .. F_{p-1}, front foot
        for i, (side, x, y, yaw) in enumerate(state):
            last = i == len(state) - 1
            _draw_footprint(
                ax, side, x, y, yaw, size, fill=False, lw=1.6 if last else 1.0, ls="--" if last else "-"
            )
        _draw_robot_top(ax, robot, trace.q_robot[k])
        added = sum(1 for a in trace.steps_added_at if a < k)
        ax.set_title(
            f"iteration {k}\n{len(state) - 1 if len(state) > 1 else 0} chain links, {added} added", fontsize=9
        )
    ax = axes[0][-1]
    _draw_targets(ax, request)
    for side, start in (("left", result.left_start), ("right", result.right_start)):
        _draw_footprint(ax, side, *start, size, fill=False, lw=1.0, ls=":")
    for i, s in enumerate(result.footsteps):
        _draw_footprint(ax, s.side, s.x_m, s.y_m, s.yaw_rad, size, fill=True, alpha=0.35, lw=1.2)
        ax.text(s.x_m, s.y_m, str(i + 1), ha="center", va="center", fontsize=8)
    _draw_robot_top(ax, robot, result.q_final)
    ax.set_title(f"retained: {result.n_steps} steps\n(planned in {result.solve_time_s:.2f} s)", fontsize=9)
    for ax in axes[0]:
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _draw_task_values(ax, request: FootstepPlanRequest, result: FootstepPlanResult) -> None:
    """Task values against the iterations on ``ax``, a dashed line at each step addition drawn to the
    curve of the highest-priority unsolved task, the one that motivated it (Fig. 10)."""
    trace = result.trace
    if trace is None:
        raise InvalidRequestError("the result has no trace: plan with record_trace=True")
    values = np.array(trace.values)
    iters = np.arange(values.shape[0])
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    tolerances = [t.tol() for t in request.tasks]
    for i, name in enumerate(trace.task_names):
        ax.plot(iters, values[:, i], color=colours[i % len(colours)], lw=1.5, label=f"task {i + 1}: {name}")
        if np.isfinite(tolerances[i]):
            ax.axhline(tolerances[i], color=colours[i % len(colours)], lw=0.6, ls=":")
    for k in trace.steps_added_at:
        k = min(k, values.shape[0] - 1)
        unsolved = [i for i in range(values.shape[1]) if values[k, i] > tolerances[i]]
        i = unsolved[0] if unsolved else values.shape[1] - 1
        ax.vlines(k, 0.0, values[k, i], color=colours[i % len(colours)], lw=1.0, ls="--")
        ax.plot(k, values[k, i], "v", color=colours[i % len(colours)], ms=5)
    ax.set_xlabel("iteration")
    ax.set_ylabel("task value (eqs. 5-6)")
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def task_values_figure(
    request: FootstepPlanRequest, result: FootstepPlanResult, path: Path, title: str = ""
) -> Path:
    """Task values (eqs. 5-6) against the iterations, a vertical line at each step addition (Fig. 10)."""
    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    _draw_task_values(ax, request, result)
    n_added = len(result.trace.steps_added_at) if result.trace else 0
    ax.set_title(title or f"task values, {n_added} step additions (dashed)", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def epsilon_study_figure(
    runs: Sequence[tuple[str, FootstepPlanRequest, FootstepPlanResult, float]], path: Path, title: str = ""
) -> Path:
    """Fig. 10 (b)-(e): one panel of task values per threshold setting (label, request, result, CPU
    time of the solve [s]), the step additions marked, the steps and the computation time in each
    panel's title."""
    fig, axes = plt.subplots(1, len(runs), figsize=(5.2 * len(runs), 3.8), squeeze=False)
    for ax, (label, request, result, solve_s) in zip(axes[0], runs, strict=True):
        _draw_task_values(ax, request, result)
        ax.set_title(f"{label}: {result.n_steps} steps, {solve_s:.2f} s CPU", fontsize=10)
    fig.suptitle(title or "threshold study (Fig. 10 b-e)", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
