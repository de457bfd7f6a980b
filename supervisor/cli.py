"""The supervisor's ``humanoid`` subcommands: run, console, fetch.

Imports stay light at module level (``humanoid --help`` must not load pinocchio or zenoh).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

EXAMPLES_RUN = """examples:
  humanoid up                                     # in another terminal: the services
  humanoid run supervisor/scripts/fetch.txt --scene ball_fetch
  humanoid run my.txt --scene ball_fetch --seed 3 --snapshot out/final.png
script language (one action per line, '#' comments, 'as NAME' names the result):
  localize green_box
  goto green_box distance=0.4
  reach right orange_ball
  grasp right as ball
  put ball on=yellow_table
"""

EXAMPLES_CONSOLE = """examples:
  humanoid console                                # type commands; 'help' lists them
  printf 'take the orange ball\\n' | humanoid console --scene ball_fetch
  humanoid console --explain "could you bring the orange ball to the yellow table?"
  humanoid console --explain "take the ball" --explain "the orange one"   # a question, its answer
what it understands: take/grab/get/pick up/fetch X, go/walk/head to X, put/place/set X on Y,
bring X to Y, release/let go, look at X, find X/where is X/can you see X, turn left/right N degrees,
step back, move forward one metre, take two steps to the left; "it", "that"; several commands
joined by "and", "then" or commas; a question when a phrase fits several objects.
exit codes: 0 ok, 1 error reply or failed run, 2 bad usage, 3 service unavailable
(1 also when the last command was not understood or its question went unanswered; with --explain,
when a line was not understood)
"""

EXAMPLES_FETCH = """examples:
  humanoid fetch                                  # the whole ball fetch, headless, with progress
  humanoid fetch --record out/fetch.mcap --snapshot out/fetch.png --seed 3
  humanoid fetch --connect                        # use services already started by `humanoid up`
"""


def add_cli(subparsers: Any) -> None:
    """Register ``run``, ``console`` and ``fetch`` on the ``humanoid`` parser."""
    p = subparsers.add_parser(
        "run",
        help="run a supervisor script (actions with failure reports and retries) on the running stack",
        description="Run a script of supervisor actions on the services started by `humanoid up`, showing "
        "progress; every action reports success or a failure reason, retried by the retry policy. Events "
        "are published on hrp/<robot>/supervisor/events. Exit code 0 when every action succeeded.",
        epilog=EXAMPLES_RUN,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("script", help="the script file (e.g. supervisor/scripts/fetch.txt)")
    _scene_options(p)
    _bus_options(p)
    p.set_defaults(func=cmd_run)

    p = subparsers.add_parser(
        "console",
        help="voice-like text console: 'take the orange ball', 'go to the yellow table', 'stop'",
        description="Plain commands mapped to supervisor actions, read from the terminal or from stdin "
        "(one per line, for tests and scripts). Progress shows while an action runs; 'stop' aborts it; "
        "'help' lists the commands; the end of input waits for the commands given.",
        epilog=EXAMPLES_CONSOLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--hand",
        choices=("either", "left", "right"),
        default="either",
        help="hand for 'take' when the words name none (either: the supervisor's choice, the one whose way "
        "is clear; 'release' then opens the hand that holds something)",
    )
    p.add_argument(
        "--explain",
        action="append",
        metavar="TEXT",
        help="print the steps TEXT would run, without running anything (repeat it for a conversation)",
    )
    p.add_argument(
        "--objects",
        help="with --explain: comma-separated known objects (default: perception's, or the learned models)",
    )
    _scene_options(p)
    _bus_options(p)
    p.set_defaults(func=cmd_console)

    p = subparsers.add_parser(
        "fetch",
        help="the whole ball fetch headless: start the stack, run the fetch script, snapshot, summary",
        description="Start every service (as `humanoid up`, restarts included) unless --connect, reset the "
        "sim to the ball-fetch scene, run supervisor/scripts/fetch.txt with progress, save a PNG of the "
        "final scene and print a summary (time, retries, success). Exit code 0 on success.",
        epilog=EXAMPLES_FETCH,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--script", help="another script to run instead of the fetch script")
    p.add_argument("--scene", default="ball_fetch", help="scene (a name in sim/scenes or a YAML path)")
    p.add_argument("--seed", type=_seed, help="random layout seed (default: the nominal layout)")
    p.add_argument("--snapshot", default="out/fetch/final.png", help="PNG of the final scene ('' for none)")
    p.add_argument("--record", metavar="FILE", help="record every message to this MCAP file")
    p.add_argument(
        "--log-dir",
        default="out/fetch/logs",
        help="each service's output to LOG_DIR/<service>.log (out/fetch/logs)",
    )
    p.add_argument("--connect", action="store_true", help="use the services of a running `humanoid up`")
    _bus_options(p)
    p.set_defaults(func=cmd_fetch)


def _seed(text: str) -> int:
    """A layout seed as ``sim/reset`` takes it (unsigned 32-bit), refused before any service starts."""
    try:
        seed = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 0 <= seed <= 2**32 - 1:
        raise argparse.ArgumentTypeError(f"{seed} is not a seed: 0..4294967295")
    return seed


def _bus_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("bus")
    group.add_argument(
        "--config", help="YAML file with a 'bus:' section (and a 'supervisor:' one: supervisor/config.py)"
    )
    group.add_argument("--hub", help="zenoh endpoint of the hub (default tcp/127.0.0.1:7447)")
    group.add_argument("--robot", help="robot name in the keys hrp/<robot>/... (default hrp2)")
    group.add_argument("--wait", type=float, default=30.0, help="seconds to wait for the services (30)")


def _scene_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("scene")
    group.add_argument("--scene", help="reset the sim to this scene first (default: keep the current one)")
    group.add_argument("--seed", type=_seed, help="with --scene: random layout seed")
    group.add_argument("--snapshot", help="save a PNG of the scene at the end")


def _bus(args: argparse.Namespace) -> Any:
    from services.bus.config import load_bus_config

    return load_bus_config(args.config, hub=args.hub, robot=args.robot)


def _config(args: argparse.Namespace) -> Any:
    from supervisor.config import load_supervisor_config

    return load_supervisor_config(args.config)


def _connect(args: argparse.Namespace, sup: Any, services: tuple[str, ...] | None = None) -> None:
    from services.errors import UnavailableError
    from supervisor.core import SERVICES

    missing = sup.wait_for_services(args.wait, services or SERVICES)
    if "sim" in missing:
        raise UnavailableError(
            f"no sim on the bus after {args.wait:.0f} s: start the stack with `humanoid up` "
            f"(missing: {', '.join(missing)})"
        )
    if missing:
        print(
            f"warning: service(s) {', '.join(missing)} not running: the actions needing them will fail "
            "with 'unavailable'",
            file=sys.stderr,
        )


def _prepare_scene(args: argparse.Namespace, sup: Any) -> None:
    from supervisor.fetch import reset_scene

    if args.scene:
        reply = reset_scene(sup, args.scene, args.seed)
        layout = "nominal layout" if reply.seed is None else f"seed {reply.seed}"
        print(f"scene {reply.scene} ({layout}): {', '.join(reply.objects)}", flush=True)


def cmd_run(args: argparse.Namespace) -> int:
    from supervisor.core import Supervisor
    from supervisor.fetch import save_snapshot
    from supervisor.script import load_script

    steps = load_script(args.script)  # parse errors before connecting
    with Supervisor.connect(_bus(args), out=sys.stdout, config=_config(args)) as sup:
        _connect(args, sup)
        _prepare_scene(args, sup)
        started = time.monotonic()
        report = sup.run(steps, run_id=f"{args.script}@{time.time():.0f}")
        if args.snapshot:
            print(f"snapshot: {save_snapshot(sup, args.snapshot)}")
        print(
            f"{'SUCCESS' if report.ok else 'FAILED'} in {time.monotonic() - started:.1f} s, "
            f"{report.retries} retries"
        )
        for r in report.reports:
            print(f"  {r.summary()}")
    return 0 if report.ok else 1


def _explain_objects(args: argparse.Namespace) -> list[str]:
    """Known objects for --explain: --objects, else perception's (if running), else the learned models."""
    from pathlib import Path

    from services.bus.discovery import repo_root
    from services.errors import HumanoidError
    from supervisor.core import Supervisor

    if args.objects:
        # perception's names are lower_snake_case: "Orange Ball" is orange_ball
        return ["_".join(o.lower().split()) for o in args.objects.split(",") if o.strip()]
    try:
        with Supervisor.connect(_bus(args), out=None) as sup:
            if not sup.wait_for_services(1.0, ("perception",)):
                return sup.known_objects()
    except HumanoidError:
        pass
    models = sorted(p.stem for p in (Path(repo_root()) / "vision" / "models").glob("*.json"))
    print(f"(perception is not running: objects of the learned models: {', '.join(models)})", file=sys.stderr)
    return models


