"""Every IK task's Jacobian against central finite differences on seeded random configurations, on
both robots and on a model with a virtual footprint chain prepended (planar x, y, theta joints before
the robot's free flyer, as the footstep planner builds it)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from services.errors import InvalidRequestError
from services.ik import (
    Capsule,
    ComPositionTask,
    ComSupportPolygonTask,
    FeetFlatTask,
    FootOutsideDiskTask,
    FrameOrientationTask,
    FramePoseTask,
    FramePositionTask,
    GazeTask,
    JointLimitsTask,
    PostureTask,
    SelfCollisionTask,
    compute_kinematics,
)
from services.ik.geometry import closest_points_segments, unit_clip
from services.ik.tasks.ground_clearance import GroundClearanceTask
from services.model import load_robot

ROBOTS = ("hrp2_like", "talos")
H = 1e-6  # finite-difference step along each tangent direction
# Central differences: truncation ~ h^2 |F'''| and round-off ~ eps |F| / h; kinematic values are
# O(1) m or rad with O(10) third derivatives, so the error is below 1e3 (h^2 + eps / h) ~ 2e-7.
FD_TOL = 1e3 * (H**2 + np.finfo(float).eps / H)


def random_configurations(robot, count: int, seed: int) -> list[np.ndarray]:
    """Half-sitting moved along random tangent directions, joints clipped into their limits."""
    rng = np.random.default_rng(seed)
    model = robot.model
    q_hs = np.array(robot.q_half_sitting)
    out = []
    for _ in range(count):
        q = pin.integrate(model, q_hs, rng.normal(scale=0.4, size=model.nv))
        q[7:] = np.clip(q[7:], robot.q_lower[7:] + 1e-3, robot.q_upper[7:] - 1e-3)
        out.append(q)
    return out


def finite_difference_jacobian(task, model: pin.Model, data: pin.Data, q: np.ndarray) -> np.ndarray:
    """dF/dq by central differences along every tangent direction (pin.integrate, so free flyers
    and planar joints are differentiated on their manifold)."""
    columns = []
    for i in range(model.nv):
        step = np.zeros(model.nv)
        step[i] = H
        values = []
        for sign in (1.0, -1.0):
            q_i = pin.integrate(model, q, sign * step)
            compute_kinematics(model, data, q_i, True)
            values.append(task.compute_error(q_i, data))
        columns.append((values[0] - values[1]) / (2.0 * H))
    return np.column_stack(columns)


def check_jacobian(task, model: pin.Model, q: np.ndarray) -> None:
    data = model.createData()
    compute_kinematics(model, data, q, True)
    F, J = task.compute(q, data)
    assert J.shape == (F.shape[0], model.nv)
    np.testing.assert_allclose(task.compute_error(q, data), F)
    np.testing.assert_allclose(task.compute_jacobian(q, data), J)
    J_fd = finite_difference_jacobian(task, model, data, q)
    np.testing.assert_allclose(J, J_fd, atol=FD_TOL, rtol=0)


def tasks_for(robot, q: np.ndarray, rng: np.random.Generator) -> list:
    """One instance of every task, targets drawn at random around the robot."""
    model = robot.model
    frames = robot.frames
    data = robot.new_data()
    pin.framesForwardKinematics(model, data, q)
    target = rng.normal(size=3)
    R_target = pin.exp3(rng.normal(size=3))
    T_target = pin.SE3(R_target, target)
    polygon = robot.support_polygon(robot.q_half_sitting)
    all_joints = [model.names[j] for j in range(1, model.njoints)]
    sole = data.oMf[model.getFrameId(frames.left_sole)]
    near_disk = sole.translation[:2] + rng.normal(scale=0.05, size=2)
    far_disk = sole.translation[:2] + np.array([0.6, 0.3])
    return [
        FramePositionTask(model, frames.right_grasp, target),
        FramePositionTask(model, frames.right_grasp, target, mask=(True, False, True)),
        FrameOrientationTask(model, frames.left_grasp, R_target),
        FrameOrientationTask(model, frames.left_grasp, R_target, mask=(False, True, True)),
        FramePoseTask(model, frames.left_sole, T_target),
        FramePoseTask(model, frames.right_sole, T_target, mask=(False, False, True, True, True, False)),
        ComPositionTask(model, target),
        ComSupportPolygonTask(model, 0.02, polygon_world_xy=polygon, all_edges=True),
        ComSupportPolygonTask(
            model,
            0.02,
            sole_frames=(frames.left_sole, frames.right_sole),
            sole_size_m=robot.sole_size_m,
            all_edges=True,
        ),
        JointLimitsTask(model, margin_rad=0.05),
        PostureTask(model, robot.q_half_sitting),
        PostureTask(model, robot.q_half_sitting, joint_names=all_joints),
        GazeTask(model, frames.gaze, target, axis_in_camera=(1.0, 0.0, 0.0)),
        GazeTask(model, frames.gaze, target, axis_in_camera=(1.0, 0.0, 0.0), form="direction"),
        GazeTask(model, frames.gaze, target, axis_in_camera=(0.3, -0.5, 1.0), form="direction"),
        SelfCollisionTask(
            model, robot.capsules, robot.collision_pairs, activation_m=100.0, max_rows_per_pair=1
        ),
        FootOutsideDiskTask(model, frames.left_sole, robot.sole_size_m, near_disk, 0.1),
        FootOutsideDiskTask(model, frames.left_sole, robot.sole_size_m, far_disk, 0.1),
        FeetFlatTask(model, (frames.left_sole, frames.right_sole), ground_height_m=0.01),
        GroundClearanceTask(
            model,
            [(frames.right_grasp, (0.02, -0.03, 0.05)), (frames.left_sole, (0.1, 0.05, 0.0))],
            clearance_m=0.02,
            activation_m=100.0,
        ),
    ]


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_task_jacobians_match_finite_differences(robot_name: str) -> None:
    robot = load_robot(robot_name)
    rng = np.random.default_rng(7)
    for q in random_configurations(robot, 2, seed=11):
        for task in tasks_for(robot, q, rng):
            try:
                check_jacobian(task, robot.model, q)
            except AssertionError as error:
                raise AssertionError(f"{robot_name}: {task!r}: {error}") from None


def footprint_chain_model(robot) -> tuple[pin.Model, np.ndarray]:
    """The robot behind a virtual footprint: prismatic x, prismatic y, revolute z, then the free flyer.
    Returns the model and a configuration (footprint moved, robot in half-sitting)."""
    chain = pin.Model()
    inertia = pin.Inertia.Zero()
    j_x = chain.addJoint(
        0,
        pin.JointModelPX(),
        pin.SE3.Identity(),
        "footprint_x",
        np.array([1e3]),
        np.array([1e3]),
        np.array([-2.0]),
        np.array([2.0]),
    )
    chain.appendBodyToJoint(j_x, inertia, pin.SE3.Identity())
    j_y = chain.addJoint(
        j_x,
        pin.JointModelPY(),
        pin.SE3.Identity(),
        "footprint_y",
        np.array([1e3]),
        np.array([1e3]),
        np.array([-2.0]),
        np.array([2.0]),
    )
    chain.appendBodyToJoint(j_y, inertia, pin.SE3.Identity())
    j_t = chain.addJoint(
        j_y,
        pin.JointModelRZ(),
        pin.SE3.Identity(),
        "footprint_theta",
        np.array([1e3]),
        np.array([1e3]),
        np.array([-math.pi]),
        np.array([math.pi]),
    )
    chain.appendBodyToJoint(j_t, inertia, pin.SE3.Identity())
    frame = chain.addFrame(pin.Frame("footprint", j_t, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    model = pin.appendModel(chain, robot.model, frame, pin.SE3.Identity())
    q = np.concatenate(([0.3, -0.2, 0.4], robot.q_half_sitting))
    return model, q


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_task_jacobians_on_a_model_with_a_virtual_footprint_chain(robot_name: str) -> None:
    robot = load_robot(robot_name)
    model, q = footprint_chain_model(robot)
    frames = robot.frames
    rng = np.random.default_rng(3)
    q = pin.integrate(model, q, rng.normal(scale=0.2, size=model.nv))
    target = np.array([1.0, 0.5, 0.8])
    for task in (
        FramePositionTask(model, frames.right_grasp, target),
        FramePoseTask(model, frames.left_sole, pin.SE3(pin.exp3(rng.normal(size=3)), target)),
        ComSupportPolygonTask(
            model,
            0.02,
            sole_frames=(frames.left_sole, frames.right_sole),
            sole_size_m=robot.sole_size_m,
            all_edges=True,
        ),
        GazeTask(model, frames.gaze, target, axis_in_camera=(1.0, 0.0, 0.0)),
        FootOutsideDiskTask(model, "footprint", robot.sole_size_m, (0.4, -0.1), 0.2),
        PostureTask(model, q, joint_names=["footprint_x", "footprint_y", "footprint_theta"]),
        JointLimitsTask(model),
    ):
        check_jacobian(task, model, q)


def test_self_collision_rows_per_pair() -> None:
    """Two parallel capsules side by side: the closest points are not unique, so up to three rows
    (closest pair + endpoint pairs) hold the pair apart; a skew pair far away gives none."""
    robot = load_robot("hrp2_like")
    model = robot.model
    q = np.array(robot.q_half_sitting)
    data = model.createData()
    compute_kinematics(model, data, q, True)
    frame = robot.frames.torso
    capsules = [
        Capsule("a", frame, (0.0, 0.0, 0.0), (0.0, 0.0, 0.3), 0.05),
        Capsule("b", frame, (0.12, 0.0, 0.0), (0.12, 0.0, 0.3), 0.05),
        Capsule("far", robot.frames.left_sole, (0.0, 0.0, 0.0), (0.1, 0.0, 0.0), 0.02),
    ]
    task = SelfCollisionTask(model, capsules, pairs=[(0, 1), (0, 2)], margin_m=0.01, activation_m=0.05)
    G, J = task.compute(q, data)
    assert 2 <= G.shape[0] <= 3
    # surface gap 0.12 - 0.1 = 0.02 > margin 0.01: every row satisfied, by exactly 0.01
    np.testing.assert_allclose(G, -0.01, atol=1e-12)
    assert task.value_of(G) == 0.0
    np.testing.assert_allclose(task.distances(data), [0.02, task.distances(data)[1]])
    # Capsules on one frame do not move relative to each other: zero Jacobian rows.
    np.testing.assert_allclose(J, 0.0, atol=1e-12)


def test_support_polygon_rows_face_the_com() -> None:
    """Eq. (11): rows only for the edges facing C, plus every violated edge."""
    robot = load_robot("talos")
    model = robot.model
    q = np.array(robot.q_half_sitting)
    data = model.createData()
    compute_kinematics(model, data, q, True)
    c = data.com[0][:2]
    square = c + np.array([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]])
    task = ComSupportPolygonTask(model, 0.02, polygon_world_xy=square)
    G, _ = task.compute(q, data)
    assert G.shape == (4,)  # centred in a square: all four edges face it
    np.testing.assert_allclose(G, 0.02 - 0.1)
    # C left of the square: the left edge (violated, inward normal +x) and the right edge (C's
    # perpendicular foot lies on it too); the top and bottom edges do not face C.
    task.set_polygon(square + np.array([0.25, 0.0]))
    G, J = task.compute(q, data)
    assert G.shape == (2,)
    order = np.argsort(G)
    np.testing.assert_allclose(G[order], [0.02 - 0.35, 0.02 + 0.15])
    np.testing.assert_allclose(J[order], np.vstack((data.Jcom[0], -data.Jcom[0])), atol=1e-12)


def test_inequality_value_function_is_zero_when_satisfied() -> None:
    robot = load_robot("talos")
    model = robot.model
    task = FramePositionTask(model, robot.frames.right_grasp, (0.0, 0.0, 0.0), lower=-0.1, upper=0.1)
    assert task.kind == "inequality"
    assert task.value_of(np.array([0.05, -0.05, 0.0])) == 0.0
    assert task.value_of(np.array([0.13, -0.14, 0.0])) == pytest.approx(math.hypot(0.03, 0.04))
    upper_only = FramePositionTask(model, robot.frames.right_grasp, (0.0, 0.0, 0.0), upper=0.1)
    assert upper_only.value_of(np.array([-5.0, 0.05, 0.0])) == 0.0  # eq. (6): no lower bound
    assert upper_only.value_of(np.array([0.13, -0.14, 0.5])) == pytest.approx(math.hypot(0.03, 0.4))
    equality = FramePositionTask(model, robot.frames.right_grasp, (0.0, 0.0, 0.0))
    assert equality.kind == "equality"
    assert equality.value_of(np.array([3.0, 4.0, 0.0])) == pytest.approx(5.0)


def test_task_arguments_are_checked() -> None:
    model = load_robot("talos").model
    with pytest.raises(InvalidRequestError, match="unknown frame 'no_such_frame'"):
        FramePositionTask(model, "no_such_frame", (0, 0, 0))
    with pytest.raises(InvalidRequestError, match="gain must be a positive"):
        FramePositionTask(model, "right_grasp", (0, 0, 0), gain=0.0)
    with pytest.raises(InvalidRequestError, match="target must be 3 finite numbers"):
        FramePositionTask(model, "right_grasp", (0, 0))
    with pytest.raises(InvalidRequestError, match="axis mask selects no axis"):
        FramePositionTask(model, "right_grasp", (0, 0, 0), mask=(False, False, False))
    with pytest.raises(InvalidRequestError, match="rotation matrix"):
        FrameOrientationTask(model, "right_grasp", np.ones((3, 3)))
    # a reflection, non-finite, not orthonormal within 1e-6
    for not_a_rotation in (np.diag([1.0, 1.0, -1.0]), np.full((3, 3), np.nan), 1.00002 * np.eye(3)):
        with pytest.raises(InvalidRequestError, match="rotation matrix"):
            FrameOrientationTask(model, "right_grasp", not_a_rotation)
    FrameOrientationTask(model, "right_grasp", np.diag([-1.0, -1.0, 1.0]))  # a half turn is one
    with pytest.raises(InvalidRequestError, match="either polygon_world_xy"):
        ComSupportPolygonTask(model, 0.02)
    with pytest.raises(InvalidRequestError, match="unknown joint 'elbow'"):
        PostureTask(model, pin.neutral(model), joint_names=["elbow"])
    with pytest.raises(InvalidRequestError, match="unknown capsules"):
        SelfCollisionTask(model, load_robot("talos").capsules, pairs=[("l_hand", "tail")])


def test_unit_clip_is_np_clip_bit_for_bit() -> None:
    """The two-ufunc clamp used in the hot paths gives np.clip's values, signed zeros and NaN."""
    special = np.array([-0.0, 0.0, 0.5, 1.0, 1.5, -1.0, np.nan, np.inf, -np.inf, 1e-300, -1e-300])
    rng = np.random.default_rng(3)
    for n in (1, 5, 8, 17, 64):  # short arrays and SIMD-sized ones
        x = rng.choice(special, n)
        expected, got = np.clip(x, 0.0, 1.0), unit_clip(x)
        np.testing.assert_array_equal(got, expected)
        assert np.array_equal(np.signbit(got), np.signbit(expected))


