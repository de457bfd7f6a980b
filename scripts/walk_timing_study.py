"""Fall study of the walking step timing on walks like the fetch's, in the sim (pybullet DIRECT, no bus).

For each walk (seeded) and each timing setting (single support, double support) [s]: the robot stands in
an empty world, empty-handed or (every other walk) with the right hand at the supervisor's carry point
(reached first with ``services.reaching``, executed in the sim, as after a grasp: the 0.1 kg ball left
out), then plans from the state the sim reports, as the supervisor does:

- ``goto``: navigation's two stages (``services.navigation.goto.plan_goto``, car-like path, footsteps,
  whole-body stage 2 with its per-step slowdown when a joint is too fast) to a pose 1-3 m away in any
  direction, any final heading (turning steps, curves);
- ``turn``: a turn on the spot of 60-180 deg (``turn_in_place``), as the fetch's turn after a grasp;
- ``back``: 0.3-0.45 m straight back (the step back before that turn);
- ``near``: navigation's walk to a goal 0.6-1.4 m away, up to 60 deg to the side and turned by up to
  45 deg (the walk to the box or the table after the approach: walked straight, sideways and turning,
  or facing the way: turning toward it, walking, turning there);
- ``side``: 0.2-0.5 m straight to the left or right (``walking/goal``'s ``walk_to_steps``: side steps,
  the kind that rocks the robot most with the turns on the spot).

and executes it (``World.execute``), with the sim's stabilizer (``sim/stabilizer.py``) when the setting
ends in ``/s`` (e.g. ``0.7/0.1/s``). Per setting: walks planned, refused by the planner, fallen,
completed; the smallest planned multibody ZMP margin; the fastest knee (LEG_JOINT3) of the executed
plan over its 4.0 rad/s limit; the walk's duration; the largest base roll and pitch measured during
the walk and the 0.5 s after it (the rocking). JSON lines to ``--out`` as it goes (resumable reading),
a table at the end.

Usage: .venv/bin/python scripts/walk_timing_study.py [--n 12] [--start I] [--settings 0.7/0.2,0.7/0.1/s,...]
[--out F] [--summarize]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from services.collision import Scene  # noqa: E402
from services.errors import HumanoidError  # noqa: E402
from services.model.ground import sole_pose_at  # noqa: E402
from services.navigation.geometry import Pose2D  # noqa: E402
from services.navigation.goto import GotoOptions, plan_goto, start_pose  # noqa: E402
from services.navigation.stage2 import Stage2Options  # noqa: E402
from services.reaching import ReachRequest, plan_reach  # noqa: E402
from services.walking.footsteps import FootstepBounds, straight_walk, turn_in_place  # noqa: E402
from services.walking.goals import soles_on, walk_to_steps  # noqa: E402
from services.walking.timing import WalkTiming  # noqa: E402
from services.walking.wholebody import plan_walk  # noqa: E402
from sim.config import SimConfig  # noqa: E402
from sim.stabilizer import roll_pitch  # noqa: E402
from sim.world import World  # noqa: E402
from supervisor.config import SupervisorConfig  # noqa: E402

_FORWARD_M, _SIDE_M, _HEIGHT_M = SupervisorConfig().carry_m
CARRY_M = (_FORWARD_M, -_SIDE_M, _HEIGHT_M)  # the supervisor's carry point, right hand (lateral to the right)
KNEES = ("LLEG_JOINT3", "RLEG_JOINT3")
KINDS = ("goto", "turn", "back", "near", "side")


def _carry(world: World) -> None:
    """The right hand to the carry point in front of the chest (a reach executed in the sim)."""
    robot = world.robot
    q = world.state().q
    pose = start_pose(robot, q)
    c, s = math.cos(pose.theta_rad), math.sin(pose.theta_rad)
    fx, fy, z = CARRY_M
    target = np.array([pose.x_m + c * fx - s * fy, pose.y_m + s * fx + c * fy, z])
    result = plan_reach(robot, ReachRequest("right", target, q, allow_stepping=False))
    out = world.execute(result.q, hold_s=0.3)
    if out.outcome != "completed":
        raise RuntimeError(f"the carry reach did not complete: {out.message}")


def _plan(
    world: World, kind: str, rng_values: dict[str, float], timing: WalkTiming
) -> tuple[np.ndarray, float, int, str]:
    """(q trajectory, smallest planned multibody ZMP margin [m], steps, path curve) of the walk ``kind``
    from the sim's state."""
    robot = world.robot
    q = world.state().q
    if kind in ("goto", "near"):
        start = start_pose(robot, q)
        d, bearing, heading = rng_values["d"], rng_values["bearing"], rng_values["heading"]
        goal = Pose2D(
            start.x_m + d * math.cos(start.theta_rad + bearing),
            start.y_m + d * math.sin(start.theta_rad + bearing),
            math.remainder(start.theta_rad + heading, 2 * math.pi),
        )
        m = 2.0
        bounds = (
            min(start.x_m, goal.x_m) - m,
            max(start.x_m, goal.x_m) + m,
            min(start.y_m, goal.y_m) - m,
            max(start.y_m, goal.y_m) + m,
        )
        options = GotoOptions(stage2=Stage2Options(timing=timing))
        result = plan_goto(robot, Scene((), bounds), q, goal, options=options)
        steps = len(result.footsteps.sequence.steps)
        return result.motion.q, float(result.motion.zmp_margin_m), steps, result.path.curve
    data = robot.new_data()
    left, right = (sole_pose_at(robot, q, side, data) for side in ("left", "right"))
    limits = FootstepBounds.from_robot(robot)
    if kind == "turn":
        seq = turn_in_place(
            rng_values["angle"],
            2 * math.ceil(abs(rng_values["angle"]) / 0.7),
            sole_size_m=robot.sole_size_m,
            left_start=left,
            right_start=right,
            limits=limits,
        )
    elif kind == "side":
        seq = walk_to_steps(soles_on(robot, q), 0.0, rng_values["side"], 0.0, limits)
    else:
        n = max(2, round(rng_values["back"] / 0.1))
        seq = straight_walk(n, -rng_values["back"] / n, left_start=left, right_start=right, limits=limits)
    plan = plan_walk(robot, seq, q, timing=timing)
    return plan.q, float(plan.min_zmp_margin_m), len(seq.steps), kind


