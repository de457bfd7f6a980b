"""Run the paper's scenarios with their figures (shared by ``humanoid scenario footsteps-*`` and
``examples/footsteps_scenarios.py``)."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from services.errors import InfeasibleError, InvalidRequestError
from services.footsteps import scenarios
from services.footsteps.planner import plan_footsteps_best
from services.footsteps.plotting import chain_states_figure, task_values_figure
from services.model import load_robot


def run_scenario(
    name: str,
    robot_name: str = "hrp2_like",
    out_dir: Path | None = Path("out"),
    front_foot: str = "auto",
    execute: bool = False,
    posture_objective: bool = False,
) -> dict[str, Any]:
    """Plan scenario ``name`` ("reach", "pickup", "posture" or "fig10"), draw its figures into
    ``out_dir`` (``footsteps_<name>_chain.png``, ``footsteps_<name>_values.png``; None: no figure),
    optionally turn the plan into the whole-body motion (walk + reach, ``footsteps_<name>_motion.npz``;
    a plan the walking planner rejects is reported in ``motion_error``), and return a plain-data
    summary. ``posture_objective``: the stack's variant of "reach" and "pickup" (the rest posture as
    the lowest task) instead of the paper's task set."""
    if name not in scenarios.SCENARIOS:
        raise InvalidRequestError(f"unknown scenario {name!r}; valid: {sorted(scenarios.SCENARIOS)}")
    robot = load_robot(robot_name)
    factory = scenarios.SCENARIOS[name]
    scenario = factory(robot_name, posture_objective=True) if posture_objective else factory(robot_name)
    request = scenarios.with_trace(scenario.request)
    if front_foot != "auto":
        from dataclasses import replace

        request = replace(request, front_foot=front_foot)
    t0 = time.process_time()
    result, error = plan_footsteps_best(request, robot)
    cpu_s = time.process_time() - t0
    summary: dict[str, Any] = {
        "scenario": name,
        "title": scenario.title,
        "solved": error is None,
        "error": None if error is None else error.message,
        "steps": result.n_steps,
        "iterations": result.iterations,
        "steps_added_at": list(result.steps_added_at),
        "solve_wall_s": result.solve_time_s,
        "solve_cpu_s": cpu_s,
        "paper_s": scenario.paper_solve_s,
        "paper_steps": scenario.paper_steps,
        "front_foot": result.front_foot,
        "alternatives": [list(a) for a in result.alternatives],
        "residuals": {r.name: r.value for r in result.residuals},
        "footsteps": [[s.side, s.x_m, s.y_m, s.yaw_rad] for s in result.footsteps],
        "figures": [],
    }
    if out_dir is not None:
        out_dir = Path(out_dir)
        label = "solved" if error is None else "NOT SOLVED"
        title = f"{scenario.title} [{robot_name}, {label}]"
        summary["figures"].append(
            str(
                chain_states_figure(
                    robot, request, result, out_dir / f"footsteps_{name}_chain.png", title=title
                )
            )
        )
        summary["figures"].append(
            str(task_values_figure(request, result, out_dir / f"footsteps_{name}_values.png", title=title))
        )
    if execute and error is None:
        from services.footsteps.execution import execute_plan

        t0 = time.perf_counter()
        try:
            motion = execute_plan(robot, request, result)
        except InfeasibleError as exc:
            summary["motion_error"] = exc.message
            return summary
        adjustment = motion.walk_adjustment
        summary["walk_timing"] = (
            "default"
            if adjustment is None or (adjustment.com_lowering_m == 0.0 and adjustment.slowdown == 1.0)
            else f"CoM lowered {100 * adjustment.com_lowering_m:.0f} cm, supports x{adjustment.slowdown:g}"
        )
        summary["motion"] = {
            "duration_s": motion.duration_s,
            "walk_end_s": motion.walk_end_s,
            "compute_s": time.perf_counter() - t0,
            "final_errors_m": motion.final_errors_m,
            "reach_max_sole_drift_m": motion.reach_max_sole_drift_m,
            "reach_min_com_margin_m": motion.reach_min_com_margin_m,
            "reach_min_self_distance_m": motion.reach_min_self_distance_m,
            "walk": None if motion.walk is None else motion.walk.figures(),
        }
        if out_dir is not None:
            path = Path(out_dir) / f"footsteps_{name}_motion.npz"
            np.savez_compressed(path, times_s=motion.times_s, q=motion.q, walk_end_s=motion.walk_end_s)
            summary["figures"].append(str(path))
    return summary


