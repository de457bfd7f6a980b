"""Soak benchmark: many fetches in a row on one stack, and fetches with a service killed (issue 16).

Starts every service of the fetch once (the launcher of ``humanoid up``, restarts included) and runs
the fetch script ``--n`` times in a row (``--layouts nominal``, the default: the nominal layout of
``ball_fetch`` every time, so that a failure is the stack's, not a harder layout's - the layouts are
``scripts/bench fetch``'s concern; ``--layouts seeded``: seeded layouts ``seed0..seed0+n-1``), reading each
service's resident memory, threads and open files (``/proc``) after the first fetch and after the
last. ``max_growth`` is the largest relative growth of any of them, for any service, between the two
(goal <= 0.10); ``success_rate`` the share of fetches that put the ball on the table (goal >= 0.95).

``--kill``: instead, one fetch per service of ``--victims`` during which that service is killed
with SIGKILL as the supervisor's first request to it goes out (the sim: its first ``sim/execute``;
footsteps, which the fetch does not call, 5 s into the fetch): a planner's death must end in a
completed fetch (the launcher restarts it, the supervisor retries), the sim's in a failure that says
so, never in a hang.

Writes ``bench/out/soak.json`` (``--kill``: ``bench/out/soak_kill.json``).

Usage: scripts/bench soak [--n 30] [--layouts nominal|seeded] [--seed0 S] [--log-dir DIR]
       scripts/bench soak --kill [--victims perception,navigation,...]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import socket
import sys
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "soak.json"
OUT_KILL = REPO / "bench" / "out" / "soak_kill.json"
VICTIMS = ("perception", "navigation", "walking", "footsteps", "reaching", "sim")
#: Longest a fetch may take before it counts as hung [s] (a fetch takes 1-3 min on a loaded machine).
HANG_S = 900.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def resources(pid: int) -> dict[str, float]:
    """Resident memory [MB], threads and open files of a process (Linux /proc)."""
    status = Path(f"/proc/{pid}/status").read_text().splitlines()
    fields = dict(line.split(":", 1) for line in status if ":" in line)
    return {
        "rss_mb": int(fields["VmRSS"].split()[0]) / 1024.0,
        "threads": int(fields["Threads"]),
        "open_files": len(os.listdir(f"/proc/{pid}/fd")),
    }


def snapshot(launcher: Any) -> dict[str, dict[str, float]]:
    out = {}
    for name, child in launcher.children.items():
        if child.proc is not None and child.proc.poll() is None:
            out[name] = {"pid": child.proc.pid, **resources(child.proc.pid)}
    return out


def growth(before: dict[str, dict[str, float]], after: dict[str, dict[str, float]]) -> tuple[float, str]:
    """The largest relative growth of a resource of a service present (same pid) in both."""
    worst, where = 0.0, ""
    for name, b in before.items():
        a = after.get(name)
        if a is None or a["pid"] != b["pid"]:
            continue
        for key in ("rss_mb", "threads", "open_files"):
            rel = (a[key] - b[key]) / max(b[key], 1e-9)
            if rel > worst:
                worst, where = rel, f"{name}.{key}"
    return worst, where


def _run(sup: Any, fetch: Any, seed: int | None) -> tuple[dict[str, Any], Any]:
    out: list[Any] = []

    def run() -> None:
        try:
            out.append(fetch(sup, seed=seed))
        except Exception as exc:  # e.g. the reset itself failed: the fetch ends, it does not hang
            out.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    started = time.monotonic()
    thread.start()
    thread.join(HANG_S)
    if thread.is_alive():
        return {"seed": seed, "ok": False, "hung": True, "wall_s": HANG_S, "failure": "hung"}, None
    if isinstance(out[0], Exception):
        failure = f"{type(out[0]).__name__}: {out[0]}"
        return {"seed": seed, "ok": False, "hung": False, "wall_s": round(time.monotonic() - started, 1),
                "failure": failure}, None  # fmt: skip
    summary, report = out[0]
    return {
        "seed": seed,
        "ok": summary.ok,
        "hung": False,
        "wall_s": round(time.monotonic() - started, 1),
        "sim_s": round(summary.sim_s, 1),
        "retries": summary.retries,
        "failure": summary.failure,
    }, report


def soak(args: argparse.Namespace, launcher: Any, sup: Any) -> dict[str, Any]:
    from services.bus.schemas import sim as sim_msg
    from supervisor.evaluate import ball_on_table
    from supervisor.fetch import fetch

    runs, after_first = [], {}
    start = snapshot(launcher)
    for i in range(args.n):
        row, _ = _run(sup, fetch, args.seed0 + i if args.layouts == "seeded" else None)
        if not row["hung"]:
            truth = sup.bus.call(sim_msg.GROUND_TRUTH, sim_msg.GroundTruthRequest(), 10.0)
            row["on_table"] = bool(ball_on_table(truth)[0])
            row["ok"] = row["ok"] and row["on_table"]
        row["loadavg_1min"] = round(os.getloadavg()[0], 2)
        runs.append(row)
        if i == 0:
            after_first = snapshot(launcher)
        print(f"fetch {i + 1}/{args.n} seed {row['seed']}: {'ok' if row['ok'] else row['failure']} "
              f"({row['wall_s']} s)", flush=True)  # fmt: skip
        if row["hung"]:
            break
        if i + 1 < args.n:  # the figures so far, on disk after every fetch: a long soak stopped early
            partial = _soak_result(args, launcher, runs, start, after_first, snapshot(launcher))
            _write(Path(args.out or OUT), {**partial, "complete": False, "machine": _machine()})
    return {**_soak_result(args, launcher, runs, start, after_first, snapshot(launcher)), "complete": True}


def _machine() -> dict[str, Any]:
    return {"platform": platform.platform(), "cpus": os.cpu_count(), "loadavg": os.getloadavg()}


def _write(path: Path, result: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=1))


def _soak_result(
    args: argparse.Namespace,
    launcher: Any,
    runs: list[dict[str, Any]],
    start: dict[str, dict[str, float]],
    after_first: dict[str, dict[str, float]],
    end: dict[str, dict[str, float]],
) -> dict[str, Any]:
    """The soak's figures over ``runs``: success rate, growth from after the first fetch to ``end``."""
    worst, where = growth(after_first, end)
    return {
        "n": len(runs),
        "n_asked": args.n,
        "layouts": args.layouts,
        "success_rate": sum(r["ok"] for r in runs) / max(1, len(runs)),
        "max_growth": round(worst, 4),
        "max_growth_at": where,
        "services_restarted": {n: c.attempt - 1 for n, c in launcher.children.items() if c.attempt > 1},
        "resources": {"start": start, "after_first": after_first, "end": end},
        "runs": runs,
        "goals": {"success_rate": ">= 0.95", "max_growth": "<= 0.10"},
    }


