"""Learn the demo objects' colour models from simulator renders, using the segmentation mask.

"The model of the objects to be detected are previously learned using two dimensional histogram in the
{Hue, Saturation} color space by taking a sample image" (Yoshida et al., ``001_771c0ce3779b0683.txt``,
"Object Recognition and Localization"). Here the sample images are pybullet renders of a scene through
the robot's own head camera (same intrinsics and renderer as ``sim/render``), and the object's pixels are
those of its body in the render's segmentation mask, so no hand-drawn mask is needed.

Several views make the histogram robust to shading: for each layout seed, each object is seen from
several distances and directions (the camera at head height, looking at the object), which covers its
lit and shaded faces. Views where the object is hidden (fewer than ``min_view_pixels`` visible pixels)
are skipped. The learned models are then checked on every view: the best detection of each model must
lie on its object's mask.

Re-run (writes ``vision/models/<name>.json``; deterministic: same scene, seeds and views, same files)::

    humanoid perception learn-sim                       # or: python -m services.perception.learn_from_sim
    humanoid perception learn-sim --objects orange_ball --seeds 0 1 --models-dir /tmp/models

Uses the sim world directly (pybullet, no bus); ground truth is used here only to aim the learning
camera at the objects, never at run time.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from services.errors import HumanoidError, InvalidRequestError, NotFoundError
from vision.backproject import back_project
from vision.camera import look_at
from vision.camshift import DetectionConfig, detect_all
from vision.histogram import DEFAULT_MODELS_DIR, HistogramConfig, ObjectModel, learn_model, save_model, to_hsv

#: Every object of the ball_fetch scene's catalogue: the ball to fetch, the balls beside it (their
#: models put them on the map before the hand comes near), the box, the table and the chair.
DEMO_OBJECTS = ("orange_ball", "blue_ball", "purple_ball", "green_box", "yellow_table", "chair")


@dataclass(frozen=True)
class LearnSimConfig:
    """What to render and learn.

    scene: sim scene name (sim/scenes) or YAML path; seeds: layout seeds (None = the nominal layout);
    objects: names of scene objects to learn (each becomes ``<name>.json``); robot, camera: whose camera
    intrinsics render the views; distances_m: horizontal camera-object distances [m]; azimuths_rad:
    directions of the camera around the object, relative to the direction from the object to the
    robot's start position [rad]; eye_height_m: camera height [m] (the wide pair is at 1.36 m in
    half-sitting); width_px, height_px: render size; min_view_pixels: views showing fewer object pixels
    are skipped.
    """

    scene: str = "ball_fetch"
    seeds: tuple[int | None, ...] = (None, 1, 2)
    objects: tuple[str, ...] = DEMO_OBJECTS
    robot: str = "hrp2_like"
    camera: str = "wide_left"
    distances_m: tuple[float, ...] = (1.0, 2.0, 3.5)
    azimuths_rad: tuple[float, ...] = (-0.6, 0.0, 0.6)
    eye_height_m: float = 1.36
    width_px: int = 640
    height_px: int = 480
    min_view_pixels: int = 30
    histogram: HistogramConfig = field(default_factory=HistogramConfig)

    def __post_init__(self) -> None:
        if not self.objects:
            raise InvalidRequestError("give at least one object to learn")
        if not self.seeds or not self.distances_m or not self.azimuths_rad:
            raise InvalidRequestError("seeds, distances_m and azimuths_rad must not be empty")
        if min(self.distances_m) <= 0.2:
            raise InvalidRequestError(f"distances must be > 0.2 m, got {list(self.distances_m)}")


@dataclass(frozen=True)
class View:
    """One learning render: BGR image, per-object boolean masks of the visible pixels, where it came from."""

    image_bgr: np.ndarray
    masks: dict[str, np.ndarray]
    target: str
    seed: int | None
    distance_m: float
    azimuth_rad: float


@dataclass(frozen=True)
class LearnSimResult:
    """The learned models, where they were written, and the detection check on the learning views.

    views_used[name]: views that showed the object; hits[name]: views where its model's best detection
    lies on its mask; false_hits[name]: views without the object where its model still detected something;
    confused[name]: views where its model's best detection lies on another object's pixels, off its own
    (two objects of one colour: the models could not tell them apart).
    """

    models: dict[str, ObjectModel]
    paths: dict[str, Path]
    views_used: dict[str, int]
    hits: dict[str, int]
    false_hits: dict[str, int]
    confused: dict[str, int] = field(default_factory=dict)


def _aim_point(obj) -> np.ndarray:
    """Where to point the learning camera: the centre of a ball or box, mid-height of a table or chair."""
    p = np.asarray(obj.position, dtype=float).copy()
    if obj.kind in ("table", "chair"):
        p[2] += 0.6 * float(obj.size_m[2])
    return p


def render_views(config: LearnSimConfig) -> tuple[list[View], dict[str, str]]:
    """Every (seed, object, distance, azimuth) view with its segmentation masks, and each object's kind."""
    from sim import render
    from sim.world import World

    views: list[View] = []
    with World(config.robot, config.scene, config.seeds[0]) as world:
        known = world.layout.scene.names()
        missing = [n for n in config.objects if n not in known]
        if missing:
            raise NotFoundError(
                f"scene {world.layout.scene.name} has no object {missing[0]!r}; objects: {known}",
                {"valid": known},
            )
        if config.camera not in world.robot.cameras:
            raise InvalidRequestError(
                f"{world.robot.name} has no camera {config.camera!r}; cameras: {sorted(world.robot.cameras)}"
            )
        spec = world.robot.cameras[config.camera]
        for seed in config.seeds:
            layout = world.reset(None, seed)
            truth = world.ground_truth()
            robot_xy = np.asarray(layout.robot_xy, dtype=float)
            for target in config.objects:
                aim = _aim_point(truth[target])
                back = math.atan2(robot_xy[1] - aim[1], robot_xy[0] - aim[0])
                for distance in config.distances_m:
                    for azimuth in config.azimuths_rad:
                        a = back + azimuth
                        eye = np.array(
                            [
                                aim[0] + distance * math.cos(a),
                                aim[1] + distance * math.sin(a),
                                config.eye_height_m,
                            ]
                        )
                        T_world_camera = look_at(eye, aim)
                        image = render.render_camera(
                            world,
                            config.camera,
                            spec,
                            T_world_camera,
                            config.width_px,
                            config.height_px,
                            segmentation=True,
                        )
                        ids = {name: body for body, name in image.labels.items()}
                        masks = {n: image.segmentation == ids[n] for n in config.objects}
                        bgr = cv2.cvtColor(image.rgb, cv2.COLOR_RGB2BGR)
                        views.append(View(bgr, masks, target, seed, distance, azimuth))
        kinds = {n: truth[n].kind for n in config.objects}
    return views, kinds


