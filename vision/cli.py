"""Command line of the vision package: ``perception learn``, ``perception detect``, ``perception learn-sim``.

``add_cli(subparsers)`` registers a ``perception`` command group on an argparse sub-parser collection
(``humanoid`` wires it, services/cli.py); each leaf command sets ``func(args) -> int`` and raises the
typed errors of services/errors.py, which the entry point turns into messages and exit codes. Standalone:
``python -m vision.cli perception learn orange_ball --from img.png --mask mask.png``.

This module is the only one registering the ``perception`` group (services/cli.py also lists
``services.perception.cli``, which must not exist, or both would register it): ``learn-sim``, the tool
that learns the demo objects from sim renders, lives in services/perception/learn_from_sim.py and is
registered here. Its options module imports no simulator; pybullet loads only when the command runs.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from services.cli_common import examples
from services.errors import HumanoidError, InvalidRequestError, NotFoundError
from vision.backproject import back_project
from vision.camshift import DetectionConfig, check_unambiguous, detect_all
from vision.histogram import (
    DEFAULT_MODELS_DIR,
    SHAPES,
    HistogramConfig,
    learn_model,
    load_models,
    rect_mask,
    save_model,
    select_models,
    to_hsv,
)


def read_image(path: str | Path, flags: int = cv2.IMREAD_COLOR) -> np.ndarray:
    """Read an image file; NotFoundError / InvalidRequestError naming the file when it cannot be read."""
    p = Path(path)
    if not p.is_file():
        raise NotFoundError(f"no image file {p}")
    image = cv2.imread(str(p), flags)
    if image is None:
        raise InvalidRequestError(f"{p} is not an image OpenCV can read (png, jpg, ppm, ...)")
    return image


def parse_rect(text: str) -> tuple[int, int, int, int]:
    """'X,Y,W,H' [px] -> (x, y, w, h)."""
    try:
        x, y, w, h = (int(v) for v in text.split(","))
    except ValueError as e:
        raise InvalidRequestError(
            f"--rect expects X,Y,W,H in pixels (e.g. 200,150,40,40), got {text!r}"
        ) from e
    return x, y, w, h


def learn(
    name: str,
    image_paths: str | Path | Sequence[str | Path],
    mask_paths: str | Path | Sequence[str | Path] | None = None,
    rect: tuple[int, int, int, int] | None = None,
    models_dir: str | Path = DEFAULT_MODELS_DIR,
    shape: str = "blob",
    config: HistogramConfig | None = None,
) -> Path:
    """Learn object ``name``'s Hue-Saturation model from image file(s) and write ``<models_dir>/<name>.json``.

    The object's pixels are given either by mask files (one per image, non-zero = object) or by one
    rectangle ``(x, y, w, h)`` [px] applied to every image. Returns the model file's path.
    """
    images = [image_paths] if isinstance(image_paths, str | Path) else list(image_paths)
    if (mask_paths is None) == (rect is None):
        raise InvalidRequestError(
            "give the object's pixels either as mask file(s) or as a rectangle, not both"
        )
    bgr = [read_image(p) for p in images]
    if mask_paths is not None:
        masks_in = [mask_paths] if isinstance(mask_paths, str | Path) else list(mask_paths)
        if len(masks_in) != len(images):
            raise InvalidRequestError(
                f"got {len(images)} images but {len(masks_in)} masks; give one mask per image"
            )
        masks = []
        for p in masks_in:
            m = read_image(p, cv2.IMREAD_UNCHANGED)
            masks.append(m if m.ndim == 2 else m.max(axis=2))
    else:
        masks = [rect_mask(im.shape, rect) for im in bgr]
    source = ", ".join(str(p) for p in images)
    model = learn_model(name, bgr, masks, config, shape=shape, source=source)
    return save_model(model, models_dir)


def _cmd_learn(args: argparse.Namespace) -> int:
    config = HistogramConfig(h_bins=args.h_bins, s_bins=args.s_bins, s_min=args.s_min, v_min=args.v_min)
    rect = parse_rect(args.rect) if args.rect else None
    path = learn(args.name, args.images, args.masks, rect, args.models_dir, args.shape, config)
    print(f"learned {args.name!r} -> {path}")
    return 0


def _cmd_detect(args: argparse.Namespace) -> int:
    models = select_models(load_models(args.models_dir), [args.name])
    image = read_image(args.image)
    bp = back_project(to_hsv(image), models[0])
    cfg = DetectionConfig()
    det = check_unambiguous(detect_all(bp, args.name, cfg), cfg, f"'{args.name}'")
    print(
        f"{args.name}: centre ({det.centre_px[0]:.2f}, {det.centre_px[1]:.2f}) px, box "
        f"{det.box[1][0]:.1f} x {det.box[1][1]:.1f} px at {det.box[2]:.1f} deg, "
        f"confidence {det.confidence:.2f}"
    )
    if args.out:
        overlay = np.hstack([image, cv2.cvtColor(bp, cv2.COLOR_GRAY2BGR)])
        for dx in (0, image.shape[1]):
            box = ((det.box[0][0] + dx, det.box[0][1]), det.box[1], det.box[2])
            cv2.polylines(overlay, [np.intp(cv2.boxPoints(box))], True, (0, 0, 255), 2)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(args.out), overlay)
        print(f"wrote {args.out}")
    return 0


EXAMPLES = examples(
    "humanoid perception learn-sim                      # the demo objects' models from sim renders",
    "humanoid perception learn orange_ball --from ball.png --mask ball_mask.png --shape sphere",
    "humanoid perception detect orange_ball --image view.png --out out/detect.png",
)


def add_cli(subparsers) -> argparse.ArgumentParser:
    """Register the ``perception`` command group (``learn``, ``detect``, ``learn-sim``) on ``subparsers``."""
    group = subparsers.add_parser(
        "perception",
        help="learn object colour models, test detection",
        description=__doc__.split("\n")[0],
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    raw = {"epilog": EXAMPLES, "formatter_class": argparse.RawDescriptionHelpFormatter}
    sub = group.add_subparsers(dest="perception_command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "learn",
        help="learn an object's Hue-Saturation histogram from sample image(s)",
        description="Learn a named object's 2D Hue-Saturation histogram from sample images and the object's "
        "pixels (a mask per image, or one rectangle), and save it as <models-dir>/<NAME>.json.",
        **raw,
    )
    p.add_argument("name", metavar="NAME", help="object name, e.g. orange_ball (lower-case, digits, _ or -)")
    p.add_argument(
        "--from", dest="images", nargs="+", required=True, metavar="IMAGE", help="sample image file(s)"
    )
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "--mask", dest="masks", nargs="+", metavar="MASK", help="mask file(s), non-zero = object"
    )
    where.add_argument("--rect", metavar="X,Y,W,H", help="object rectangle in pixels, for every image")
    p.add_argument(
        "--models-dir", type=Path, default=DEFAULT_MODELS_DIR, help=f"default {DEFAULT_MODELS_DIR}"
    )
    p.add_argument(
        "--shape", choices=SHAPES, default="blob", help="'sphere' for balls (stereo centre correction)"
    )
    d = HistogramConfig()
    p.add_argument("--h-bins", type=int, default=d.h_bins, help=f"hue bins (default {d.h_bins})")
    p.add_argument("--s-bins", type=int, default=d.s_bins, help=f"saturation bins (default {d.s_bins})")
    p.add_argument(
        "--s-min", type=int, default=d.s_min, help=f"ignore pixels of lower saturation (default {d.s_min})"
    )
    p.add_argument(
        "--v-min", type=int, default=d.v_min, help=f"ignore pixels of lower value (default {d.v_min})"
    )
    p.set_defaults(func=_cmd_learn)

    p = sub.add_parser(
        "detect",
        help="detect a learned object in one image (back projection + CamShift)",
        description="Back-project NAME's model onto IMAGE, run CamShift from its blobs and print the "
        "detection; "
        "--out writes the image and its back projection with the CamShift box.",
        **raw,
    )
    p.add_argument("name", metavar="NAME", help="a learned object name")
    p.add_argument("--image", required=True, help="image file")
    p.add_argument(
        "--models-dir", type=Path, default=DEFAULT_MODELS_DIR, help=f"default {DEFAULT_MODELS_DIR}"
    )
    p.add_argument("--out", type=Path, help="write an overlay PNG here")
    p.set_defaults(func=_cmd_detect)

    from services.perception import learn_from_sim  # options only; the sim is imported when it runs

    p = sub.add_parser(
        "learn-sim",
        help="learn the demo objects from sim renders and their segmentation masks",
        description=learn_from_sim.__doc__.split("\n")[0]
        + " Writes <models-dir>/<NAME>.json for each object and checks detection on the views.",
        **raw,
    )
    learn_from_sim.add_arguments(p)
    p.set_defaults(func=learn_from_sim.run_cli)
    return group


def main(argv: Sequence[str] | None = None) -> int:
    """Standalone entry point: ``python -m vision.cli perception ...``."""
    parser = argparse.ArgumentParser(prog="python -m vision.cli", description="vision package commands")
    add_cli(parser.add_subparsers(dest="command", required=True, metavar="COMMAND"))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except HumanoidError as e:  # same exit codes as the `humanoid` entry point
        print(f"error: {e.code}: {e.message}", file=sys.stderr)
        return 2 if e.code == "invalid_request" else 1


if __name__ == "__main__":
    raise SystemExit(main())
