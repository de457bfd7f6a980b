"""``humanoid`` subcommands that look at the bus: list, interface, hz, bw, graph.

Imports stay light at module level: ``humanoid --help`` should not open zenoh or load numpy.
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import json
import sys
import threading
import time
from typing import Any

from services.bus.cli import _bus, _bus_options, _fail, resolve_key, silence_hint
from services.cli_common import EXIT_UNAVAILABLE, examples

LIST_KINDS = ("services", "endpoints", "topics")


def add_cli(subparsers: Any) -> None:
    """Register list, interface, hz, bw and graph."""
    _add_list(subparsers)
    _add_interface(subparsers)
    _add_hz(subparsers)
    _add_bw(subparsers)
    _add_graph(subparsers)


def _live(args: argparse.Namespace, wait_s: float = 0.6) -> set[str]:
    """The services whose liveliness token is on the bus (listens ``wait_s`` for late tokens)."""
    from services.bus.session import alive_services, bus_session

    bus = _bus(args)
    with bus_session(bus) as session:
        alive: set[str] = set()
        deadline = time.monotonic() + wait_s
        while True:
            alive |= alive_services(session, bus.robot, timeout_s=0.3)
            if time.monotonic() >= deadline:
                return alive
            time.sleep(0.05)


# ---------------------------------------------------------------------------------------------------
# list
# ---------------------------------------------------------------------------------------------------
def _add_list(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "list",
        help="the services (alive or not), endpoints and topics, from the live bus and the schemas",
        description="List the services of the stack with whether their liveliness token is on the bus, "
        "and every endpoint and topic of the schema registry with its message types and whether the "
        "service behind it is alive.",
        epilog=examples(
            "humanoid list                     # services, endpoints and topics",
            "humanoid list endpoints",
            "humanoid list topics --json | jq -r '.topics[].name'",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("kind", nargs="?", choices=LIST_KINDS, help="only this kind (default: all three)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--wait", type=float, default=0.6, help="seconds to listen for liveliness tokens (0.6)")
    _bus_options(p)
    p.set_defaults(func=cmd_list)


# The topics every service has besides its schema's (services/bus/keys.py), said under `list topics`.
EVERY_SERVICE_PUBLISHES = (
    "Every service also publishes SERVICE/heartbeat (Heartbeat, 2 Hz), SERVICE/log (LogLine: its log "
    "lines) and, for each of its endpoints, SERVICE/ENDPOINT/request, /reply and /error (a copy of each "
    "exchange, the request id as attachment)."
)


def list_document(alive: set[str]) -> dict[str, list[dict[str, Any]]]:
    """Services, endpoints and topics as JSON-ready rows."""
    from services.bus import schemas
    from services.bus.discovery import discover

    endpoints, topics = schemas.endpoints(), schemas.topics()
    entries, _problems = discover()
    owners = {s.service for s in [*endpoints.values(), *topics.values()]}
    services = []
    for name in sorted(set(entries) | owners | alive):
        entry = entries.get(name)
        services.append(
            {
                "name": name,
                "module": entry.module if entry else None,
                "alive": name in alive,
                "endpoints": sorted(p for p, s in endpoints.items() if s.service == name),
                "topics": sorted(p for p, s in topics.items() if s.service == name),
            }
        )
    return {
        "services": services,
        "endpoints": [
            {
                "name": p,
                "service": s.service,
                "request": s.request.__name__,
                "reply": s.reply.__name__,
                "alive": s.service in alive,
                "doc": s.doc,
            }
            for p, s in sorted(endpoints.items())
        ],
        "topics": [
            {
                "name": p,
                "service": s.service,
                "message": s.message.__name__,
                "alive": s.service in alive,
                "doc": s.doc,
            }
            for p, s in sorted(topics.items())
        ],
    }


def cmd_list(args: argparse.Namespace) -> int:
    from services.bus.launcher import format_table

    alive = _live(args, args.wait)
    doc = list_document(alive)
    kinds = [args.kind] if args.kind else list(LIST_KINDS)
    if not alive:
        print(f"(no service is alive on {_bus(args).hub}: is `humanoid up` running?)", file=sys.stderr)
    if args.json:
        print(json.dumps({k: doc[k] for k in kinds}, indent=2))
        return 0
    yes = {True: "yes", False: "-"}
    for i, kind in enumerate(kinds):
        if i:
            print()
        if kind == "services":
            rows = [
                (
                    s["name"],
                    yes[s["alive"]],
                    str(len(s["endpoints"])),
                    str(len(s["topics"])),
                    s["module"] or "-",
                )
                for s in doc["services"]
            ]
            print(format_table(("SERVICE", "ALIVE", "ENDPOINTS", "TOPICS", "MODULE"), rows))
        elif kind == "endpoints":
            rows = [
                (e["name"], f"{e['request']} -> {e['reply']}", yes[e["alive"]], e["doc"])
                for e in doc["endpoints"]
            ]
            print(format_table(("ENDPOINT", "REQUEST -> REPLY", "ALIVE", "WHAT"), rows))
        else:
            rows = [(t["name"], t["message"], yes[t["alive"]], t["doc"]) for t in doc["topics"]]
            print(format_table(("TOPIC", "MESSAGE", "ALIVE", "WHAT"), rows))
            print(EVERY_SERVICE_PUBLISHES)
    return 0


# ---------------------------------------------------------------------------------------------------
# interface
# ---------------------------------------------------------------------------------------------------
def _add_interface(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "interface",
        help="the fields of an endpoint's request and reply, of a topic's message, or of a message type",
        description="Show the message types of an endpoint (request, reply) or a topic: every field with "
        "its type, default, units, limits and description, nested types expanded. Read from the schemas "
        "(services/bus/schemas/); no service needs to run.",
        epilog=examples(
            "humanoid interface sim/execute",
            "humanoid interface sim/clock",
            "humanoid interface JointState                 # a message type (or walking.PlanRequest)",
            "humanoid interface navigation/goto --json | jq '.request.fields[].path'",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("name", help="SERVICE/NAME of an endpoint or a topic (`humanoid list`), or a message type")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_interface)


def find_spec(name: str) -> Any:
    """The endpoint or topic spec named ``name``; InvalidRequestError listing close names."""
    from services.bus import schemas
    from services.errors import InvalidRequestError

    name = name.strip("/")
    for prefix in ("hrp/",):
        if name.startswith(prefix) and name.count("/") >= 3:
            name = name.split("/", 2)[2]
    specs = {**schemas.topics(), **schemas.endpoints()}
    spec = specs.get(name)
    if spec is None:
        close = difflib.get_close_matches(name, list(specs), n=3, cutoff=0.5)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise InvalidRequestError(
            f"no endpoint, topic or message type {name!r}{hint}; `humanoid list` shows the endpoints and "
            f"topics: {', '.join(sorted(specs))}"
        )
    return spec


def find_type(name: str) -> tuple[str, type] | None:
    """A message type named ``Type`` or ``service.Type``; None when there is none; InvalidRequestError
    when the bare name is several services' type."""
    from services.bus.interfaces import message_types
    from services.errors import InvalidRequestError

    types = message_types()
    if name in types:
        return name, types[name]
    matches = sorted(q for q in types if q.split(".", 1)[1] == name)
    if len(matches) > 1:
        raise InvalidRequestError(f"{name} is the name of several types: {', '.join(matches)}; name one")
    return (matches[0], types[matches[0]]) if matches else None