def learn_from_views(
    views: Sequence[View], kinds: dict[str, str], config: LearnSimConfig, source: str
) -> dict[str, ObjectModel]:
    """One model per object from the views showing at least ``min_view_pixels`` of it."""
    models = {}
    for name in config.objects:
        used = [v for v in views if np.count_nonzero(v.masks[name]) >= config.min_view_pixels]
        if not used:
            raise NotFoundError(
                f"{name!r} is not visible in any learning view (fewer than {config.min_view_pixels} px each)"
            )
        shape = "sphere" if kinds[name] == "ball" else "blob"
        models[name] = learn_model(
            name,
            [v.image_bgr for v in used],
            [v.masks[name] for v in used],
            config.histogram,
            shape=shape,
            source=f"{source}; {len(used)} views",
        )
    return models


def check_models(
    models: dict[str, ObjectModel], views: Sequence[View], min_view_pixels: int
) -> tuple[dict[str, int], dict[str, int], dict[str, int], dict[str, int]]:
    """(views showing each object, views where its best detection is on it, views without it where the
    model detected something anyway, views where its best detection lies on another object's pixels
    and off its own: :class:`LearnSimResult`)."""
    cfg = DetectionConfig()
    used = dict.fromkeys(models, 0)
    hits = dict.fromkeys(models, 0)
    false_hits = dict.fromkeys(models, 0)
    confused = dict.fromkeys(models, 0)
    for view in views:
        hsv = to_hsv(view.image_bgr)
        for name, model in models.items():
            candidates = detect_all(back_project(hsv, model), name, cfg)
            visible = np.count_nonzero(view.masks[name]) >= min_view_pixels
            on_it = False
            if visible:
                used[name] += 1
                if candidates:
                    u, v = candidates[0].centre_px
                    ys, xs = np.nonzero(view.masks[name])
                    # On the object: the centroid is inside the mask's bounding box (a table's centroid
                    # may fall between its legs).
                    on_it = bool(xs.min() - 1 <= u <= xs.max() + 1 and ys.min() - 1 <= v <= ys.max() + 1)
                    hits[name] += on_it
            elif candidates and not np.any(view.masks[name]):
                false_hits[name] += 1
            if candidates and not on_it:
                u, v = (round(c) for c in candidates[0].centre_px)
                height, width = view.masks[name].shape
                if 0 <= u < width and 0 <= v < height:
                    confused[name] += any(mask[v, u] for other, mask in view.masks.items() if other != name)
    return used, hits, false_hits, confused