def run_epsilon_study(
    robot_name: str = "hrp2_like", out_dir: Path | None = Path("out")
) -> list[dict[str, Any]]:
    """Fig. 10's threshold study: the ``fig10`` scenario with every epsilon_i scaled low, average and
    high (``scenarios.EPSILON_STUDY``); rows (label, scale, solved, steps, steps_added_at, solve_s)
    and, with ``out_dir``, ``footsteps_fig10_epsilon.png``."""
    from services.footsteps.plotting import epsilon_study_figure

    robot = load_robot(robot_name)
    rows, runs = [], []
    for label, scale in scenarios.EPSILON_STUDY.items():
        request = scenarios.with_trace(scenarios.fig10(robot_name, scale).request)
        t0, c0 = time.perf_counter(), time.process_time()
        result, error = plan_footsteps_best(request, robot)
        solve_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
        runs.append((f"{label} epsilon (x{scale:g})", request, result, cpu_s))
        rows.append(
            {
                "label": label,
                "epsilon_scale": scale,
                "solved": error is None,
                "steps": result.n_steps,
                "iterations": result.iterations,
                "steps_added_at": list(result.steps_added_at),
                "solve_s": solve_s,
                "cpu_s": cpu_s,
            }
        )
    if out_dir is not None:
        epsilon_study_figure(
            runs,
            Path(out_dir) / "footsteps_fig10_epsilon.png",
            title=f"Fig. 10 threshold study [{robot_name}]",
        )
    return rows


def _paper_solve(paper_s: float | None) -> str:
    """The paper's solve time of a scenario [s], or that it gives none (Fig. 10: nan in the table)."""
    if paper_s is None or not math.isfinite(paper_s):
        return "paper: -"
    return f"paper: {paper_s} s on a 2.13 GHz Core 2"


def format_summary(summary: dict[str, Any]) -> str:
    """A few human-readable lines for one scenario."""
    lines = [
        f"{summary['scenario']}: {summary['title']}",
        f"  {'solved' if summary['solved'] else 'NOT solved: ' + str(summary['error'])}",
        f"  steps {summary['steps']} (paper: {summary['paper_steps'] or '-'}), "
        f"iterations {summary['iterations']}, "
        f"steps added after iterations {summary['steps_added_at']}",
        f"  solve {summary['solve_wall_s']:.3f} s wall, {summary['solve_cpu_s']:.3f} s CPU "
        f"({_paper_solve(summary['paper_s'])}), front foot {summary['front_foot']}",
        "  residuals " + ", ".join(f"{k} {v:.4f}" for k, v in summary["residuals"].items()),
    ]
    for side, x, y, yaw in summary["footsteps"]:
        lines.append(f"    {side:5s} x {x:+.3f} m  y {y:+.3f} m  yaw {yaw:+.3f} rad")
    motion = summary.get("motion")
    if motion:
        errors = ", ".join(f"{k} {1000 * v:.1f} mm" for k, v in motion["final_errors_m"].items())
        lines.append(
            f"  motion: {motion['duration_s']:.2f} s (walk {motion['walk_end_s']:.2f} s) computed in "
            f"{motion['compute_s']:.2f} s; final hand error {errors or '-'}; closest self-collision "
            f"pair {1000 * motion['reach_min_self_distance_m']:.0f} mm"
        )
    if summary.get("motion_error"):
        lines.append(f"  motion: the walking planner rejects the plan: {summary['motion_error']}")
    for path in summary["figures"]:
        lines.append(f"  wrote {path}")
    return "\n".join(lines)