def cmd_interface(args: argparse.Namespace) -> int:
    from services.bus.interfaces import describe, describe_type
    from services.errors import InvalidRequestError

    try:
        found = find_type(args.name) if "/" not in args.name else None
        doc = describe_type(*found) if found else describe(find_spec(args.name))
    except InvalidRequestError as exc:
        return _fail(exc.message)
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(
        f"{doc['kind']} {doc['name']} (service {doc['service']})" + (f": {doc['doc']}" if doc["doc"] else "")
    )
    parts = ("request", "reply") if doc["kind"] == "endpoint" else ("message",)
    for part in parts:
        print()
        print(_format_part(part, doc[part]))
    return 0


def _format_part(label: str, part: dict[str, Any]) -> str:
    from services.bus.launcher import format_table

    head = f"{label}: {part['type']}" + (f"  - {part['doc']}" if part["doc"] else "")
    if not part["fields"]:
        return head + "\n  (no fields)"
    rows = []
    for f in part["fields"]:
        rows.append(
            (
                "  " + "  " * f["depth"] + f["path"].rsplit(".", 1)[-1] if f["depth"] else "  " + f["path"],
                f["type"],
                f["default"],
                f["units"] or "-",
                f["limits"] or "-",
                f["doc"],
            )
        )
    return head + "\n" + format_table(("  FIELD", "TYPE", "DEFAULT", "UNITS", "LIMITS", "DESCRIPTION"), rows)


# ---------------------------------------------------------------------------------------------------
# hz / bw
# ---------------------------------------------------------------------------------------------------
def _rate_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("topic", help="SERVICE/NAME or a key expression (wildcards allowed)")
    p.add_argument("--window", type=int, default=1000, help="statistics over the last N messages (1000)")
    p.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
    p.add_argument("--interval", type=float, default=1.0, help="seconds between printed lines (1)")
    p.add_argument("--json", action="store_true", help="one JSON object per printed line")
    p.add_argument(
        "--wait",
        type=float,
        default=5.0,
        help="fail (exit 3) when no message arrives within this many seconds (5)",
    )
    _bus_options(p)


