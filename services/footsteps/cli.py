"""``humanoid scenario footsteps-reach | footsteps-pickup | footsteps-posture``: the footstep paper's
scenarios (section 4) with their figures in ``out/``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from services.cli_common import examples

SCENARIO_COMMANDS = {
    "footsteps-reach": (
        "reach",
        "reach a ball 2 m away with a disk obstacle on the floor in between (section 4.1)",
    ),
    "footsteps-pickup": ("pickup", "pick up an object on the floor between the feet (section 4.2)"),
    "footsteps-posture": ("posture", "recover the rest posture while looking at a ball (section 4.3)"),
}


def scenario_subparsers(subparsers: argparse._SubParsersAction) -> argparse._SubParsersAction:
    """The sub-commands of ``humanoid scenario``, created on first use and shared by every package
    that contributes scenarios (the parser keeps them in ``_humanoid_scenarios``)."""
    parser = subparsers.choices.get("scenario")
    if parser is None:
        parser = subparsers.add_parser(
            "scenario",
            help="run a named demonstration scenario",
            description="Run a named demonstration scenario; `humanoid scenario NAME --help` documents each.",
            epilog=examples(
                "humanoid scenario footsteps-reach       # the footstep paper's section 4.1; figures: out/",
                "humanoid scenario footsteps-posture --json",
                "humanoid scenario chair-egress          # contact planning out of a chair",
            ),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        parser.set_defaults(func=lambda _args: parser.print_help() or 2)
        parser._humanoid_scenarios = parser.add_subparsers(dest="scenario", metavar="SCENARIO")  # type: ignore[attr-defined]
    return parser._humanoid_scenarios  # type: ignore[attr-defined]


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    """Register ``humanoid scenario footsteps-*``."""
    scenarios = scenario_subparsers(subparsers)
    for command, (name, help_text) in SCENARIO_COMMANDS.items():
        p = scenarios.add_parser(
            command,
            help=help_text,
            description=f"Footstep planning as inverse kinematics: {help_text}. Prints the footsteps, the "
            "solve time beside the paper's, and writes the chain states and task values figures.",
            epilog=examples(
                f"humanoid scenario {command}                 # figures in out/",
                f"humanoid scenario {command} --no-figures --json",
                f"humanoid scenario {command} --robot talos --out out/talos",
            ),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        p.add_argument("--robot", default="hrp2_like", help="robot model (default: hrp2_like)")
        p.add_argument(
            "--out", type=Path, default=Path("out"), help="directory of the PNG figures (default: out)"
        )
        p.add_argument("--no-figures", action="store_true", help="do not draw the figures")
        p.add_argument(
            "--front-foot",
            choices=("auto", "left", "right"),
            default="auto",
            help="foot making the last step; auto solves for both and keeps fewer steps (section 5.2)",
        )
        p.add_argument(
            "--execute",
            action="store_true",
            help="also turn the plan into the whole-body motion (walking pattern generator + final reach), "
            "saved as out/footsteps_<name>_motion.npz",
        )
        p.add_argument(
            "--posture-objective",
            action="store_true",
            help="the stack's variant: the rest posture as the lowest task (default: the paper's task set)",
        )
        p.add_argument("--json", action="store_true", help="print the summary as JSON")
        p.set_defaults(func=_run, footsteps_scenario=name)


def _run(args: argparse.Namespace) -> int:
    from services.footsteps.demo import format_summary, run_scenario

    summary = run_scenario(
        args.footsteps_scenario,
        robot_name=args.robot,
        out_dir=None if args.no_figures else args.out,
        front_foot=args.front_foot,
        execute=args.execute,
        posture_objective=args.posture_objective and args.footsteps_scenario in ("reach", "pickup"),
    )
    print(json.dumps(summary, indent=2) if args.json else format_summary(summary))
    return 0 if summary["solved"] else 1
