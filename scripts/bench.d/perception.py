"""Perception benchmark: 3D error of the ball's localization and time per stereo pair.

For 30 seeded placements of the orange ball (radius 5 cm) at each of 1.0, 1.5, 2.5 and 3.5 m in front of
the robot's wide stereo pair, localize it and compare with ground truth. Reports ``err_cm`` =
{"1.0": {"median", "max"}, ...} and ``ms_per_pair`` (detection in both images + stereo, i.e. the
vision.localize call; rendering excluded) for the default stereo method, and the same figures for every
method on the same images: centroid triangulation, the paper's pixel correlation ("bm" StereoBM, "sgbm"
StereoSGBM on a crop around the object; "bm_full": StereoBM on the whole image, the paper's "dense 3D
image of the current scene"), and silhouette edges. Footprints (``footprints``): the box, the table and
the chair from 1.5, 2.5 and 4 m (centre, side length and yaw errors); ``footprints_occluded``: the table
with the chair in front of it, from 2.3 m. Writes bench/out/perception.json.

Goals (issue 8): median <= 1 cm at 1.5 m, <= 3 cm at 2.5 m, <= 20 ms per pair.

Image sources (``--source``), both yielding :class:`StereoSample`:

* ``sim`` (default): pybullet renders of the hrp2_like robot's wide pair at 640x480, random head pan/tilt,
  the ball at a random bearing (services/perception/sim_placements.py); the camera pose comes from the
  robot's kinematics, the ball model is the learned one (vision/models/orange_ball.json);
* ``synthetic``: the vision.synthetic ray caster (anti-aliased, textured, sensor noise), the ball model
  learned from one of its renders.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from services.errors import NotFoundError
from services.perception.sim_placements import StereoSample, sim_source
from vision import synthetic
from vision.camera import CameraIntrinsics, StereoRig
from vision.histogram import ObjectModel, learn_model, load_models
from vision.localize import LocalizeConfig, locate
from vision.stereo import METHODS, StereoConfig

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "bench" / "out" / "perception.json"
DISTANCES_M = (1.0, 1.5, 2.5, 3.5)
FOOTPRINT_DISTANCES_M = (1.5, 2.5, 4.0)
#: The footprint scene: the demo's box, table and chair (ball_fetch sizes) 12 m apart, so none hides
#: another from 4 m.
FOOTPRINT_SCENE = {
    "name": "footprint_bench",
    "description": "the green box, the yellow table and the chair, far apart",
    "robot": {"x": -6.0, "y": -6.0, "yaw": 0.0},
    "floor": {"colour": "light_grey", "friction": 1.0},
    "objects": [
        {
            "name": "green_box",
            "kind": "box",
            "size": [0.5, 0.6, 0.7],
            "colour": "green",
            "xy": [0.0, 0.0],
            "yaw": 0.2,
        },
        {
            "name": "yellow_table",
            "kind": "table",
            "size": [1.0, 0.6, 0.72],
            "colour": "yellow",
            "xy": [12.0, 0.0],
            "yaw": 0.3,
        },
        {
            "name": "chair",
            "kind": "chair",
            "size": [0.45, 0.45, 0.45],
            "back_height": 0.45,
            "colour": "brown",
            "xy": [0.0, 12.0],
            "yaw": 2.0,
        },
    ],
}


def _placed(name: str, xy: tuple[float, float], yaw: float) -> dict:
    """FOOTPRINT_SCENE's object ``name`` moved to ``xy`` [m] and ``yaw`` [rad] (world frame)."""
    (obj,) = (o for o in FOOTPRINT_SCENE["objects"] if o["name"] == name)
    return {**obj, "xy": list(xy), "yaw": yaw}


#: The occluded case: the table with the chair 0.75 m in front of it (toward +y, where the robot is).
OCCLUDED_SCENE = {
    **FOOTPRINT_SCENE,
    "name": "footprint_occluded",
    "description": "the yellow table with the chair in front of it",
    "objects": [_placed("yellow_table", (0.0, 0.0), 0.1), _placed("chair", (-0.35, 0.75), 2.0)],
}
GOALS_CM = {"1.5": 1.0, "2.5": 3.0}
GOAL_MS = 20.0
DEFAULT_METHOD = StereoConfig().method


