"""Tests of perception on simulator renders, without the bus: the learned models (vision/models), the
learning tool, localization against ground truth, the robot-model glue and the look-around helpers.

Renders are pybullet's (sim.world.World, DIRECT mode), as ``sim/render`` makes them; camera poses come
from the robot's kinematics. Ground truth is used only to score.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from services.errors import InvalidRequestError, NotFoundError
from services.model import load_robot
from services.perception.learn_from_sim import DEMO_OBJECTS, LearnSimConfig, learn_sim
from services.perception.locate import head_stereo, localize_config, locate_object, object_model
from services.perception.look_around import (
    head_joints,
    head_trajectory,
    scan_angles,
    turn_offsets,
)
from services.perception.sim_placements import sim_source
from vision.camera import CameraIntrinsics
from vision.histogram import load_models
from vision.localize import LocalizeConfig

ROBOT = "hrp2_like"
GOALS_CM = {1.0: 1.0, 1.5: 1.0, 2.5: 3.0}  # median 3D error goals (issue 8; 1.0 m held to the 1.5 m one)


@pytest.fixture(scope="module")
def models():
    return load_models()


@pytest.fixture(scope="module")
def robot():
    return load_robot(ROBOT)


@pytest.fixture(scope="module")
def ball_fetch():
    from sim.world import World

    with World(ROBOT, "ball_fetch") as world:
        yield world


def look(world, pan_rad: float = 0.0, tilt_rad: float = 0.0, camera: str = "wide"):
    """Set the head (no physics step), render the pair; (head stereo from the kinematics, left, right)."""
    robot = world.robot
    head = head_joints(robot, camera)
    q = world.state().q.copy()
    q[robot.joint_index(head.pan).idx_q] = pan_rad
    q[robot.joint_index(head.tilt).idx_q] = tilt_rad
    world.pyrobot.reset(q)
    left, right = world.render(camera, 640, 480)
    stereo = head_stereo(robot, world.state().q, camera, 640, 480)
    bgr = [cv2.cvtColor(im.rgb, cv2.COLOR_RGB2BGR) for im in (left, right)]
    return stereo, bgr[0], bgr[1]


def inside_box(p, centre, half_extents, yaw_rad: float, margin_m: float) -> bool:
    """Whether world point p is inside a box yawed about z, grown by margin_m."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    d = np.asarray(p, float) - np.asarray(centre, float)
    local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])
    return bool(np.all(np.abs(local) <= np.asarray(half_extents) + margin_m))


def yaw_of(quaternion_xyzw) -> float:
    x, y, z, w = quaternion_xyzw
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


# ---------------------------------------------------------------------------------------------- models


def test_the_demo_objects_have_learned_models(models):
    assert set(DEMO_OBJECTS) <= set(models)
    assert all(models[n].shape == "sphere" for n in ("orange_ball", "blue_ball", "purple_ball"))
    assert all(models[n].shape == "blob" for n in ("green_box", "yellow_table", "chair"))
    for name in DEMO_OBJECTS:
        assert "learn-sim" in models[name].source
        assert models[name].n_pixels > 10_000


def test_learn_sim_rewrites_models_that_match_the_committed_ones(tmp_path, models):
    config = LearnSimConfig(seeds=(None,), distances_m=(1.5, 3.0), azimuths_rad=(0.3,))
    result = learn_sim(config, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"{n}.json" for n in DEMO_OBJECTS)
    for name in DEMO_OBJECTS:
        assert result.views_used[name] >= 2
        assert result.hits[name] == result.views_used[name], name
        assert result.false_hits[name] == 0, name
        assert result.confused[name] == 0, name  # identities apart: never on another object's pixels
        fresh, committed = result.models[name].hist, models[name].hist
        assert cv2.compareHist(fresh, committed, cv2.HISTCMP_CORREL) > 0.9, name
        assert result.models[name].floor_size_m == models[name].floor_size_m, name  # the catalogue's


def test_learn_sim_names_the_scene_objects_when_one_is_missing(tmp_path):
    with pytest.raises(NotFoundError, match=r"no object 'red_cube'.*orange_ball"):
        learn_sim(LearnSimConfig(objects=("red_cube",), seeds=(None,)), tmp_path)


def test_unknown_object_is_an_invalid_request_listing_the_known_names(models):
    with pytest.raises(InvalidRequestError, match="unknown object 'purple_cube'") as e:
        object_model(models, "purple_cube")
    assert all(n in e.value.message for n in DEMO_OBJECTS)
    assert set(DEMO_OBJECTS) <= set(e.value.details["valid"])
    with pytest.raises(InvalidRequestError, match="learn-sim"):
        object_model({}, "orange_ball")


