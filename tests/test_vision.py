"""Tests of the vision package on ray-cast stereo pairs with exact ground truth (vision.synthetic).

Cameras: 640x480, 60 deg horizontal field of view, baseline 0.144 m (HRP-2's wide pair); an orange ball
of 5 cm radius, a green box and a yellow table in a textured room.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from services.errors import InvalidRequestError, NotFoundError
from vision import synthetic as syn
from vision.backproject import back_project
from vision.camera import CameraIntrinsics, StereoRig, look_at, transform_points
from vision.camshift import DetectionConfig, Tracker, camshift, check_unambiguous, detect_all
from vision.cli import learn, main
from vision.histogram import (
    HistogramConfig,
    learn_model,
    load_model,
    load_models,
    save_model,
    select_models,
    to_hsv,
)
from vision.localize import LocalizeConfig, localize, locate
from vision.stereo import (
    StereoConfig,
    point_from_pixel_disparity,
    sphere_centre_pixel,
    to_world,
    triangulate_centroids,
)

RIG = StereoRig(CameraIntrinsics.from_hfov(640, 480, math.radians(60.0)), 0.144)
NAMES = ("orange_ball", "green_box", "yellow_table")


def demo_scene(ball=(2.0, 0.25, 0.75), extra=()) -> syn.Scene:
    return syn.Scene(
        (
            *syn.room(),
            syn.Sphere("orange_ball", ball, syn.BALL_RADIUS_M, syn.ORANGE),
            syn.Box("green_box", (ball[0] + 0.05, ball[1], 0.35), (0.2, 0.25, 0.35), syn.GREEN, 0.2),
            *syn.table("yellow_table", (2.6, -0.9), 0.7, yaw_rad=-0.3),
            *extra,
        )
    )


def stereo(scene: syn.Scene, T_world_left: np.ndarray, seed: int = 0):
    left, right = syn.render_stereo(scene, RIG, T_world_left, 2, 2.0, np.random.default_rng(seed))
    return left, right


@pytest.fixture(scope="module")
def models():
    """The three demo objects learned from one viewpoint (label masks as the segmentation)."""
    scene = demo_scene()
    render = syn.render(
        scene, RIG.intrinsics, look_at([0.3, 0.6, 1.35], [2.2, -0.2, 0.6]), 2, 2.0, np.random.default_rng(1)
    )
    return {
        n: learn_model(
            n,
            [render.image_bgr],
            [scene.mask_of(render.labels, n)],
            shape="sphere" if n == "orange_ball" else "blob",
        )
        for n in NAMES
    }


@pytest.fixture(scope="module")
def demo_pair():
    """The demo scene seen from another viewpoint."""
    T = look_at([0.0, 0.0, 1.3], [2.2, -0.3, 0.5])
    left, right = stereo(demo_scene(), T, seed=2)
    return left, right, T


# ---------------------------------------------------------------- cameras and the renderer's ground truth


def test_renderer_draws_the_ball_where_it_projects():
    T = look_at([0.0, 0.0, 1.3], [2.0, 0.3, 0.7])
    left, right = stereo(demo_scene(), T)
    c_cam = transform_points(np.linalg.inv(T), [2.0, 0.25, 0.75])
    for render, p in ((left, c_cam), (right, c_cam - [RIG.baseline_m, 0, 0])):
        u, v = RIG.intrinsics.project(p)
        assert render.labels[round(v), round(u)] == 2  # the sphere is primitive 2
        mask = render.labels == 2
        radius_px = RIG.intrinsics.fx * syn.BALL_RADIUS_M / np.linalg.norm(p)
        assert mask.sum() == pytest.approx(math.pi * radius_px**2, rel=0.1)


def test_triangulation_inverts_projection_and_to_world_applies_the_pose():
    rng = np.random.default_rng(3)
    T_world_cam = look_at([0.1, -0.2, 1.3], [2.0, 0.5, 0.4])
    for _ in range(20):
        p = np.array([rng.uniform(-1, 1), rng.uniform(-0.7, 0.7), rng.uniform(0.5, 4.0)])
        uv_l = RIG.intrinsics.project(p)
        uv_r = RIG.intrinsics.project(p - [RIG.baseline_m, 0.0, 0.0])
        q = triangulate_centroids(RIG, tuple(uv_l), tuple(uv_r))
        np.testing.assert_allclose(q, p, atol=1e-9)
        np.testing.assert_allclose(to_world(q, T_world_cam), T_world_cam[:3, :3] @ p + T_world_cam[:3, 3])
    with pytest.raises(NotFoundError, match="disparity"):
        triangulate_centroids(RIG, (100.0, 50.0), (120.0, 50.0))
    with pytest.raises(InvalidRequestError):
        point_from_pixel_disparity(RIG, 1.0, 1.0, 0.0)


def test_sphere_centre_pixel_inverts_the_silhouette_ellipse_centre():
    k = RIG.intrinsics
    r, rng = 0.05, np.random.default_rng(4)
    for _ in range(20):
        p = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.4, 0.4), rng.uniform(0.8, 3.0)])
        d = np.linalg.norm(p)
        # Silhouette ends along the radial line: rays at theta -+ alpha; its centre is their midpoint.
        t, tau = math.hypot(p[0], p[1]) / p[2], r / math.sqrt(d * d - r * r)
        ends = [(t - tau) / (1 + t * tau), (t + tau) / (1 - t * tau)]
        scale = 0.5 * sum(ends) / t
        centroid = (k.cx + (p[0] / p[2]) * scale * k.fx, k.cy + (p[1] / p[2]) * scale * k.fy)
        np.testing.assert_allclose(sphere_centre_pixel(RIG, centroid, r, d), k.project(p), atol=1e-9)


# ------------------------------------------------------------------------------- models: learning, files


def test_model_round_trips_through_its_file(tmp_path, models):
    path = save_model(models["orange_ball"], tmp_path)
    assert path.name == "orange_ball.json"
    loaded = load_model(path)
    np.testing.assert_allclose(loaded.hist, models["orange_ball"].hist, atol=1e-5)
    assert (loaded.shape, loaded.config, loaded.n_pixels) == (
        "sphere",
        HistogramConfig(),
        models["orange_ball"].n_pixels,
    )
    assert set(load_models(tmp_path)) == {"orange_ball"}
    assert loaded.floor_size_m is None  # a ball: none catalogued
    sized = load_model(
        save_model(dataclasses.replace(models["orange_ball"], floor_size_m=(1.0, 0.6)), tmp_path)
    )
    assert sized.floor_size_m == (1.0, 0.6)
    with pytest.raises(InvalidRequestError, match="floor_size_m"):
        dataclasses.replace(models["orange_ball"], floor_size_m=(1.0, -0.6))
    assert load_models(tmp_path / "absent") == {}
    with pytest.raises(NotFoundError):
        load_model(tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text('{"format": "humanoid-vision/hs-histogram", "version": 1}')
    with pytest.raises(InvalidRequestError, match="malformed"):
        load_model(tmp_path / "bad.json")
    (tmp_path / "bad.json").write_text("not json")
    with pytest.raises(InvalidRequestError, match="not valid JSON"):
        load_model(tmp_path / "bad.json")


def test_learning_rejects_bad_names_and_colourless_objects():
    grey = np.full((50, 50, 3), 128, np.uint8)
    mask = np.ones((50, 50), bool)
    with pytest.raises(InvalidRequestError, match="coloured enough"):
        learn_model("grey_thing", [grey], [mask])
    with pytest.raises(InvalidRequestError, match="not valid"):
        learn_model("Orange Ball", [grey], [mask])
    with pytest.raises(InvalidRequestError, match="masks"):
        learn_model("x", [grey], [])


def test_unknown_object_name_lists_the_known_names(models):
    with pytest.raises(
        InvalidRequestError, match=r"known objects are \['green_box', 'orange_ball', 'yellow_table'\]"
    ) as e:
        select_models(models, ["blue_cup"])
    assert e.value.details["valid"] == sorted(NAMES)


# ------------------------------------------------------------------------------------------- detection


def test_each_model_finds_its_object_and_only_it(models, demo_pair):
    left, _, _ = demo_pair
    scene = demo_scene()
    hsv = to_hsv(left.image_bgr)
    for name, model in models.items():
        det = check_unambiguous(detect_all(back_project(hsv, model), name), DetectionConfig())
        u, v = det.centre_px
        truth = scene.mask_of(left.labels, name)
        # The centroid sits on the object (the table's: inside the box around top and legs).
        ys, xs = np.nonzero(truth)
        assert xs.min() <= u <= xs.max() and ys.min() <= v <= ys.max()
        assert det.confidence > 0.3
        # The CamShift box holds most of the object.
        box = np.zeros_like(truth, np.uint8)
        cv2.fillConvexPoly(box, np.intp(cv2.boxPoints(det.box)), 1)
        assert truth[box.astype(bool)].sum() > 0.6 * truth.sum()
        # The model supports (almost) no pixel of the other objects.
        bp = back_project(hsv, model)
        for other in NAMES:
            if other != name:
                assert (bp[scene.mask_of(left.labels, other)] >= DetectionConfig().threshold).mean() < 0.01


def test_objects_are_not_found_in_images_without_them(models):
    empty = syn.Scene(syn.room())
    left, right = stereo(empty, look_at([0.0, 0.0, 1.3], [2.2, -0.3, 0.5]), seed=5)
    for model in models.values():
        with pytest.raises(NotFoundError, match="not in view") as e:
            locate(model, left.image_bgr, right.image_bgr, RIG, np.eye(4))
        assert e.value.details["reason"] == "not_in_view"


def test_black_image_is_not_found(models):
    black = np.zeros((480, 640, 3), np.uint8)
    with pytest.raises(NotFoundError, match="not in view"):
        locate(models["orange_ball"], black, black, RIG, np.eye(4))
    with pytest.raises(NotFoundError) as e:
        localize(list(models.values()), black, black, RIG, np.eye(4))
    assert set(e.value.details["missing"]) == set(NAMES)
    assert localize(list(models.values()), black, black, RIG, np.eye(4), require_all=False) == []


def test_two_similar_balls_are_ambiguous(models):
    second = syn.Sphere("orange_ball_2", (2.0, -0.25, 0.75), syn.BALL_RADIUS_M, syn.ORANGE)
    T = look_at([0.0, 0.0, 1.3], [2.0, 0.0, 0.7])
    left, right = stereo(demo_scene(extra=(second,)), T, seed=6)
    with pytest.raises(NotFoundError, match="ambiguous: two blobs of similar score") as e:
        locate(models["orange_ball"], left.image_bgr, right.image_bgr, RIG, T)
    assert e.value.details["reason"] == "ambiguous"


def test_wrong_image_size_is_an_invalid_request(models):
    small = np.zeros((240, 320, 3), np.uint8)
    with pytest.raises(InvalidRequestError, match="320x240 px but the intrinsics are for 640x480"):
        locate(models["orange_ball"], small, small, RIG, np.eye(4))


# ---------------------------------------------------------------------------------------------- tracking


def test_tracker_recovers_by_redetection_after_a_13cm_jump(models):
    T = look_at([0.0, 0.0, 1.3], [1.5, 0.0, 0.75])
    bp = {}
    for key, y in (("start", 0.0), ("small", 0.02), ("jump", 0.15)):
        ball = (1.5, y, 0.75)
        scene = syn.Scene((*syn.room(), syn.Sphere("orange_ball", ball, syn.BALL_RADIUS_M, syn.ORANGE)))
        img = syn.render(scene, RIG.intrinsics, T, 2, 2.0, np.random.default_rng(7)).image_bgr
        bp[key] = (back_project(to_hsv(img), models["orange_ball"]), ball)

    def pixel(ball):
        return RIG.intrinsics.project(transform_points(np.linalg.inv(T), ball))

    tracker = Tracker()
    first = tracker.update("orange_ball", bp["start"][0])
    assert first is not None and first.redetected
    small = tracker.update("orange_ball", bp["small"][0])
    assert small is not None and not small.redetected  # a 2 cm move is tracked by CamShift alone
    np.testing.assert_allclose(small.centre_px, pixel(bp["small"][1]), atol=1.5)

    # 13 cm further the window no longer overlaps the ball: CamShift alone comes back empty...
    assert camshift(bp["jump"][0], tracker.window("orange_ball"), DetectionConfig()) is None
    # ...and the tracker re-detects it over the whole image.
    jumped = tracker.update("orange_ball", bp["jump"][0])
    assert jumped is not None and jumped.redetected
    np.testing.assert_allclose(jumped.centre_px, pixel(bp["jump"][1]), atol=1.5)
    assert tracker.redetections["orange_ball"] == 2
    assert tracker.update("orange_ball", np.zeros_like(bp["jump"][0])) is None


# ------------------------------------------------------------------------------------ stereo localization


def test_several_objects_in_one_call(models, demo_pair):
    left, right, T = demo_pair
    found = localize([models[n] for n in NAMES], left.image_bgr, right.image_bgr, RIG, T)
    by_name = {f.name: f for f in found}
    assert list(by_name) == list(NAMES)
    ball = by_name["orange_ball"]
    assert np.linalg.norm(np.asarray(ball.position_world) - [2.0, 0.25, 0.75]) < 0.01
    assert ball.size_m[0] == pytest.approx(0.1, abs=0.015) and ball.size_m[1] == pytest.approx(0.1, abs=0.015)
    # Box and table: the centre of the visible coloured surfaces, near the solids.
    assert np.linalg.norm(np.asarray(by_name["green_box"].position_world) - [2.05, 0.25, 0.35]) < 0.3
    assert np.linalg.norm(np.asarray(by_name["yellow_table"].position_world)[:2] - [2.6, -0.9]) < 0.35
    for f in found:
        assert 0.0 < f.confidence <= 1.0 and f.method == "centroid"


@pytest.mark.parametrize(("distance_m", "goal_cm"), [(1.0, 1.0), (1.5, 1.0), (2.5, 3.0)])
def test_ball_localization_error_is_within_the_goals(models, distance_m, goal_cm):
    """Median 3D error over seeded random placements (camera pose and ball pixel) at one distance."""
    rng = np.random.default_rng([8, int(distance_m * 10)])
    errors = []
    for _ in range(6):
        place = syn.random_ball_placement(rng, RIG, distance_m)
        left, right = syn.render_stereo(place.scene, RIG, place.T_world_left_camera, 2, 2.0, rng)
        loc = locate(models["orange_ball"], left.image_bgr, right.image_bgr, RIG, place.T_world_left_camera)
        errors.append(100 * np.linalg.norm(np.asarray(loc.position_world) - place.ball_centre_world))
    assert np.median(errors) <= goal_cm, errors
    assert max(errors) <= 2 * goal_cm, errors


@pytest.mark.parametrize("method", ["bm", "sgbm"])
def test_dense_stereo_methods_localize_the_ball(models, demo_pair, method):
    left, right, T = demo_pair
    config = LocalizeConfig(stereo=StereoConfig(method=method))
    loc = locate(models["orange_ball"], left.image_bgr, right.image_bgr, RIG, T, config)
    assert loc.method == method
    assert np.linalg.norm(np.asarray(loc.position_world) - [2.0, 0.25, 0.75]) < 0.02


@pytest.mark.parametrize("method", ["bm", "sgbm"])
def test_correlating_the_whole_image_gives_the_crops_disparities(models, demo_pair, method):
    """The paper's dense 3D image of the whole scene and the crop around the object (which holds the
    whole disparity search range) agree on the object's median disparity."""
    left, right, T = demo_pair
    found = [
        locate(
            models["orange_ball"],
            left.image_bgr,
            right.image_bgr,
            RIG,
            T,
            LocalizeConfig(stereo=StereoConfig(method=method, dense_full_frame=full)),
        )
        for full in (False, True)
    ]
    crop, whole = found
    assert whole.method == crop.method == method
    # SGBM aggregates costs along paths that reach past the crop: the medians may differ by a hair
    assert abs(whole.disparity_px - crop.disparity_px) <= 0.25
    assert np.linalg.norm(np.subtract(whole.position_world, crop.position_world)) < 0.01


