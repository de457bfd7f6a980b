"""Write pictures of every shipped scene: an overview snapshot and the head's wide stereo pair.

Usage: ``python -m sim.gallery [--model hrp2_like] [--seed N] [--out out/sim]`` writes
``<out>/<scene>_overview.png`` and ``<out>/<scene>_wide.png`` (left | right, as the robot sees the
scene from its start pose).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from sim.scene import available_scenes
from sim.world import World


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m sim.gallery", description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="hrp2_like", help="robot model (hrp2_like or talos)")
    parser.add_argument("--seed", type=int, default=None, help="layout seed (default: nominal layouts)")
    parser.add_argument("--out", type=Path, default=Path("out/sim"), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    with World(args.model, "empty") as world:
        for scene in available_scenes():
            world.reset(scene, args.seed)
            (args.out / f"{scene}_overview.png").write_bytes(world.snapshot("overview", 800, 600))
            left, right = world.render("wide", 640, 480)
            pair = np.hstack([left.rgb, np.full((480, 4, 3), 255, np.uint8), right.rgb])
            cv2.imwrite(str(args.out / f"{scene}_wide.png"), cv2.cvtColor(pair, cv2.COLOR_RGB2BGR))
            print(f"wrote {args.out / scene}_overview.png and {scene}_wide.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
