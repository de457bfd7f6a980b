"""``humanoid``: the single command line of the stack.

Subcommands come from the packages: each module of :data:`CLI_MODULES` defines
``add_cli(subparsers)`` and registers its subcommands with ``set_defaults(func=...)``, where
``func(args) -> int`` is the exit code.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: Modules contributing subcommands, in the order they appear in ``humanoid --help``.
CLI_MODULES = (
    "services.bus.cli",
    "vision.cli",
    "services.model.cli",
    "services.ik.cli",
    "services.footsteps.cli",
    "services.contacts.cli",
    "supervisor.cli",
    "services.viz.cli",
)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``humanoid`` parser; with ``command``, modules after the one defining it are not imported
    (``humanoid status`` need not load OpenCV for another package's subcommands)."""
    parser = argparse.ArgumentParser(
        prog="humanoid",
        description="Autonomy stack for an HRP-2-like humanoid over Eclipse Zenoh. "
        "`humanoid up` starts the services; `humanoid <command> --help` documents each command.",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in CLI_MODULES:
        module = importlib.import_module(name)
        add_cli = getattr(module, "add_cli", None)
        if add_cli is None:
            raise AttributeError(f"{name} has no add_cli(subparsers) function")
        add_cli(subparsers)
        # (``scenario`` gathers sub-commands from several modules: all of them are imported)
        if command is not None and command in subparsers.choices and command != "scenario":
            break
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = argv[0] if argv and not argv[0].startswith("-") else None
    parser = build_parser(command)
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 2
    from services.errors import HumanoidError

    try:
        return int(func(args) or 0)
    except HumanoidError as exc:
        print(f"error: {exc.code}: {exc.message}", file=sys.stderr)
        return 2 if exc.code == "invalid_request" else 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
