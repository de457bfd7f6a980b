"""The simulated world (sim/): scenes, camera math, standing, trajectory execution, falls, collisions,
grasping, rendering. Real pybullet in DIRECT mode, no bus (the service is tested in test_sim_service.py)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from services.errors import InvalidRequestError, NotFoundError
from services.footsteps import scenarios
from services.model.specs import Intrinsics
from sim import motions
from sim.cameras import look_at, project, projection_matrix, view_matrix
from sim.config import SimConfig
from sim.scene import COLOURS, ObjectSpec, available_scenes, layout, load_scene, parse_scene, with_object
from sim.world import World

pytestmark = pytest.mark.integration

SHIPPED = ("ball_fetch", "bar_carry", "empty", "footsteps_pickup", "footsteps_reach")


# ------------------------------------------------------------------------------------------------ scenes
def test_shipped_scenes_load_and_lay_out():
    assert set(SHIPPED) <= set(available_scenes())
    for name in SHIPPED:
        scene = load_scene(name)
        nominal = layout(scene)
        assert [o.name for o in nominal.objects] == scene.names()
        assert layout(scene, seed=7) == layout(scene, seed=7)  # reproducible


def test_ball_fetch_has_the_demo_objects_with_distinct_hues():
    scene = load_scene("ball_fetch")
    assert scene.object("orange_ball").colour == COLOURS["orange"]
    assert scene.object("green_box").colour == COLOURS["green"]
    assert scene.object("yellow_table").colour == COLOURS["yellow"]
    hues = [
        cv2.cvtColor(np.uint8([[[int(255 * c) for c in COLOURS[n][:3]]]]), cv2.COLOR_RGB2HSV)[0, 0, 0]
        for n in ("orange", "green", "yellow", "blue", "purple")
    ]
    gaps = [
        min(abs(int(a) - int(b)), 180 - abs(int(a) - int(b)))
        for i, a in enumerate(hues)
        for b in hues[i + 1 :]
    ]
    assert min(gaps) >= 10  # OpenCV hue units (2 deg): at least 20 deg apart
    nominal = layout(scene)
    box = nominal.object("green_box")
    assert math.hypot(*box.position[:2]) > 3.0  # far from the robot
    for ball in ("orange_ball", "blue_ball", "purple_ball"):
        assert nominal.object(ball).position[2] == pytest.approx(box.top_z_m + 0.05)


def test_randomized_balls_stay_on_the_box_and_apart():
    scene = load_scene("ball_fetch")
    nominal = layout(scene)
    moved = 0
    for seed in range(30):
        lay = layout(scene, seed=seed)
        box = lay.object("green_box")
        c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
        balls = [lay.object(n) for n in ("orange_ball", "blue_ball", "purple_ball")]
        for ball in balls:
            dx, dy = ball.position[0] - box.position[0], ball.position[1] - box.position[1]
            assert abs(c * dx + s * dy) <= 0.25 - 0.05 + 1e-9
            assert abs(-s * dx + c * dy) <= 0.30 - 0.05 + 1e-9
        for i, a in enumerate(balls):
            for b in balls[i + 1 :]:
                assert math.dist(a.position, b.position) >= 0.1 - 1e-9
        moved += lay.object("green_box").position != nominal.object("green_box").position
    assert moved == 30


def test_footstep_scenes_match_the_paper_set_ups():
    reach = layout(load_scene("footsteps_reach"))
    ball, disk = reach.object("orange_ball"), reach.object("obstacle_disk")
    assert math.hypot(*ball.position[:2]) == pytest.approx(2.05, abs=0.1)
    assert 0.6 < ball.position[2] < 0.9  # table height
    assert 0.3 < disk.position[0] < ball.position[0] - 0.3  # the disk lies between robot and ball
    pickup = layout(load_scene("footsteps_pickup"))
    obj, disk = pickup.object("orange_block"), pickup.object("obstacle_disk")
    assert abs(obj.position[1]) < 0.01 and abs(obj.position[0]) < 0.1  # between the feet (soles +-0.12 m)
    np.testing.assert_allclose(obj.position, scenarios.PICKUP_OBJECT_M, atol=1e-9)  # the planner's target
    assert disk.position[:2] == obj.position[:2]
    bar = layout(load_scene("bar_carry")).object("bar").spec
    assert (bar.length_m, 2 * bar.radius_m, bar.mass_kg) == (1.8, 0.024, 0.5)  # motion autonomy paper §2


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"objects": [{"name": "a", "kind": "pyramid"}]}, "kind must be one of"),
        (
            {
                "objects": [
                    {"name": "a", "kind": "ball", "radius": 0.1},
                    {"name": "a", "kind": "ball", "radius": 0.1},
                ]
            },
            "used twice",
        ),
        ({"objects": [{"name": "a", "kind": "ball", "radius": 0.1, "on": "b"}]}, "unknown keys"),
        (
            {"objects": [{"name": "a", "kind": "ball", "radius": 0.1, "on_top_of": "b"}]},
            "not declared before",
        ),
        ({"objects": [{"name": "a", "kind": "box"}]}, "needs 'size'"),
        ({"objects": [{"name": "a", "kind": "ball", "radius": 0.1, "colour": "mauve"}]}, "unknown colour"),
        ({"objects": [{"name": "a", "kind": "ball", "radius": -1}]}, "must be positive"),
        ({"floor": {"colour": "grey", "texture": "wood"}}, "unknown keys"),
    ],
)
def test_scene_validation_messages(doc, message):
    with pytest.raises(InvalidRequestError, match=message):
        parse_scene(doc, "test.yaml")


def test_unknown_scene_lists_the_available_ones():
    with pytest.raises(NotFoundError, match="ball_fetch"):
        load_scene("no_such_scene")


@pytest.mark.parametrize("model", ["hrp2_like", "talos"])
def test_every_shipped_scene_starts_at_rest_without_contacts(model):
    with World(model, "empty") as world:
        for name in SHIPPED:
            lay = world.reset(name, seed=11)
            world.hold(0.5)
            assert world.collisions() == [], name
            assert not world.fallen()
            truth = world.ground_truth()
            for obj in lay.objects:  # nothing fell off its support or rolled away
                moved = np.linalg.norm(truth[obj.name].position - np.array(obj.position))
                assert moved < 5e-3, (name, obj.name)


# ------------------------------------------------------------------------------------------------ cameras
def test_projection_matrix_reproduces_the_pinhole_model():
    rng = np.random.default_rng(0)
    intr = Intrinsics(640, 480, 500.0, 510.0, 300.0, 250.0)
    T_world_camera = look_at(np.array([0.3, -0.2, 1.4]), np.array([3.0, 0.5, 0.6]))
    view = np.array(view_matrix(T_world_camera)).reshape(4, 4).T
    proj = np.array(projection_matrix(intr, 0.05, 30.0)).reshape(4, 4).T
    points = (
        T_world_camera[:3, :3]
        @ np.vstack([rng.uniform(-1, 1, 20), rng.uniform(-1, 1, 20), rng.uniform(1, 8, 20)])
        + T_world_camera[:3, 3:4]
    )
    clip = proj @ view @ np.vstack([points, np.ones(20)])
    ndc = clip[:2] / clip[3]
    uv_gl = np.stack([(ndc[0] + 1) * intr.width_px / 2, (1 - ndc[1]) * intr.height_px / 2], axis=1)
    np.testing.assert_allclose(uv_gl, project(points.T, T_world_camera, intr.K), atol=1e-9)


def test_points_behind_the_camera_do_not_project():
    T = look_at(np.zeros(3), np.array([1.0, 0.0, 0.0]))
    uv = project(np.array([[-1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]), T, Intrinsics(64, 48, 50, 50, 32, 24).K)
    assert np.isnan(uv[0]).all() and uv[1] == pytest.approx([32, 24])


# ------------------------------------------------------------------------------------------------ robot
@pytest.mark.slow
@pytest.mark.parametrize("model", ["hrp2_like", "talos"])
def test_stands_in_half_sitting_for_10_s_without_drifting(model):
    with World(model, "empty") as world:
        start = world.state()
        soles0 = {s: world.robot.sole_pose(start.q, s).translation for s in ("left", "right")}
        world.hold(10.0)
        end = world.state()
        assert end.sim_time_s - start.sim_time_s == pytest.approx(10.0)
        assert np.linalg.norm(end.q[:3] - start.q[:3]) < 1.5e-3  # base drift [m]
        assert math.degrees(world.tilt_rad()) < 0.3
        for side, p0 in soles0.items():
            assert np.linalg.norm(world.robot.sole_pose(end.q, side).translation[:2] - p0[:2]) < 1.5e-3
        assert world.collisions() == []


def test_solver_iterations_are_the_robots_unless_configured():
    import pybullet as p

    assert SimConfig().solver_iterations is None
    for model, expected in (("hrp2_like", 20), ("talos", 50)):
        with World(model, "empty") as world:
            assert world.solver_iterations == expected == world.robot.pybullet_solver_iterations
            params = p.getPhysicsEngineParameters(physicsClientId=world.client)
            assert params["numSolverIterations"] == expected
    with World("talos", "empty", config=SimConfig(solver_iterations=30)) as world:
        assert p.getPhysicsEngineParameters(physicsClientId=world.client)["numSolverIterations"] == 30
    with pytest.raises(InvalidRequestError, match=r"solver_iterations must be an integer >= 1 .* got 0"):
        SimConfig(solver_iterations=0)


@pytest.mark.parametrize("model", ["hrp2_like", "talos"])
def test_squat_and_rise_tracks_within_1_cm(model):
    with World(model, "empty") as world:
        q0 = world.state().q
        traj = motions.squat_trajectory(world.robot, q0, depth_m=0.08, down_s=1.2, pause_s=0.3, up_s=1.2)
        assert q0[2] - traj[:, 2].min() == pytest.approx(0.08)
        result = world.execute(traj, hold_s=0.2)
        assert result.outcome == "completed", result.message
        assert result.samples_executed == len(traj)
        assert result.duration_s == pytest.approx((len(traj) - 1) * 0.005 + 0.2)
        assert result.base_error_m < 0.01  # waist height (task space) within 1 cm
        assert result.tracking_error_rad < 0.01
        assert result.foot_slip_m < 1e-3
        assert abs(result.state.q[2] - q0[2]) < 2e-3


def test_a_lean_over_the_toes_is_reported_as_a_fall():
    with World("hrp2_like", "empty") as world:
        traj = motions.lean_forward_trajectory(world.robot, world.state().q)
        result = world.execute(traj)
        assert result.outcome == "fell", result.message
        assert "fell" in result.message
        assert result.fall_tilt_rad > world.robot.params.fall_tilt_rad or (
            result.fall_base_height_m < world.robot.params.fall_base_height_m
        )
        assert result.samples_executed < len(traj)
        assert world.fallen()
        world.reset()
        assert not world.fallen()


def test_arm_hitting_a_box_is_a_collision_naming_the_links():
    scene = with_object(
        load_scene("empty"),
        ObjectSpec(name="crate", kind="box", colour=COLOURS["blue"], xy=(0.45, -0.3), size_m=(0.3, 0.3, 1.0)),
    )
    with World("hrp2_like", scene) as world:
        q0 = world.state().q
        swing = motions.joint_motion(world.robot, q0, {"RARM_JOINT0": -1.2}, 1.0)
        result = world.execute(swing)
        assert result.outcome == "collision", result.message
        assert result.collisions and {c.other for c in result.collisions} == {"crate"}
        assert all(c.robot_link.startswith("RARM_LINK") for c in result.collisions)
        assert "crate" in result.message and "RARM_LINK" in result.message
        assert result.samples_executed < len(swing)


def test_backing_out_of_a_collision_may_touch_what_it_leaves_until_the_contact_breaks():
    """The arm stopped on the crate and pressing on it: holding there is a collision; the executed part
    played backward with the crate ``leaving`` completes; swinging back into it after leaving it is a
    collision again."""
    scene = with_object(
        load_scene("empty"),
        ObjectSpec(name="crate", kind="box", colour=COLOURS["blue"], xy=(0.45, -0.3), size_m=(0.3, 0.3, 1.0)),
    )
    with World("hrp2_like", scene) as world:
        swing = motions.joint_motion(world.robot, world.state().q, {"RARM_JOINT0": -1.2}, 1.0)
        stopped = world.execute(swing)
        assert stopped.outcome == "collision"
        back = swing[: stopped.samples_executed][::-1]
        assert (
            world.execute(np.repeat(back[:1], 3, axis=0)).outcome == "collision"
        )  # holding still in contact: a collision
        result = world.execute(back, leaving=("crate",))
        assert result.outcome == "completed", result.message
        assert not world.collisions()
        there_and_back = np.vstack([back[::-1], back])
        assert world.execute(there_and_back, leaving=("crate",)).outcome == "collision"


def test_trajectory_validation_messages():
    with World("hrp2_like", "empty") as world:
        q0 = world.state().q
        with pytest.raises(InvalidRequestError, match="shape"):
            world.execute(np.zeros((10, 5)))
        far = q0.copy()
        far[world.robot.joint_index("RLEG_JOINT3").idx_q] += 0.5
        with pytest.raises(InvalidRequestError, match=r"RLEG_JOINT3.*plan from the current state"):
            world.execute(far[None, :])
        beyond = q0.copy()
        beyond[world.robot.joint_index("HEAD_JOINT0").idx_q] = 10.0
        with pytest.raises(InvalidRequestError, match=r"HEAD_JOINT0.*outside its limits"):
            world.execute(np.vstack([q0, beyond]))
        with pytest.raises(InvalidRequestError, match="multiple of the physics step"):
            world.execute(q0[None, :], dt_s=0.0025)
        with pytest.raises(NotFoundError, match="no_such_object"):
            world.execute(q0[None, :], allowed_contacts=("no_such_object",))


def test_a_joint_played_with_less_effort_yields_for_that_execution_only():
    """The right arm held forward (its weight about 13 N m on the shoulder): with 5 % of the shoulder's
    120 N m it sags; the next execution has the full effort again and lifts it back."""
    with World("hrp2_like", "empty") as world:
        shoulder = world.robot.joint_index("RARM_JOINT0").idx_q
        lift = motions.joint_motion(world.robot, world.state().q, {"RARM_JOINT0": -1.5}, 1.0)
        assert world.execute(lift).outcome == "completed"
        held = np.repeat(lift[-1:], 200, axis=0)  # 1 s
        assert world.execute(held, effort_scale={"RARM_JOINT0": 0.05}).outcome == "completed"
        sagged = world.state().q
        assert sagged[shoulder] - lift[-1][shoulder] > 0.1
        back = motions.joint_motion(world.robot, sagged, {"RARM_JOINT0": -1.5}, 1.0)
        assert world.execute(back, hold_s=0.5).outcome == "completed"
        assert abs(world.state().q[shoulder] - lift[-1][shoulder]) < 0.02
        with pytest.raises(InvalidRequestError, match="not a body joint"):
            world.execute(held[:2], effort_scale={"RARM_GRIPPER": 0.5})
        with pytest.raises(InvalidRequestError, match=r"in \(0, 1\]"):
            world.execute(held[:2], effort_scale={"RARM_JOINT0": 0.0})


# ------------------------------------------------------------------------------------------------ grasping
def _ball_on_stand_scene():
    scene = load_scene("empty")
    scene = with_object(
        scene,
        ObjectSpec(name="stand", kind="table", colour=COLOURS["grey"], xy=(5.0, 0.0), size_m=(0.2, 0.2, 0.9)),
    )
    return with_object(
        scene,
        ObjectSpec(
            name="ball", kind="ball", colour=COLOURS["orange"], xy=(5.0, 2.0), radius_m=0.05, mass_kg=0.1
        ),
    )


def test_grasp_lift_and_release_a_ball():
    with World("hrp2_like", _ball_on_stand_scene()) as world:
        robot = world.robot
        reach = motions.joint_motion(robot, world.state().q, {"RARM_JOINT0": -0.6, "RARM_JOINT3": -0.9}, 1.0)
        assert world.execute(reach, hold_s=0.2).outcome == "completed"
        # Put the ball between the open fingers, resting on the stand.
        centre = robot.frame_pose(world.state().q, robot.frames.grasp("right")).translation
        world.set_object_pose("stand", [centre[0], centre[1], centre[2] - 0.05 - 0.9])
        world.set_object_pose("ball", centre)
        world.step(5)
        assert world.collisions() == []

        closed = world.gripper("right", "close")
        assert (closed.outcome, closed.held) == ("grasped", "ball")
        assert closed.finger_q < robot.params.gripper.closed_q - 0.05  # stopped on the ball
        assert world.ground_truth()["ball"].held_by == "right"

        lift = motions.joint_motion(robot, world.state().q, {"RARM_JOINT0": -0.9}, 1.0)
        result = world.execute(lift, hold_s=0.2)
        assert result.outcome == "completed", result.message
        ball = world.ground_truth()["ball"].position
        hand = robot.frame_pose(world.state().q, robot.frames.grasp("right")).translation
        assert ball[2] > centre[2] + 0.1  # lifted off the stand
        assert np.linalg.norm(ball - hand) < 0.03  # and still in the hand

        opened = world.gripper("right", "open")
        assert (opened.outcome, opened.held, opened.released) == ("released", "", "ball")
        world.hold(1.0)
        assert world.ground_truth()["ball"].position[2] < ball[2] - 0.1  # fell out of the open hand
        assert world.ground_truth()["ball"].held_by == ""


def test_closing_on_nothing_is_not_grasped():
    with World("hrp2_like", "empty") as world:
        result = world.gripper("left", "close")
        assert (result.outcome, result.held) == ("not_grasped", "")
        assert result.finger_q == pytest.approx(world.robot.params.gripper.closed_q, abs=2e-3)
        assert world.gripper("left", "open").outcome == "opened"
        with pytest.raises(InvalidRequestError, match="side must be"):
            world.gripper("middle", "close")
        with pytest.raises(InvalidRequestError, match=r"open.*close"):
            world.gripper("left", "squeeze")


# ------------------------------------------------------------------------------------------------ images
@pytest.mark.parametrize(("scene", "size"), [("footsteps_reach", (640, 480)), ("ball_fetch", (320, 240))])
def test_ball_appears_where_ground_truth_projects_it(scene, size):
    with World("hrp2_like", scene) as world:
        ball = world.ground_truth()["orange_ball"]
        for pair in ("wide", "narrow"):
            left, right = world.render(pair, *size, depth=True, segmentation=True)
            baseline = world.robot.stereo_pairs[pair].baseline_m
            T_left_right = np.linalg.inv(left.T_world_camera) @ right.T_world_camera
            assert T_left_right[:3, 3] == pytest.approx([baseline, 0.0, 0.0], abs=1e-9)
            for image in (left, right):
                assert image.rgb.shape == (size[1], size[0], 3) and image.rgb.dtype == np.uint8
                mask = image.segmentation == world.bodies["orange_ball"]
                assert image.labels[world.bodies["orange_ball"]] == "orange_ball"
                assert mask.sum() > 10
                rows, cols = np.nonzero(mask)
                centroid = np.array([cols.mean() + 0.5, rows.mean() + 0.5])
                expected = project(ball.position, image.T_world_camera, image.intrinsics.K)[0]
                assert np.linalg.norm(centroid - expected) < 2.0
                # The pixels are orange: red high, blue low.
                r, g, b = image.rgb[mask].mean(axis=0)
                assert r > 150 and b < 60 and g < r
                depth_centre = (np.linalg.inv(image.T_world_camera) @ np.r_[ball.position, 1.0])[2]
                assert image.depth_m[mask].min() == pytest.approx(depth_centre - 0.05, abs=0.01)


def test_render_rejects_unknown_cameras_and_sizes():
    with World("hrp2_like", "empty") as world:
        with pytest.raises(NotFoundError, match="wide"):
            world.render("fisheye")
        with pytest.raises(InvalidRequestError, match="image size"):
            world.render("wide", 0, 480)
        single = world.render("narrow_right", 160, 120)
        assert [im.name for im in single] == ["narrow_right"]
        assert single[0].depth_m is None and single[0].segmentation is None


def test_snapshot_is_a_png_of_the_requested_size():
    with World("hrp2_like", "ball_fetch") as world:
        for viewpoint in ("overview", "front", "top"):
            png = world.snapshot(viewpoint, 320, 240)
            assert png[:8] == b"\x89PNG\r\n\x1a\n"
            image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
            assert image.shape == (240, 320, 3)
        with pytest.raises(InvalidRequestError, match="overview"):
            world.snapshot("moon")
