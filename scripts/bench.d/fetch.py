"""Ball-fetch benchmark: the whole fetch script over seeded random layouts of the demo scene.

Starts every service once (the launcher of ``humanoid up``, on a private hub port), then for each seed
``0..n-1`` resets the sim to ``ball_fetch`` with that seed (random box, ball, table and chair
placement within the scene file's ranges) and runs ``supervisor/scripts/fetch.txt``.

A run succeeds when the script succeeds **and** the sim's ground truth (benchmarks may read it; the
supervisor never does) has the orange ball resting on the yellow table: not held, its centre within the
table top's rectangle and 0 to 6 cm above the top plus its radius.

Writes ``bench/out/fetch.json``: ``n``, ``success_rate``, ``median_wall_s``, ``median_sim_s`` (over all
runs), ``retries`` (total), ``real_time_factor`` (median sim / wall), ``median_think_s`` (median wall
time from an action attempt's start to its first ``sim/execute`` chunk, over every attempt that moved
the robot: how long the robot stands still thinking), ``footsteps_plan_calls`` (median calls to
``footsteps/plan`` per fetch, counted in the recorded log: the stack's recorder writes every
``footsteps/**`` message to an MCAP file beside ``--out`` and each fetch's requests are those logged
between its start and end; in ``--worker`` mode, the supervisor's requests as they go out), and per run: seed,
ok, script_ok, on_table, wall_s, sim_s, retries, think_s (median), footsteps_plan_calls, failure,
sim_by_phase_s (simulated seconds per phase from the transcript: :func:`sim_by_phase`), cpu_s (CPU
seconds of each process during the fetch: :class:`CpuWatch`), and ``median_sim_by_phase_s`` and
``median_cpu_s`` over the runs. CPU time, unlike wall time, moves little with the machine's load: it
says where a fetch's compute goes (the services are separate processes: sim, perception, navigation,
footsteps, walking, reaching, record; ``supervisor`` is this process: the supervisor, the launcher's
threads and this benchmark's bookkeeping).
The supervisor's transcript of each fetch goes to ``LOG_DIR/transcript_<seed>.txt``.
Goals (issues 10, 15): success >= 95 %, wall time <= sim time, median think <= 1 s, >= 2 footstep
plans per fetch.

Side by side (issue 15's wall-time goal): ``--baseline DIR`` runs a second checkout (e.g. a git worktree
of the commit to compare with, its own ``.venv`` made by its ``scripts/_venv.sh``) in the same run. Each
tree's stack runs in its own worker process (this file with ``--worker``, under that tree's Python and
``PYTHONPATH``); the seeds alternate between the two (this tree first on even seeds, the baseline first on
odd ones) so that the machine's load hits both alike. Adds ``baseline`` (the baseline's figures and runs),
``baseline_median_wall_s`` and ``wall_ratio`` (this tree's median wall time / the baseline's),
``baseline_median_sim_s`` and ``sim_ratio`` (the same for simulated time: independent of the load) and
``cpu_ratio`` (the medians of the whole stack's CPU seconds per fetch: nearly independent of the load) to
the JSON.
Neither stack has a subscriber on ``hrp/**`` (timings compare only under the same subscriber conditions).

Layouts outside the seeded family (``--layouts NAME,...|all``, ``scripts/bench.d/_fetch_layouts.py``):
the box turned or elsewhere, the balls closer together or at the box's edge, another ball to take, the
table turned or on the other side, the ball on the floor or on the table to be put on the box. Each is a
scene file written to ``LOG_DIR/scenes`` (the sim loads it by name: ``sim: scene_dirs``) and its own
script; a run is judged on that layout's ball and surface; runs carry ``layout`` instead of a seed.

Usage: scripts/bench fetch [--n N] [--seed0 S] [--log-dir DIR] [--baseline DIR] [--layouts NAMES]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import re
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "fetch.json"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


#: Motion announcements of the supervisor's transcript: "<what>: 11.2 s motion, 9 steps (navigation/goto".
_MOTION = re.compile(r"([0-9.]+) s motion(?:, [0-9]+ steps?)? \(([a-z_]+/[a-z_]+)")

PHASES = {
    "navigation/goto": "walk",
    "footsteps/plan": "last_steps",
    "walking/goal": "step_back_turn",
    "walking/plan": "walk_other",
    "reaching/reach": "arm",
}
"""Phase of a motion by the planner that made it (the first endpoint named in its announcement)."""


def sim_by_phase(transcript: str, sim_s: float) -> dict[str, float]:
    """Simulated seconds per phase of one fetch, from its transcript: the motions announced as
    "<what>: X s motion[, N steps] (planner/endpoint ...)" summed by :data:`PHASES` (the "ok:" lines,
    which repeat the last walk's announcement, are skipped), ``other`` the rest of ``sim_s`` (head
    motions, looking, standing). A motion stopped early (collision) counts its planned duration."""
    out = dict.fromkeys(PHASES.values(), 0.0)
    for line in transcript.splitlines():
        message = line.split("]", 1)[-1].strip()
        match = _MOTION.search(message)
        if match is None or message.startswith("ok:"):
            continue
        phase = PHASES.get(match.group(2), "walk_other")
        out[phase] += float(match.group(1))
    out["other"] = sim_s - sum(out.values())
    return {k: round(v, 2) for k, v in out.items()}


class CallWatch:
    """Per fetch: the wall time from each action attempt's start (the runner's ``started`` event) to
    its first ``sim/execute`` request, and the ``footsteps/plan`` requests (the supervisor's bus hook)."""

    def __init__(self, sup: Any) -> None:  # supervisor.core.Supervisor
        self.think_s: list[float] = []
        self.footsteps_plans = 0
        self._started: float | None = None
        self._forward = sup.runner.on_event
        sup.runner.on_event = self._on_event
        sup.bus.on_call = self._on_call

    def reset(self) -> None:
        self.think_s, self.footsteps_plans, self._started = [], 0, None

    def _on_event(self, event: Any) -> None:  # supervisor.runner.Event
        self._forward(event)
        if event.kind == "started":
            self._started = time.monotonic()

    def _on_call(self, spec: Any) -> None:  # services.bus.spec.EndpointSpec
        if spec.path == "footsteps/plan":
            self.footsteps_plans += 1
        elif spec.path == "sim/execute" and self._started is not None:
            self.think_s.append(time.monotonic() - self._started)
            self._started = None


def process_cpu_s(pid: int) -> float:
    """CPU time [s] (user + system, every thread, ended ones included) of process ``pid`` so far (Linux
    ``/proc/<pid>/stat``, 10 ms resolution); 0.0 when the process is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return 0.0
    fields = stat.rsplit(")", 1)[1].split()  # after the command name, which may hold spaces
    utime, stime = int(fields[11]), int(fields[12])  # fields 14 and 15 of proc(5)
    return (utime + stime) / os.sysconf("SC_CLK_TCK")


class CpuWatch:
    """CPU seconds of each process of the stack between :meth:`reset` and :meth:`read`: the launcher's
    children by service name (a restarted service counts from its new process's start) and
    ``supervisor``, this process."""

    def __init__(self, launcher: Any) -> None:  # services.bus.launcher.Launcher
        self.launcher = launcher
        self._start: dict[str, tuple[int, float]] = {}

    def _now(self) -> dict[str, tuple[int, float]]:
        children = dict(self.launcher.children)
        if getattr(self.launcher, "recorder", None) is not None:
            children["record"] = self.launcher.recorder
        out = {name: (child.pid, process_cpu_s(child.pid)) for name, child in children.items() if child.pid}
        out["supervisor"] = (os.getpid(), time.process_time())
        return out

    def reset(self) -> None:
        self._start = self._now()

    def read(self) -> dict[str, float]:
        """``{process: CPU s since reset}``, sorted by name."""
        out = {}
        for name, (pid, cpu_s) in self._now().items():
            pid0, cpu0_s = self._start.get(name, (pid, 0.0))
            # (a process that ended since reads 0: never a negative figure)
            out[name] = round(max(0.0, cpu_s - (cpu0_s if pid0 == pid else 0.0)), 2)
        return dict(sorted(out.items()))


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench fetch", description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=20, help="number of seeded layouts (20)")
    parser.add_argument("--seed0", type=int, default=0, help="first seed (0)")
    parser.add_argument("--log-dir", default="bench/out/fetch-logs", help="services' output")
    parser.add_argument("--out", default=str(OUT), help="JSON output file")
    parser.add_argument("--baseline", default="", help="another checkout to run side by side (its .venv)")
    parser.add_argument(
        "--layouts", default="", help="layouts outside the seeded family, comma-separated or 'all' (no seeds)"
    )
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)  # seeds on stdin
    args = parser.parse_args(argv)
    if args.baseline:
        if args.layouts:
            parser.error("--layouts runs this tree only (the baseline may not have them)")
        return side_by_side(args, Path(args.baseline).resolve())

    from services.bus.config import BusConfig
    from services.bus.schemas import footsteps as fs_msg
    from services.bus.schemas import sim as sim_msg
    from supervisor.core import Supervisor
    from supervisor.evaluate import ball_on_table
    from supervisor.fetch import fetch, running_stack
    from supervisor.script import parse_script

    bus = BusConfig().with_hub_port(_free_port())
    runs = []
    windows: list[tuple[int, int]] = []
    # The footstep planner's messages are recorded (not in a side-by-side worker: no subscriber there).
    record = None if args.worker else str(Path(args.out).with_suffix(".mcap"))
    # Imported only when recording: a side-by-side worker runs this file in an older tree too.
    stack_options: dict[str, Any] = {}
    layouts = _layouts_module().by_name(args.layouts) if args.layouts else []
    if record:
        from supervisor.evaluate import record_config

        Path(args.log_dir).mkdir(parents=True, exist_ok=True)
        config_path = record_config(Path(args.log_dir) / "record.yaml")
        if layouts:  # the layouts' scene files, loaded by name by the sim
            scenes = _layouts_module().write_scenes(layouts, Path(args.log_dir).resolve() / "scenes")
            with open(config_path, "a") as config:
                config.write(f"sim:\n  scene_dirs: [{json.dumps(str(scenes))}]\n")
        stack_options = {"record": record, "config_path": config_path}
    with (
        running_stack(bus, log_dir=args.log_dir, **stack_options) as launcher,
        Supervisor.connect(bus) as sup,
    ):
        missing = sup.wait_for_services(30.0)
        if missing:
            print(f"services missing: {', '.join(missing)}", file=sys.stderr)
        watch = CallWatch(sup)
        cpu = CpuWatch(launcher)
        seeds = _stdin_seeds() if args.worker else range(args.seed0, args.seed0 + args.n)
        # lazily: a worker's seeds arrive on stdin one at a time (a list would wait for its EOF)
        cases = ((layout.name, layout) for layout in layouts) if layouts else ((seed, None) for seed in seeds)
        for seed, layout in cases:
            watch.reset()
            cpu.reset()
            start_ns = time.time_ns()
            # The supervisor's transcript of each fetch beside the services' logs (failures by cause).
            with open(Path(args.log_dir) / f"transcript_{seed}.txt", "w") as transcript:
                sup.out = transcript
                try:
                    if layout is None:
                        summary, _report = fetch(sup, seed=seed)
                    else:
                        steps = parse_script(layout.script())
                        summary, _report = fetch(sup, scene=layout.scene_name, steps=steps)
                finally:
                    sup.out = None
            windows.append((start_ns, time.time_ns()))
            cpu_s = cpu.read()
            transcript_text = (Path(args.log_dir) / f"transcript_{seed}.txt").read_text()
            gt = sup.bus.call(sim_msg.GROUND_TRUTH, sim_msg.GroundTruthRequest(), 10.0)
            judged = {} if layout is None else {"ball": layout.ball, "table": layout.surface}
            on_table, why = ball_on_table(gt, **judged)
            run = {
                "layout" if layout is not None else "seed": seed,
                "ok": summary.ok and on_table,
                "script_ok": summary.ok,
                "on_table": on_table,
                "wall_s": round(summary.wall_s, 2),
                "sim_s": round(summary.sim_s, 2),
                "retries": summary.retries,
                "think_s": round(statistics.median(watch.think_s), 2) if watch.think_s else None,
                "think_samples_s": [round(t, 2) for t in watch.think_s],
                "footsteps_plan_calls": watch.footsteps_plans,
                "failure": summary.failure or why,
                "sim_by_phase_s": sim_by_phase(transcript_text, summary.sim_s),
                "cpu_s": cpu_s,
            }
            runs.append(run)
            print(
                f"{'layout' if layout else 'seed'} {seed!s:>3}  {'ok  ' if run['ok'] else 'FAIL'}  "
                f"wall {run['wall_s']:6.1f} s  "
                f"sim {run['sim_s']:6.1f} s  retries {run['retries']}  think {run['think_s']} s  "
                f"footsteps/plan x{run['footsteps_plan_calls']}  cpu {sum(cpu_s.values()):.1f} s  "
                f"{run['failure']}",
                flush=True,
            )
            if args.worker:
                print(WORKER_TAG + json.dumps(run), flush=True)
    if args.worker:
        return 0
    if record:  # the recorder has closed the log: count there
        from supervisor.evaluate import requests_in_log

        for run, count in zip(runs, requests_in_log(record, fs_msg.PLAN, windows), strict=True):
            run["footsteps_plan_calls"] = count
    result = summarize(runs)
    result.update(
        {
            "goals": {
                "success_rate": 0.95,
                "real_time_factor": 1.0,
                "median_think_s": 1.0,
                "footsteps_plan_calls": 2,
            },
            "runs": runs,
            "machine": {
                "cpus": os.cpu_count(),
                "python": platform.python_version(),
                "load_avg": os.getloadavg(),
            },
            "when": time.strftime("%Y-%m-%dT%H:%M:%S"),
        }
    )
    print_table(result)
    return write(result, Path(args.out))


def _layouts_module() -> Any:
    """``_fetch_layouts.py`` beside this file (bench.d is not a package)."""
    path = Path(__file__).with_name("_fetch_layouts.py")
    spec = importlib.util.spec_from_file_location("bench_fetch_layouts", path)
    assert spec is not None and spec.loader is not None
    module = sys.modules.get(spec.name)
    if module is None:
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # dataclasses look their module up by name
        spec.loader.exec_module(module)
    return module


def summarize(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The figures over ``runs`` (the per-seed dicts)."""
    n = len(runs)
    return {
        "n": n,
        "success_rate": sum(r["ok"] for r in runs) / max(n, 1),
        "median_wall_s": statistics.median(r["wall_s"] for r in runs) if runs else None,
        "median_sim_s": statistics.median(r["sim_s"] for r in runs) if runs else None,
        "retries": sum(r["retries"] for r in runs),
        "real_time_factor": statistics.median(r["sim_s"] / max(r["wall_s"], 1e-9) for r in runs)
        if runs
        else None,
        "median_think_s": statistics.median(t for r in runs for t in r["think_samples_s"])
        if any(r["think_samples_s"] for r in runs)
        else None,
        "footsteps_plan_calls": statistics.median(r["footsteps_plan_calls"] for r in runs) if runs else None,
        "median_sim_by_phase_s": {
            phase: round(statistics.median(r["sim_by_phase_s"][phase] for r in runs), 2)
            for phase in runs[0]["sim_by_phase_s"]
        }
        if runs and all("sim_by_phase_s" in r for r in runs)
        else None,
        "median_cpu_s": {
            name: round(statistics.median(r["cpu_s"].get(name, 0.0) for r in runs), 2)
            for name in sorted({name for r in runs for name in r["cpu_s"]})
        }
        if runs and all("cpu_s" in r for r in runs)
        else None,
        "median_cpu_total_s": round(statistics.median(sum(r["cpu_s"].values()) for r in runs), 2)
        if runs and all("cpu_s" in r for r in runs)
        else None,
    }


def print_table(result: dict[str, Any]) -> None:
    """The summary table of one tree's figures."""
    n = result["n"]
    print()
    print(
        f"{'n':>4} {'success':>8} {'median wall [s]':>16} {'median sim [s]':>15} "
        f"{'retries':>8} {'sim/wall':>9} {'think [s]':>10} {'footsteps/plan':>15}"
    )
    print(
        f"{n:>4} {result['success_rate']:>8.0%} {result['median_wall_s']:>16.1f} "
        f"{result['median_sim_s']:>15.1f} "
        f"{result['retries']:>8} {result['real_time_factor']:>9.2f} "
        f"{result['median_think_s'] or 0.0:>10.2f} {result['footsteps_plan_calls'] or 0:>15}"
    )
    if result.get("median_sim_by_phase_s"):
        phases = ", ".join(f"{k} {v:.1f}" for k, v in result["median_sim_by_phase_s"].items())
        print(f"median sim per phase [s]: {phases}")
    if result.get("median_cpu_s"):
        cpu = ", ".join(f"{k} {v:.1f}" for k, v in result["median_cpu_s"].items())
        print(f"median CPU per process [s]: {cpu} (total {sum(result['median_cpu_s'].values()):.1f})")


def write(result: dict[str, Any], out: Path) -> int:
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


# ------------------------------------------------------------------------ side by side with a baseline
WORKER_TAG = "FETCH-RUN "
"""Prefix of the line on which a worker prints a finished run (JSON)."""


def _stdin_seeds() -> Any:
    """Seeds, one per line on stdin, as the parent sends them (EOF ends)."""
    for line in sys.stdin:
        if line.strip():
            yield int(line)


class Worker:
    """One tree's stack in a worker process: ``run(seed)`` fetches once and returns the run's dict."""

    def __init__(self, tree: Path, log_dir: Path) -> None:
        python = tree / ".venv" / "bin" / "python"
        if not python.is_file():
            raise SystemExit(f"{python} not found: make the tree's venv with its scripts/_venv.sh")
        self.tree = tree
        log_dir.mkdir(parents=True, exist_ok=True)
        self.proc = subprocess.Popen(
            [str(python), str(Path(__file__).resolve()), "--worker", "--log-dir", str(log_dir)],
            cwd=tree,
            env={**os.environ, "PYTHONPATH": str(tree)},
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )

    def run(self, seed: int) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(f"{seed}\n")
        self.proc.stdin.flush()
        for line in self.proc.stdout:
            if line.startswith(WORKER_TAG):
                return json.loads(line[len(WORKER_TAG) :])
        raise SystemExit(f"the worker of {self.tree} ended before seed {seed}'s result")

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.terminate()
            self.proc.wait(timeout=10)


def side_by_side(args: argparse.Namespace, baseline: Path) -> int:
    """Run every seed on this tree and on ``baseline``, alternating which goes first."""
    log_dir = Path(args.log_dir)
    trees = {"this": REPO, "baseline": baseline}
    workers = {name: Worker(tree, log_dir / name) for name, tree in trees.items()}
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name in trees}
    loads = []
    try:
        for seed in range(args.seed0, args.seed0 + args.n):
            order = ("this", "baseline") if seed % 2 == 0 else ("baseline", "this")
            for name in order:
                run = workers[name].run(seed)
                run["load_avg_1min"] = round(os.getloadavg()[0], 2)
                loads.append(run["load_avg_1min"])
                runs[name].append(run)
                print(
                    f"{name:8s} seed {seed:3d}  {'ok  ' if run['ok'] else 'FAIL'}  "
                    f"wall {run['wall_s']:6.1f} s  "
                    f"sim {run['sim_s']:6.1f} s  cpu {sum(run['cpu_s'].values()):5.1f} s  "
                    f"retries {run['retries']}  load {run['load_avg_1min']}  "
                    f"{run['failure']}",
                    flush=True,
                )
    finally:
        for worker in workers.values():
            worker.close()
    result = summarize(runs["this"])
    base = summarize(runs["baseline"])
    result.update(
        {
            "baseline_median_wall_s": base["median_wall_s"],
            "wall_ratio": round(result["median_wall_s"] / base["median_wall_s"], 3)
            if result["median_wall_s"] and base["median_wall_s"]
            else None,
            "baseline_median_sim_s": base["median_sim_s"],
            # CPU seconds of the whole stack per fetch, this / the baseline: the load moves it little
            "cpu_ratio": round(result["median_cpu_total_s"] / base["median_cpu_total_s"], 3)
            if result["median_cpu_total_s"] and base["median_cpu_total_s"]
            else None,
            "sim_ratio": round(result["median_sim_s"] / base["median_sim_s"], 3)
            if result["median_sim_s"] and base["median_sim_s"]
            else None,
            "goals": {
                "success_rate": 0.95,
                "wall_ratio": 0.7,
                "median_think_s": 1.0,
                "footsteps_plan_calls": 2,
            },
            "runs": runs["this"],
            "baseline": {
                **base,
                "tree": str(baseline),
                "commit": _commit(baseline),
                "runs": runs["baseline"],
            },
            "commit": _commit(REPO),
            "machine": {
                "cpus": os.cpu_count(),
                "python": platform.python_version(),
                "load_avg": os.getloadavg(),
                "load_avg_1min_during": [min(loads), statistics.median(loads), max(loads)] if loads else None,
            },
            "when": time.strftime("%Y-%m-%dT%H:%M:%S"),
        }
    )
    for name, figures in (("this tree", result), ("baseline", base)):
        print(f"\n{name}:", end="")
        print_table(figures)
    print(f"\nwall ratio (this / baseline, medians): {result['wall_ratio']}")
    print(f"sim ratio (this / baseline, medians): {result['sim_ratio']}")
    print(f"CPU ratio (this / baseline, medians of the stack's CPU s per fetch): {result['cpu_ratio']}")
    return write(result, Path(args.out))


def _commit(tree: Path) -> str:
    """The short commit of ``tree``'s HEAD (+ ``-dirty`` with uncommitted changes)."""
    head = subprocess.run(
        ["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    )
    dirty = subprocess.run(
        ["git", "-C", str(tree), "status", "--porcelain", "-uno"], capture_output=True, text=True
    )
    return head.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")


if __name__ == "__main__":  # a worker: scripts/bench.d/fetch.py --worker (seeds on stdin)
    raise SystemExit(main(sys.argv[1:]))