def _knee_ratio(robot, q: np.ndarray, dt_s: float = 0.005) -> float:
    """Fastest knee over its velocity limit along the planned ``q`` (finite differences)."""
    worst = 0.0
    for name in KNEES:
        j = robot.model.getJointId(name)
        iq, iv = robot.model.joints[j].idx_q, robot.model.joints[j].idx_v
        speed = np.abs(np.diff(q[:, iq])) / dt_s
        worst = max(worst, float(speed.max()) / float(robot.model.velocityLimit[iv]))
    return worst


class _Rocking:
    """``World.on_tick`` hook: the largest base roll and pitch [deg] (base frame, from the measured q)."""

    def __init__(self) -> None:
        self.roll_deg = 0.0
        self.pitch_deg = 0.0

    def __call__(self, world: World) -> None:
        roll, pitch = roll_pitch(world.pyrobot.read_q())
        self.roll_deg = max(self.roll_deg, abs(math.degrees(roll)))
        self.pitch_deg = max(self.pitch_deg, abs(math.degrees(pitch)))


def run_one(
    index: int, kind: str, carrying: bool, values: dict[str, float], setting: tuple[float, float, bool]
) -> dict:
    ss, ds, stab = setting
    timing = WalkTiming(single_support_s=ss, double_support_s=ds)
    row: dict = {
        "index": index,
        "kind": kind,
        "carrying": carrying,
        "ss": ss,
        "ds": ds,
        "stab": stab,
        **values,
    }
    t0 = time.perf_counter()
    with World("hrp2_like", "empty", config=SimConfig(stabilizer=stab)) as world:
        if carrying:
            _carry(world)
        try:
            q, margin, row["steps"], row["curve"] = _plan(world, kind, values, timing)
        except HumanoidError as exc:
            row.update(outcome="refused", message=str(exc)[:200])
            return row
        row["zmp_margin_mm"] = 1e3 * margin
        row["knee_ratio"] = _knee_ratio(world.robot, q)
        row["duration_s"] = (q.shape[0] - 1) * 0.005
        rocking = _Rocking()
        world.on_tick = rocking
        cpu0 = time.process_time()
        out = world.execute(q, hold_s=0.5)
        row["exec_cpu_s"] = time.process_time() - cpu0
        row.update(outcome=out.outcome, message=out.message[:200], slip_mm=1e3 * out.foot_slip_m)
        row.update(max_roll_deg=rocking.roll_deg, max_pitch_deg=rocking.pitch_deg)
    row["wall_s"] = time.perf_counter() - t0
    return row


