"""``humanoid logs SERVICE [-f]``: show or follow the log a service of ``humanoid up`` writes.

Imports stay light at module level: ``humanoid --help`` should not open zenoh or load numpy.
"""

from __future__ import annotations

import argparse
import difflib
import os
import sys
import time
from collections import deque
from pathlib import Path
from typing import Any

from services.cli_common import EXIT_USAGE, examples


def add_cli(subparsers: Any) -> None:
    """Register ``logs``."""
    from services.bus.logfiles import DEFAULT_LOG_DIR

    p = subparsers.add_parser(
        "logs",
        help="show or follow a service's log (out/logs/<service>.log, written by `humanoid up`)",
        description="Print the last lines of the log of SERVICE, which `humanoid up` writes to "
        "LOG_DIR/<service>.log (rotated to .1, .2, ... past 5 MB); with -f keep printing what it "
        "writes (across rotations and restarts). Without SERVICE, list the logs there.",
        epilog=examples(
            "humanoid logs                      # the services that have a log",
            "humanoid logs sim -n 50",
            "humanoid logs navigation -f        # follow, Ctrl-C to stop",
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("service", nargs="?", help="service name (`humanoid logs` lists them)")
    p.add_argument("-f", "--follow", action="store_true", help="keep printing new lines (Ctrl-C to stop)")
    p.add_argument("-n", "--lines", type=int, default=40, help="how many last lines to print first (40)")
    p.add_argument("--all", action="store_true", help="print the rotated files too, oldest first")
    p.add_argument("--log-dir", default=DEFAULT_LOG_DIR, help=f"where the logs are ({DEFAULT_LOG_DIR})")
    p.add_argument("--duration", type=float, help="with -f: stop after this many seconds")
    p.set_defaults(func=cmd_logs)


def cmd_logs(args: argparse.Namespace) -> int:
    from services.bus.launcher import format_table
    from services.bus.logfiles import log_files

    log_dir = Path(args.log_dir)
    present = sorted(p.name[: -len(".log")] for p in log_dir.glob("*.log")) if log_dir.is_dir() else []
    if not args.service:
        if not present:
            print(f"no log in {log_dir}/ (`humanoid up` writes them there)", file=sys.stderr)
            return EXIT_USAGE
        rows = []
        for name in present:
            files = log_files(log_dir, name)
            stat = files[-1].stat()
            rows.append(
                (
                    name,
                    f"{sum(f.stat().st_size for f in files) / 1e3:.1f} KB",
                    str(len(files)),
                    time.strftime("%H:%M:%S", time.localtime(stat.st_mtime)),
                    str(files[-1]),
                )
            )
        print(format_table(("SERVICE", "SIZE", "FILES", "LAST WRITE", "PATH"), rows))
        return 0
    files = log_files(log_dir, args.service)
    if not files:
        close = difflib.get_close_matches(args.service, present, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        known = ", ".join(present) or "none"
        print(f"error: no log for {args.service!r} in {log_dir}/{hint}; logs there: {known}", file=sys.stderr)
        return EXIT_USAGE
    tail: deque[str] = deque(maxlen=None if args.all else max(0, args.lines))
    for path in files if args.all else files[-2:]:
        with open(path, errors="replace") as f:
            tail.extend(f)
    sys.stdout.writelines(tail)
    sys.stdout.flush()
    if args.follow:
        return _follow(files[-1], args.duration)
    return 0


def _follow(path: Path, duration_s: float | None) -> int:
    """Print what is appended to ``path``; reopen it when it is rotated (new inode) or truncated."""
    end = time.monotonic() + duration_s if duration_s else None
    f = open(path, errors="replace")  # noqa: SIM115 (reopened on rotation, closed below)
    f.seek(0, os.SEEK_END)
    inode = os.fstat(f.fileno()).st_ino
    try:
        while end is None or time.monotonic() < end:
            line = f.readline()
            if line:
                sys.stdout.write(line)
                sys.stdout.flush()
                continue
            time.sleep(0.1)
            try:
                stat = path.stat()
            except FileNotFoundError:
                continue
            if stat.st_ino != inode or stat.st_size < f.tell():
                f.close()
                f = open(path, errors="replace")  # noqa: SIM115
                inode = os.fstat(f.fileno()).st_ino
    except KeyboardInterrupt:
        pass
    finally:
        f.close()
    return 0
