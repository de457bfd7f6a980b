"""Navigation benchmark (stage 1): planning time and length of car-like paths, against plain OMPL.

- ``room_plan_ms``: ``plan_path`` in the 6 x 6 m demo room (walls, two tables, boxes, a pillar, a shelf),
  south-west corner to north-east corner, default configuration (BIT*, forward preferred, R = 0.5 m),
  median over ``--runs`` seeds. Goal (issue 9): <= 100 ms.
- ``cluttered_plan_ms``: the same over ``--runs`` scenes of 20 seeded random boxes/cylinders (8 x 8 m).

Every time is the whole call (distance grid, enclosure check, OMPL search and simplification, dense
sampling and its verification). Variants in the same run: ``bitstar_first`` (BIT* stopped at its first
solution), ``rrt`` (first solution + simplification),
``reeds_shepp`` (BIT* on Reeds-Shepp curves: how much it walks backward), and ``ompl_default``, a plain
OMPL call with default settings (``SimpleSetup`` on a ``DubinsStateSpace``, the planner OMPL picks, its
default collision-check resolution, ``solve(1 s)``, ``simplifySolution()``) using the same footprint
checker as validity callback; its path is re-checked at 2 cm to count the samples it lets collide.
Also timed: footsteps along the room path and the bar sweep of the bar scenario.

Stage 2, the bar scenario of "Manipulating While Walking" (`001_771c0ce3779b0683.txt`, Figures 2-3): from
hrp2_like holding the bar on its stands to 3.2 m ahead past the table with the box, the bar carried at
0.8 m (``plan_goto``: path, footsteps, whole-body walk, 3D check, smooth reshaping until collision-free):

- ``bar_reshape_s``: wall time of the whole two-stage plan, median over ``--bar-runs`` runs (CPU time and
  the share of each stage alongside);
- ``bar_iterations``: whole-body solutions computed (1 = the first motion was already collision-free).

``bar_rotation_case``: the bar past the box and a pole beside it (``bar_rotation_scenario``), where
lifting alone does not pass: the lift-only reshaping's error, then the paper's sampled reshaping with
``--rotation-runs`` sampling seeds: reshaped or not, the held offset (up, roll, yaw), min clearance, key
frames, wall and CPU time.

Writes bench/out/navigation.json.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

from ompl import geometric as og

from services.collision import CarriedBar, Scene
from services.errors import HumanoidError
from services.model import load_robot
from services.navigation.demo_scenes import (
    bar_rotation_scenario,
    bar_scenario,
    bar_scenario_start,
    demo_room,
    random_clutter,
)
from services.navigation.footsteps_along_path import footsteps_along_path
from services.navigation.geometry import BodyModel, FootprintChecker, Pose2D, body_model
from services.navigation.goto import GotoOptions, plan_goto
from services.navigation.path import PlannerConfig, densify, make_state_space, plan_path, set_se2_state
from services.navigation.reshaping import ReshapeOptions, SamplingOptions
from services.navigation.stage2 import Stage2Options
from services.navigation.upper_body import sweep_carried_object

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "navigation.json"
GOAL_ROOM_MS = 100.0
PLAIN_OMPL_PLANNERS: set[str] = set()  # the planner(s) OMPL's SimpleSetup picked by default

Problem = tuple[Scene, Pose2D, Pose2D]


def _stats(values: list[float]) -> dict[str, float]:
    if not values:
        return {"median": math.nan, "p90": math.nan, "max": math.nan}
    ordered = sorted(values)
    return {
        "median": statistics.median(ordered),
        "p90": ordered[min(len(ordered) - 1, math.ceil(0.9 * len(ordered)) - 1)],
        "max": ordered[-1],
    }


def ours(config: PlannerConfig) -> Callable[[Problem, BodyModel, int], dict[str, float]]:
    def run(problem: Problem, body: BodyModel, seed: int) -> dict[str, float]:
        scene, start, goal = problem
        t0 = time.perf_counter()
        path = plan_path(scene, body, start, goal, PlannerConfig(**{**config.__dict__, "seed": seed}))
        ms = 1e3 * (time.perf_counter() - t0)
        return {
            "ms": ms,
            "length_m": path.length_m,
            "reverse_m": path.reverse_length_m,
            "colliding_samples": 0,
        }

    return run


def ompl_default(problem: Problem, body: BodyModel, seed: int) -> dict[str, float]:
    """Plain OMPL with default settings, same state space family, radius and validity callback."""
    from ompl import util as ou

    scene, start, goal = problem
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(seed)
    ou.setLogLevel(level)
    t0 = time.perf_counter()
    checker = FootprintChecker(scene, body)
    space = make_state_space("dubins", 0.5, scene.bounds_xy_m)
    ss = og.SimpleSetup(space)
    ss.setStateValidityChecker(lambda s: checker.is_free(s.getX(), s.getY(), s.getYaw()))
    a, g = space.allocState(), space.allocState()
    set_se2_state(a, start.x_m, start.y_m, start.theta_rad)
    set_se2_state(g, goal.x_m, goal.y_m, goal.theta_rad)
    ss.setStartAndGoalStates(a, g)
    ss.solve(1.0)
    if not ss.haveExactSolutionPath():
        raise RuntimeError("plain OMPL found no exact solution in 1 s")
    ss.simplifySolution()
    vertices = [(s.getX(), s.getY(), s.getYaw()) for s in ss.getSolutionPath().getStates()]
    ms = 1e3 * (time.perf_counter() - t0)
    xy, theta, s_m, _ = densify(vertices, "dubins", 0.5, 0.02)
    bad = sum(not checker.is_free(float(x), float(y), float(t)) for (x, y), t in zip(xy, theta, strict=True))
    PLAIN_OMPL_PLANNERS.add(ss.getPlanner().getName())
    return {"ms": ms, "length_m": float(s_m[-1]), "reverse_m": 0.0, "colliding_samples": bad}


def measure(
    name: str,
    planner: Callable[[Problem, BodyModel, int], dict[str, float]],
    problems: list[Problem],
    body: BodyModel,
) -> dict[str, object]:
    rows = []
    failures = []
    for seed, problem in enumerate(problems, start=1):
        try:
            rows.append(planner(problem, body, seed))
        except (HumanoidError, RuntimeError) as error:
            failures.append(f"seed {seed}: {error}")
    return {
        "variant": name,
        "runs": len(problems),
        "solved": len(rows),
        "ms": _stats([r["ms"] for r in rows]),
        "length_m": _stats([r["length_m"] for r in rows]),
        "reverse_m_median": statistics.median([r["reverse_m"] for r in rows]) if rows else math.nan,
        "paths_with_colliding_samples": sum(r["colliding_samples"] > 0 for r in rows),
        "failures": failures,
    }


def bar_stage2(robot_name: str, runs: int) -> dict[str, object]:
    """The two-stage plan of the bar scenario, ``runs`` times (wall and CPU time, iterations, figures)."""
    robot = load_robot(robot_name)
    scene, _, goal = bar_scenario()
    q_start = bar_scenario_start(robot)
    options = GotoOptions(stage2=Stage2Options(carry_height_m=0.8))
    walls, cpus, result = [], [], None
    for _ in range(runs):
        t0, c0 = time.perf_counter(), time.process_time()
        result = plan_goto(robot, scene, q_start, goal, CarriedBar(), options)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    assert result is not None
    motion = result.motion
    report = motion.report()
    return {
        "wall_s": _stats(walls),
        "cpu_s": _stats(cpus),
        "iterations": len(motion.iterations),
        "iteration_wall_s": [it.wall_time_s for it in motion.iterations],
        "stage_timings_s": result.timings_s,
        "steps": len(result.footsteps.sequence.steps),
        "trajectory_s": float(motion.times_s[-1]),
        "segments_lifted": report["segments_lifted"],
        "first_min_clearance_m": motion.iterations[0].min_clearance_m,
        "min_clearance_m": report["min_clearance_m"],
        "zmp_margin_m": report["zmp_margin_m"],
        "hand_error_m": report["hand_error_m"],
        "bar_height_max_m": float(motion.bar_centre_m[:, 2].max()),
    }


def bar_rotation_case(robot_name: str, runs: int) -> dict[str, object]:
    """The bar past a box and a pole (``bar_rotation_scenario``), where lifting alone does not pass: the
    lift-only reshaping once (its error), then the paper's sampled reshaping with sampling seeds 0 ..
    ``runs`` - 1 (reshaped, clearance, key frames, time)."""
    robot = load_robot(robot_name)
    scene, _, goal = bar_rotation_scenario()
    q_start = bar_scenario_start(robot)

    def options(reshape: ReshapeOptions) -> GotoOptions:
        return GotoOptions(stage2=Stage2Options(carry_height_m=0.8, reshape=reshape))

    try:
        plan_goto(robot, scene, q_start, goal, CarriedBar(), options(ReshapeOptions(mode="lift")))
        lift: dict[str, object] = {"reshaped": True}
    except HumanoidError as error:
        lift = {"reshaped": False, "reason": error.details.get("reason"), "message": error.message}
    rows = []
    for seed in range(runs):
        reshape = ReshapeOptions(sampling=SamplingOptions(seed=seed))
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            result = plan_goto(robot, scene, q_start, goal, CarriedBar(), options(reshape))
        except HumanoidError as error:
            rows.append({"seed": seed, "reshaped": False, "reason": error.details.get("reason")})
            continue
        motion = result.motion
        report = motion.report()
        (window,) = motion.windows if len(motion.windows) == 1 else (None,)
        rows.append(
            {
                "seed": seed,
                "reshaped": True,
                "wall_s": time.perf_counter() - t0,
                "cpu_s": time.process_time() - c0,
                "iterations": report["iterations"],
                "first_min_clearance_m": motion.iterations[0].min_clearance_m,
                "min_clearance_m": report["min_clearance_m"],
                "zmp_margin_m": report["zmp_margin_m"],
                "hand_error_m": report["hand_error_m"],
                "drawn": sum(st.drawn for st in motion.sampling),
                "windows": len(motion.windows),
                "key_frames": report["key_frames"],
                "roll_deg": None if window is None else math.degrees(window.offset.roll_rad),
                "yaw_deg": None if window is None else math.degrees(window.offset.yaw_rad),
                "up_m": None if window is None else window.offset.up_m,
            }
        )
    done = [r for r in rows if r["reshaped"]]
    return {
        "lift_only": lift,
        "runs": runs,
        "reshaped": len(done),
        "wall_s": _stats([r["wall_s"] for r in done]),
        "cpu_s": _stats([r["cpu_s"] for r in done]),
        "min_clearance_m": min((r["min_clearance_m"] for r in done), default=math.nan),
        "rows": rows,
    }


def _table(results: dict[str, dict[str, dict[str, object]]]) -> str:
    head = (
        f"{'problem':9s} {'variant':13s} {'solved':>7s} {'ms med':>8s} {'ms p90':>8s} {'ms max':>8s} "
        f"{'len med':>8s} {'len max':>8s} {'back m':>7s} {'hits':>5s}"
    )
    lines = [head, "-" * len(head)]
    for problem, variants in results.items():
        for name, r in variants.items():
            ms, length = r["ms"], r["length_m"]
            lines.append(
                f"{problem:9s} {name:13s} {r['solved']:>3d}/{r['runs']:<3d} {ms['median']:8.1f} "
                f"{ms['p90']:8.1f} {ms['max']:8.1f} {length['median']:8.2f} {length['max']:8.2f} "
                f"{r['reverse_m_median']:7.2f} {r['paths_with_colliding_samples']:5d}"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="scripts/bench navigation",
        description="Stage-1 navigation planning time in the demo room and among 20 random obstacles, "
        "against plain OMPL defaults; writes bench/out/navigation.json.",
    )
    parser.add_argument("--runs", type=int, default=20, help="seeds per problem (default 20)")
    parser.add_argument("--robot", default="hrp2_like", help="body model (default hrp2_like)")
    parser.add_argument("--no-peer", action="store_true", help="skip the plain-OMPL comparison")
    parser.add_argument(
        "--bar-runs", type=int, default=3, help="runs of the stage-2 bar scenario (default 3; 0: skip)"
    )
    parser.add_argument(
        "--rotation-runs",
        type=int,
        default=3,
        help="sampling seeds of the bar past a box and a pole (bar_rotation_case; default 3; 0: skip)",
    )
    parser.add_argument(
        "--out", type=Path, default=OUT, help=f"JSON output (default {OUT.relative_to(REPO)})"
    )
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs must be >= 1")
    body = body_model(args.robot)
    default = PlannerConfig()

    room = demo_room()
    problems = {
        "room": [room] * args.runs,
        "clutter": [random_clutter(20, seed) for seed in range(args.runs)],
    }
    variants: dict[str, Callable[[Problem, BodyModel, int], dict[str, float]]] = {
        "default": ours(default),
        "bitstar_first": ours(PlannerConfig(optimize_time_s=0.0)),
        "rrt": ours(PlannerConfig(planner="rrt")),
        "reeds_shepp": ours(PlannerConfig(curve="reeds_shepp")),
    }
    if not args.no_peer:
        variants["ompl_default"] = ompl_default
    results = {
        problem: {name: measure(name, planner, cases, body) for name, planner in variants.items()}
        for problem, cases in problems.items()
    }

    # downstream of the path: footsteps on the room path, bar sweep in the bar scenario
    room_scene, room_start, room_goal = room
    room_path = plan_path(room_scene, body, room_start, room_goal, default)
    t0 = time.perf_counter()
    steps = footsteps_along_path(room_path)
    footsteps_ms = 1e3 * (time.perf_counter() - t0)
    bar_scene, bar_start, bar_goal = bar_scenario()
    bar_path = plan_path(bar_scene, body, bar_start, bar_goal, default)
    t0 = time.perf_counter()
    sweep = sweep_carried_object(bar_scene, bar_path, CarriedBar(height_m=0.9), body)
    bar_sweep_ms = 1e3 * (time.perf_counter() - t0)

    bar = bar_stage2(args.robot, args.bar_runs) if args.bar_runs > 0 else None
    rotation = bar_rotation_case(args.robot, args.rotation_runs) if args.rotation_runs > 0 else None

    room_ms = results["room"]["default"]["ms"]["median"]
    doc = {
        "room_plan_ms": room_ms,
        "cluttered_plan_ms": results["clutter"]["default"]["ms"]["median"],
        "bar_reshape_s": bar["wall_s"]["median"] if bar else math.nan,
        "bar_iterations": bar["iterations"] if bar else 0,
        "goal_room_plan_ms": GOAL_ROOM_MS,
        "meets_goals": bool(room_ms <= GOAL_ROOM_MS and results["room"]["default"]["solved"] == args.runs),
        "config": {k: v for k, v in default.__dict__.items()},
        "robot": args.robot,
        "runs": args.runs,
        "results": results,
        "room_footsteps": {
            "ms": footsteps_ms,
            "steps": len(steps.sequence.steps),
            "path_m": room_path.length_m,
        },
        "bar_sweep": {
            "ms": bar_sweep_ms,
            "segments": [seg.__dict__ for seg in sweep.segments],
            "path_samples": len(bar_path.s_m),
        },
        "bar_stage2": bar,
        "bar_rotation_case": rotation,
        "ompl_default_planner": sorted(PLAIN_OMPL_PLANNERS),
        "machine": f"{platform.processor() or platform.machine()}, python {platform.python_version()}",
    }
    print(_table(results))
    print(
        f"(ompl_default: OMPL SimpleSetup defaults, planner {', '.join(sorted(PLAIN_OMPL_PLANNERS))}; "
        "hits = paths with footprint samples in collision at 2 cm)"
    )
    print(f"footsteps along the room path: {len(steps.sequence.steps)} steps in {footsteps_ms:.1f} ms")
    print(f"bar sweep (bar scenario, {len(bar_path.s_m)} samples): {bar_sweep_ms:.1f} ms")
    for seg in sweep.segments:
        print(
            f"  {seg.part} hits {list(seg.obstacles)}: anticipating s={seg.s_anticipate_m:.2f}, colliding "
            f"{seg.s_collide_m:.2f}..{seg.s_collide_end_m:.2f}, regaining {seg.s_regain_m:.2f} m, "
            f"clears at {seg.clear_height_m:.3f} m"
        )
    if bar is not None:
        lifted = ", ".join(f"{w['height_m']:.3f} m over {w['obstacles']}" for w in bar["segments_lifted"])
        print(
            f"bar scenario, two stages ({bar['steps']} steps, {bar['trajectory_s']:.1f} s of motion): "
            f"{bar['wall_s']['median']:.2f} s wall median ({bar['cpu_s']['median']:.2f} s CPU), "
            f"{bar['iterations']} whole-body solutions, lifted {lifted}; clearance "
            f"{1e3 * bar['first_min_clearance_m']:.0f} -> {1e3 * bar['min_clearance_m']:.0f} mm, ZMP margin "
            f"{1e3 * bar['zmp_margin_m']:.0f} mm"
        )
    if rotation is not None:
        lift = rotation["lift_only"]
        print(
            f"bar past a box and a pole: lift only -> {lift.get('reason') or 'reshaped'}; sampled "
            f"reshaping {rotation['reshaped']}/{rotation['runs']} seeds reshaped, "
            f"{rotation['wall_s']['median']:.2f} s wall median ({rotation['cpu_s']['median']:.2f} s CPU), "
            f"min clearance {1e3 * rotation['min_clearance_m']:.0f} mm"
        )
        for r in rotation["rows"]:
            if r["reshaped"]:
                keys = r["key_frames"][0] if r["key_frames"] else []
                times = ", ".join(f"{k['key_frame']} {k['t_s']:.2f}" for k in keys)
                print(
                    f"  seed {r['seed']}: {r['iterations']} solutions, {r['drawn']} drawn, "
                    f"up {r['up_m']:+.2f} m, roll {r['roll_deg']:+.0f} deg, yaw {r['yaw_deg']:+.0f} deg, "
                    f"clearance {1e3 * r['first_min_clearance_m']:.0f} -> "
                    f"{1e3 * r['min_clearance_m']:.0f} mm; key frames [s] {times}; {r['wall_s']:.1f} s"
                )
            else:
                print(f"  seed {r['seed']}: not reshaped ({r['reason']})")
    verdict = "met" if doc["meets_goals"] else "NOT met"
    print(f"goal: room path <= {GOAL_ROOM_MS:.0f} ms -> {verdict} ({room_ms:.1f} ms)")
    for problem, variants_result in results.items():
        for name, r in variants_result.items():
            for failure in r["failures"][:3]:
                print(f"  {problem}/{name} failure: {failure}", file=sys.stderr)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