def test_ball_cut_by_the_image_border_falls_back_to_dense_stereo(models):
    k = RIG.intrinsics
    T = look_at([0.0, 0.0, 1.3], [1.5, 0.0, 0.75])
    # A ball whose centre projects 8 px inside the right border of the left image (about half cut off).
    ray = np.array([(k.width - 9 - k.cx) / k.fx, 0.0, 1.0])
    centre = transform_points(T, ray / np.linalg.norm(ray) * 1.5)
    scene = syn.Scene((*syn.room(), syn.Sphere("orange_ball", tuple(centre), syn.BALL_RADIUS_M, syn.ORANGE)))
    left, right = stereo(scene, T, seed=9)
    loc = locate(models["orange_ball"], left.image_bgr, right.image_bgr, RIG, T)
    assert loc.left.touches_border and loc.method == "bm"
    assert np.linalg.norm(np.asarray(loc.position_world) - centre) < 0.03


# --------------------------------------------------------------------------------------------------- CLI


def test_cli_learn_writes_a_model_that_detects(tmp_path, demo_pair):
    scene = demo_scene()
    left, _, _ = demo_pair
    cv2.imwrite(str(tmp_path / "img.png"), left.image_bgr)
    cv2.imwrite(str(tmp_path / "mask.png"), scene.mask_of(left.labels, "green_box").astype(np.uint8) * 255)
    models_dir = tmp_path / "models"
    rc = main(
        [
            "perception",
            "learn",
            "green_box",
            "--from",
            str(tmp_path / "img.png"),
            "--mask",
            str(tmp_path / "mask.png"),
            "--models-dir",
            str(models_dir),
        ]
    )
    assert rc == 0 and (models_dir / "green_box.json").is_file()
    assert (
        main(
            [
                "perception",
                "detect",
                "green_box",
                "--image",
                str(tmp_path / "img.png"),
                "--models-dir",
                str(models_dir),
            ]
        )
        == 0
    )
    # A rectangle works too (here: the box's front face).
    ys, xs = np.nonzero(scene.mask_of(left.labels, "green_box"))
    rect = (int(np.percentile(xs, 30)), int(np.percentile(ys, 30)), 10, 10)
    path = learn("box_face", tmp_path / "img.png", rect=rect, models_dir=models_dir)
    assert load_model(path).n_pixels == 100
    # Errors are reported with the entry point's exit codes: a missing file (1), an unknown object (2).
    assert (
        main(
            [
                "perception",
                "learn",
                "x",
                "--from",
                str(tmp_path / "absent.png"),
                "--rect",
                "0,0,5,5",
                "--models-dir",
                str(models_dir),
            ]
        )
        == 1
    )
    assert (
        main(
            [
                "perception",
                "detect",
                "blue_cup",
                "--image",
                str(tmp_path / "img.png"),
                "--models-dir",
                str(models_dir),
            ]
        )
        == 2
    )
    with pytest.raises(SystemExit) as e:
        main(["perception", "learn", "--help"])
    assert e.value.code == 0


