"""Contact-before-motion benchmark (Escande et al., §3): the chair egress planned from the seated robot.

Runs the search with the method of §2.8 (one leaf per (spot, surface) pair, sons in f_T order), then
interpolates the motion (§3.3, n postures per transition; its collision check and local re-planning
reported), and plays the plan in a pybullet world (DIRECT) set by set, each transition re-planned from
the measured state (services/contacts/closed_loop.py);
then the same search with §2.8 switched off (every son generated), to compare the nodes generated, as
the paper does ("about four times less"). Figures beside the paper's (81 sets, 2400 nodes, about 5 h
on a Pentium IV 3.4 GHz; interpolation about 90 s with n = 20). Writes bench/out/contacts.json and the
plan found (bench/out/contacts_plan.npz: ``humanoid scenario chair-egress --plan`` plays it again).

``--cpu``: the budget is the search's CPU time (one core: the BLAS is single-threaded) instead of its
wall clock, which on a loaded machine also counts the other processes' turns; both are reported
(``plan_s``, ``plan_cpu_s``).

``--scenes [NAMES]``: instead, the family of layouts and payloads the tests had not used
(``_contacts_scenes.py``: the chair scene moved, turned, other heights, the table far, beside or absent, a
box in the way, goals out of reach, odd budgets and node caps), each sent to ``contacts/plan`` over the
bus of a real stack (sim + contacts, the generated scenes in both services' ``scene_dirs``); every plan
checked independently (contacts on their surfaces, no collision in pybullet's shapes, static balance by
an LP), the short ones played with ``sim/execute``; every refusal checked typed (code, reason,
``residual_m``), within its budget; the services' restarts counted. Writes
bench/out/contacts_scenes.json.

Usage: scripts/bench contacts [--budget S] [--cpu] [--n N] [--skip-off] [--limb-load] [--scenes [NAMES]]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

from services.contacts.defaults import LIMB_LOAD

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "bench" / "out" / "contacts.json"
PLAN = ROOT / "bench" / "out" / "contacts_plan.npz"  # the §2.8 plan (humanoid scenario chair-egress --plan)
PAPER = {
    "sets": 81,
    "nodes_generated": 2400,
    "plan_s": 5 * 3600.0,
    "interpolation_s": 90.0,
    "n": 20,
    "nodes_without_2_8": "about 4 x 2400",
    "machine": "Pentium IV 3.4 GHz, 2 GB",
}


def run(
    best_first: bool,
    budget_s: float,
    n: int,
    execute: bool,
    limb_load: bool,
    cpu: bool = False,
    slope_k: float | None = None,
) -> dict:
    from services.contacts.closed_loop import execute_set_by_set
    from services.contacts.interpolate import InterpolationConfig, interpolate_plan
    from services.contacts.planner import build, default_problem
    from services.contacts.search import ContactPlanner, SearchConfig
    from services.model import load_robot
    from sim.scene import layout, load_scene
    from sim.world import World, start_configuration

    robot = load_robot("hrp2_like")
    q0 = start_configuration(robot, layout(load_scene("chair_egress")))
    problem = default_problem(
        robot,
        q0,
        search=SearchConfig(
            best_first_sons=best_first,
            # --cpu: the CPU budget bounds the search; the wall clock only guards against a stall
            time_budget_s=budget_s * (20.0 if cpu else 1.0),
            cpu_budget_s=budget_s if cpu else None,
        ),
        limb_load=limb_load,
        **({} if slope_k is None else {"slope_k": slope_k}),
    )
    gen, trajectory, start, pairs = build(robot, problem)
    weight_n = robot.total_mass_kg * 9.81
    planner = ContactPlanner(gen, trajectory, problem.goal, pairs, problem.search)
    result = planner.plan(start, q0)
    row = {
        "best_first_sons_2_8": best_first,
        "status": result.status,
        "sets": len(result.path),
        "nodes_generated": result.nodes_generated,
        "nodes_expanded": result.nodes_expanded,
        "posture_generations": result.posture_generations,
        "plan_s": round(result.plan_s, 1),
        "plan_cpu_s": round(result.plan_cpu_s, 1),
        "budget_kind": "cpu" if cpu else "wall",
        "slope_k": problem.slope_k,
        "limb_load": limb_load,
        "best_waist_y_m": round(float(result.best.q[1]), 3),
        # |force| each bounded spot may carry (limb_load.py; {} when the bound is off)
        "limb_load_n": {spot: round(v * weight_n, 1) for spot, v in gen.max_load.items()},
        "changes": [n.change for n in result.path],
    }
    print(
        f"  §2.8 {'on ' if best_first else 'off'}: {result.status}, {row['sets']} sets, "
        f"{row['nodes_generated']} nodes generated, {row['nodes_expanded']} expanded, {row['plan_s']} s "
        f"({row['plan_cpu_s']} s CPU)",
        flush=True,
    )
    if result.status != "reached" or not execute:
        return row
    from services.contacts.plan_file import save_plan

    row["plan_file"] = str(
        save_plan(
            PLAN,
            [nd.contacts for nd in result.path],
            [nd.q for nd in result.path],
            [nd.change for nd in result.path],
            {k: row[k] for k in ("nodes_generated", "nodes_expanded", "plan_s", "plan_cpu_s")},
        ).relative_to(ROOT)
    )
    motion = interpolate_plan(
        gen, [nd.contacts for nd in result.path], [nd.q for nd in result.path], InterpolationConfig(n=n)
    )
    row["interpolation_s"] = round(motion.interpolation_s, 1)
    row["motion_s"] = round(motion.q.shape[0] * motion.dt_s, 1)
    row["interpolation_refinements"] = motion.refinements
    row["interpolation_collisions"] = [
        f"transition {c.transition}: {c.capsule} {c.depth_m * 100:.1f} cm into {c.box}"
        for c in motion.collisions
    ]
    with World(robot, "chair_egress") as world:
        t0 = time.perf_counter()

        def play(q_segment, dt, effort_scale, force_targets):
            executed = world.execute(
                q_segment,
                dt,
                supports=("chair", "table"),
                effort_scale=effort_scale,
                force_targets=force_targets,
            )
            return executed.outcome, executed.message

        def report(r):
            print(
                f"    transition {r.index:3d}: {r.outcome}, supports {r.support_error_m * 100:.1f} cm off "
                f"{r.reason}".rstrip(),
                flush=True,
            )

        run_ = execute_set_by_set(
            gen,
            [nd.contacts for nd in result.path],
            [nd.q for nd in result.path],
            play,
            lambda: world.state().q,
            InterpolationConfig(n=n),
            report,
        )
        world.hold(1.0)
        q = world.state().q
        standing = all(abs(float(robot.sole_pose(q, s).translation[2])) < 0.01 for s in ("left", "right"))
        row.update(
            execution="set by set, re-planned from the measured state (services/contacts/closed_loop.py)",
            executed_outcome=run_.outcome,
            executed_message=run_.message,
            transitions_played=len(run_.transitions),
            replan_s=round(run_.replan_s, 1),
            executed_ok=bool(
                run_.outcome == "completed"
                and not world.fallen()
                and standing
                and q[1] > problem.goal.value_m - 0.05
            ),
            final_waist_m=[round(float(v), 3) for v in q[:3]],
            final_tilt_deg=round(math.degrees(world.tilt_rad()), 1),
            execution_wall_s=round(time.perf_counter() - t0, 1),
        )
    print(
        f"    interpolation {row['interpolation_s']} s (n = {n}), execution: {row['executed_outcome']}, "
        f"ok = {row['executed_ok']}",
        flush=True,
    )
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=float, default=300.0, help="search budget per run [s] (300)")
    parser.add_argument(
        "--cpu", action="store_true", help="the budget is the search's CPU time (one core), not wall"
    )
    parser.add_argument("--n", type=int, default=10, help="postures per transition in the interpolation (10)")
    parser.add_argument("--skip-off", action="store_true", help="do not run the search without §2.8")
    parser.add_argument(
        "--limb-load",
        action=argparse.BooleanOptionalAction,
        default=LIMB_LOAD,
        help="bound the arms' contact forces (limb_load.py; default on; --no-limb-load: the paper's)",
    )
    parser.add_argument(
        "--slope-k",
        type=float,
        default=None,
        help="f_T's slope k (eq. 1; default the planner's 15, with the limb-load bound)",
    )
    parser.add_argument(
        "--scenes",
        nargs="?",
        const="all",
        default=None,
        help="the generated layouts and payloads over the bus (all, or NAME,NAME; see _contacts_scenes.py)",
    )
    args = parser.parse_args(argv)
    if args.scenes is not None:
        return run_scenes(args.scenes)
    load = Path("/proc/loadavg").read_text().split()[:3]
    limb_load = args.limb_load
    setting = {"limb_load": limb_load, "cpu": args.cpu, "slope_k": args.slope_k}
    rows = [run(True, args.budget, args.n, execute=True, **setting)]
    if not args.skip_off:
        rows.append(run(False, args.budget, args.n, execute=False, **setting))
    report = {
        "runs": rows,
        "paper": PAPER,
        "loadavg_at_start": load,
        "loadavg_at_end": Path("/proc/loadavg").read_text().split()[:3],
        "cpu_count": os.cpu_count(),
        "goal": "waist y >= 0.6 m standing on both soles (chair_egress)",
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(report, indent=2))
    head = f"{'run':10s} {'status':9s} {'sets':>5s} {'nodes':>6s} {'expanded':>8s} {'plan s':>7s}"
    print(f"{head} {'CPU s':>7s}")
    for r in rows:
        print(
            f"{'§2.8 on' if r['best_first_sons_2_8'] else '§2.8 off':10s} {r['status']:9s} {r['sets']:5d} "
            f"{r['nodes_generated']:6d} {r['nodes_expanded']:8d} {r['plan_s']:7.1f} {r['plan_cpu_s']:7.1f}"
        )
    paper = f"{PAPER['sets']:5d} {PAPER['nodes_generated']:6d} {'-':>8s} {PAPER['plan_s']:7.0f}"
    print(f"{'paper':10s} {'reached':9s} {paper}")
    print("wrote", OUT, "load average", " ".join(load))
    return 0


def _scenes_module():
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location(
        "_contacts_scenes", Path(__file__).with_name("_contacts_scenes.py")
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["_contacts_scenes"] = module
    spec.loader.exec_module(module)
    return module


def run_scenes(names: str) -> int:
    """``--scenes``: the generated family over the bus (see the module docstring)."""
    import numpy as np

    from services.bus.config import BusConfig
    from services.bus.schemas import contacts as msg
    from services.bus.schemas import sim
    from services.bus.session import Client, open_session
    from services.errors import HumanoidError
    from services.model import load_robot
    from sim.scene import find_scene, layout, load_scene
    from sim.world import start_configuration
    from supervisor.fetch import running_stack

    family_module = _scenes_module()
    family = family_module.cases()
    if names != "all":
        wanted = names.split(",")
        unknown = sorted(set(wanted) - {c.name for c in family})
        if unknown:
            raise SystemExit(f"unknown cases {unknown}; known: {[c.name for c in family]}")
        family = [c for c in family if c.name in wanted]
    out_dir = OUT.parent / "contacts_scenes"
    folder = family_module.write_scenes(family, out_dir / "scenes")
    config = out_dir / "stack.yaml"
    dirs = json.dumps([str(folder)])
    config.write_text(f"sim:\n  scene_dirs: {dirs}\ncontacts:\n  scene_dirs: {dirs}\n")
    robot = load_robot("hrp2_like")
    bus = BusConfig().with_hub_port(_free_port())
    load0 = Path("/proc/loadavg").read_text().split()[:3]
    rows: list[dict] = []
    with running_stack(
        bus, services=("sim", "contacts"), log_dir=str(out_dir / "logs"), config_path=str(config)
    ) as launcher:
        first_pids = {name: c.pid for name, c in launcher.children.items()}
        session = open_session(bus)
        try:
            client = Client(session, bus.robot)
            client.wait_for(["sim", "contacts"], 120.0)
            for case in family:
                path = find_scene(case.scene, [folder])
                q0 = start_configuration(robot, layout(load_scene(path)))
                fields = {"start_contacts": family_module.SEATED, **case.request}
                request = msg.PlanRequest(scene=case.scene, q_start=family_module.start_q(case, q0), **fields)
                row = {
                    "case": case.name,
                    "scene": case.scene,
                    "note": case.note,
                    "expect": case.expect,
                    "budget_s": request.time_budget_s,
                    "max_nodes": request.max_nodes,
                }
                t0 = time.monotonic()
                try:
                    reply = client.call(msg.PLAN, request, timeout_s=request.time_budget_s + 120.0)
                    row.update(
                        answer="plan",
                        sets=len(reply.sets),
                        changes=list(reply.changes),
                        nodes=reply.nodes_generated,
                        motion_s=reply.q.shape[0] * reply.dt_s,
                    )
                    checker = family_module.PlanChecker(path)
                    try:
                        row["problems"] = checker.check(reply, q0)
                    finally:
                        checker.close()
                except HumanoidError as exc:
                    reply = None
                    row.update(
                        answer=exc.code,
                        reason=exc.details.get("reason"),
                        residual_m=exc.details.get("residual_m"),
                        message=exc.message[:200],
                        problems=family_module.answer_problems(case, exc.code, exc.details),
                    )
                row["reply_s"] = round(time.monotonic() - t0, 2)
                if row["reply_s"] > request.time_budget_s + 5.0:
                    row["problems"].append(
                        f"replied {row['reply_s']} s for a {request.time_budget_s} s budget"
                    )
                if case.expect == "plan" and row["answer"] != "plan":
                    row["problems"].append("no plan where one exists")
                if reply is not None and case.execute and reply.q.shape[0]:
                    client.call(sim.RESET, sim.ResetRequest(scene=case.scene), 120.0)
                    supports = sorted({c.surface.split(".")[0] for s in reply.sets for c in s} - {"floor"})
                    done = client.call(
                        sim.EXECUTE,
                        sim.ExecuteRequest(
                            q=np.ascontiguousarray(reply.q), dt_s=reply.dt_s, supports=supports, hold_s=1.0
                        ),
                        timeout_s=600.0,
                    )
                    row["executed"] = done.outcome
                    if done.outcome != "completed":
                        row["problems"].append(f"executed: {done.outcome} ({done.message[:120]})")
                row["loadavg"] = round(os.getloadavg()[0], 2)
                rows.append(row)
                print(
                    f"{case.name:24s} {row['answer']:16s} {row.get('reason') or row.get('sets')!s:24s} "
                    f"{row['reply_s']:7.1f} {row.get('executed', '-'):10s} {row['loadavg']:5.1f}  "
                    f"{'; '.join(row['problems'])[:120]}",
                    flush=True,
                )
            restarted = {n: c.attempt - 1 for n, c in launcher.children.items() if c.pid != first_pids[n]}
        finally:
            session.close()
    report = {
        "cases": rows,
        "ok": sum(not r["problems"] for r in rows),
        "n": len(rows),
        "services_restarted": restarted,
        "loadavg_at_start": load0,
        "loadavg_at_end": Path("/proc/loadavg").read_text().split()[:3],
        "cpu_count": os.cpu_count(),
    }
    out = OUT.with_name("contacts_scenes.json")
    out.write_text(json.dumps(report, indent=2))
    print(
        f"{report['ok']}/{report['n']} cases check out; services restarted {restarted}; wrote {out}; "
        f"load {' '.join(load0)} -> {' '.join(report['loadavg_at_end'])}"
    )
    return 0 if report["ok"] == report["n"] and not restarted else 1


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


if __name__ == "__main__":
    raise SystemExit(main())
