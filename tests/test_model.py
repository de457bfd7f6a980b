"""Robot model invariants for both robots, in pinocchio and in pybullet (DIRECT), and standing."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from services.errors import InvalidRequestError
from services.model import load_robot, robot_names
from services.model.generate_urdf import DEFAULT_URDF_PATH, urdf_text
from services.model.geometry import segment_distance
from services.model.ground import convex_hull_ccw, signed_distance
from services.model.params import _BOUND_KEYS, params_from_dict
from services.model.pybullet_robot import PybulletRobot

ROBOTS = ["hrp2_like", "talos"]


@pytest.fixture
def client():
    cid = p.connect(p.DIRECT)
    p.setGravity(0.0, 0.0, -9.81, physicsClientId=cid)
    yield cid
    p.disconnect(cid)


def _add_ground(cid: int) -> int:
    plane = p.createMultiBody(
        0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid), physicsClientId=cid
    )
    p.changeDynamics(plane, -1, lateralFriction=1.0, physicsClientId=cid)
    return plane


def _random_q(robot, rng: np.random.Generator) -> np.ndarray:
    q = robot.q_half_sitting.copy()
    lo = robot.q_lower[7:]
    hi = robot.q_upper[7:]
    q[7:] = lo + (hi - lo) * rng.uniform(0.1, 0.9, size=lo.shape)
    q[:3] = rng.uniform(-1.0, 1.0, 3) + np.array([0.0, 0.0, 1.5])
    quat = rng.normal(size=4)
    q[3:7] = quat / np.linalg.norm(quat)
    return q


# ----------------------------------------------------------------------------------------- generator
def test_generated_urdf_is_committed_and_up_to_date():
    assert DEFAULT_URDF_PATH.read_text(encoding="utf-8") == urdf_text(), (
        "services/model/data/hrp2_like.urdf is stale: run scripts/gen_hrp2_urdf.py"
    )


def test_hrp2_urdf_every_link_has_an_inertial_and_only_primitives():
    root = ET.parse(DEFAULT_URDF_PATH).getroot()
    for link in root.findall("link"):
        mass = link.find("inertial/mass")
        assert mass is not None and float(mass.get("value")) > 0.0, link.get("name")
    assert root.findall(".//mesh") == []
    actuated = [j for j in root.findall("joint") if j.get("type") != "fixed"]
    assert len(actuated) == 30
    for j in actuated:
        lim = j.find("limit")
        assert float(lim.get("lower")) < float(lim.get("upper"))
        assert float(lim.get("velocity")) > 0.0 and float(lim.get("effort")) > 0.0


def test_unknown_robot_lists_valid_names():
    with pytest.raises(InvalidRequestError, match="hrp2_like") as err:
        load_robot("hrp3")
    assert err.value.details["valid"] == robot_names()


def test_a_service_model_option_is_checked_at_start_up():
    from services.model.options import with_model
    from sim.config import SimConfig

    assert with_model(SimConfig(), None).model == "hrp2_like"
    assert with_model(SimConfig(), "talos").model == "talos"
    with pytest.raises(InvalidRequestError, match="valid robots are"):
        with_model(SimConfig(), "hrp3")


def test_hrp2_dimensions():
    robot = load_robot("hrp2_like")
    assert robot.total_mass_kg == pytest.approx(58.0, abs=1e-9)
    assert len(robot.joint_names) == 30
    q = robot.q_half_sitting
    data = robot.forward(q)
    # waist at 0.6487 m in half-sitting (CONVENTIONS §5)
    assert q[2] == pytest.approx(0.6487, abs=2e-4)

    def pos(frame: str) -> np.ndarray:
        return data.oMf[robot.frame_id(frame)].translation

    hip, knee, ankle = (data.oMi[robot.model.getJointId(f"RLEG_JOINT{i}")].translation for i in (2, 3, 4))
    thigh = knee - hip
    assert np.hypot(thigh[0], thigh[2]) == pytest.approx(0.30, abs=1e-9)
    assert np.linalg.norm(ankle - knee) == pytest.approx(0.30, abs=1e-9)
    assert ankle[2] - pos("right_sole")[2] == pytest.approx(0.105, abs=1e-9)
    assert robot.sole_size_m == (0.24, 0.14)
    for side in ("left", "right"):
        assert robot.gripper_joint(side) not in robot.arm_joints(side)
        assert len(robot.arm_joints(side)) == 6


def test_hrp2_height_is_1_54_m_in_pybullet(client):
    robot = load_robot("hrp2_like")
    q = robot.neutral()
    q = robot.place_on_ground(q, 0.0, 0.0, 0.0)
    sim = PybulletRobot(robot, client, q)
    top = max(
        p.getAABB(sim.body_id, link, physicsClientId=client)[1][2]
        for link in range(-1, p.getNumJoints(sim.body_id, physicsClientId=client))
    )
    assert top == pytest.approx(1.54, abs=0.005)


# ----------------------------------------------------------------------------------------- both robots
@pytest.mark.parametrize("name", ROBOTS)
def test_half_sitting_soles_flat_on_ground_and_com_over_support(name):
    robot = load_robot(name)
    q = robot.q_half_sitting
    assert not q.flags.writeable
    assert np.all(q[7:] >= robot.q_lower[7:]) and np.all(q[7:] <= robot.q_upper[7:])
    for side in ("left", "right"):
        T = robot.sole_pose(q, side)
        assert T.translation[2] == pytest.approx(0.0, abs=1e-9)
        np.testing.assert_allclose(T.rotation, np.eye(3), atol=1e-9)
    assert robot.mid_feet_pose(q) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    polygon = robot.support_polygon(q)
    com = robot.com(q)
    assert -signed_distance(com[:2], polygon)[0] > 0.05
    assert com[2] == pytest.approx(robot.params.com_height_m, abs=0.01)


@pytest.mark.parametrize("name", ROBOTS)
def test_frames_cameras_and_grippers(name):
    robot = load_robot(name)
    q = robot.q_half_sitting
    data = robot.forward(q, robot.new_data())
    T_gaze = data.oMf[robot.frame_id(robot.frames.gaze)]
    np.testing.assert_allclose(T_gaze.rotation[:, 0], [1.0, 0.0, 0.0], atol=0.01)  # looks forward
    for pair_name, baseline in (("wide", 0.144), ("narrow", 0.058)):
        pair = robot.stereo_pairs[pair_name]
        assert pair.baseline_m == baseline
        T_l = data.oMf[robot.frame_id(robot.cameras[pair.left].frame)]
        T_r = data.oMf[robot.frame_id(robot.cameras[pair.right].frame)]
        # optical convention: z forward (= gaze x), x right, y down; right camera at -baseline along x_left
        np.testing.assert_allclose(T_l.rotation[:, 2], T_gaze.rotation[:, 0], atol=1e-9)
        np.testing.assert_allclose(T_l.rotation[:, 1], [0.0, 0.0, -1.0], atol=0.01)
        np.testing.assert_allclose(T_l.actInv(T_r.translation), [baseline, 0.0, 0.0], atol=1e-9)
        cam = robot.cameras[pair.left]
        small = cam.scaled(320, 240)
        assert small.hfov_rad == pytest.approx(cam.hfov_rad)
        assert small.K[0, 2] == 160.0
    for side in ("left", "right"):
        grasp = data.oMf[robot.frame_id(robot.frames.grasp(side))].translation
        assert np.sign(grasp[1]) == (1.0 if side == "left" else -1.0)
        assert 0.3 < grasp[2] < 1.0
        g = robot.params.gripper
        idx = robot.joint_index(robot.gripper_joint(side)).idx_q
        for value in (g.open_q, g.closed_q):
            assert robot.q_lower[idx] <= value <= robot.q_upper[idx]
    with pytest.raises(InvalidRequestError, match="'left' or 'right'"):
        robot.sole_pose(q, "middle")
    with pytest.raises(InvalidRequestError, match="valid joints"):
        robot.joint_index("NO_SUCH_JOINT")


@pytest.mark.parametrize("name", ROBOTS)
def test_capsules_do_not_collide_in_half_sitting(name):
    robot = load_robot(name)
    names = {c.name for c in robot.capsules}
    assert len(names) == len(robot.capsules)
    for a, b in robot.collision_pairs:
        assert a in names and b in names and a != b
    distances = robot.collision_pair_distances(robot.q_half_sitting)
    closest = min(distances, key=distances.get)
    assert distances[closest] > 0.0, f"{closest} penetrate by {-distances[closest]:.3f} m"
    # Some right-arm postures bring the hand/forearm into the body: the pair distances must see them.
    rng = np.random.default_rng(1)
    arm = [robot.joint_index(j).idx_q for j in robot.arm_joints("right")]
    found = set()
    for _ in range(300):
        q = robot.q_half_sitting.copy()
        q[arm] = rng.uniform(robot.q_lower[arm], robot.q_upper[arm])
        found |= {pair for pair, d in robot.collision_pair_distances(q).items() if d < 0.0}
    assert {pair for pair in found if pair[0] in ("r_hand", "r_forearm")}, found


@pytest.mark.parametrize("name", ROBOTS)
def test_placement_and_support_polygon(name):
    robot = load_robot(name)
    q = robot.half_sitting_at(1.5, -0.7, 2.5)
    assert robot.mid_feet_pose(q) == pytest.approx((1.5, -0.7, 2.5), abs=1e-9)
    for side in ("left", "right"):
        assert robot.sole_pose(q, side).translation[2] == pytest.approx(0.0, abs=1e-9)
    poly = robot.support_polygon(q)
    x, y = poly[:, 0], poly[:, 1]
    area = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    assert area > 0.0  # counter-clockwise
    single = robot.support_polygon(q, feet=("left",))
    assert 0.5 * float(
        np.sum(single[:, 0] * np.roll(single[:, 1], -1) - np.roll(single[:, 0], -1) * single[:, 1])
    ) == (pytest.approx(robot.sole_size_m[0] * robot.sole_size_m[1]))


@pytest.mark.parametrize("name", ROBOTS)
def test_pybullet_loads_same_joints_limits_and_mass(name, client):
    robot = load_robot(name)
    sim = PybulletRobot(robot, client)
    assert len(sim.joint_ids) == len(robot.joint_names)
    total = 0.0
    for link in range(-1, p.getNumJoints(sim.body_id, physicsClientId=client)):
        total += p.getDynamicsInfo(sim.body_id, link, physicsClientId=client)[0]
    assert total == pytest.approx(robot.total_mass_kg, abs=1e-6)
    for jid, jname in zip(sim.joint_ids, robot.joint_names, strict=True):
        info = p.getJointInfo(sim.body_id, int(jid), physicsClientId=client)
        assert info[1].decode() == jname
        idx = robot.joint_index(jname)
        assert info[8] == pytest.approx(robot.q_lower[idx.idx_q])
        assert info[9] == pytest.approx(robot.q_upper[idx.idx_q])
        assert info[11] == pytest.approx(robot.v_max[idx.idx_v])
    assert sim.link_index(robot.frames.left_sole) >= 0
    with pytest.raises(InvalidRequestError, match="no link"):
        sim.link_index("no_such_link")


@pytest.mark.parametrize("name", ROBOTS)
def test_pybullet_state_round_trip_and_frames_match(name, client):
    robot = load_robot(name)
    sim = PybulletRobot(robot, client)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = _random_q(robot, rng)
        v = rng.normal(size=robot.nv)
        sim.reset(q, v)
        q_back = sim.read_q()
        np.testing.assert_allclose(q_back[:3], q[:3], atol=1e-9)
        assert abs(float(np.dot(q_back[3:7], q[3:7]))) == pytest.approx(1.0, abs=1e-9)
        np.testing.assert_allclose(q_back[7:], q[7:], atol=1e-9)
        np.testing.assert_allclose(sim.read_v(), v, atol=1e-9)
        # pybullet link frames agree with pinocchio frames (sole: the foot link's frame is its parent joint).
        data = robot.forward(q, robot.new_data())
        for side in ("left", "right"):
            foot = sim.sole_links[side]
            state = p.getLinkState(sim.body_id, foot, computeForwardKinematics=1, physicsClientId=client)
            T_world_link = pin.XYZQUATToSE3(np.array([*state[4], *state[5]]))
            fid = robot.frame_id(robot.frames.sole(side))
            T_world_joint = data.oMi[robot.model.frames[fid].parentJoint]
            assert np.allclose(T_world_link.homogeneous, T_world_joint.homogeneous, atol=1e-6)


@pytest.mark.parametrize("name", ROBOTS)
def test_pybullet_feet_collide_through_a_flat_sole_box_at_the_sole_frame(name, client):
    """talos's foot mesh has a non-flat bottom: in pybullet (only) each foot collides through one box of
    the sole rectangle whose bottom face is the sole frame; hrp2_like's URDF foot already is such a box."""
    robot = load_robot(name)
    sim = PybulletRobot(robot, client)
    q = robot.q_half_sitting
    for side in ("left", "right"):
        link = sim.sole_links[side]
        shapes = p.getCollisionShapeData(sim.body_id, link, physicsClientId=client)
        assert [shape[2] for shape in shapes] == [p.GEOM_BOX]
        size = np.array(shapes[0][3])
        np.testing.assert_allclose(size[:2], robot.sole_size_m, atol=1e-9)
        # Box corners in the world: pybullet gives the shape pose in the link's inertial frame.
        state = p.getLinkState(sim.body_id, link, computeForwardKinematics=1, physicsClientId=client)
        T_world_inertial = pin.XYZQUATToSE3(np.array([*state[0], *state[1]]))
        T_world_box = T_world_inertial * pin.XYZQUATToSE3(np.array([*shapes[0][5], *shapes[0][6]]))
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        corners = (signs * size / 2) @ T_world_box.rotation.T + T_world_box.translation
        T_sole = robot.sole_pose(q, side)
        local = (corners - T_sole.translation) @ T_sole.rotation  # corners in the sole frame
        bottom = local[local[:, 2] < size[2] / 2]
        np.testing.assert_allclose(bottom[:, 2], 0.0, atol=1e-9)  # the bottom face is the sole
        half = np.broadcast_to(np.array(robot.sole_size_m) / 2, (4, 2))
        np.testing.assert_allclose(np.abs(bottom[:, :2]), half, atol=1e-9)
    if name == "talos":
        assert robot.pybullet_sole_box_m == 0.02 and robot.pybullet_solver_iterations == 50
        # The pinocchio model keeps the URDF's foot mesh.
        geoms = robot.build_geometry_model("collision").geometryObjects
        assert any(g.name.startswith("leg_left_6_link") and g.meshPath.endswith(".stl") for g in geoms)


