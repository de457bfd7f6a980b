"""Figures of the chair experiment (Escande et al., §3): Fig. 5-like strip of witness postures rendered
from the sim, and f_T (eq. 1) and the progress s' along T of every contact set of the plan, as PNGs.

* ``out/contacts_chair_witnesses.png``: a chosen subset of the witness postures (Fig. 5), each rendered
  in the chair_egress scene (pybullet, DIRECT) with its change of contact;
* ``out/contacts_chair_potential.png``: f_T and s' of each set's witness, set by set.

The plan is computed (search, then interpolation) and saved as ``out/contacts_chair_plan.npz`` in the
format of ``humanoid scenario chair-egress --save-plan`` (``services/contacts/plan_file.py``: the
scenario plays it with ``--plan``); with ``--reuse`` an existing one is drawn again, with ``--plan FILE``
a plan the scenario saved.

Usage: python examples/contacts_chair.py [--budget S] [--reuse | --plan FILE] [--out out] [--panels N]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import io
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from services.errors import InvalidRequestError


def _problem(slope_k: float | None = None, budget_s: float = 300.0):
    """The robot and the chair scenario's default problem (``services.contacts.planner``)."""
    from services.contacts.interpolate import InterpolationConfig
    from services.contacts.planner import default_problem
    from services.contacts.search import SearchConfig
    from services.model import load_robot
    from sim.scene import layout, load_scene
    from sim.world import start_configuration

    robot = load_robot("hrp2_like")
    q0 = start_configuration(robot, layout(load_scene("chair_egress")))
    problem = default_problem(
        robot,
        q0,
        search=SearchConfig(time_budget_s=budget_s),
        interpolation=InterpolationConfig(n=10),
        **({} if slope_k is None else {"slope_k": slope_k}),
    )
    return robot, problem


def compute_plan(budget_s: float, path: Path) -> Path:
    """Plan (search, then interpolation) and save the plan as ``humanoid scenario chair-egress
    --save-plan`` does (``services/contacts/plan_file.py``): either draws or plays the other's."""
    from services.contacts.plan_file import save_plan
    from services.contacts.planner import plan

    robot, problem = _problem(budget_s=budget_s)

    def progress(kind, node, generated, expanded, elapsed) -> None:
        print(
            f"[{elapsed:6.1f} s] nodes {generated:4d} depth {node.depth:3d} f_T {node.f:8.2f} {node.change}",
            flush=True,
        )

    result = plan(robot, problem, progress)
    nodes = result.search.path
    meta = {
        "nodes_generated": result.search.nodes_generated,
        "nodes_expanded": result.search.nodes_expanded,
        "plan_s": result.search.plan_s,
        "interpolation_s": result.motion.interpolation_s,
        "slope_k": problem.slope_k,
    }
    return save_plan(path, [n.contacts for n in nodes], [n.q for n in nodes], [n.change for n in nodes], meta)


def figure_data(path: Path) -> dict:
    """The witnesses and changes of the saved plan at ``path``, with f_T (eq. 1) and s' of each witness
    on the chair scenario's rough trajectory (its slope k as saved, else the default)."""
    from services.contacts.plan_file import load_plan
    from services.contacts.planner import build

    saved = load_plan(path)
    robot, problem = _problem(slope_k=saved.meta.get("slope_k"))
    _gen, trajectory, _start, _pairs = build(robot, problem)
    return {
        "witnesses": saved.witnesses,
        "changes": saved.changes,
        "f": np.array([trajectory.value(q) for q in saved.witnesses]),
        "s": np.array([trajectory.progress(q) for q in saved.witnesses]),
    }


def render_strip(data: dict, out: Path, panels: int) -> Path:
    from PIL import Image  # matplotlib's dependency

    from sim.world import World

    witnesses, changes = data["witnesses"], data["changes"]
    chosen = np.unique(np.linspace(0, len(witnesses) - 1, panels).round().astype(int))
    images = []
    with World("hrp2_like", "chair_egress") as world:
        for k in chosen:
            world.pyrobot.reset(witnesses[k])
            png = world.snapshot(width_px=320, height_px=240, eye=(1.9, -1.4, 1.5), target=(0.2, 0.25, 0.5))
            images.append(np.asarray(Image.open(io.BytesIO(png))))
    cols = 4
    rows = int(np.ceil(len(chosen) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3.2 * rows))
    for ax in np.ravel(axes):
        ax.axis("off")
    for ax, k, image in zip(np.ravel(axes), chosen, images, strict=False):
        ax.imshow(image)
        ax.set_title(f"set {k}: {changes[k]}"[:48], fontsize=8)
    fig.suptitle("Witness postures of the plan (cf. Fig. 5 of Escande et al.)")
    fig.tight_layout()
    path = out / "contacts_chair_witnesses.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_potential(data: dict, out: Path) -> Path:
    fig, ax = plt.subplots(figsize=(8, 4))
    k = np.arange(len(data["f"]))
    ax.plot(k, data["f"], "o-", label="f_T of the witness (eq. 1)")
    ax.set_xlabel("contact set")
    ax.set_ylabel("f_T")
    ax2 = ax.twinx()
    ax2.plot(k, data["s"], "s--", color="tab:orange", label="s' along T")
    ax2.set_ylabel("s'")
    fig.legend(loc="upper right")
    ax.set_title("The potential f_T along the plan")
    fig.tight_layout()
    path = out / "contacts_chair_potential.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    """The command line (``argv``: its arguments, default ``sys.argv[1:]``); the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=float, default=300.0, help="search budget [s] (300)")
    which = parser.add_mutually_exclusive_group()  # one plan to draw: the last one, or a saved one
    which.add_argument("--reuse", action="store_true", help="draw OUT/contacts_chair_plan.npz again")
    which.add_argument(
        "--plan",
        type=Path,
        help="draw this saved plan (`humanoid scenario chair-egress --save-plan FILE`)",
    )
    parser.add_argument("--out", type=Path, default=Path("out"), help="output directory (out)")
    parser.add_argument("--panels", type=int, default=8, help="witness postures in the strip (8)")
    args = parser.parse_args(argv)
    plan_path = args.plan or args.out / "contacts_chair_plan.npz"
    if args.plan is None and not (args.reuse and plan_path.is_file()):
        args.out.mkdir(parents=True, exist_ok=True)
        print("plan written to", compute_plan(args.budget, plan_path))
    try:
        data = figure_data(plan_path)
    except (InvalidRequestError, FileNotFoundError) as exc:  # a plan of before session 11, no file
        print(f"error: {exc}; plan again without --reuse (or --plan FILE of --save-plan)", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)  # only once there is a plan to draw
    print("wrote", render_strip(data, args.out, args.panels))
    print("wrote", plot_potential(data, args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