def cmd_console(args: argparse.Namespace) -> int:
    if args.explain:
        from supervisor.console import Listener

        listener = Listener(_explain_objects(args), args.hand)
        refused = False
        for text in args.explain:
            understanding = listener.hear(text)
            refused = refused or understanding.refused  # any line not understood (not only the last)
            print(understanding.explain())
        return 1 if refused else 0
    from supervisor.core import Supervisor
    from supervisor.fetch import save_snapshot
    from supervisor.repl import ConsoleLoop, stdin_lines

    with Supervisor.connect(_bus(args), out=sys.stdout, config=_config(args)) as sup:
        _connect(args, sup)
        _prepare_scene(args, sup)
        loop = ConsoleLoop(sup, sup.known_objects(), sys.stdout, hand=args.hand, prompt=sys.stdin.isatty())
        code = loop.run(stdin_lines())
        if args.snapshot:
            print(f"snapshot: {save_snapshot(sup, args.snapshot)}")
    return code


def cmd_fetch(args: argparse.Namespace) -> int:
    import contextlib

    from services.bus.service import configure_logging
    from supervisor.core import Supervisor
    from supervisor.fetch import fetch, running_stack
    from supervisor.script import load_script

    steps = load_script(args.script) if args.script else None
    bus = _bus(args)
    _config(args)  # a bad supervisor section fails before the services start
    configure_logging("WARNING")
    with contextlib.ExitStack() as stack:
        if not args.connect:
            print(
                f"[fetch] starting the services{' and recording to ' + args.record if args.record else ''}",
                flush=True,
            )
            stack.enter_context(running_stack(bus, record=args.record, log_dir=args.log_dir, out=sys.stdout))
        sup = stack.enter_context(Supervisor.connect(bus, out=sys.stdout, config=_config(args)))
        _connect(args, sup)
        summary, _report = fetch(
            sup, scene=args.scene, seed=args.seed, steps=steps, snapshot=args.snapshot or None
        )
        print(summary.text(), flush=True)
    if args.record:
        print(f"[fetch] log: {args.record} (humanoid log-info {args.record}; humanoid replay {args.record})")
    return 0 if summary.ok else 1