def _stand(name: str, cid: int, duration_s: float = 10.0, dt_s: float = 1e-3) -> tuple[float, float]:
    """Max base tilt [deg] and max sole slip [m] while standing in half-sitting under position control."""
    robot = load_robot(name)
    p.setTimeStep(dt_s, physicsClientId=cid)
    _add_ground(cid)
    sim = PybulletRobot(robot, cid)
    q0 = robot.q_half_sitting
    sim.set_position_targets(q0)
    soles0 = {side: robot.sole_pose(q0, side).translation for side in ("left", "right")}
    tilt_deg, slip_m = 0.0, 0.0
    steps = round(duration_s / dt_s)
    for i in range(steps):
        p.stepSimulation(physicsClientId=cid)
        if i % 100 == 99 or i == steps - 1:
            q = sim.read_q()
            R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
            tilt_deg = max(tilt_deg, math.degrees(math.acos(min(1.0, R[2, 2]))))
            for side, p0 in soles0.items():
                slip = np.linalg.norm(robot.sole_pose(q, side).translation[:2] - p0[:2])
                slip_m = max(slip_m, float(slip))
    return tilt_deg, slip_m


@pytest.mark.parametrize("dt_s", [1e-3, 5e-3])
@pytest.mark.parametrize("name", ROBOTS)
def test_stands_in_half_sitting_for_10_s(name, dt_s, client):
    tilt_deg, slip_m = _stand(name, client, duration_s=10.0, dt_s=dt_s)
    assert tilt_deg < 0.3
    assert slip_m < 1e-3