def test_a_dense_stereo_past_the_request_budget_is_abandoned_with_a_typed_timeout(models, demo_pair):
    """Issue 16: one OpenCV stereo call cannot be interrupted; within a request's budget it runs where it
    can be abandoned: the typed timeout comes when the budget ends, and the next request still gets the
    same disparities as without a budget (the abandoned computation holds the one stereo slot meanwhile)."""
    from services import budget
    from services.errors import RequestTimeoutError

    left, right, T = demo_pair
    config = LocalizeConfig(stereo=StereoConfig(method="sgbm", dense_full_frame=True))
    big_l, big_r = (cv2.resize(im.image_bgr, (1280, 960)) for im in (left, right))  # about 1 s of SGBM
    big_rig = StereoRig(CameraIntrinsics.from_hfov(1280, 960, math.radians(60.0)), RIG.baseline_m)
    with (
        pytest.raises(RequestTimeoutError, match=r"dense stereo \(sgbm.*abandoned") as err,
        budget.within(0.2),
    ):
        locate(models["orange_ball"], big_l, big_r, big_rig, T, config)
    assert err.value.details["budget_s"] == 0.2
    free = locate(models["orange_ball"], left.image_bgr, right.image_bgr, RIG, T, config)
    with budget.within(60.0):
        bounded = locate(models["orange_ball"], left.image_bgr, right.image_bgr, RIG, T, config)
    assert bounded.disparity_px == free.disparity_px
