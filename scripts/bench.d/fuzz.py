"""Fuzz benchmark: hostile payloads against every endpoint of a running stack (issue 16).

Starts every service that serves an endpoint (the launcher of ``humanoid up``, on a private hub port,
restarts included), then sends ``--payloads`` payloads spread evenly over the endpoints, drawn by
hypothesis from each request schema and mutated (``tests/fuzzing.py``: valid, leaf, unknown, bytes,
binary); an endpoint slower than ``--time-per-endpoint`` gets fewer, and the fast ones share the
rest in a second pass. Each answer is classified: ok, a typed error, ``internal`` (an unhandled
exception: a bug), ``no_reply`` (nothing within ``--timeout`` seconds). Services restarted by the
launcher are counted.

Writes ``bench/out/fuzz.json``: ``payloads``, ``endpoints``, ``typed_errors``, ``ok``, ``internal``,
``no_reply``, ``services_restarted``, per endpoint and per mutation counts, and the first failures
(endpoint, mutation, message, the payload's head). Goals: internal 0, no_reply 0, services_restarted 0.

Usage: scripts/bench fuzz [--payloads N] [--timeout S] [--seed S] [--log-dir DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "fuzz.json"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _pass(
    spec: Any,
    n: int,
    args: argparse.Namespace,
    session: Any,
    robot: str,
    tally: Any,
    q_ref: tuple[float, ...],
    seed_offset: int = 0,
) -> int:
    """One endpoint's share of payloads; how many were sent (fewer when its time ran out)."""
    t0 = time.monotonic()
    before = tally.payloads
    _fuzz_endpoint(spec, n, args, session, robot, tally, q_ref, seed_offset)
    sent = tally.payloads - before
    counts = dict(tally.by_endpoint.get(spec.path, {}))
    print(f"{spec.path:24s} {sent:6d} payloads in {time.monotonic() - t0:6.1f} s: {counts}", flush=True)
    return sent


def _fuzz_endpoint(
    spec: Any,
    n: int,
    args: argparse.Namespace,
    session: Any,
    robot: str,
    tally: Any,
    q_ref: tuple[float, ...],
    seed_offset: int = 0,
) -> None:
    """Send ``n`` hypothesis-drawn payloads to ``spec`` and count the answers in ``tally``."""
    from fuzzing import payloads, send
    from hypothesis import HealthCheck, Phase, given, seed, settings

    @seed(args.seed + seed_offset)
    @settings(
        max_examples=n,
        deadline=None,
        database=None,
        phases=(Phase.generate,),
        suppress_health_check=list(HealthCheck),
    )
    @given(payloads(spec, q_ref))
    def run(case: tuple[str, bytes]) -> None:
        if time.monotonic() > deadline:
            return  # the endpoint's time is up: the remaining examples are drawn, not sent
        kind, raw = case
        outcome, message = send(session, robot, spec, raw, args.timeout)
        tally.add(spec, kind, raw, outcome, message)

    deadline = time.monotonic() + args.time_per_endpoint
    run()


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="scripts/bench fuzz", description=__doc__.split("\n\n")[0])
    parser.add_argument("--payloads", type=int, default=10_000, help="payloads in all (10000)")
    parser.add_argument("--timeout", type=float, default=45.0, help="seconds to wait for an answer (45)")
    parser.add_argument("--seed", type=int, default=0, help="hypothesis seed (0)")
    parser.add_argument(
        "--time-per-endpoint",
        type=float,
        default=240.0,
        help="seconds one endpoint may take in one pass (240); the payloads a slow endpoint did not get "
        "go to the others in a second pass",
    )
    parser.add_argument("--only", default="", help="comma-separated endpoints (service/name) to fuzz")
    parser.add_argument("--log-dir", default="bench/out/fuzz-logs", help="services' output")
    parser.add_argument("--out", default=str(OUT), help="JSON output file")
    args = parser.parse_args(argv)

    for path in (REPO, REPO / "tests"):
        if str(path) not in sys.path:
            sys.path.insert(0, str(path))
    from fuzzing import Tally, reference_q

    from services.bus.config import BusConfig
    from services.bus.discovery import RECORDER, discover
    from services.bus.schemas import endpoints
    from services.bus.session import Client
    from supervisor.fetch import running_stack

    found, _ = discover()
    # not the recorder's record/status: the stack runs without a recorder (it would log the whole fuzz)
    specs = [s for p, s in sorted(endpoints().items()) if s.service in found and s.service != RECORDER]
    if args.only:
        wanted = {p.strip() for p in args.only.split(",")}
        specs = [s for s in specs if s.path in wanted]
    services = tuple(sorted({s.service for s in specs}))
    per_endpoint = max(1, -(-args.payloads // max(1, len(specs))))
    bus = BusConfig().with_hub_port(_free_port())
    tally = Tally()
    started = time.monotonic()
    with running_stack(bus, services=services, log_dir=args.log_dir) as launcher:
        from services.bus.session import open_session

        session = open_session(bus)
        try:
            Client(session, bus.robot).wait_for(list(services), 60.0)
            first_pids = {name: c.pid for name, c in launcher.children.items()}
            q_ref = reference_q(session, bus.robot) if "sim" in services else ()
            fast = []
            for spec in specs:
                sent = _pass(spec, per_endpoint, args, session, bus.robot, tally, q_ref)
                if sent >= per_endpoint:
                    fast.append(spec)
            missing = args.payloads - tally.payloads
            if missing > 0 and fast:  # second pass: what the slow endpoints did not take
                extra = -(-missing // len(fast))
                for i, spec in enumerate(fast):
                    _pass(spec, extra, args, session, bus.robot, tally, q_ref, seed_offset=i + 1)
            restarted = {
                name: c.attempt - 1 for name, c in launcher.children.items() if c.pid != first_pids[name]
            }
        finally:
            session.close()
    result = {
        "payloads": tally.payloads,
        "endpoints": [s.path for s in specs],
        "typed_errors": tally.typed_errors,
        "ok": tally.outcomes.get("ok", 0),
        "internal": tally.outcomes.get("internal", 0),
        "no_reply": tally.outcomes.get("no_reply", 0),
        "bad_error": tally.outcomes.get("bad_error", 0),
        "services_restarted": sum(restarted.values()),
        "restarted": restarted,
        "outcomes": dict(tally.outcomes),
        "by_endpoint": {k: dict(v) for k, v in tally.by_endpoint.items()},
        "by_mutation": dict(tally.by_mutation),
        "failures": tally.failures,
        "samples": tally.samples,
        "wall_s": round(time.monotonic() - started, 1),
        "seed": args.seed,
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "loadavg": os.getloadavg()},
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    print(
        f"\n{result['payloads']} payloads over {len(specs)} endpoints in {result['wall_s']} s: "
        f"typed errors {result['typed_errors']}, ok {result['ok']}, internal {result['internal']}, "
        f"no reply {result['no_reply']}, services restarted {result['services_restarted']} "
        f"(load average {os.getloadavg()[0]:.1f}); wrote {out}"
    )
    bad = result["internal"] + result["no_reply"] + result["bad_error"] + result["services_restarted"]
    return 1 if bad else 0