def default_rig() -> StereoRig:
    """640x480, 60 deg horizontal field of view, 0.144 m baseline (HRP-2's wide pair)."""
    return StereoRig(CameraIntrinsics.from_hfov(640, 480, np.deg2rad(60.0)), 0.144)


def synthetic_source(
    n_per_distance: int = 30,
    distances_m: Iterable[float] = DISTANCES_M,
    seed: int = 0,
    supersample: int = 2,
    noise_sigma: float = 2.0,
    rig: StereoRig | None = None,
) -> Iterator[StereoSample]:
    """Seeded ray-cast stereo pairs of the ball on a green box, a yellow table aside, textured room."""
    rig = rig or default_rig()
    for distance in distances_m:
        rng = np.random.default_rng([seed, round(distance * 1000)])
        for _ in range(n_per_distance):
            place = synthetic.random_ball_placement(rng, rig, distance)
            left, right = synthetic.render_stereo(
                place.scene, rig, place.T_world_left_camera, supersample, noise_sigma, rng
            )
            yield StereoSample(
                left.image_bgr,
                right.image_bgr,
                rig.intrinsics,
                rig.baseline_m,
                place.T_world_left_camera,
                place.ball_centre_world,
                distance,
            )


def learn_synthetic_ball_model(seed: int = 12345, supersample: int = 2) -> ObjectModel:
    """The ball's model learned from one render (not one of the benchmark's) and its label mask."""
    rig = default_rig()
    rng = np.random.default_rng(seed)
    place = synthetic.random_ball_placement(rng, rig, 1.2)
    render = synthetic.render(place.scene, rig.intrinsics, place.T_world_left_camera, supersample, 2.0, rng)
    mask = place.scene.mask_of(render.labels, "orange_ball")
    return learn_model("orange_ball", [render.image_bgr], [mask], shape="sphere", source="synthetic render")


FULL_FRAME = ("bm_full", "sgbm_full")
"""Dense correlation of the whole image (the paper's "dense 3D image of the current scene"), then the
median disparity of the object's pixels: the same estimator as "bm"/"sgbm" on a crop, at full cost."""
BENCH_METHODS = (*METHODS, "bm_full")


def stereo_config(name: str) -> StereoConfig:
    """The stereo configuration of a benchmark variant: a vision.stereo method, or "bm_full"/"sgbm_full"."""
    if name in FULL_FRAME:
        return StereoConfig(method=name.removesuffix("_full"), dense_full_frame=True)
    return StereoConfig(method=name)


def _stats(values: list[float]) -> dict[str, float]:
    a = np.asarray(values, float)
    if a.size == 0:
        return {"median": float("nan"), "max": float("nan"), "n": 0}
    return {"median": round(float(np.median(a)), 3), "max": round(float(a.max()), 3), "n": int(a.size)}


def run(
    image_source: Iterable[StereoSample], ball_model: ObjectModel, methods: Iterable[str] = BENCH_METHODS
) -> dict:
    """Localize the ball in every sample with every stereo method; errors [cm] and times [ms]."""
    methods = list(methods)
    errors: dict[str, dict[str, list[float]]] = {m: {} for m in methods}
    times: dict[str, list[float]] = {m: [] for m in methods}
    failures: dict[str, list[str]] = {m: [] for m in methods}
    used: dict[str, dict[str, int]] = {m: {} for m in methods}
    for sample in image_source:
        rig = StereoRig(sample.intrinsics, sample.baseline_m)
        key = f"{sample.distance_m:.1f}"
        for method in methods:
            config = LocalizeConfig(stereo=stereo_config(method))
            t0 = time.perf_counter()
            try:
                loc = locate(
                    ball_model, sample.left_bgr, sample.right_bgr, rig, sample.T_world_left_camera, config
                )
            except NotFoundError as e:
                failures[method].append(f"{key} m: {e.message}")
                continue
            times[method].append((time.perf_counter() - t0) * 1e3)
            err_cm = 100.0 * float(np.linalg.norm(np.asarray(loc.position_world) - sample.ball_world))
            errors[method].setdefault(key, []).append(err_cm)
            used[method][loc.method] = used[method].get(loc.method, 0) + 1
    result: dict = {"methods": {}}
    for method in methods:
        result["methods"][method] = {
            "err_cm": {k: _stats(v) for k, v in sorted(errors[method].items())},
            "ms_per_pair": round(float(np.mean(times[method])), 2) if times[method] else float("nan"),
            "ms_per_pair_p95": round(float(np.percentile(times[method], 95)), 2)
            if times[method]
            else float("nan"),
            "failures": failures[method],
            "estimator_used": used[method],
        }
    return result


