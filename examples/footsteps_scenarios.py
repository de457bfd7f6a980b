"""The three scenarios of the footstep paper (Kanoun, Laumond, Yoshida, section 4), planned by
footstep planning as inverse kinematics, with their figures:

- out/footsteps_<name>_chain.png: top views of the virtual chain at several iterations of
  Algorithm 1 and the retained footsteps with the final posture (like Figs. 6, 7 and 11);
- out/footsteps_<name>_values.png: the task values against the iterations, a dashed line at each
  step addition (like Fig. 10);
- out/footsteps_fig10_epsilon.png: Fig. 10's threshold study (reach > gaze > posture with low,
  average and high epsilon_i: step additions and computation times), scenario ``fig10``.

    .venv/bin/python examples/footsteps_scenarios.py                 # all three
    .venv/bin/python examples/footsteps_scenarios.py reach --execute # + walk and reach motion
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from services.footsteps.demo import format_summary, run_epsilon_study, run_scenario
from services.footsteps.scenarios import SCENARIOS


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("names", nargs="*", help=f"scenarios among {sorted(SCENARIOS)} (default: all)")
    parser.add_argument("--robot", default="hrp2_like", help="robot model (default: hrp2_like)")
    parser.add_argument("--out", type=Path, default=Path("out"), help="figure directory (default: out)")
    parser.add_argument("--execute", action="store_true", help="also compute the walk + reach motion")
    parser.add_argument(
        "--posture-objective",
        action="store_true",
        help="reach and pickup with the rest posture as the lowest task (the stack's variant)",
    )
    args = parser.parse_args(argv)
    unknown = sorted(set(args.names) - set(SCENARIOS))
    if unknown:
        parser.error(f"unknown scenarios {unknown}; choose among {sorted(SCENARIOS)}")
    failures = 0
    for name in args.names or ["reach", "pickup", "posture", "fig10"]:
        summary = run_scenario(
            name,
            robot_name=args.robot,
            out_dir=args.out,
            execute=args.execute,
            posture_objective=args.posture_objective and name in ("reach", "pickup"),
        )
        print(format_summary(summary), flush=True)
        failures += not summary["solved"]
        if name == "fig10":
            for row in run_epsilon_study(args.robot, args.out):
                print(
                    f"  epsilon {row['label']} (x{row['epsilon_scale']:g}): {row['steps']} steps, "
                    f"added after iterations {row['steps_added_at']}, {row['solve_s']:.2f} s wall, "
                    f"{row['cpu_s']:.2f} s CPU"
                )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