def test_closest_points_of_segments_against_dense_sampling() -> None:
    """Closest points of random, parallel and point segments: parameters in [0, 1] and a distance
    no larger than the best of a dense grid over both segments (to the grid's resolution)."""
    rng = np.random.default_rng(5)
    p0, p1 = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    q0, q1 = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    q1[:10] = q0[:10] + 2.0 * (p1[:10] - p0[:10])  # parallel pairs
    p1[10:15] = p0[10:15]  # point first segment
    q1[15:20] = q0[15:20]  # point second segment
    p1[20:23], q1[20:23] = p0[20:23], q0[20:23]  # two points
    for lo, hi in ((0, 40), (0, 10), (10, 20), (20, 23)):  # mixed, then each kind on its own
        sl = slice(lo, hi)
        s, t = closest_points_segments(p0[sl], p1[sl], q0[sl], q1[sl])
        assert np.all((s >= 0.0) & (s <= 1.0) & (t >= 0.0) & (t <= 1.0))
        A = p0[sl] + s[:, None] * (p1[sl] - p0[sl])
        B = q0[sl] + t[:, None] * (q1[sl] - q0[sl])
        found = np.linalg.norm(B - A, axis=1)
        grid = np.linspace(0.0, 1.0, 201)
        P = p0[sl, None] + grid[None, :, None] * (p1[sl] - p0[sl])[:, None]
        Q = q0[sl, None] + grid[None, :, None] * (q1[sl] - q0[sl])[:, None]
        best = np.linalg.norm(P[:, :, None] - Q[:, None], axis=-1).min(axis=(1, 2))
        step = (np.linalg.norm(p1[sl] - p0[sl], axis=1) + np.linalg.norm(q1[sl] - q0[sl], axis=1)) / 200
        assert np.all(found <= best + 1e-12)
        assert np.all(found >= best - step)