def test_unknown_stereo_pair_and_method_are_invalid_requests(robot):
    with pytest.raises(InvalidRequestError, match=r"no stereo pair 'front'.*\['narrow', 'wide'\]"):
        head_stereo(robot, robot.q_half_sitting, "front", 640, 480)
    with pytest.raises(InvalidRequestError, match="q must have shape"):
        head_stereo(robot, np.zeros(5), "wide", 640, 480)
    with pytest.raises(InvalidRequestError, match="stereo method 'laser'"):
        localize_config(LocalizeConfig(), "laser")


def test_camera_matrix_with_corner_origin_is_shifted_to_pixel_centres(robot):
    """sim/render and the robot models put pixel (i, j)'s centre at (j + 0.5, i + 0.5); vision at (j, i)."""
    from sim.cameras import project

    K = robot.cameras["wide_left"].K
    intr = CameraIntrinsics.from_matrix(K, 640, 480)
    assert (intr.cx, intr.cy) == (K[0, 2] - 0.5, K[1, 2] - 0.5)
    p_camera = np.array([[0.31, -0.12, 2.2]])
    uv_sim = project(p_camera, np.eye(4), K)[0]
    np.testing.assert_allclose(intr.project(p_camera)[0], uv_sim - 0.5, atol=1e-12)
    with pytest.raises(InvalidRequestError, match="3x3"):
        CameraIntrinsics.from_matrix(np.eye(2), 640, 480)


# ---------------------------------------------------------------------------------------------- sim renders


def test_models_find_the_ball_box_and_table_in_sim_renders(ball_fetch, models):
    truth = ball_fetch.ground_truth()
    stereo, left, right = look(ball_fetch)  # ahead: the box with the balls, 3.4 m away
    ball = locate_object(models, "orange_ball", stereo, left, right)
    # 3.4 m away: 0.1 px of disparity is 1.7 cm of depth; the 2.5 m goal (3 cm) still holds.
    assert np.linalg.norm(np.subtract(ball.position_world, truth["orange_ball"].position)) < 0.03
    box = locate_object(models, "green_box", stereo, left, right)
    gt = truth["green_box"]
    half = np.asarray(gt.size_m) / 2
    assert inside_box(box.position_world, gt.position, half, yaw_of(gt.quaternion), margin_m=0.05)
    assert box.method == "centroid" and box.left.border_sides == ("bottom",)  # cut at the bottom: still

    stereo, left, right = look(ball_fetch, pan_rad=-0.785, tilt_rad=0.2)  # right: the table, 3.4 m away
    table = locate_object(models, "yellow_table", stereo, left, right)
    gt = truth["yellow_table"]
    sx, sy, height = gt.size_m
    centre = np.asarray(gt.position) + np.array([0.0, 0.0, height / 2])
    assert inside_box(table.position_world, centre, (sx / 2, sy / 2, height / 2), yaw_of(gt.quaternion), 0.1)
    assert table.confidence > 0.3


def test_objects_are_not_found_in_images_without_them(models):
    """The robot alone: looking ahead at the floor and down at its own (grey, blue, red) body."""
    from sim.world import World

    with World(ROBOT, "empty") as world:
        for pan, tilt in ((0.0, 0.0), (0.0, 0.785), (0.785, 0.785), (-0.785, 0.785)):
            stereo, left, right = look(world, pan_rad=pan, tilt_rad=tilt)
            for name in DEMO_OBJECTS:
                with pytest.raises(NotFoundError, match="not in view") as e:
                    locate_object(models, name, stereo, left, right)
                assert e.value.details["reason"] == "not_in_view", (name, pan, tilt)


def test_only_the_table_model_fires_on_the_table(ball_fetch, models):
    stereo, left, right = look(ball_fetch, pan_rad=-0.785, tilt_rad=0.2)  # the table and the brown chair
    locate_object(models, "yellow_table", stereo, left, right)
    # The chair beside it is found too (an obstacle the supervisor's map needs), where it stands.
    chair = locate_object(models, "chair", stereo, left, right)
    truth = ball_fetch.ground_truth()["chair"].position
    assert np.linalg.norm(np.subtract(chair.position_world[:2], truth[:2])) < 0.3
    for name in ("orange_ball", "green_box"):
        with pytest.raises(NotFoundError) as e:
            locate_object(models, name, stereo, left, right)
        assert e.value.details["reason"] == "not_in_view", name