def _yaw_error(a: float, b: float, period: float) -> float:
    """|a - b| modulo ``period`` [rad] (a rectangle's yaw is defined modulo pi, a square's modulo pi/2)."""
    d = (a - b) % period
    return min(d, period - d)


def _footprint_errors(
    world, models: dict, name: str, bearings, distance: float, config, cell, missing
) -> None:
    """Render the wide pair from ``distance`` [m] of object ``name``'s centre at each of ``bearings``
    [rad] (world; the robot facing it, the head tilted toward its middle) and add its footprint's errors
    to ``cell`` (centre [cm], long and short side measured - true [cm], yaw [deg]) or a line to
    ``missing``."""
    import cv2

    from services.perception.locate import head_stereo, locate_object
    from services.perception.look_around import head_joints

    robot = world.robot
    head = head_joints(robot, "wide")
    q0 = world.state().q.copy()
    obj = world.layout.object(name)
    sx, sy = obj.spec.size_m[:2]
    true_yaw = obj.yaw_rad if sx >= sy else obj.yaw_rad + math.pi / 2
    length, width = max(sx, sy), min(sx, sy)
    period = math.pi / 2 if abs(sx - sy) < 0.05 else math.pi
    centre = np.asarray(obj.position[:2])
    for bearing in bearings:
        base = centre + distance * np.array([math.cos(bearing), math.sin(bearing)])
        yaw = bearing + math.pi
        q = q0.copy()
        q[0:2] = base
        q[3:7] = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        tilt = head.tilt_sign * math.atan2(1.0, distance)
        q[robot.joint_index(head.tilt).idx_q] = float(np.clip(tilt, *head.tilt_limits))
        world.pyrobot.reset(q)
        left, right = world.render("wide", 640, 480)
        stereo = head_stereo(robot, world.state().q, "wide", 640, 480)
        bgr = [cv2.cvtColor(im.rgb, cv2.COLOR_RGB2BGR) for im in (left, right)]
        try:
            fp = locate_object(models, name, stereo, *bgr, config).footprint
        except NotFoundError as e:
            missing.append(f"{name} at {math.degrees(bearing):.0f} deg: {e.message}")
            continue
        if fp is None:
            missing.append(f"{name} at {math.degrees(bearing):.0f} deg: no footprint")
            continue
        cell["centre_cm"].append(100.0 * float(np.linalg.norm(np.subtract(fp.center_m, centre))))
        cell["long_cm"].append(100.0 * (fp.size_m[0] - length))
        cell["short_cm"].append(100.0 * (fp.size_m[1] - width))
        cell["yaw_deg"].append(math.degrees(_yaw_error(fp.yaw_rad, true_yaw, period)))
    world.pyrobot.reset(q0)


def _summary(rows: dict, missing: dict) -> dict:
    out: dict = {}
    for key, cell in rows.items():
        out[key] = {
            name: {
                "median": round(float(np.median(v)), 2) if v else float("nan"),
                "max_abs": round(float(np.max(np.abs(v))), 2) if v else float("nan"),
                "n": len(v),
            }
            for name, v in cell.items()
        }
        out[key]["no_footprint"] = missing.get(key, [])
    return out


def _cell() -> dict[str, list[float]]:
    return {"centre_cm": [], "long_cm": [], "short_cm": [], "yaw_deg": []}