def _add_hz(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "hz",
        help="the rate of a topic: mean over a window, min/max/std of the period",
        description="Measure how often messages arrive on TOPIC (wall clock of this process), with the "
        "min, max and standard deviation of the interval between them, printed every --interval.",
        epilog=examples(
            "humanoid hz sim/clock                    # about 200 Hz with a realtime sim",
            "humanoid hz sim/joint_state --duration 5 --json",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _rate_options(p)
    p.set_defaults(func=cmd_rate, measure="hz")


def _add_bw(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "bw",
        help="the bandwidth of a topic: bytes per second, message sizes (mean/min/max)",
        description="Measure the bandwidth used by TOPIC: bytes per second over a window, with the mean, "
        "min and max message size, printed every --interval.",
        epilog=examples(
            "humanoid bw sim/joint_state",
            "humanoid bw 'diag/**' --window 100 --duration 3 --json",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _rate_options(p)
    p.set_defaults(func=cmd_rate, measure="bw")


def _stats_line(stats: Any, measure: str) -> str:
    from services.bus.rates import human_bytes

    if measure == "hz":
        return (
            f"average rate: {stats.rate_hz:.1f} Hz  min: {stats.period_min_s * 1e3:.2f} ms  "
            f"max: {stats.period_max_s * 1e3:.2f} ms  std dev: {stats.period_std_s * 1e3:.2f} ms  "
            f"window: {stats.window}"
        )
    return (
        f"{human_bytes(stats.bytes_per_s)}/s  mean: {human_bytes(stats.size_mean_b)}  "
        f"min: {human_bytes(stats.size_min_b)}  max: {human_bytes(stats.size_max_b)}  window: {stats.window}"
    )


def cmd_rate(args: argparse.Namespace) -> int:
    import dataclasses

    import zenoh

    from services.bus.rates import RateMeter
    from services.bus.session import bus_session

    bus = _bus(args)
    key = resolve_key(args.topic, bus.robot)
    try:
        zenoh.KeyExpr(key)
        meter = RateMeter(args.window)
    except (zenoh.ZError, ValueError) as exc:
        return _fail(f"{args.topic!r}: {exc}")
    lock = threading.Lock()

    def on_sample(sample: Any) -> None:  # zenoh thread: count only
        size = len(sample.payload)
        now = time.monotonic()
        with lock:
            meter.add(now, size)

    started = time.monotonic()
    end = started + args.duration if args.duration else None
    printed = False
    with bus_session(bus) as session:
        sub = session.declare_subscriber(key, on_sample)
        try:
            if not args.json:
                print(f"listening on {key} (Ctrl-C to stop)", file=sys.stderr, flush=True)
            next_print = started + args.interval
            while end is None or time.monotonic() < end:
                time.sleep(min(0.05, max(0.0, next_print - time.monotonic())))
                now = time.monotonic()
                with lock:
                    count = meter.count
                    stats = meter.stats()
                if count == 0 and now - started > args.wait:
                    print(
                        f"error: no message on {key} within {args.wait:.1f} s; is its service running? "
                        f"(`humanoid list topics`){silence_hint(key)}",
                        file=sys.stderr,
                    )
                    return EXIT_UNAVAILABLE
                if now >= next_print:
                    next_print += args.interval
                    if stats is not None:
                        printed = True
                        if args.json:
                            print(json.dumps({"topic": key, **dataclasses.asdict(stats)}), flush=True)
                        else:
                            print(_stats_line(stats, args.measure), flush=True)
        except KeyboardInterrupt:
            pass
        finally:
            with contextlib.suppress(zenoh.ZError):
                sub.undeclare()
    if not printed:
        with lock:
            stats = meter.stats()
        if stats is None:
            print(f"error: fewer than 2 messages on {key}{silence_hint(key)}", file=sys.stderr)
            return EXIT_UNAVAILABLE
        print(
            json.dumps({"topic": key, **dataclasses.asdict(stats)})
            if args.json
            else _stats_line(stats, args.measure)
        )
    return 0


# ---------------------------------------------------------------------------------------------------
# graph
# ---------------------------------------------------------------------------------------------------
def _add_graph(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "graph",
        help="which service serves, publishes, calls and subscribes to what (text, Mermaid, DOT)",
        description="The graph of the stack: endpoints and topics each service owns (from the schemas), "
        "what it calls and subscribes to (from its source), and whether it is alive now (the bus).",
        epilog=examples(
            "humanoid graph",
            "humanoid graph --format mermaid --output out/graph.mmd",
            "humanoid graph --format dot | dot -Tpng > graph.png",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--format", choices=("text", "mermaid", "dot"), default="text", help="output (text)")
    p.add_argument("--output", "-o", help="write to this file instead of the terminal")
    p.add_argument("--offline", action="store_true", help="do not ask the bus which services are alive")
    _bus_options(p)
    p.set_defaults(func=cmd_graph)


def cmd_graph(args: argparse.Namespace) -> int:
    from pathlib import Path

    from services.bus.graph import build_graph, to_dot, to_mermaid, to_text

    nodes = build_graph(None if args.offline else _live(args))
    text = {"text": to_text, "mermaid": to_mermaid, "dot": to_dot}[args.format](nodes)
    if args.output:
        Path(args.output).parent.mkdir(parents=True, exist_ok=True)
        Path(args.output).write_text(text if text.endswith("\n") else text + "\n")
        print(f"{args.format} graph written to {args.output}")
    else:
        print(text.rstrip("\n"))
    return 0