def test_standing_detects_a_bad_posture(client):
    """The standing check can fail: with the hips bent far forward (CoM outside the soles) it falls."""
    robot = load_robot("hrp2_like")
    p.setTimeStep(1e-3, physicsClientId=client)
    _add_ground(client)
    q = robot.q_half_sitting.copy()
    for side in "RL":
        q[robot.joint_index(f"{side}LEG_JOINT4").idx_q] = -0.4189 + 0.5  # ankles pitched: body leans
    q = robot.place_on_ground(q, 0.0, 0.0, 0.0)
    sim = PybulletRobot(robot, client, q)
    sim.set_position_targets(q)
    for _ in range(2000):
        p.stepSimulation(physicsClientId=client)
    R = sim.base_pose().rotation
    assert math.degrees(math.acos(min(1.0, R[2, 2]))) > 5.0


# ----------------------------------------------------------------------------------------- grippers
@pytest.mark.parametrize(("shape", "radius_m"), [("ball", 0.05), ("bar", 0.012)])
def test_hrp2_gripper_holds_ball_and_bar(shape, radius_m, client):
    """At the held position the object rests on the fixed finger with the moving finger clear when open;
    the moving finger reaches it before the closed limit (so closing squeezes it)."""
    robot = load_robot("hrp2_like")
    sim = PybulletRobot(robot, client)
    side = "right"
    offset = robot.held_object_offset(side, radius_m)
    g = robot.params.gripper
    idx = robot.joint_index(robot.gripper_joint(side)).idx_q
    fixed_finger, moving_finger = sim.link_index("RARM_LINK5"), sim.link_index("RARM_LINK6")

    def distances(gripper_q: float) -> tuple[float, float]:
        q = robot.q_half_sitting.copy()
        q[idx] = gripper_q
        sim.reset(q)
        T = robot.frame_pose(q, robot.frames.grasp(side))
        centre = T.act(offset)
        if shape == "ball":
            col = p.createCollisionShape(p.GEOM_SPHERE, radius=radius_m, physicsClientId=client)
            orn = [0.0, 0.0, 0.0, 1.0]
        else:  # bar along the grasp frame x axis (across the closing direction y)
            col = p.createCollisionShape(p.GEOM_CYLINDER, radius=radius_m, height=0.3, physicsClientId=client)
            R = T.rotation @ pin.rpy.rpyToMatrix(0.0, math.pi / 2.0, 0.0)
            orn = pin.Quaternion(R).coeffs().tolist()
        body = p.createMultiBody(
            0, col, basePosition=centre.tolist(), baseOrientation=orn, physicsClientId=client
        )
        p.performCollisionDetection(physicsClientId=client)
        pts = p.getClosestPoints(sim.body_id, body, 0.3, physicsClientId=client)
        p.removeBody(body, physicsClientId=client)
        return (
            min(pt[8] for pt in pts if pt[3] == fixed_finger),
            min(pt[8] for pt in pts if pt[3] == moving_finger),
        )

    open_gap_m = 0.13
    d_fixed, d_moving = distances(g.open_q)
    assert d_fixed == pytest.approx(0.0, abs=1e-3)
    assert d_moving == pytest.approx(open_gap_m - 2.0 * radius_m, abs=1e-3)
    touching_q = g.open_q + (open_gap_m - 2.0 * radius_m)
    assert distances(touching_q)[1] == pytest.approx(0.0, abs=1e-3)
    assert touching_q < g.closed_q


