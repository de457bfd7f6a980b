"""The bus's ``humanoid`` subcommands: up, status, call, echo, record, replay, log-info.

Imports stay light at module level: ``humanoid --help`` should not open zenoh or load numpy.
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import json
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

from services.cli_common import (
    EXIT_CODES_TEXT,
    EXIT_UNAVAILABLE,
    EXIT_USAGE,
    examples,
    exit_code_for,
    stop_event,
)

EXAMPLES_CALL = f"""examples:
  humanoid call diag/echo '{{"text": "hello"}}'
  humanoid call diag/echo '{{"blob": [[1, 2], [3, 4]]}}'     # arrays as nested lists
  humanoid call sim/state | jq .held
{EXIT_CODES_TEXT}
"""


def add_cli(subparsers: Any) -> None:
    """Register the bus subcommands on the ``humanoid`` parser."""
    _add_up(subparsers)
    _add_status(subparsers)
    _add_call(subparsers)
    _add_echo(subparsers)
    _add_record(subparsers)
    _add_replay(subparsers)
    _add_log_info(subparsers)


def _bus_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("bus")
    group.add_argument("--config", help="YAML file with a 'bus:' section (and per-service sections)")
    group.add_argument("--hub", help="zenoh endpoint of the hub (default tcp/127.0.0.1:7447)")
    group.add_argument("--robot", help="robot name in the keys hrp/<robot>/... (default hrp2)")


def _bus(args: argparse.Namespace) -> Any:
    from services.bus.config import load_bus_config

    return load_bus_config(args.config, hub=args.hub, robot=args.robot)


def silence_hint(key: str) -> str:
    """Why ``key`` may be silent although its service runs ('' when nothing is known): the sim publishes
    its state topics per step of sim time, and it steps only during a motion unless it runs in real time."""
    from services.bus.schemas import sim

    if "/".join(key.split("/")[-2:]) in {t.path for t in (sim.CLOCK, sim.JOINT_STATE, sim.BASE_POSE)}:
        return (
            "; the sim publishes it per step of sim time: only during a motion, unless its config says "
            "`realtime: true` (sim/README.md)"
        )
    return ""


def _fail(message: str, code: int = 2) -> int:
    print(f"error: {message}", file=sys.stderr)
    return code


# ---------------------------------------------------------------------------------------------------
# up
# ---------------------------------------------------------------------------------------------------
def _add_up(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "up",
        help="start the services, restart those that die, stop all on Ctrl-C",
        description="Start every service of the stack (or those named), each in its own process; wait "
        "until all are alive; print a status table; restart a service that dies; Ctrl-C or SIGTERM stops "
        "everything within 2 s. Each service's output goes to out/logs/<service>.log (`humanoid logs`).",
        epilog=examples(
            "humanoid up                                 # every service; Ctrl-C stops them",
            "humanoid up --services sim,perception --record out/run.mcap",
            "humanoid up --log-dir ''                    # service output in this terminal",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--services", help="comma-separated service names (default: every service found)")
    p.add_argument("--record", metavar="FILE", help="also record every message to this MCAP file")
    p.add_argument(
        "--foxglove",
        nargs="?",
        const=8765,
        type=int,
        metavar="PORT",
        help="also serve the live view to Foxglove on ws://127.0.0.1:PORT (8765): the viz service",
    )
    p.add_argument(
        "--log-dir",
        help="each service's output to LOG_DIR/<service>.log, rotated (default out/logs, or the config's "
        "launcher.log_dir; '' for this terminal); read them with `humanoid logs SERVICE`",
    )
    p.add_argument("--ready-timeout", type=float, help="seconds every service has to become alive (30)")
    p.add_argument("--duration", type=float, help="stop by itself this many seconds after all are ready")
    p.add_argument("--list", action="store_true", help="list the services found and exit")
    _bus_options(p)
    p.set_defaults(func=cmd_up)


def cmd_up(args: argparse.Namespace) -> int:
    import dataclasses

    from services.bus.config import load_section
    from services.bus.discovery import RECORDER, VIZ, default_services, discover
    from services.bus.launcher import Launcher, LauncherConfig, format_table, run_up
    from services.bus.logfiles import DEFAULT_LOG_DIR
    from services.bus.service import configure_logging

    configure_logging("INFO")
    found, problems = discover()
    for problem in problems:
        print(f"warning: {problem}", file=sys.stderr)
    startable = {name: e for name, e in found.items() if name not in (RECORDER, VIZ)}
    if args.list:
        rows = [(name, e.module) for name, e in sorted(startable.items())]
        print(format_table(("SERVICE", "MODULE"), rows))
        return 0
    if args.services:
        names = [n.strip() for n in args.services.split(",") if n.strip()]
        unknown = [n for n in names if n not in startable]
        if unknown:
            hint = " (the recorder starts with --record FILE)" if RECORDER in unknown else ""
            hint += " (the live view starts with --foxglove [PORT])" if VIZ in unknown else ""
            known = ", ".join(sorted(startable))
            return _fail(f"unknown service(s) {', '.join(unknown)}{hint}; services found: {known}")
    else:
        names = default_services(found)  # diag only when asked (--services)
    entries = [startable[n] for n in names] + [found[RECORDER]]
    if args.foxglove is not None and VIZ in found:
        entries.append(found[VIZ])
    bus = _bus(args)
    config = load_section(args.config, "launcher", LauncherConfig)
    if args.ready_timeout is not None:
        config = dataclasses.replace(config, ready_timeout_s=args.ready_timeout)
    if args.log_dir is not None or not config.log_dir:
        log_dir = DEFAULT_LOG_DIR if args.log_dir is None else args.log_dir
        config = dataclasses.replace(config, log_dir=log_dir)
    if config.log_dir:
        print(f"service logs: {config.log_dir}/<service>.log (humanoid logs SERVICE -f)", flush=True)
    launcher = Launcher(
        bus, entries, config, config_path=args.config, record=args.record, duration_s=args.duration,
        foxglove_port=args.foxglove,
    )  # fmt: skip
    return run_up(launcher)


# ---------------------------------------------------------------------------------------------------
# status
# ---------------------------------------------------------------------------------------------------
def _add_status(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "status",
        help="the live services, their heartbeat age and requests served",
        description="List the services whose liveliness token is present, with the age of their last "
        "heartbeat (a service stuck holding the GIL keeps its token but stops beating).",
        epilog=examples("humanoid status", "humanoid status --json | jq '.services[].service'"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--wait", type=float, default=0.8, help="seconds to listen for heartbeats (0.8)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    _bus_options(p)
    p.set_defaults(func=cmd_status)


def cmd_status(args: argparse.Namespace) -> int:
    from services.bus import keys
    from services.bus.codec import decode
    from services.bus.launcher import format_table
    from services.bus.schemas.common import Heartbeat
    from services.bus.session import alive_services, bus_session

    bus = _bus(args)
    beats: dict[str, tuple[Heartbeat, float]] = {}
    lock = threading.Lock()

    def on_beat(sample: Any) -> None:  # zenoh thread: decode and store only
        try:
            beat = decode(sample.payload.to_bytes(), Heartbeat)
        except Exception:
            return
        with lock:
            beats[beat.service] = (beat, time.time())

    with bus_session(bus) as session:
        sub = session.declare_subscriber(keys.all_heartbeats(bus.robot), on_beat)
        deadline = time.monotonic() + max(0.1, args.wait)
        alive: set[str] = set()
        while time.monotonic() < deadline:
            alive |= alive_services(session, bus.robot, timeout_s=0.3)
            time.sleep(0.05)
        alive = alive or alive_services(session, bus.robot, timeout_s=0.5)
        sub.undeclare()
    now = time.time()
    rows = []
    for name in sorted(alive):
        entry: dict[str, Any] = {"service": name, "alive": True}
        with lock:
            got = beats.get(name)
        if got is not None:
            beat, _received = got
            entry.update(
                pid=beat.pid,
                heartbeat_age_s=round(max(0.0, now - beat.wall_time_s), 3),
                uptime_s=round(beat.uptime_s, 1),
                requests_served=beat.requests_served,
                requests_failed=beat.requests_failed,
            )
        else:
            entry.update(
                pid=None, heartbeat_age_s=None, uptime_s=None, requests_served=None, requests_failed=None
            )
        rows.append(entry)
    if args.json:
        print(json.dumps({"hub": bus.hub, "robot": bus.robot, "services": rows}, indent=2))
        return 0 if rows else 1
    if not rows:
        print(f"no service is alive for robot {bus.robot!r} (hub {bus.hub}); is `humanoid up` running?")
        return 1
    table = []
    for r in rows:
        age = r["heartbeat_age_s"]
        table.append(
            (
                r["service"],
                str(r["pid"] or "-"),
                f"{age:.2f} s" if age is not None else f"none in {args.wait:.1f} s (stuck?)",
                f"{r['uptime_s']:.0f} s" if r["uptime_s"] is not None else "-",
                str(r["requests_served"] if r["requests_served"] is not None else "-"),
                str(r["requests_failed"] if r["requests_failed"] is not None else "-"),
            )
        )
    print(format_table(("SERVICE", "PID", "HEARTBEAT AGE", "UPTIME", "SERVED", "FAILED"), table))
    return 0


# ---------------------------------------------------------------------------------------------------
# call
# ---------------------------------------------------------------------------------------------------
def _add_call(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "call",
        help="send a request to a running service and print the reply as JSON",
        description="Send a JSON request to SERVICE/ENDPOINT, validated against the endpoint's schema, and "
        "print the reply as JSON (arrays as nested lists).",
        epilog=EXAMPLES_CALL,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("endpoint", help="SERVICE/ENDPOINT, e.g. diag/echo")
    p.add_argument("request", nargs="?", default="{}", help="the request as a JSON object (default {})")
    p.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for the reply (30)")
    p.add_argument(
        "--max-elements",
        type=int,
        default=10_000,
        help="print larger arrays as <ndarray dtype shape> (default 10000; 0: print every array in full)",
    )
    _bus_options(p)
    p.set_defaults(func=cmd_call)


def build_request(endpoint: str, text: str) -> tuple[Any, Any]:
    """``(spec, request)`` from the command line; InvalidRequestError saying what to fix."""
    import msgspec

    from services.bus import schemas
    from services.bus.codec import from_builtins
    from services.errors import InvalidRequestError

    specs = schemas.endpoints()
    spec = specs.get(endpoint)
    if spec is None:
        close = difflib.get_close_matches(endpoint, list(specs), n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise InvalidRequestError(
            f"unknown endpoint {endpoint!r}{hint}; valid endpoints: {', '.join(sorted(specs))}"
        )
    try:
        value = msgspec.json.decode(text.encode())
    except msgspec.DecodeError as exc:
        raise InvalidRequestError(
            f"the request for {endpoint} is not valid JSON ({exc}); "
            f"fields: {describe_fields(spec.request)}. {_call_example(endpoint, spec.request)}"
        ) from None
    if not isinstance(value, dict):
        raise InvalidRequestError(
            f"the request for {endpoint} must be a JSON object, not {type(value).__name__}; "
            f"fields: {describe_fields(spec.request)}"
        )
    valid = set(spec.request.__struct_fields__)
    unknown = sorted(set(value) - valid)
    if unknown:
        raise InvalidRequestError(
            f"unknown field(s) {', '.join(unknown)} for {endpoint}; fields: {describe_fields(spec.request)}"
        )
    try:
        request = from_builtins(value, spec.request)
    except InvalidRequestError as exc:
        raise InvalidRequestError(f"{exc.message}; fields: {describe_fields(spec.request)}") from None
    return spec, request


def _call_example(endpoint: str, request: Any) -> str:
    """An example call that works (no required field), else where the fields are described."""
    import msgspec

    if any(f.required for f in msgspec.structs.fields(request)):
        return f"`humanoid interface {endpoint}` describes each field"
    return f"Example: humanoid call {endpoint} '{{}}'"


def describe_fields(type_: Any) -> str:
    """``name (type, default ...)`` for each field of a message type."""
    import msgspec

    from services.bus.interfaces import type_text

    parts = []
    for f in msgspec.structs.fields(type_):
        kind = type_text(f.type)
        if f.required:
            parts.append(f"{f.name} ({kind}, required)")
        else:
            default = f.default if f.default is not msgspec.NODEFAULT else f.default_factory()
            parts.append(f"{f.name} ({kind}, default {json.dumps(default, default=str)})")
    return ", ".join(parts) or "none"


def cmd_call(args: argparse.Namespace) -> int:
    from services.bus.codec import decode, encode
    from services.bus.session import Client, bus_session
    from services.errors import HumanoidError, InvalidRequestError

    try:
        spec, request = build_request(args.endpoint, args.request)
    except InvalidRequestError as exc:
        return _fail(exc.message)
    bus = _bus(args)
    with bus_session(bus) as session:
        client = Client(session, bus.robot)
        try:
            client.wait_for([spec.service], timeout_s=min(3.0, args.timeout))
            raw = client.call_raw(spec.service, spec.name, encode(request), args.timeout)
            reply = decode(raw, spec.reply)
        except HumanoidError as exc:
            print(f"error: {exc.code}: {exc.message}", file=sys.stderr)
            if exc.details:
                print(json.dumps({"details": exc.details}, indent=2, default=str), file=sys.stderr)
            return exit_code_for(exc.code)
    print(json.dumps(_printable(reply, args.max_elements), indent=2))
    return 0


def _printable(msg: Any, max_elements: int) -> Any:
    """JSON-ready builtins of a message; arrays as lists, or summarised past ``max_elements``."""
    import msgspec
    import numpy as np

    def hook(obj: Any) -> Any:
        if isinstance(obj, np.ndarray):
            if max_elements and obj.size > max_elements:
                return f"<ndarray {obj.dtype} {tuple(obj.shape)}>"
            return obj.tolist()
        if isinstance(obj, np.generic):
            return obj.item()
        raise NotImplementedError(f"cannot print objects of type {type(obj).__name__}")

    return msgspec.to_builtins(msg, enc_hook=hook)


# ---------------------------------------------------------------------------------------------------
# echo
# ---------------------------------------------------------------------------------------------------
def _add_echo(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "echo",
        help="print the messages on a key expression (binary arrays summarised)",
        description="Print every message published on KEY, a zenoh key expression (hrp/hrp2/diag/**) or "
        "SERVICE/NAME for hrp/<robot>/SERVICE/NAME. Large arrays of binary frames are shown as "
        "<ndarray dtype shape>, undecodable payloads as hex. --json prints one object per line.",
        epilog=examples(
            "humanoid echo 'supervisor/**'",
            "humanoid echo sim/clock --once --json | jq .message.sim_time_s",
            "humanoid echo sim/base_pose --field position --count 5",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("key", help="key expression, or SERVICE/NAME (wildcards * and ** allowed)")
    p.add_argument("--count", type=int, help="exit after this many messages")
    p.add_argument("--once", action="store_const", const=1, dest="count", help="exit after one message")
    p.add_argument("--duration", type=float, help="exit after this many seconds")
    p.add_argument("--compact", action="store_true", help="one line per message")
    p.add_argument(
        "--json",
        action="store_true",
        help="one JSON object per line: {key, time_s, size_b, request_id, message} (for jq)",
    )
    p.add_argument(
        "--field",
        metavar="PATH",
        help="print only this field of each message (dotted: position.0, images.0.name)",
    )
    p.add_argument(
        "--max-elements",
        type=int,
        default=64,
        help="arrays up to this many elements in full, larger ones as <ndarray dtype shape> (64)",
    )
    p.add_argument(
        "--wait",
        type=float,
        help="with --count/--once: fail (exit 3) when nothing arrives within this many seconds",
    )
    _bus_options(p)
    p.set_defaults(func=cmd_echo)


def resolve_key(key: str, robot: str) -> str:
    """A key expression from the command line: ``hrp/...`` as is, else ``hrp/<robot>/<key>``."""
    from services.bus import keys

    key = key.strip("/")
    return key if key.startswith(keys.PREFIX + "/") or key == "**" else f"{keys.PREFIX}/{robot}/{key}"


def cmd_echo(args: argparse.Namespace) -> int:
    import queue

    import zenoh

    from services.bus.session import bus_session, request_id_from

    bus = _bus(args)
    key = resolve_key(args.key, bus.robot)
    try:
        zenoh.KeyExpr(key)
    except zenoh.ZError as exc:
        return _fail(f"{key!r} is not a valid key expression: {exc}")
    inbox: queue.Queue[tuple[str, bytes, int | None]] = queue.Queue(maxsize=1000)

    def on_sample(sample: Any) -> None:  # zenoh thread: hand over only
        with contextlib.suppress(queue.Full):  # a slow terminal drops messages, never blocks zenoh
            inbox.put_nowait(
                (str(sample.key_expr), sample.payload.to_bytes(), request_id_from(sample.attachment))
            )

    count = 0
    started = time.monotonic()
    deadline = started + args.duration if args.duration else None
    with bus_session(bus) as session:
        sub = session.declare_subscriber(key, on_sample)
        try:
            print(f"listening on {key} (Ctrl-C to stop){silence_hint(key)}", file=sys.stderr, flush=True)
            while (args.count is None or count < args.count) and (
                deadline is None or time.monotonic() < deadline
            ):
                try:
                    sample_key, data, rid = inbox.get(timeout=0.1)
                except queue.Empty:
                    if args.wait and count == 0 and time.monotonic() - started > args.wait:
                        why = silence_hint(key)
                        print(f"error: no message on {key} within {args.wait:.1f} s{why}", file=sys.stderr)
                        return EXIT_UNAVAILABLE
                    continue
                count += 1
                content = message_content(data, args.max_elements)
                if args.field:
                    try:
                        content = field_at(content, args.field)
                    except KeyError as exc:
                        print(f"error: {exc.args[0]}", file=sys.stderr)
                        return EXIT_USAGE
                if args.json:
                    doc = content if args.field else {
                        "key": sample_key, "time_s": round(time.time(), 6), "size_b": len(data),
                        "request_id": rid, "message": content,
                    }
                    print(json.dumps(doc, default=str), flush=True)
                    continue
                if args.field:
                    print(json.dumps(content, default=str), flush=True)
                    continue
                stamp = time.strftime("%H:%M:%S") + f".{int(time.time() * 1000) % 1000:03d}"
                extra = f"  request {rid}" if rid is not None else ""
                text = (
                    json.dumps(content, default=str)
                    if args.compact
                    else json.dumps(content, indent=2, default=str)
                )
                print(f"--- {sample_key}  [{len(data)} B]  {stamp}{extra}\n{text}", flush=True)
        except KeyboardInterrupt:
            pass
        except BrokenPipeError:  # `| head`: the reader is gone
            with contextlib.suppress(OSError):
                sys.stdout = open(os.devnull, "w")  # noqa: SIM115
        finally:
            sub.undeclare()
    return 0


def message_content(data: bytes, max_elements: int) -> Any:
    """A frame as JSON-ready data: arrays of up to ``max_elements`` as nested lists, larger ones as
    ``<ndarray dtype shape>``, undecodable bytes as a hex summary (see services.bus.frames)."""
    import msgspec
    import numpy as np

    from services.bus.frames import frame_kind, parse_frame, replace_arrays, summarize

    if frame_kind(data) == "octets":
        return summarize(data)
    try:
        doc, refs = parse_frame(data)
    except (msgspec.DecodeError, ValueError):
        return summarize(data)
    by_path = {r.path: r for r in refs}

    def show(path: str, ref: dict[str, Any]) -> Any:
        shape = tuple(ref["shape"])
        if path in by_path and int(np.prod(shape)) <= max_elements:
            return by_path[path].array().tolist()
        return f"<ndarray {np.dtype(ref['dtype'])} {shape}>"

    return replace_arrays(doc, show)


def field_at(doc: Any, path: str) -> Any:
    """``doc`` at a dotted (or slashed) path: ``position.0``; KeyError naming the valid keys."""
    node = doc
    for part in [p for p in path.replace("/", ".").split(".") if p]:
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.lstrip("-").isdigit() and -len(node) <= int(part) < len(node):
            node = node[int(part)]
        else:
            if isinstance(node, dict):
                valid = ", ".join(map(str, node))
            elif isinstance(node, list):
                valid = f"0..{len(node) - 1}"
            else:
                valid = "none (not a mapping or a list)"
            raise KeyError(f"no field {part!r} in {path!r}; valid here: {valid}")
    return node


# ---------------------------------------------------------------------------------------------------
# record / replay / log-info
# ---------------------------------------------------------------------------------------------------
def _add_record(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "record",
        help="record every message on hrp/** to an MCAP file (until Ctrl-C)",
        description="Run the recorder in the foreground: every message on the bus goes to FILE (MCAP: open "
        "it in Foxglove, play it back with `humanoid replay`). Ctrl-C or SIGTERM finishes the file.",
        epilog=examples(
            "humanoid record out/run.mcap                # until Ctrl-C",
            "humanoid record out/clock.mcap --duration 5 --key-expr 'hrp/hrp2/sim/clock'",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", help="MCAP file to write")
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    p.add_argument("--key-expr", help="what to record (default hrp/**)")
    _bus_options(p)
    p.set_defaults(func=cmd_record)


def cmd_record(args: argparse.Namespace) -> int:
    import dataclasses
    from pathlib import Path

    from services.bus.config import load_section
    from services.bus.recorder import RecorderConfig, RecorderService
    from services.bus.service import configure_logging, exit_if_still_busy, serve

    configure_logging("INFO")
    config = load_section(args.config, "record", RecorderConfig)
    config = dataclasses.replace(config, output=str(Path(args.file).resolve()))
    try:  # an unwritable place is said before anything starts
        Path(config.output).parent.mkdir(parents=True, exist_ok=True)
        with open(config.output, "ab"):
            pass
    except OSError as exc:
        return _fail(f"cannot write the log {config.output}: {exc.strerror or exc}")
    if args.key_expr:
        config = dataclasses.replace(config, key_expr=args.key_expr)
    bus = _bus(args)
    stop = stop_event(args.duration)
    serve(RecorderService, config, bus, stop)
    print(f"log written to {config.output}", flush=True)
    exit_if_still_busy(RecorderService.name, logging.getLogger("humanoid.record"))
    return 0


def _add_replay(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "replay",
        help="republish a log with its timing, or re-send its requests and diff the replies",
        description="Republish every message of an MCAP log on its key with the original relative timing "
        "(heartbeats left out), showing a progress bar. With --requests, re-send every recorded request "
        "to the running services instead and report the replies that differ from the recorded ones.",
        epilog=examples(
            "humanoid replay out/demo/fetch.mcap                 # progress bar",
            "humanoid replay run.mcap --start 30 --rate 2 --loop",
            "humanoid replay run.mcap --topics 'hrp/*/sim/*' --verbose",
            "humanoid replay run.mcap --requests                 # re-send requests, diff replies",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", help="MCAP file written by `humanoid record`")
    p.add_argument(
        "--rate", "--speed", dest="speed", type=float, default=1.0,
        help="playback speed factor (2 = twice as fast; --speed is the same)",
    )
    p.add_argument("--start", type=float, default=0.0, help="start this many seconds into the log (0)")
    p.add_argument("--loop", action="store_true", help="play the log again and again until Ctrl-C")
    p.add_argument(
        "--topics",
        action="append",
        metavar="GLOB",
        help="only keys matching this shell glob (* matches across /), e.g. 'hrp/*/sim/*'; repeatable, "
        "or comma-separated",
    )
    p.add_argument("--heartbeats", action="store_true", help="also republish the recorded heartbeats")
    p.add_argument(
        "--requests", action="store_true", help="re-send the recorded requests and compare replies"
    )
    p.add_argument("--timeout", type=float, default=30.0, help="--requests: seconds per request (30)")
    p.add_argument(
        "--foxglove",
        nargs="?",
        const=8765,
        type=int,
        metavar="PORT",
        help="serve the log to Foxglove on ws://127.0.0.1:PORT (8765) instead of publishing on the bus",
    )
    p.add_argument("--verbose", action="store_true", help="a line per message instead of the progress bar")
    p.add_argument("--quiet", action="store_true", help="neither progress nor a line per message")
    _bus_options(p)
    p.set_defaults(func=cmd_replay)


def cmd_replay(args: argparse.Namespace) -> int:
    from collections import Counter

    from services.bus.launcher import format_table
    from services.bus.mcaplog import LogReader
    from services.bus.replay import key_filter, replay, replay_requests
    from services.bus.session import bus_session
    from services.errors import HumanoidError

    patterns = [p.strip() for arg in args.topics or [] for p in arg.split(",") if p.strip()] or None
    if args.foxglove is not None:
        from services.viz.player import serve_log

        def ready(port: int) -> None:
            print(
                f"Foxglove: open a connection to ws://127.0.0.1:{port} (playing on the first subscription; "
                "Ctrl-C to stop)"
            )

        accept = key_filter(patterns, heartbeats=args.heartbeats, views=True)
        try:
            stats = serve_log(
                args.file, port=args.foxglove, speed=args.speed, on_ready=ready, wait_for_viewer_s=600,
                linger_s=600, start_s=args.start, loop=args.loop, accept=accept,
            )  # fmt: skip
        except KeyboardInterrupt:
            return 130
        except HumanoidError as exc:
            return _fail(exc.message)
        print(f"served {stats.messages} messages on {stats.channels} channels in {stats.duration_s:.2f} s")
        return 0
    try:
        reader = LogReader(args.file)
    except HumanoidError as exc:
        return _fail(exc.message)
    bus = _bus(args)
    progress: Progress | None = None
    with bus_session(bus) as session:
        _wait_for_peers(session)
        try:
            if args.requests:
                accept = key_filter(patterns) if patterns else None

                def show(outcome: Any) -> None:
                    if not args.quiet or outcome.status != "same":
                        detail = f": {outcome.detail}" if outcome.detail else ""
                        print(
                            f"{outcome.endpoint} #{outcome.request_id}: {outcome.status}{detail}", flush=True
                        )

                outcomes = replay_requests(
                    session, reader, timeout_s=args.timeout, accept=accept, on_outcome=show
                )
                by_endpoint: dict[str, Counter[str]] = {}
                for o in outcomes:
                    by_endpoint.setdefault(o.endpoint, Counter())[o.status] += 1
                rows = [
                    (
                        ep,
                        str(sum(c.values())),
                        str(c["same"]),
                        str(c["differs"]),
                        str(c["failed"] + c["no_record"]),
                    )
                    for ep, c in sorted(by_endpoint.items())
                ]
                print(format_table(("ENDPOINT", "REQUESTS", "SAME", "DIFFERS", "FAILED"), rows))
                differs = sum(o.status != "same" for o in outcomes)
                print(f"{len(outcomes)} requests re-sent, {differs} with a different or missing reply")
                return 1 if differs else 0

            info = reader.info()
            if args.start > info.duration_s:
                length = f"{info.duration_s:.2f} s long"
                return _fail(f"--start {args.start:g} s is past the log's end (it is {length})")
            progress = None if args.quiet or args.verbose else Progress(info, args.start, args.speed)

            def show_msg(msg: Any) -> None:
                if args.verbose:
                    print(f"{msg.key}  [{len(msg.data)} B]", flush=True)
                elif progress is not None:
                    progress.update(msg)

            rounds = 0
            with _ctrl_c_sets() as stopped:
                while not stopped.is_set():
                    rounds += 1
                    stats = replay(
                        session,
                        reader,
                        speed=args.speed,
                        accept=key_filter(patterns, heartbeats=args.heartbeats),
                        on_message=show_msg,
                        start_s=args.start,
                        stop=stopped,
                    )
                    if stopped.is_set():
                        raise KeyboardInterrupt
                    if progress is not None:
                        progress.finish()
                    if not args.loop or stats.published == 0:
                        break
        except KeyboardInterrupt:
            if progress is not None:
                progress.finish(complete=False)
            return 130
        except HumanoidError as exc:
            return _fail(exc.message)
    tail = " (the log's last chunk was cut off)" if reader.unreadable_tail else ""
    again = f" ({rounds} rounds, the last:)" if rounds > 1 else ""
    print(
        f"replayed{again} {stats.published} messages in {stats.duration_s:.2f} s, "
        f"skipped {stats.skipped}{tail}"
    )
    return 0


class Progress:
    """A one-line progress bar on stderr for ``replay`` (a line per 10 % when stderr is no terminal)."""

    def __init__(self, info: Any, start_s: float, speed: float, width: int = 30) -> None:
        self.start_ns = info.start_ns + int(start_s * 1e9)
        self.total_s = max(1e-9, (info.end_ns - self.start_ns) / 1e9)
        self.speed = speed
        self.width = width
        self.tty = sys.stderr.isatty()
        self.count = 0
        self._last_draw = 0.0
        self._last_tenth = -1
        self._done = 0.0

    def update(self, msg: Any) -> None:
        self.count += 1
        now = time.monotonic()
        done = min(1.0, max(0.0, (msg.log_time_ns - self.start_ns) / 1e9 / self.total_s))
        if self.tty and now - self._last_draw >= 0.1:
            self._last_draw = now
            self._draw(done, end="\r")
        elif not self.tty and int(done * 10) > self._last_tenth:
            self._last_tenth = int(done * 10)
            self._draw(done, end="\n")

    def _draw(self, done: float, end: str) -> None:
        self._done = done
        bar = "#" * round(done * self.width)
        text = (
            f"[{bar:<{self.width}}] {done * 100:5.1f} %  {done * self.total_s:7.1f} / {self.total_s:.1f} s  "
            f"{self.count} msgs  x{self.speed:g}"
        )
        print(text, end=end, file=sys.stderr, flush=True)

    def finish(self, complete: bool = True) -> None:
        """End the bar's line: at 100 % when the log was played to its end, else where it stopped."""
        if self.count and (self.tty or self._done < 1.0):
            self._draw(1.0 if complete else self._done, end="\n")
        self.count = 0
        self._last_tenth = -1