def footprint_case(n_per_distance: int, seed: int, config: LocalizeConfig) -> dict:
    """Footprints of the box, the table and the chair seen by the sim's wide pair from 1.5, 2.5 and 4 m
    at ``n_per_distance`` seeded bearings each (the robot facing the object, the head tilted toward its
    middle): centre error [cm], side errors [cm] (measured - true, longer and shorter side), yaw error
    [deg], and how often no footprint came out."""
    from sim.scene import parse_scene
    from sim.world import World

    models = load_models()
    rows: dict[str, dict[str, list[float]]] = {}
    missing: dict[str, list[str]] = {}
    with World("hrp2_like", parse_scene(FOOTPRINT_SCENE, "footprint_bench")) as world:
        for distance in FOOTPRINT_DISTANCES_M:
            key = f"{distance:.1f}"
            cell = rows.setdefault(key, _cell())
            rng = np.random.default_rng([seed, round(distance * 1000)])
            for name in ("green_box", "yellow_table", "chair"):
                bearings = rng.uniform(-math.pi, math.pi, n_per_distance)
                _footprint_errors(
                    world, models, name, bearings, distance, config, cell, missing.setdefault(key, [])
                )
    return _summary(rows, missing)


def occluded_case(n: int, seed: int, config: LocalizeConfig) -> dict:
    """The table partly hidden by the chair in front of it (the fetch's table behind the chair: seeds
    13, 21, 23): the chair 0.75 m from the table's centre toward the robot, the robot 2.3 m from the
    table's centre at ``n`` seeded bearings within 25 deg of the chair's direction. Errors of the
    table's footprint as :func:`footprint_case` (key "2.3")."""
    from sim.scene import parse_scene
    from sim.world import World

    models = load_models()
    rows = {"2.3": _cell()}
    missing: dict[str, list[str]] = {"2.3": []}
    with World("hrp2_like", parse_scene(OCCLUDED_SCENE, "footprint_occluded")) as world:
        rng = np.random.default_rng([seed, 2300])
        bearings = math.pi / 2 + rng.uniform(-math.radians(25.0), math.radians(25.0), n)
        _footprint_errors(world, models, "yellow_table", bearings, 2.3, config, rows["2.3"], missing["2.3"])
    return _summary(rows, missing)


def _footprint_table(result: dict) -> str:
    head = (
        f"{'distance':>9}{'centre cm med/max':>20}{'long side cm':>17}{'short side cm':>17}"
        f"{'yaw deg med/max':>18}{'none':>6}"
    )
    lines = [head, "-" * len(head)]
    for key, cell in result.items():
        cells = "".join(
            f"{cell[name]['median']:>10.1f} / {cell[name]['max_abs']:<5.1f}"
            for name in ("centre_cm", "long_cm", "short_cm", "yaw_deg")
        )
        lines.append(f"{key + ' m':>9}{cells}{len(cell['no_footprint']):>6}")
    return "\n".join(lines)