def test_the_ball_model_ignores_the_red_disk(models):
    """footsteps_reach: the orange ball on a grey stand 2 m ahead, a red disk on the floor before it."""
    from sim.world import World

    with World(ROBOT, "footsteps_reach") as world:
        stereo, left, right = look(world, tilt_rad=0.35)
        ball = locate_object(models, "orange_ball", stereo, left, right)
        error_m = np.linalg.norm(
            np.subtract(ball.position_world, world.ground_truth()["orange_ball"].position)
        )
    assert error_m < 0.01


def test_close_to_the_table_its_silhouette_edges_give_the_depth(ball_fetch, models):
    """0.9 m from the table it is cut by both side borders and its faces have no texture to correlate."""
    gt = ball_fetch.ground_truth()["yellow_table"]
    yaw = math.atan2(gt.position[1], gt.position[0])
    q = ball_fetch.state().q.copy()
    q[:2] = np.asarray(gt.position[:2]) - 0.9 * np.array([math.cos(yaw), math.sin(yaw)])
    q[3:7] = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    ball_fetch.pyrobot.reset(q)
    try:
        stereo, left, right = look(ball_fetch, tilt_rad=0.6)
        table = locate_object(models, "yellow_table", stereo, left, right)
    finally:
        ball_fetch.pyrobot.reset(ball_fetch.robot.q_half_sitting)
    assert {"left", "right"} <= set(table.left.border_sides) and table.method == "edges"
    sx, sy, height = gt.size_m
    centre = np.asarray(gt.position) + np.array([0.0, 0.0, height / 2])
    assert inside_box(table.position_world, centre, (sx / 2, sy / 2, height / 2), yaw_of(gt.quaternion), 0.05)


def test_edge_disparity_skips_edges_on_the_image_border():
    from vision.stereo import edge_disparity_median

    disc = np.zeros((40, 40), bool)
    cv2.circle(disc.view(np.uint8), (20, 20), 15, 1, -1)
    # Right image: the disc 7 px further left; both edges of its 31 rows count.
    d, n = edge_disparity_median(disc, (100, 50, 40, 40), disc, (93, 50, 40, 40), 640)
    assert d == 7.0 and n == 2 * 31
    # A bar cut by the left border of both images: only its right edges count.
    bar_left, bar_right = np.zeros((20, 30), bool), np.zeros((20, 30), bool)
    bar_left[:, :25], bar_right[:, :19] = True, True
    d, n = edge_disparity_median(bar_left, (0, 50, 30, 20), bar_right, (0, 50, 30, 20), 640)
    assert (d, n) == (6.0, 20)
    # The same bar cut by the left image's measurement window (CamShift's box of a big object close by)
    # at its last column: that edge is not the contour either (the footprint's outline skips it alike).
    with pytest.raises(NotFoundError, match="edge stereo"):
        edge_disparity_median(bar_left[:, :23], (0, 50, 23, 20), bar_right, (0, 50, 30, 20), 640)
    bar = np.ones((20, 25), bool)
    with pytest.raises(NotFoundError, match="edge stereo") as e:  # cut by both borders: no edge left
        edge_disparity_median(bar, (0, 50, 25, 20), bar, (0, 50, 25, 20), 25)
    assert e.value.details["reason"] == "no_disparity"


def test_a_black_image_is_not_found(robot, models):
    stereo = head_stereo(robot, robot.q_half_sitting, "wide", 640, 480)
    black = np.zeros((480, 640, 3), np.uint8)
    for name in DEMO_OBJECTS:
        with pytest.raises(NotFoundError) as e:
            locate_object(models, name, stereo, black, black)
        assert e.value.details["reason"] == "not_in_view"


@pytest.fixture(scope="module")
def placements():
    """8 seeded sim placements of the ball at each distance (the benchmark draws 30 with another seed)."""
    return list(sim_source(n_per_distance=8, distances_m=tuple(GOALS_CM), seed=7))


@pytest.mark.parametrize("distance_m", list(GOALS_CM))
def test_ball_localization_error_is_within_the_goals(placements, models, robot, distance_m):
    errors_cm = []
    for s in placements:
        if s.distance_m != distance_m:
            continue
        stereo = head_stereo(robot, robot.q_half_sitting, "wide", 640, 480)  # rig only; pose from the sample
        loc = locate_object(
            models,
            "orange_ball",
            type(stereo)(stereo.name, stereo.pair, stereo.rig, s.T_world_left_camera),
            s.left_bgr,
            s.right_bgr,
        )
        errors_cm.append(100.0 * np.linalg.norm(np.asarray(loc.position_world) - s.ball_world))
        assert loc.method == "centroid"
        assert abs(loc.size_m[0] - 0.1) < 0.02  # the ball's diameter
    assert len(errors_cm) == 8
    assert np.median(errors_cm) <= GOALS_CM[distance_m]
    assert max(errors_cm) <= 3.0 * GOALS_CM[distance_m]