@contextlib.contextmanager
def _ctrl_c_sets() -> Iterator[threading.Event]:
    """While inside, Ctrl-C (SIGINT) sets the yielded event instead of raising KeyboardInterrupt
    wherever the main thread happens to be (a KeyboardInterrupt raised between a zenoh call and its
    clean-up could leave the session unable to close); the previous handler is restored on exit."""
    stopped = threading.Event()
    previous = signal.signal(signal.SIGINT, lambda *_: stopped.set())
    try:
        yield stopped
    finally:
        signal.signal(signal.SIGINT, previous)


def _wait_for_peers(session: Any, timeout_s: float = 3.0) -> None:
    """Give a fresh session time to connect and learn the peers' subscriptions before publishing."""
    deadline = time.monotonic() + timeout_s
    while not list(session.info.peers_zid()) and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(0.2)  # declarations follow the connection


def _add_log_info(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "log-info",
        help="channels, message counts, bytes, rates, duration and schemas of an MCAP log",
        description="Summarise an MCAP log: duration, channels with their encodings, schema names, "
        "message counts, bytes (before chunk compression) and rates. A log whose recorder was killed is "
        "reported as truncated and read up to its last complete chunk.",
        epilog=examples("humanoid log-info out/demo/fetch.mcap", "humanoid log-info run.mcap --json"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", help="MCAP file")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_log_info)


def _human_bytes(n: int) -> str:
    """``812 B``, ``3.4 kB``, ``12.5 MB`` (bytes of messages before chunk compression)."""
    for unit, size in (("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n} B"


def _log_info_row(c: Any) -> tuple[str, ...]:
    size, rate = _human_bytes(c.bytes), f"{c.rate_hz:.1f}"
    return (c.topic, c.role, c.message_encoding, c.schema_name or "-", str(c.messages), size, rate)


def cmd_log_info(args: argparse.Namespace) -> int:
    import dataclasses

    from services.bus.launcher import format_table
    from services.bus.mcaplog import LogReader
    from services.errors import HumanoidError

    try:
        info = LogReader(args.file).info()
    except HumanoidError as exc:
        return _fail(exc.message)
    if args.json:
        doc = dataclasses.asdict(info)
        doc["duration_s"] = info.duration_s
        print(json.dumps(doc, indent=2))
        return 0
    state = (
        "complete"
        if info.complete
        else "truncated: no summary (the recorder was stopped abruptly); read up to its last complete chunk"
    )
    if info.unreadable_tail:
        state += ", the cut-off rest skipped"
    print(f"file:      {info.path} ({info.size_bytes / 1e6:.2f} MB, {state})")
    print(f"duration:  {info.duration_s:.3f} s")
    if info.messages:
        start = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(info.start_ns / 1e9))
        print(f"start:     {start}")
    print(f"messages:  {info.messages}")
    print(f"channels:  {len(info.channels)}")
    rows = [_log_info_row(c) for c in info.channels]
    print(format_table(("TOPIC", "ROLE", "ENCODING", "SCHEMA", "MESSAGES", "BYTES", "HZ"), rows))
    return 0