def _table(result: dict) -> str:
    keys = sorted({k for m in result["methods"].values() for k in m["err_cm"]}, key=float)
    head = (
        f"{'method':<9}"
        + "".join(f"{k + ' m med/max [cm]':>22}" for k in keys)
        + f"{'ms/pair':>9}{'p95':>7}{'fail':>6}"
    )
    lines = [head, "-" * len(head)]
    for name, m in result["methods"].items():
        cells = "".join(
            f"{m['err_cm'][k]['median']:>11.2f} / {m['err_cm'][k]['max']:<8.2f}"
            if k in m["err_cm"]
            else f"{'-':>22}"
            for k in keys
        )
        mark = " (default)" if name == DEFAULT_METHOD else ""
        lines.append(
            f"{name:<9}{cells}{m['ms_per_pair']:>9.2f}{m['ms_per_pair_p95']:>7.2f}{len(m['failures']):>6}{mark}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="scripts/bench perception",
        description="3D localization error of the ball at 1.0/1.5/2.5/3.5 m and ms per stereo pair "
        "for every stereo method, and footprint errors at 1.5/2.5/4 m (sim renders by default); writes "
        "bench/out/perception.json.",
    )
    parser.add_argument(
        "--source",
        choices=("sim", "synthetic"),
        default="sim",
        help="pybullet renders of the robot's wide pair (default) or the vision.synthetic ray caster",
    )
    parser.add_argument("--n", type=int, default=30, help="placements per distance (default 30)")
    parser.add_argument("--seed", type=int, default=0, help="placement seed (default 0)")
    parser.add_argument(
        "--supersample", type=int, default=2, help="synthetic: rays per pixel per axis (default 2)"
    )
    parser.add_argument(
        "--noise", type=float, default=2.0, help="synthetic: sensor noise std [grey levels] (default 2)"
    )
    parser.add_argument(
        "--methods", default=",".join(BENCH_METHODS), help=f"comma list of {(*METHODS, *FULL_FRAME)}"
    )
    parser.add_argument(
        "--footprints",
        type=int,
        default=4,
        help="bearings per object and distance of the footprint case (sim; default 4, 0: skip)",
    )
    parser.add_argument(
        "--out", type=Path, default=OUT, help=f"JSON output (default {OUT.relative_to(REPO)})"
    )
    args = parser.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    bad = [m for m in methods if m not in (*METHODS, *FULL_FRAME)]
    if bad:
        parser.error(f"unknown method {bad[0]!r}; choose from {(*METHODS, *FULL_FRAME)}")
    if DEFAULT_METHOD not in methods:
        methods.insert(0, DEFAULT_METHOD)

    if args.source == "sim":
        models = load_models()
        if "orange_ball" not in models:
            print(
                "no vision/models/orange_ball.json: run `humanoid perception learn-sim` first",
                file=sys.stderr,
            )
            return 1
        model = models["orange_ball"]
        source = sim_source(args.n, DISTANCES_M, args.seed)
        description = (
            f"sim (pybullet TINY renderer) hrp2_like wide pair 640x480, hfov 60 deg, baseline 0.144 m, "
            f"ball radius 5 cm, head pan +-0.6 rad, tilt down 0-0.6 rad, seed {args.seed}; "
            f"model vision/models/orange_ball.json; camera pose from the robot kinematics"
        )
    else:
        model = learn_synthetic_ball_model(supersample=args.supersample)
        source = synthetic_source(args.n, DISTANCES_M, args.seed, args.supersample, args.noise)
        description = (
            f"vision.synthetic ray caster, 640x480, hfov 60 deg, baseline 0.144 m, ball radius 5 cm, "
            f"supersample {args.supersample}, noise {args.noise}, seed {args.seed}"
        )
    result = run(source, model, methods)
    footprints = footprint_case(args.footprints, args.seed, LocalizeConfig()) if args.footprints > 0 else None
    occluded = (
        occluded_case(args.footprints * 2, args.seed, LocalizeConfig()) if args.footprints > 0 else None
    )
    default = result["methods"][DEFAULT_METHOD]
    doc = {
        "err_cm": default["err_cm"],
        "ms_per_pair": default["ms_per_pair"],
        "method": DEFAULT_METHOD,
        "n_per_distance": args.n,
        "goals": {"err_cm_median": GOALS_CM, "ms_per_pair": GOAL_MS},
        "meets_goals": bool(
            all(default["err_cm"].get(k, {}).get("median", np.inf) <= g for k, g in GOALS_CM.items())
            and default["ms_per_pair"] <= GOAL_MS
            and not default["failures"]
        ),
        "image_source": args.source,
        "source": description,
        **{k: v for k, v in result.items()},
        "footprints": footprints,
        "footprints_occluded": occluded,
    }
    print(f"source: {description}")
    print(_table(result))
    print(
        f"goals: median <= 1 cm at 1.5 m, <= 3 cm at 2.5 m, <= {GOAL_MS:.0f} ms per pair -> "
        f"{'met' if doc['meets_goals'] else 'NOT met'}"
    )
    if footprints is not None:
        print(
            f"footprints (sim wide pair, box/table/chair, {args.footprints} bearings each; side errors "
            "measured - true, median / max |.|):"
        )
        print(_footprint_table(footprints))
    if occluded is not None:
        print(f"the table behind the chair ({2 * args.footprints} bearings, 2.3 m):")
        print(_footprint_table(occluded))
    for name, m in result["methods"].items():
        for f in m["failures"][:3]:
            print(f"  {name} failure: {f}", file=sys.stderr)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