# ----------------------------------------------------------------------------------------- helpers
def test_params_validation_messages():
    robot = load_robot("hrp2_like")
    raw = {
        "footstep_bounds": {k: getattr(robot.params.footstep_bounds, k) for k in _BOUND_KEYS}
        | {"dx_min_m": 0.3},
        "step_height_m": 0.05,
        "com_height_m": 0.75,
        "step_duration_s": 0.8,
        "double_support_s": 0.1,
        "manipulability_threshold": 1.5e-4,
        "ee_error_threshold_m": 4e-5,
        "fall_base_height_m": 0.4,
        "fall_tilt_rad": 0.5,
        "gripper": {"open_q": 0.0, "closed_q": 0.12},
    }
    with pytest.raises(InvalidRequestError, match="dx_min_m must be below dx_max_m"):
        params_from_dict(raw)
    raw["footstep_bounds"]["dx_min_m"] = -0.22
    assert params_from_dict(raw).footstep_bounds.dx_min_m == -0.22
    with pytest.raises(InvalidRequestError, match="unknown keys"):
        params_from_dict(raw | {"stepheight": 1.0})
    assert robot.params.manipulability_threshold == 1.5e-4
    assert robot.params.ee_error_threshold_m == 4e-5
    (dx, dy, dth) = robot.params.footstep_bounds.for_swing("right")
    assert dy == (-0.25, -0.07) and dx == (-0.22, 0.22)
    assert dth == pytest.approx((-math.pi / 4, 0.1))