def kill_each(args: argparse.Namespace, launcher: Any, sup: Any) -> dict[str, Any]:
    from supervisor.fetch import fetch

    rows = []
    for victim in [v.strip() for v in args.victims.split(",") if v.strip()]:
        child = launcher.children.get(victim)
        if child is None or child.proc is None:
            rows.append({"victim": victim, "skipped": "not running"})
            continue
        pid = child.proc.pid
        killed = threading.Event()

        def kill(spec: Any, victim: str = victim, pid: int = pid, killed: threading.Event = killed) -> None:
            # the sim: as the first motion goes out (mid-fetch, after the reset and the first looks)
            first = spec.path == "sim/execute" if victim == "sim" else spec.service == victim
            if first and not killed.is_set():
                killed.set()
                threading.Thread(target=os.killpg, args=(pid, signal.SIGKILL)).start()

        timer = None
        if victim == "footsteps":  # the fetch does not call it: kill it while the fetch runs

            def late_kill(pid: int = pid, killed: threading.Event = killed) -> None:
                killed.set()
                os.killpg(pid, signal.SIGKILL)

            timer = threading.Timer(5.0, late_kill)
            timer.start()
        else:
            sup.bus.on_call = kill
        seen = len(sup.events)
        try:
            row, _report = _run(sup, fetch, None)
        finally:
            sup.bus.on_call = None
            if timer is not None:
                timer.cancel()
        row.update(
            victim=victim,
            killed=killed.is_set(),
            restarted=child.proc.pid != pid,
            failures=[
                {"step": e.step, "reason": e.reason, "message": e.message[:300]}
                for e in sup.events[seen:]
                if e.kind == "failed"
            ][-5:],
        )
        rows.append(row)
        print(f"kill {victim}: fetch {'completed' if row['ok'] else 'failed: ' + row['failure']}", flush=True)
        deadline = time.monotonic() + 120
        while child.state != "ready" and time.monotonic() < deadline:
            time.sleep(0.5)
    return {"kills": rows}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench soak", description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=30, help="fetches in a row (30)")
    parser.add_argument(
        "--layouts", choices=("nominal", "seeded"), default="nominal", help="ball_fetch layouts (nominal)"
    )
    parser.add_argument("--seed0", type=int, default=0, help="first layout seed with --layouts seeded (0)")
    parser.add_argument("--kill", action="store_true", help="one fetch per victim, killed mid-fetch")
    parser.add_argument("--victims", default=",".join(VICTIMS), help="services to kill with --kill")
    parser.add_argument("--log-dir", default="bench/out/soak-logs", help="services' output")
    parser.add_argument("--out", default="", help="JSON output file")
    args = parser.parse_args(argv)
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))

    from services.bus.config import BusConfig
    from supervisor.core import SERVICES, Supervisor
    from supervisor.fetch import running_stack

    bus = BusConfig().with_hub_port(_free_port())
    services = tuple(dict.fromkeys((*SERVICES, "footsteps")))  # the fetch calls footsteps/plan too
    started = time.monotonic()
    stack = running_stack(bus, services=services, log_dir=args.log_dir)
    with stack as launcher, Supervisor.connect(bus) as sup:
        missing = sup.wait_for_services(60.0)
        if missing:
            print(f"services missing: {', '.join(missing)}", file=sys.stderr)
            return 1
        result = kill_each(args, launcher, sup) if args.kill else soak(args, launcher, sup)
    result["wall_s"] = round(time.monotonic() - started, 1)
    result["machine"] = _machine()
    out = Path(args.out or (OUT_KILL if args.kill else OUT))
    _write(out, result)
    if args.kill:
        ok = all(r.get("ok") == (r.get("victim") != "sim") for r in result["kills"] if "skipped" not in r)
        print(f"wrote {out} (load average {os.getloadavg()[0]:.1f})")
        return 0 if ok else 1
    print(
        f"{result['n']} fetches: success rate {result['success_rate']:.2f}, max growth "
        f"{result['max_growth']:.3f} ({result['max_growth_at']}), load average {os.getloadavg()[0]:.1f}; "
        f"wrote {out}"
    )
    return 0 if result["success_rate"] >= 0.95 and result["max_growth"] <= 0.10 else 1