def test_ground_clearance_rows_only_near_the_ground_and_the_solver_keeps_the_points_above_it() -> None:
    """A point below its clearance has G > 0; a point farther than the activation distance has no
    row; the solver's inequality (eq. 4 with eq. 13's form) keeps the points at the clearance while
    a task pulls the hand into the floor."""
    from services.ik import FramePositionTask, HierarchicalSolver, Level

    robot = load_robot("hrp2_like")
    model, data = robot.model, robot.new_data()
    q = np.array(robot.q_half_sitting)
    pin.framesForwardKinematics(model, data, q)
    z_hand = data.oMf[model.getFrameId(robot.frames.right_grasp)].translation[2]
    near = GroundClearanceTask(
        model, [(robot.frames.right_grasp, (0.0, 0.0, 0.0))], clearance_m=z_hand + 0.01
    )
    compute_kinematics(model, data, q, False)
    G, J = near.compute(q, data)
    assert G.shape == (1,) and G[0] == pytest.approx(0.01) and J.shape == (1, model.nv)
    far = GroundClearanceTask(model, [(robot.frames.right_grasp, (0.0, 0.0, 0.0))], clearance_m=0.01)
    assert far.compute(q, data)[0].shape == (0,)
    assert far.heights(data)[0] == pytest.approx(z_hand)
    with pytest.raises(InvalidRequestError, match="needs at least one point"):
        GroundClearanceTask(model, [])
    # the hand pulled 0.2 m below the floor at the lower priority (1 cm per step, within the activation
    # distance) stops at the clearance
    corner = (robot.frames.right_grasp, (0.0, 0.0, -0.03))
    clearance = GroundClearanceTask(model, [corner], clearance_m=0.05, gain=0.5)
    feet = [
        FramePoseTask(model, f, robot.frame_pose(q, f))
        for f in (robot.frames.left_sole, robot.frames.right_sole)
    ]
    target = data.oMf[model.getFrameId(robot.frames.right_grasp)].translation + np.array([0.25, 0.0, -1.0])
    levels = [
        Level((*feet, clearance)),
        Level((FramePositionTask(model, robot.frames.right_grasp, target, max_step=0.01),)),
    ]
    solver = HierarchicalSolver(model)
    lowest = math.inf
    for _ in range(150):
        q = pin.integrate(model, q, solver.solve(levels, q))
        pin.framesForwardKinematics(model, data, q)
        lowest = min(lowest, float(clearance.heights(data)[0]))
    # (the rows are linear: a step may overshoot by a few millimetres, then the damper pushes back)
    assert lowest >= 0.05 - 3e-3 and float(clearance.heights(data)[0]) == pytest.approx(0.05, abs=2e-3)