def test_convex_hull_keeps_rectangle_corners_that_differ_by_float_noise():
    """A rectangle given twice (the second copy off by float noise) has a 4-vertex hull. The former
    monotone chain (cross product <= 1e-12 m^2 = collinear) dropped real corners next to pairs of
    near-duplicate points: here it returned 3 vertices, without the corner (1.1434, -2.0590)."""
    pts = np.array(
        [
            [1.1434142164861272, -1.9190459993194082],
            [1.143414216486128, -2.059045999319408],
            [1.1434142164861285, -2.0590459993194075],
            [1.1434142164861285, -1.9190459993194076],
            [1.3834142164861265, -1.9190459993194078],
            [1.3834142164861287, -2.0590459993194075],
            [1.3834142164861287, -1.9190459993194076],
            [1.3834142164861292, -2.0590459993194066],
        ]
    )
    hull = convex_hull_ccw(pts)
    assert hull.shape == (4, 2)
    for corner in ([1.1434, -1.9190], [1.1434, -2.0590], [1.3834, -2.0590], [1.3834, -1.9190]):
        assert np.abs(hull - corner).max(axis=1).min() < 1e-4
    rng = np.random.default_rng(11)
    for _ in range(300):
        yaw = rng.choice([0.0, math.pi / 2, math.pi, rng.uniform(-math.pi, math.pi)])
        c, s = math.cos(yaw), math.sin(yaw)
        corners = np.array([[0.12, 0.07], [-0.12, 0.07], [-0.12, -0.07], [0.12, -0.07]]) @ np.array(
            [[c, s], [-s, c]]
        ) + rng.uniform(-2.0, 2.0, 2)
        noisy = corners + rng.normal(0.0, 1e-15, corners.shape)
        hull = convex_hull_ccw(np.vstack([corners, noisy, corners.mean(axis=0)]))
        assert hull.shape == (4, 2)
        assert all(-signed_distance(pt, hull)[0] >= -1e-12 for pt in corners)