def walks(n: int, seed: int, kinds: tuple[str, ...] = KINDS) -> list[tuple[int, str, bool, dict[str, float]]]:
    """The seeded walk set: ``kinds`` in turn, carrying on every other one of each kind."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        kind = kinds[i % len(kinds)]
        carrying = (i // len(kinds)) % 2 == 0
        values = {
            "d": float(rng.uniform(1.0, 3.0)),
            "bearing": float(rng.uniform(-math.pi, math.pi)),
            "heading": float(rng.uniform(-math.pi, math.pi)),
            "angle": float(rng.choice([-1, 1]) * rng.uniform(math.radians(60), math.pi)),
            "back": float(rng.uniform(0.3, 0.45)),
            "side": float(rng.choice([-1, 1]) * rng.uniform(0.2, 0.5)),
        }
        if kind == "near":
            values.update(
                d=float(rng.uniform(0.6, 1.4)),
                bearing=float(rng.uniform(-math.pi / 3, math.pi / 3)),
                heading=float(rng.uniform(-math.pi / 4, math.pi / 4)),
            )
        keep = {
            "goto": ("d", "bearing", "heading"),
            "near": ("d", "bearing", "heading"),
            "turn": ("angle",),
            "back": ("back",),
            "side": ("side",),
        }[kind]
        out.append((i, kind, carrying, {k: values[k] for k in keep}))
    return out


def table(rows: list[dict]) -> str:
    lines = [
        "| single / double support [s] | walks | refused | fell | completed | min ZMP margin [mm] "
        "| knee > limit (walks) | max knee / limit | median duration [s] | max roll / pitch [deg] "
        "| median roll / pitch [deg] |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    settings = sorted({(r["ss"], r["ds"], r.get("stab", False)) for r in rows}, reverse=True)
    for ss, ds, stab in settings:
        rs = [r for r in rows if (r["ss"], r["ds"], r.get("stab", False)) == (ss, ds, stab)]
        name = f"{ss} / {ds}{' stabilized' if stab else ''}"
        planned = [r for r in rs if r["outcome"] != "refused"]
        margins = [r["zmp_margin_mm"] for r in planned]
        knees = [r["knee_ratio"] for r in planned]
        rolls = [r["max_roll_deg"] for r in planned if "max_roll_deg" in r]
        pitches = [r["max_pitch_deg"] for r in planned if "max_pitch_deg" in r]
        rocking = (
            f"{max(rolls):.2f} / {max(pitches):.2f} | {float(np.median(rolls)):.2f} / "
            f"{float(np.median(pitches)):.2f}"
            if rolls
            else "- | -"
        )
        lines.append(
            f"| {name} | {len(rs)} | {len(rs) - len(planned)} "
            f"| {sum(r['outcome'] == 'fell' for r in rs)} | {sum(r['outcome'] == 'completed' for r in rs)} "
            f"| {min(margins):.1f} | {sum(k > 1.0 for k in knees)} | {max(knees):.2f} "
            f"| {float(np.median([r['duration_s'] for r in planned])):.1f} | {rocking} |"
            if planned
            else f"| {name} | {len(rs)} | {len(rs)} | - | - | - | - | - | - | - | - |"
        )
    return "\n".join(lines)


def _setting(text: str) -> tuple[float, float, bool]:
    """``ss/ds`` or ``ss/ds/s`` (the stabilizer on) -> (single, double support [s], stabilizer)."""
    parts = text.split("/")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] != "s"):
        raise SystemExit(f"a setting is ss/ds or ss/ds/s, got {text!r}")
    return float(parts[0]), float(parts[1]), len(parts) == 3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=12, help="walks (goto, turn, back in turn)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--kinds", default=",".join(KINDS), help="walk kinds in turn")
    parser.add_argument("--start", type=int, default=0, help="first walk index (resume a run)")
    parser.add_argument(
        "--settings", default="0.7/0.2,0.7/0.1,0.7/0.1/s", help="ss/ds [s], /s: with the sim's stabilizer"
    )
    parser.add_argument("--out", default="/tmp/walk_timing_study.jsonl")
    parser.add_argument("--summarize", action="store_true", help="only print the table of --out")
    args = parser.parse_args(argv)
    out = Path(args.out)
    if not args.summarize:
        settings = [_setting(s) for s in args.settings.split(",")]
        with out.open("a") as f:
            kinds = tuple(args.kinds.split(","))
            for index, kind, carrying, values in walks(args.n, args.seed, kinds)[args.start :]:
                for setting in settings:
                    row = run_one(index, kind, carrying, values, setting)
                    f.write(json.dumps(row) + "\n")
                    f.flush()
                    print(json.dumps(row), flush=True)
    rows = [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