def catalogued_floor_size(scene: str, name: str) -> tuple[float, float] | None:
    """The sides of object ``name``'s floor rectangle [m] in the scene's description (the catalogue the
    views were rendered from: the same for every seed, only poses are random); None for a ball.
    A catalogue assumption: the models carry the true sizes of the scene's objects, as a robot told
    the furniture's dimensions would (services/perception/README.md)."""
    from sim.scene import load_scene

    objects = load_scene(scene).objects
    spec = next((o for o in objects if o.name == name), None)
    if spec is None:
        raise InvalidRequestError(
            f"no object {name!r} in scene {scene!r}: its objects are {[o.name for o in objects]}"
        )
    if spec.kind not in ("box", "table", "chair"):
        return None
    return float(spec.size_m[0]), float(spec.size_m[1])


def learn_sim(
    config: LearnSimConfig | None = None, models_dir: str | Path = DEFAULT_MODELS_DIR
) -> LearnSimResult:
    """Render the views, learn one model per object, write ``<models_dir>/<name>.json``, check them."""
    config = config or LearnSimConfig()
    views, kinds = render_views(config)
    seeds = ", ".join("nominal" if s is None else str(s) for s in config.seeds)
    source = (
        f"humanoid perception learn-sim: scene {config.scene} (seeds {seeds}), {config.robot} "
        f"{config.camera} {config.width_px}x{config.height_px}, distances {list(config.distances_m)} m, "
        f"azimuths {list(config.azimuths_rad)} rad, segmentation masks"
    )
    models = learn_from_views(views, kinds, config, source)
    models = {
        name: replace(m, floor_size_m=catalogued_floor_size(config.scene, name)) for name, m in models.items()
    }
    paths = {name: save_model(model, models_dir) for name, model in models.items()}
    used, hits, false_hits, confused = check_models(models, views, config.min_view_pixels)
    return LearnSimResult(models, paths, used, hits, false_hits, confused)


# ---------------------------------------------------------------------------------------------- command line
def _seed(text: str) -> int | None:
    if text in ("nominal", "none", "None"):
        return None
    try:
        return int(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"a seed is an integer or 'nominal', got {text!r}") from e


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``perception learn-sim`` (shared by ``humanoid`` and ``python -m``)."""
    d = LearnSimConfig()
    parser.add_argument("--scene", default=d.scene, help=f"sim scene (default {d.scene})")
    parser.add_argument(
        "--seeds",
        nargs="+",
        type=_seed,
        default=list(d.seeds),
        metavar="SEED",
        help="layout seeds, 'nominal' for the scene file's layout (default: nominal 1 2)",
    )
    parser.add_argument(
        "--objects", nargs="+", default=list(d.objects), metavar="NAME", help=f"default {' '.join(d.objects)}"
    )
    parser.add_argument(
        "--distances",
        nargs="+",
        type=float,
        default=list(d.distances_m),
        metavar="M",
        help=f"camera distances [m] (default {' '.join(map(str, d.distances_m))})",
    )
    parser.add_argument(
        "--azimuths",
        nargs="+",
        type=float,
        default=list(d.azimuths_rad),
        metavar="RAD",
        help="camera directions around the object, relative to the robot's side [rad] "
        f"(default {' '.join(map(str, d.azimuths_rad))})",
    )
    parser.add_argument("--robot", default=d.robot, help=f"robot whose camera renders (default {d.robot})")
    parser.add_argument(
        "--models-dir", type=Path, default=DEFAULT_MODELS_DIR, help=f"default {DEFAULT_MODELS_DIR}"
    )


def run_cli(args: argparse.Namespace) -> int:
    """Learn as ``args`` say and print what was written and how the models detect on the views."""
    config = LearnSimConfig(
        scene=args.scene,
        seeds=tuple(args.seeds),
        objects=tuple(args.objects),
        robot=args.robot,
        distances_m=tuple(args.distances),
        azimuths_rad=tuple(args.azimuths),
    )
    result = learn_sim(config, args.models_dir)
    for name, path in result.paths.items():
        m = result.models[name]
        print(
            f"{name:<14} {m.shape:<6} {m.n_pixels:>8} px -> {path}   detected on it in "
            f"{result.hits[name]}/{result.views_used[name]} views, elsewhere in {result.false_hits[name]}, "
            f"on another object in {result.confused[name]}"
        )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m services.perception.learn_from_sim", description=__doc__.split("\n")[0]
    )
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run_cli(args)
    except HumanoidError as e:
        print(f"error: {e.code}: {e.message}", file=sys.stderr)
        return 2 if e.code == "invalid_request" else 1


if __name__ == "__main__":
    raise SystemExit(main())