def test_geometry_helpers():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1.0, 1.0, size=(50, 2))
    hull = convex_hull_ccw(pts)
    for pt in pts:
        assert -signed_distance(pt, hull)[0] >= -1e-12
    assert -signed_distance(np.array([5.0, 0.0]), hull)[0] < 0.0
    # segment distance against dense sampling
    for _ in range(20):
        a0, a1, b0, b1 = rng.normal(size=(4, 3))
        s = np.linspace(0.0, 1.0, 201)
        pa = a0 + s[:, None] * (a1 - a0)
        pb = b0 + s[:, None] * (b1 - b0)
        brute = np.min(np.linalg.norm(pa[:, None, :] - pb[None, :, :], axis=2))
        d = segment_distance(a0, a1, b0, b1)
        assert d <= brute + 1e-12
        assert d == pytest.approx(brute, abs=0.02)


def test_ground_rectangle_and_bounds():
    """services.model.ground: the rectangle's frame round-trips, its signed distance is the Euclidean
    distance outside and minus the distance to the boundary inside; the robot's stepping bounds carry
    its own sole."""
    from services.model.ground import FootstepBounds, Rectangle, SolePose, sole_corners, sole_pose_at

    rng = np.random.default_rng(3)
    rect = Rectangle((1.0, -2.0), (0.6, 0.2), 0.7)
    pts = rng.uniform(-3.0, 3.0, (200, 2))
    np.testing.assert_allclose(rect.to_world(rect.to_local(pts)), pts, atol=1e-12)
    corners = rect.corners()
    d = rect.signed_distance(pts)
    for pt, dist in zip(pts, d, strict=True):
        on_edges = [
            np.linalg.norm(pt - (a + np.clip(np.dot(pt - a, b - a) / np.dot(b - a, b - a), 0, 1) * (b - a)))
            for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True)
        ]
        assert abs(dist) == pytest.approx(min(on_edges), abs=1e-12)
        assert (dist < 0) == bool(np.all(np.abs(rect.to_local(pt)[0]) < [0.3, 0.1]))
    np.testing.assert_array_equal(sole_corners(SolePose(1.0, -2.0, 0.7), 0.6, 0.2), corners)
    for name in ("hrp2_like", "talos"):
        robot = load_robot(name)
        bounds = FootstepBounds.from_robot(robot)
        assert (bounds.sole_length_m, bounds.sole_width_m) == tuple(robot.sole_size_m)
        left = sole_pose_at(robot, robot.q_half_sitting, "left")
        assert left.y_m > 0.0 and abs(left.yaw_rad) < 1e-9