# --------------------------------------------------------------------------------------------- looking around


def test_head_joints_are_found_with_the_sign_that_looks_down(robot):
    head = head_joints(robot)
    assert (head.pan, head.tilt) == ("HEAD_JOINT0", "HEAD_JOINT1")
    q = robot.q_half_sitting.copy()
    q[robot.joint_index(head.tilt).idx_q] = head.tilt_sign * 0.3
    gaze = robot.camera_pose(q, "wide_left").rotation[:, 2]
    assert gaze[2] == pytest.approx(-math.sin(0.3), abs=1e-6)  # 0.3 rad below the horizon


@pytest.mark.parametrize("name", ["hrp2_like", "talos"])
def test_scan_sweeps_the_pan_range_with_overlapping_views_and_turns_cover_the_circle(name):
    robot = load_robot(name)
    head = head_joints(robot)
    angles = scan_angles(robot, overlap=0.25)
    pans = sorted({p for p, _ in angles})
    tilts = {t for _, t in angles}
    assert pans[0] == pytest.approx(head.pan_limits[0]) and pans[-1] == pytest.approx(head.pan_limits[1])
    assert np.all(np.diff(pans) <= 0.75 * head.hfov_rad + 1e-9)
    assert len(angles) == len(pans) * len(tilts) == len(set(angles))
    assert all(head.tilt_limits[0] <= t <= head.tilt_limits[1] for t in tilts)
    assert angles[0][0] == pytest.approx(pans[min(range(len(pans)), key=lambda k: abs(pans[k]))])
    # Body headings (start + offsets), each widened by what the head sees: no gap around the circle.
    coverage = head.pan_limits[1] - head.pan_limits[0] + head.hfov_rad
    headings = sorted([0.0, *turn_offsets(robot)])
    gaps = np.diff([*headings, headings[0] + 2.0 * math.pi])
    assert np.all(gaps < coverage)


def test_head_trajectory_moves_only_the_head_within_its_speed(robot):
    q0 = robot.q_half_sitting
    q = head_trajectory(robot, q0, 0.6, 0.4, max_speed_rad_s=1.0)
    head = head_joints(robot)
    ip, it = robot.joint_index(head.pan).idx_q, robot.joint_index(head.tilt).idx_q
    np.testing.assert_array_equal(q[0], q0)
    assert (q[-1, ip], q[-1, it]) == pytest.approx((0.6, 0.4))
    others = np.delete(q, [ip, it], axis=1)
    np.testing.assert_array_equal(others, np.repeat(np.delete(q0, [ip, it])[None], len(q), axis=0))
    assert np.abs(np.diff(q[:, [ip, it]], axis=0)).max() / 0.005 <= 1.0 + 1e-9
    with pytest.raises(InvalidRequestError, match=r"HEAD_JOINT0 = 2\.000 rad is outside its limits"):
        head_trajectory(robot, q0, 2.0, 0.0)


def test_scanning_the_head_finds_the_out_of_view_table(models):
    """The supervisor's loop, with the sim world in place of the bus: not in view, scan until found."""
    from sim.world import World

    with World(ROBOT, "ball_fetch") as world:
        robot = world.robot

        def locate_now():
            left, right = world.render("wide", 640, 480)
            stereo = head_stereo(robot, world.state().q, "wide", 640, 480)
            bgr = [cv2.cvtColor(im.rgb, cv2.COLOR_RGB2BGR) for im in (left, right)]
            return locate_object(models, "yellow_table", stereo, *bgr)

        with pytest.raises(NotFoundError) as e:
            locate_now()
        assert e.value.details["reason"] == "not_in_view"
        found, visited = None, 0
        for pan, tilt in scan_angles(robot):
            result = world.execute(head_trajectory(robot, world.state().q, pan, tilt), hold_s=0.1)
            assert result.outcome == "completed", result.message
            visited += 1
            try:
                found = locate_now()
                break
            except NotFoundError as e:
                assert e.details["reason"] == "not_in_view"
        assert found is not None and visited <= 3
        gt = world.ground_truth()["yellow_table"]
        assert np.linalg.norm(np.subtract(found.position_world[:2], gt.position[:2])) < 0.6
