"""What every ``humanoid`` subcommand shares: exit codes, the examples epilog, the help groups."""

from __future__ import annotations

import signal
import threading

#: Exit codes of every subcommand (README, "The `humanoid` command").
EXIT_OK = 0
EXIT_ERROR = 1  # an error reply (infeasible, not_found, timeout, internal), or a failed run
EXIT_USAGE = 2  # bad usage: unknown option, malformed request, unknown endpoint
EXIT_UNAVAILABLE = 3  # the service (or a message on a topic) is not there

#: ``humanoid --help`` lists the subcommands in these groups, in this order; others go under "more".
HELP_GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("run", ("up", "run", "console", "fetch", "scenario", "view")),
    ("inspect", ("status", "list", "interface", "call", "echo", "hz", "bw", "logs", "graph")),
    ("record", ("record", "replay", "log-info")),
    ("tools", ("perception", "model", "ik", "completion")),
)

EXIT_CODES_TEXT = "exit codes: 0 ok, 1 error reply or failed run, 2 bad usage, 3 service unavailable"


def exit_code_for(code: str) -> int:
    """The exit code for a :class:`~services.errors.HumanoidError` code."""
    if code == "invalid_request":
        return EXIT_USAGE
    if code == "unavailable":
        return EXIT_UNAVAILABLE
    return EXIT_ERROR


def examples(*lines: str) -> str:
    """An ``examples:`` epilog (use with ``RawDescriptionHelpFormatter``)."""
    return "examples:\n" + "\n".join(f"  {line}" for line in lines) + "\n" + EXIT_CODES_TEXT + "\n"


def stop_event(duration_s: float | None = None) -> threading.Event:
    """An event set by SIGINT or SIGTERM, or after ``duration_s`` [s] of wall time when given: the stop
    of a subcommand that serves until asked (record, view)."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    if duration_s:
        timer = threading.Timer(duration_s, stop.set)
        timer.daemon = True
        timer.start()
    return stop
