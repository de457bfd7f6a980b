"""Runnable example: learn the three demo objects, localize them in a synthetic stereo pair, draw Figure 9.

``python -m vision.demo`` ray-casts (vision.synthetic) an orange ball on a green box and a yellow table
in a textured room, learns each object's Hue-Saturation model from a first render and its label mask,
localizes all three in a second stereo pair taken from elsewhere, prints world positions against ground
truth, and writes ``out/vision/figure9.png``: like Figure 9 of Yoshida et al., the HSV image and the back
projection of the table's colour model with the CamShift rectangle, plus every detection on the image.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from vision import synthetic as syn
from vision.backproject import back_project
from vision.camera import CameraIntrinsics, StereoRig, look_at
from vision.histogram import learn_model, to_hsv
from vision.localize import localize

COLOURS = {"orange_ball": (0, 0, 255), "green_box": (255, 0, 255), "yellow_table": (255, 128, 0)}


def demo_scene() -> tuple[syn.Scene, dict[str, np.ndarray]]:
    """The demo scene and the ground-truth centres [m] (world) of its objects (table: top centre)."""
    ball = (2.0, 0.25, 0.75)
    prims = (
        *syn.room(),
        syn.Sphere("orange_ball", ball, syn.BALL_RADIUS_M, syn.ORANGE),
        syn.Box("green_box", (2.05, 0.25, 0.35), (0.2, 0.25, 0.35), syn.GREEN, 0.2),
        *syn.table("yellow_table", (2.6, -0.9), 0.7, yaw_rad=-0.3),
    )
    truth = {
        "orange_ball": np.array(ball),
        "green_box": np.array([2.05, 0.25, 0.35]),
        "yellow_table": np.array([2.6, -0.9, 0.685]),
    }
    return syn.Scene(prims), truth


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m vision.demo", description=__doc__.split("\n")[0])
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out/vision/figure9.png"),
        help="figure path (.png), or a folder to write figure9.png in",
    )
    args = parser.parse_args(argv)

    rig = StereoRig(CameraIntrinsics.from_hfov(640, 480, np.deg2rad(60.0)), 0.144)
    scene, truth = demo_scene()
    rng = np.random.default_rng(0)
    # Learn from one viewpoint...
    T_learn = look_at([0.3, 0.6, 1.35], [2.2, -0.2, 0.6])
    sample = syn.render(scene, rig.intrinsics, T_learn, 2, 2.0, rng)
    models = [
        learn_model(n, [sample.image_bgr], [scene.mask_of(sample.labels, n)], shape=s, source="vision.demo")
        for n, s in (("orange_ball", "sphere"), ("green_box", "blob"), ("yellow_table", "blob"))
    ]
    # ...localize from another.
    T_world_left = look_at([0.0, 0.0, 1.3], [2.2, -0.3, 0.5])
    left, right = syn.render_stereo(scene, rig, T_world_left, 2, 2.0, rng)
    found = localize(models, left.image_bgr, right.image_bgr, rig, T_world_left)
    print(f"{'object':<14}{'world position [m]':>26}{'truth [m]':>26}{'err [cm]':>10}{'conf':>6}  method")
    for loc in found:
        t = truth[loc.name]
        err = 100 * np.linalg.norm(np.asarray(loc.position_world) - t)
        pos = "(" + ", ".join(f"{v:6.3f}" for v in loc.position_world) + ")"
        tru = "(" + ", ".join(f"{v:6.3f}" for v in t) + ")"
        print(f"{loc.name:<14}{pos:>26}{tru:>26}{err:>10.2f}{loc.confidence:>6.2f}  {loc.method}")
    print("(box and table: the point is the centre of what the cameras see, not the solid's centre)")

    hsv = to_hsv(left.image_bgr)
    table = next(m for m in models if m.name == "yellow_table")
    bp = cv2.cvtColor(back_project(hsv, table), cv2.COLOR_GRAY2BGR)
    overlay = left.image_bgr.copy()
    for loc in found:
        box = np.intp(cv2.boxPoints(loc.left.box))
        cv2.polylines(overlay, [box], True, COLOURS[loc.name], 2)
        if loc.name == "yellow_table":
            cv2.polylines(bp, [box], True, (0, 0, 255), 2)
        cv2.putText(
            overlay, loc.name, box.min(axis=0) - [0, 4], cv2.FONT_HERSHEY_SIMPLEX, 0.45, COLOURS[loc.name], 1
        )
    figure = np.hstack([hsv, bp, overlay])
    if args.out.suffix.lower() != ".png":  # a folder (or a name without the extension): the figure in it
        args.out = args.out / "figure9.png"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), figure)
    print(f"wrote {args.out} (HSV image | back projection of the table model + CamShift box | detections)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
