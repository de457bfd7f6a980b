"""``humanoid``: the single command line of the stack.

Subcommands come from the packages: each module of :data:`CLI_MODULES` defines
``add_cli(subparsers)`` and registers its subcommands with ``set_defaults(func=...)``, where
``func(args) -> int`` is the exit code (:mod:`services.cli_common`: 0 ok, 1 error reply, 2 bad usage,
3 service unavailable). ``humanoid --help`` lists them in the groups of
:data:`services.cli_common.HELP_GROUPS`.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from services.cli_common import EXIT_CODES_TEXT, EXIT_USAGE, HELP_GROUPS, exit_code_for

#: Modules contributing subcommands (``humanoid --help`` groups them by HELP_GROUPS).
CLI_MODULES = (
    "services.bus.cli",
    "services.bus.cli_inspect",
    "services.bus.cli_logs",
    "vision.cli",
    "services.model.cli",
    "services.ik.cli",
    "services.footsteps.cli",
    "services.contacts.cli",
    "supervisor.cli",
    "services.viz.cli",
    "services.cli_completion",
)


def _grouped_commands(subparsers: argparse._SubParsersAction) -> str:  # type: ignore[type-arg]
    """The subcommands with their one-line help, under the headings of HELP_GROUPS."""
    helps = {a.dest: a.help or "" for a in subparsers._choices_actions}
    width = max((len(n) for n in helps), default=0) + 2
    placed: set[str] = set()
    blocks = []
    for title, names in HELP_GROUPS:
        present = [n for n in names if n in helps]
        if present:
            blocks.append(f"{title}:\n" + "\n".join(f"  {n:<{width}}{helps[n]}" for n in present))
            placed.update(present)
    rest = [n for n in helps if n not in placed]
    if rest:
        blocks.append("more:\n" + "\n".join(f"  {n:<{width}}{helps[n]}" for n in rest))
    return "\n\n".join(blocks)


def _document_exit_codes(parser: argparse.ArgumentParser) -> None:
    """Every subcommand's ``--help`` ends with the exit codes (issue 20), whichever package made it."""
    for action in parser._actions:
        if not isinstance(action, argparse._SubParsersAction):
            continue
        for sub in action.choices.values():
            if EXIT_CODES_TEXT not in (sub.epilog or ""):
                sub.epilog = f"{sub.epilog.rstrip()}\n{EXIT_CODES_TEXT}" if sub.epilog else EXIT_CODES_TEXT
            _document_exit_codes(sub)


def build_parser(command: str | None = None, *, grouped: bool = True) -> argparse.ArgumentParser:
    """The ``humanoid`` parser; with ``command``, modules after the one defining it are not imported
    (``humanoid status`` need not load OpenCV for another package's subcommands). ``grouped``: the
    help lists the subcommands by group (off for tools that walk the parser, e.g. completion)."""
    parser = argparse.ArgumentParser(
        prog="humanoid",
        description="Autonomy stack for an HRP-2-like humanoid over Eclipse Zenoh. "
        "`humanoid up` starts the services; `humanoid <command> --help` documents each command.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for name in CLI_MODULES:
        module = importlib.import_module(name)
        add_cli = getattr(module, "add_cli", None)
        if add_cli is None:
            raise AttributeError(f"{name} has no add_cli(subparsers) function")
        add_cli(subparsers)
        # (``scenario`` gathers sub-commands from several modules: all of them are imported)
        if command is not None and command in subparsers.choices and command != "scenario":
            break
    _document_exit_codes(parser)
    if command is None and grouped:  # the full list: grouped instead of argparse's single list
        subparsers.help = argparse.SUPPRESS
        parser.usage = "humanoid [-h] COMMAND ..."
        parser.epilog = _grouped_commands(subparsers) + "\n\n" + EXIT_CODES_TEXT
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = argv[0] if argv and not argv[0].startswith("-") else None
    parser = build_parser(command)
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return EXIT_USAGE
    from services.errors import HumanoidError

    try:
        return int(func(args) or 0)
    except HumanoidError as exc:
        print(f"error: {exc.code}: {exc.message}", file=sys.stderr)
        return exit_code_for(exc.code)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # `humanoid ... | head`: the reader left; not an error
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    raise SystemExit(main())
