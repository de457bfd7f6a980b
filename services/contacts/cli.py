"""``humanoid scenario chair-egress``: the chair experiment of Escande et al. (§3) in one process: plan the
contact sets from the seated robot of the ``chair_egress`` scene (or of any layout with the robot seated
on a chair, ``--scene``, with its goal ``--goal-axis/--goal-value/--goal-below``), printing every set as
it is expanded, interpolate the motion (§3.3), play it in a pybullet world (DIRECT) and report whether
the robot ends standing beside the table. (Over the bus, the same is the supervisor's ``stand_up``
action on a stack started with ``humanoid up`` and the sim in that scene.)"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from services.contacts.defaults import LIMB_LOAD

EXAMPLES = """examples:
  humanoid scenario chair-egress                     # plan (<= 300 s), interpolate, execute, report
  humanoid scenario chair-egress --budget 600 --no-best-first   # all sons generated (no §2.8)
  humanoid scenario chair-egress --save-plan out/chair_plan.npz   # then, without searching again:
  humanoid scenario chair-egress --plan out/chair_plan.npz        # execute the saved plan set by set
  humanoid scenario chair-egress --limb-load --slope-k 15         # the setting that ends standing (session 9)
"""


def add_cli(subparsers: Any) -> None:
    """Register ``humanoid scenario chair-egress``."""
    from services.footsteps.cli import scenario_subparsers

    p = scenario_subparsers(subparsers).add_parser(
        "chair-egress",
        help="get out of a chair at a table by contact-before-motion planning (Escande et al., §3)",
        description=__doc__,
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--scene",
        default="chair_egress",
        help="the scene (a name in sim/scenes or a .yaml path) with the robot seated on its chair "
        "(default chair_egress; any layout: T is made from it)",
    )
    p.add_argument(
        "--goal-axis", choices=("x", "y", "z"), default="y", help="the waist coordinate to pass (y)"
    )
    p.add_argument("--goal-value", type=float, default=0.6, help="the waist must pass this [m] (0.6)")
    p.add_argument("--goal-below", action="store_true", help="pass the goal's coordinate downward")
    p.add_argument("--budget", type=float, default=300.0, help="search time budget [s] (300)")
    p.add_argument("--max-nodes", type=int, default=1000, help="nodes generated at most (1000)")
    p.add_argument("--no-best-first", action="store_true", help="generate every son (§2.8 off)")
    p.add_argument("--n", type=int, default=10, help="posture generations per transition (§3.3's n)")
    p.add_argument("--no-execute", action="store_true", help="plan and interpolate only")
    p.add_argument("--save-plan", type=Path, help="write the plan found to this .npz (plan_file.py)")
    p.add_argument(
        "--plan", type=Path, help="execute a plan saved by --save-plan (no search, no interpolation)"
    )
    p.add_argument(
        "--limb-load",
        action=argparse.BooleanOptionalAction,
        default=LIMB_LOAD,
        help="bound the arms' contact forces by their joints' torques (limb_load.py; default on; "
        "--no-limb-load: friction only, the paper's)",
    )
    p.add_argument(
        "--slope-k",
        type=float,
        default=None,
        help="f_T's slope k (eq. 1; default PlanProblem's 15, with the limb-load bound: ends standing; the "
        "paper-like setting of sessions 7-8: --no-limb-load --slope-k 30)",
    )
    p.add_argument(
        "--force-control",
        action="store_true",
        help="executed set by set, the arms in contact follow their planned forces (sim/compliance.py; "
        "an experiment, off by default: it fell earlier, services/contacts/README.md)",
    )
    p.add_argument(
        "--open-loop",
        action="store_true",
        help="play the planned motion as is (default: set by set, re-planned from the measured state)",
    )
    p.set_defaults(func=cmd_scenario)


def supports_of(sets: list) -> tuple[str, ...]:
    """The objects any link may touch during the motion (sim/execute's supports): the owners of the
    plan's surfaces (``<object>.seat`` / ``<object>.top``), the floor aside."""
    return tuple(sorted({c.surface.split(".")[0] for s in sets for c in s} - {"floor"}))


def _closed_loop(
    robot: Any,
    environment: Any,
    sets: list,
    witnesses: list,
    world: Any,
    n: int,
    limb_load: bool,
    force_control: bool = False,
) -> tuple[str, str]:
    """Play the plan set by set in ``world``, each transition re-planned from the measured state
    (``services.contacts.closed_loop``; ``force_control``: the arms follow their planned forces);
    prints one line per transition; (outcome, message)."""
    from services.contacts.closed_loop import TransitionReport, execute_set_by_set, execution_generator
    from services.contacts.interpolate import InterpolationConfig

    gen = execution_generator(robot, environment, limb_load)

    supports = supports_of(sets)

    def play(q, dt, effort_scale, force_targets):
        executed = world.execute(
            q, dt, supports=supports, effort_scale=effort_scale, force_targets=force_targets
        )
        return executed.outcome, executed.message

    def report(r: TransitionReport) -> None:
        print(
            f"  transition {r.index:3d}: {r.outcome:9s} supports off by {r.support_error_m * 100:4.1f} cm, "
            f"{'re-planned' if r.replanned else 'as planned'} in {r.replan_s:.1f} s "
            f"{r.reason}".rstrip(),
            flush=True,
        )

    run = execute_set_by_set(
        gen,
        sets,
        witnesses,
        play,
        lambda: world.state().q,
        InterpolationConfig(n=n, force_control=force_control),
        report,
    )
    world.hold(1.0)
    return run.outcome, run.message


def check_arguments(args: argparse.Namespace) -> None:
    """Bad options refused before the minutes of planning (InvalidRequestError, exit code 2): the
    limits of the ``contacts/plan`` and ``contacts/transition`` requests (services/contacts/README.md)."""
    from services.errors import InvalidRequestError

    if not 0 < args.budget <= 600:
        raise InvalidRequestError(f"--budget {args.budget:g}: the search budget must be in (0, 600] s")
    if not 1 <= args.max_nodes <= 100_000:
        raise InvalidRequestError(f"--max-nodes {args.max_nodes}: must be in 1..100000")
    if not 2 <= args.n <= 100:
        raise InvalidRequestError(f"--n {args.n}: posture generations per transition must be in 2..100")
    if args.plan is not None and not args.plan.is_file():
        raise InvalidRequestError(f"--plan {args.plan}: no such file (write one with --save-plan FILE)")


def cmd_scenario(args: argparse.Namespace) -> int:
    import numpy as np

    from services.contacts.chair_egress import FINAL_PAIRS
    from services.contacts.environment import environment_of
    from services.contacts.interpolate import InterpolationConfig
    from services.contacts.plan_file import load_plan, save_plan
    from services.contacts.planner import default_problem, plan
    from services.contacts.search import Goal, Node, SearchConfig
    from services.model import load_robot
    from sim.scene import layout, load_scene
    from sim.world import World, start_configuration

    check_arguments(args)
    robot = load_robot("hrp2_like")
    q0 = start_configuration(robot, layout(load_scene(args.scene)))
    goal = Goal(args.goal_axis, args.goal_value, FINAL_PAIRS, -1.0 if args.goal_below else 1.0)

    def progress(kind: str, node: Node, generated: int, expanded: int, elapsed: float) -> None:
        print(
            f"[{elapsed:6.1f} s] nodes {generated:4d} expanded {expanded:4d}  depth {node.depth:3d}  "
            f"f_T {node.f:8.2f}  waist ({node.q[0]:+.2f}, {node.q[1]:+.2f}, {node.q[2]:.2f})  {node.change}",
            flush=True,
        )

    problem = default_problem(
        robot,
        q0,
        scene=args.scene,
        goal=goal,
        search=SearchConfig(
            best_first_sons=not args.no_best_first, max_nodes=args.max_nodes, time_budget_s=args.budget
        ),
        # executed set by set, each transition is interpolated from the measured state: no whole motion
        interpolation=InterpolationConfig(n=args.n)
        if (args.open_loop or args.no_execute) and not args.plan
        else None,
        limb_load=args.limb_load,
        **({} if args.slope_k is None else {"slope_k": args.slope_k}),
    )
    motion = None
    if args.plan:
        saved = load_plan(args.plan)
        sets, witnesses = saved.sets, list(saved.witnesses)
        print(f"plan read from {args.plan}: {len(sets)} sets {saved.meta}")
        environment = environment_of(layout(load_scene(problem.scene)))
    else:
        result = plan(robot, problem, progress)
        s = result.search
        print(
            f"plan: {len(s.path)} sets, {s.nodes_generated} nodes generated, {s.nodes_expanded} expanded, "
            f"{s.posture_generations} posture generations, {s.plan_s:.1f} s"
        )
        for k, node in enumerate(s.path):
            print(f"  {k:3d} {node.change:50s} {' '.join(c.describe() for c in node.contacts)}")
        sets, witnesses, environment, motion = (
            result.sets,
            list(result.witnesses),
            result.environment,
            result.motion,
        )
        if args.save_plan:
            meta = {
                "nodes_generated": s.nodes_generated,
                "nodes_expanded": s.nodes_expanded,
                "plan_s": s.plan_s,
                "slope_k": problem.slope_k,
            }
            print(
                "plan written to",
                save_plan(args.save_plan, sets, witnesses, [n.change for n in s.path], meta),
            )
    if motion is not None:
        print(
            f"interpolation: {motion.q.shape[0]} samples ({motion.q.shape[0] * motion.dt_s:.1f} s of motion) "
            f"in {motion.interpolation_s:.1f} s"
        )
    if args.no_execute:
        return 0
    with World(robot, args.scene) as world:
        if motion is not None:  # --open-loop: the planned motion as is
            executed = world.execute(motion.q, motion.dt_s, supports=supports_of(sets), hold_s=1.0)
            outcome, message = executed.outcome, executed.message
        else:
            outcome, message = _closed_loop(
                robot, environment, sets, witnesses, world, args.n, args.limb_load, args.force_control
            )
        q = world.state().q
        standing = all(
            abs(float(robot.sole_pose(q, side).translation[2])) < 0.01 for side in ("left", "right")
        )
        print(
            f"execution: {outcome}: {message}; waist at "
            f"({q[0]:+.2f}, {q[1]:+.2f}, {q[2]:.2f}) m, tilt {math.degrees(world.tilt_rad()):.1f} deg, "
            f"{'standing on both soles' if standing else 'not standing on both soles'}"
        )
        ok = (
            outcome == "completed"
            and standing
            and not world.fallen()
            and goal.residual_m(np.asarray(q)) < 0.05
        )
    print("chair egress:", "succeeded" if ok else "failed")
    return 0 if ok else 1
