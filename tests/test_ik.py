"""The prioritized IK solver: strict priorities, inequalities, hard limits, infeasible levels,
exactness against a direct QP of each level, level options and the iteration loop, on both robots."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from proxsuite import proxqp

from services.errors import InvalidRequestError
from services.ik import (
    ArmManipulability,
    Capsule,
    ComSupportPolygonTask,
    FramePoseTask,
    FramePositionTask,
    GazeTask,
    HierarchicalSolver,
    JointLimitsTask,
    Level,
    PostureTask,
    SelfCollisionTask,
    SolverConfig,
    compute_kinematics,
    dof_mask,
    link_mass_weights,
    manipulability,
    task_value,
)
from services.model import load_robot

ROBOTS = ("hrp2_like", "talos")


def standing(robot):
    """(q0, feet level, CoM level, data at q0) for the robot standing in half-sitting."""
    model = robot.model
    q0 = np.array(robot.q_half_sitting)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q0)
    feet = Level(
        tuple(
            FramePoseTask(model, frame, pin.SE3(data.oMf[model.getFrameId(frame)]))
            for frame in (robot.frames.left_sole, robot.frames.right_sole)
        ),
        name="feet",
    )
    com = Level((ComSupportPolygonTask(model, 0.02, polygon_world_xy=robot.support_polygon(q0)),), name="com")
    return q0, feet, com, data


def frame_position(robot, data, frame: str) -> np.ndarray:
    return np.array(data.oMf[robot.model.getFrameId(frame)].translation)


def reach_target(robot, data) -> np.ndarray:
    """A point 0.3 m in front of the chest, at the height of the chest minus 0.1 m."""
    chest = frame_position(robot, data, robot.frames.torso)
    hand = frame_position(robot, data, robot.frames.right_grasp)
    return np.array([chest[0] + 0.3, hand[1], chest[2] - 0.1])


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_reach_and_look_converges(robot_name: str) -> None:
    """Feet fixed > CoM in the polygon > hand on a target > gaze at it > rest posture."""
    robot = load_robot(robot_name)
    model = robot.model
    q0, feet, com, data = standing(robot)
    target = reach_target(robot, data)
    levels = [
        feet,
        com,
        Level((FramePositionTask(model, robot.frames.right_grasp, target, max_step=0.2),), name="hand"),
        Level(
            (GazeTask(model, robot.frames.gaze, target, axis_in_camera=(1.0, 0.0, 0.0), max_step=0.2),),
            name="gaze",
        ),
        # a rest posture pulled at half speed: full-speed steps of a low level far from its optimum
        # keep disturbing the levels above through second-order effects
        Level((PostureTask(model, q0, gain=0.5),), name="posture", tol=math.inf),
    ]
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    result = solver.run(levels, q0, tol=1e-4, max_iters=50)
    assert result.converged, (result.reason, result.residuals)
    assert result.reason == "converged"
    assert result.values.shape == (result.iterations + 1, 5)
    assert result.task_values.shape == (result.iterations + 1, 6)
    assert np.all(result.residuals[:4] <= 1e-4)
    # the gaze axis points at the target (not away from it)
    compute_kinematics(model, data, result.q, True)
    T_gaze = data.oMf[model.getFrameId(robot.frames.gaze)]
    to_target = target - T_gaze.translation
    assert T_gaze.rotation[:, 0] @ to_target / np.linalg.norm(to_target) > 0.999
    hand = frame_position(robot, data, robot.frames.right_grasp)
    assert np.linalg.norm(hand - target) <= 1e-4


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_lower_level_cannot_change_a_higher_levels_achieved_value(robot_name: str) -> None:
    """Level 1 is infeasible (the hand asked at two points at once): its least-squares compromise
    must come out the same whether or not a conflicting level 2 (the hand at a third point) and a
    posture level sit below it."""
    robot = load_robot(robot_name)
    model = robot.model
    q0, feet, _, data = standing(robot)
    hand = robot.frames.right_grasp
    p = frame_position(robot, data, hand)
    top = Level(
        (
            FramePositionTask(model, hand, p + np.array([0.1, 0.0, 0.0]), name="a"),
            FramePositionTask(model, hand, p + np.array([0.0, 0.1, 0.0]), name="b"),
        ),
        name="conflict",
        damping=1e-9,  # (undamped, to compare with the plain least-squares compromise below)
        error_damping=0.0,
    )
    below = Level((FramePositionTask(model, hand, p + np.array([0.0, 0.0, 0.2]), name="c"),), name="below")
    posture = Level((PostureTask(model, q0 + 0.0),), name="posture")
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    q = pin.integrate(model, q0, np.random.default_rng(2).normal(scale=0.05, size=model.nv))
    J = pin.computeFrameJacobian(model, solver.data, q, model.getFrameId(hand), pin.LOCAL_WORLD_ALIGNED)[:3]
    dq_alone = solver.solve([feet, top], q)
    dq_all = solver.solve([feet, top, below, posture], q)
    reports = solver.last_report
    np.testing.assert_allclose(J @ dq_all, J @ dq_alone, atol=1e-9)
    # The compromise is the least-squares one: the hand steps to the midpoint of a and b (from q,
    # a and b as seen from q), residual |a - b| / sqrt(2); the hand's motion is then fully decided,
    # so level 2 keeps its whole error.
    compute_kinematics(model, data, q, True)
    p_q = frame_position(robot, data, hand)
    a, b, c = (t.target_world_m for t in (*top.tasks, below.tasks[0]))
    np.testing.assert_allclose(J @ dq_all, 0.5 * (a + b) - p_q, atol=1e-5)
    assert reports[1].residual == pytest.approx(np.linalg.norm(a - b) / math.sqrt(2.0), rel=1e-4)
    assert reports[2].residual == pytest.approx(np.linalg.norm(0.5 * (a + b) - c), rel=1e-4)


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_inequality_slack_is_fixed_for_the_levels_below(robot_name: str) -> None:
    """An inequality level that cannot be met (the hand above a height it cannot reach in one
    step because of a velocity limit) keeps its optimal violation whatever the levels below ask."""
    robot = load_robot(robot_name)
    model = robot.model
    q0, feet, _, data = standing(robot)
    hand = robot.frames.right_grasp
    p = frame_position(robot, data, hand)
    high = Level(
        (FramePositionTask(model, hand, p, mask=(False, False, True), lower=0.5, name="high"),), name="high"
    )
    down = Level((FramePositionTask(model, hand, p - np.array([0.0, 0.0, 0.5]), name="down"),), name="down")
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper, dq_max=0.05)
    J = pin.computeFrameJacobian(model, solver.data, q0, model.getFrameId(hand), pin.LOCAL_WORLD_ALIGNED)[2]
    dq_alone = solver.solve([feet, high], q0)
    violation_alone = solver.last_report[1].residual
    dq_all = solver.solve([feet, high, down], q0)
    assert violation_alone > 0.1  # the velocity limit really prevents meeting it
    assert solver.last_report[1].residual == pytest.approx(violation_alone, abs=1e-7)
    assert J @ dq_all == pytest.approx(J @ dq_alone, abs=1e-7)
    assert np.all(np.abs(dq_all) <= 0.05 + 1e-9)


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_joint_limits_are_never_crossed(robot_name: str) -> None:
    """Reaching far beyond the arm drives joints into their limits: no iterate crosses them (the
    plain solve + integrate loop, without the clipping that ``run`` adds)."""
    robot = load_robot(robot_name)
    model = robot.model
    q0, feet, com, data = standing(robot)
    chest = frame_position(robot, data, robot.frames.torso)
    target = np.array([chest[0] + 0.9, 0.0, 0.3])
    reach = Level((FramePositionTask(model, robot.frames.right_grasp, target, max_step=0.2),), name="hand")
    levels = [feet, com, reach, Level((PostureTask(model, q0),), name="posture")]
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    q = q0
    # (1e-12: the rounding of q + dq when dq takes a joint exactly onto its limit)
    lower, upper = robot.q_lower[7:] - 1e-12, robot.q_upper[7:] + 1e-12
    at_limit = 0
    for _ in range(30):
        q = pin.integrate(model, q, solver.solve(levels, q))
        assert np.all(q[7:] >= lower) and np.all(q[7:] <= upper)
        at_limit = max(at_limit, int(np.count_nonzero(np.minimum(q[7:] - lower, upper - q[7:]) < 1e-9)))
    assert at_limit >= 1  # the limits were really reached


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_inequalities_hold_at_convergence(robot_name: str) -> None:
    """Reaching forward and low puts the CoM on the polygon margin and joints on the joint-limit
    task's margin: at convergence both inequality tasks hold (value 0, eq. 6) while active."""
    robot = load_robot(robot_name)
    model = robot.model
    q0, feet, com, data = standing(robot)
    chest = frame_position(robot, data, robot.frames.torso)
    target = np.array([chest[0] + 0.5, -0.2, 0.6])
    limits_task = JointLimitsTask(model, margin_rad=0.05, q_lower=robot.q_lower, q_upper=robot.q_upper)
    levels = [
        feet,
        Level((limits_task,), name="joint limits"),
        com,
        Level((FramePositionTask(model, robot.frames.right_grasp, target, max_step=0.2),), name="hand"),
        Level((PostureTask(model, q0, gain=0.5),), name="posture", tol=math.inf),
    ]
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    result = solver.run(levels, q0, tol=1e-6, max_iters=60)
    assert result.converged, (result.reason, result.residuals)
    compute_kinematics(model, data, result.q, True)
    G = com.tasks[0].compute_error(result.q, data)
    assert task_value(com.tasks[0], result.q, data) <= 1e-6
    assert G.max() > -1e-4  # the CoM is on the margin: the constraint is active
    values = limits_task.compute_error(result.q, data)
    room = np.minimum(values - limits_task.lower, limits_task.upper - values)
    assert room.min() >= -1e-6 and room.min() < 1e-4  # active, and held
    assert task_value(limits_task, result.q, data) <= 1e-6


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_capsule_distance_constraint_stops_a_lower_task(robot_name: str) -> None:
    """Eqs. (12)-(13): a ball held by a fixed foot's frame sits on the hand target; the capsule
    constraint (a level above the hand) stops the grasp sphere at radii + margin from it."""
    robot = load_robot(robot_name)
    model = robot.model
    q0, feet, com, data = standing(robot)
    T_torso = data.oMf[model.getFrameId(robot.frames.torso)]
    target = T_torso.act(np.array([0.35, -0.15, -0.2]))
    T_sole = data.oMf[model.getFrameId(robot.frames.left_sole)]
    center = tuple(T_sole.actInv(target))
    capsules = [
        Capsule("grasp", robot.frames.right_grasp, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.03),
        Capsule("ball", robot.frames.left_sole, center, center, 0.08),
    ]
    collision = SelfCollisionTask(model, capsules, pairs=[(0, 1)], margin_m=0.01)
    levels = [
        feet,
        com,
        Level((collision,), name="capsules"),
        Level((FramePositionTask(model, robot.frames.right_grasp, target, max_step=0.2),), name="hand"),
        Level((PostureTask(model, q0, gain=0.5),), name="posture", tol=math.inf),
    ]
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    result = solver.run(levels, q0, tol=1e-6, max_iters=100)
    assert result.reason == "stagnated"
    compute_kinematics(model, data, result.q, True)
    assert collision.distances(data)[0] == pytest.approx(0.01, abs=1e-5)
    hand_error = np.linalg.norm(frame_position(robot, data, robot.frames.right_grasp) - target)
    assert hand_error == pytest.approx(0.08 + 0.03 + 0.01, abs=1e-4)
    assert np.all(result.residuals[:3] < 1e-6)


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_infeasible_top_level_returns_its_least_squares_optimum(robot_name: str) -> None:
    """The hand asked at two points 0.2 m apart in the top level: the loop ends at the midpoint
    (the least-squares optimum) with the residual |a - b| / sqrt(2), no exception."""
    robot = load_robot(robot_name)
    model = robot.model
    q0, _, _, data = standing(robot)
    hand = robot.frames.right_grasp
    p = frame_position(robot, data, hand)
    a, b = p + np.array([0.05, 0.1, 0.0]), p + np.array([0.05, -0.1, 0.0])
    top = Level((FramePositionTask(model, hand, a, name="a"), FramePositionTask(model, hand, b, name="b")))
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    result = solver.run([top, Level((PostureTask(model, q0),), tol=math.inf)], q0, tol=1e-6, max_iters=50)
    assert result.reason == "stagnated"
    assert not result.converged
    assert result.residuals[0] == pytest.approx(0.2 / math.sqrt(2.0), rel=1e-6)
    compute_kinematics(model, data, result.q, True)
    np.testing.assert_allclose(frame_position(robot, data, hand), 0.5 * (a + b), atol=1e-6)


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_each_level_is_the_optimum_of_its_qp(robot_name: str) -> None:
    """With joint limits active, our levels equal a direct proxsuite QP of each level over dq
    (equalities above as equality constraints, limits as bounds), and the fast path equals the
    forced-QP path."""
    robot = load_robot(robot_name)
    model = robot.model
    q0, feet, _, data = standing(robot)
    # a start close to several joint limits, and a hand target that pushes into them
    q = q0.copy()
    q[7:] = np.clip(q[7:], robot.q_lower[7:] + 0.02, robot.q_upper[7:] - 0.02)
    target = frame_position(robot, data, robot.frames.right_grasp) + np.array([0.15, -0.15, 0.25])
    # constant damping on every level, so that the reference QPs below have the same objective
    feet = Level(feet.tasks, name="feet", damping=1e-4, error_damping=0.0)
    hand = Level(
        (FramePositionTask(model, robot.frames.right_grasp, target),),
        name="hand",
        damping=1e-4,
        error_damping=0.0,
    )
    posture = Level((PostureTask(model, q0 + 0.0),), name="posture", damping=1e-4, error_damping=0.0)
    levels = [feet, hand, posture]
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper, limit_gain=0.5)
    dq = solver.solve(levels, q)
    assert any(report.used_qp for report in solver.last_report)
    for config in (SolverConfig(always_qp=True), SolverConfig(always_qp=True, qp_kkt_shortcut=False)):
        forced = HierarchicalSolver(model, robot.q_lower, robot.q_upper, limit_gain=0.5, config=config)
        np.testing.assert_allclose(forced.solve(levels, q), dq, atol=1e-6)
    assert forced._qp.calls > 0  # proxsuite itself was exercised

    systems = solver.evaluate(levels, q)
    lb, ub = solver.hard_bounds(q, 1.0)
    C = np.eye(model.nv)[solver.box_v_idx]
    eq_A, eq_b = None, None
    previous = np.zeros(model.nv)
    for system, level in zip(systems, levels, strict=True):
        # level k: min 1/2 ||A dq - b||^2 + mu/2 ||dq - dq_above||^2, equalities above held, bounds
        H = system.A.T @ system.A + level.damping * np.eye(model.nv)
        g = -system.A.T @ system.b - level.damping * previous
        result = proxqp.dense.solve(H, g, eq_A, eq_b, C, lb, ub, eps_abs=1e-11, eps_rel=0)
        previous = result.x
        eq_A = system.A if eq_A is None else np.vstack((eq_A, system.A))
        eq_b = system.A @ result.x if eq_b is None else np.concatenate((eq_b, system.A @ result.x))
    np.testing.assert_allclose(dq, previous, atol=5e-6)


def test_weighted_pseudo_inverse_and_selection_matrix() -> None:
    """Eq. (4) of the reaching paper: with link-mass weights the redundancy of a level goes to the
    light links (smaller weighted norm than the plain minimum norm, same task motion); a selection
    matrix keeps the level on the selected joints only."""
    robot = load_robot("hrp2_like")
    model = robot.model
    q0, feet, _, data = standing(robot)
    target = frame_position(robot, data, robot.frames.right_grasp) + np.array([0.05, 0.0, 0.05])
    task = FramePositionTask(model, robot.frames.right_grasp, target)
    weights = link_mass_weights(model)
    assert weights.shape == (model.nv,) and np.all(weights > 0.0)
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    plain = solver.solve([feet, Level((task,), damping=1e-9, error_damping=0.0)], q0)
    weighted = solver.solve([feet, Level((task,), damping=1e-9, error_damping=0.0, weights=weights)], q0)
    J = pin.computeFrameJacobian(
        model, solver.data, q0, model.getFrameId(robot.frames.right_grasp), pin.LOCAL_WORLD_ALIGNED
    )[:3]
    np.testing.assert_allclose(J @ weighted, J @ plain, atol=1e-7)
    metric = np.sqrt(weights)
    assert weighted @ (metric * weighted) < plain @ (metric * plain)
    arm = dof_mask(model, robot.arm_joints("right"))
    selected = solver.solve([Level((task,), selection=arm, damping=1e-9, error_damping=0.0)], q0)
    assert np.all(selected[~arm] == 0.0)
    np.testing.assert_allclose(
        J @ selected, -(frame_position(robot, data, robot.frames.right_grasp) - target), atol=1e-5
    )


def test_joints_near_their_limits_are_locked_by_the_level_option() -> None:
    robot = load_robot("talos")
    model = robot.model
    q0, _, _, data = standing(robot)
    joint = robot.arm_joints("right")[3]
    idx = robot.joint_index(joint)
    q = q0.copy()
    q[idx.idx_q] = robot.q_upper[idx.idx_q] - 0.01
    target = frame_position(robot, data, robot.frames.right_grasp) + np.array([0.05, 0.05, 0.05])
    task = FramePositionTask(model, robot.frames.right_grasp, target)
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    free = solver.solve([Level((task,))], q)
    locked = solver.solve([Level((task,), lock_near_limits_rad=0.05)], q)
    assert abs(free[idx.idx_v]) > 1e-4
    assert locked[idx.idx_v] == 0.0


def test_velocity_limits_and_a_virtual_footprint_chain() -> None:
    """The solver runs on a model with planar footprint joints before the free flyer; the hard
    velocity bound holds and the prismatic footprint limits are respected."""
    from tests.test_ik_tasks import footprint_chain_model

    robot = load_robot("talos")
    model, q = footprint_chain_model(robot)
    q[:3] = 0.0
    solver = HierarchicalSolver(model, dq_max=0.1)
    data = model.createData()
    compute_kinematics(model, data, q, False)
    target = np.array([3.0, 0.0, 0.9])  # beyond the 2 m footprint range: stops at the limit
    levels = [
        Level((PostureTask(model, q, joint_names=["root_joint"]),), name="base on its footprint"),
        Level((FramePositionTask(model, robot.frames.right_grasp, target),)),
        Level((PostureTask(model, q, joint_names=robot.joint_names),), tol=math.inf),
    ]
    for _ in range(60):
        dq = solver.solve(levels, q)
        assert np.all(np.abs(dq) <= 0.1 + SolverConfig().feasibility_tol)
        q = pin.integrate(model, q, dq)
        assert -2.0 - 1e-12 <= q[0] <= 2.0 + 1e-12 and -2.0 - 1e-12 <= q[1] <= 2.0 + 1e-12
    assert q[0] > 1.99  # pushed against the footprint limit, never beyond


def test_monitors() -> None:
    robot = load_robot("hrp2_like")
    model = robot.model
    q0 = np.array(robot.q_half_sitting)
    data = model.createData()
    compute_kinematics(model, data, q0, True)
    arm = ArmManipulability(model, robot.frames.right_grasp, robot.arm_joints("right")[0])
    J = pin.getFrameJacobian(
        model, data, model.getFrameId(robot.frames.right_grasp), pin.LOCAL_WORLD_ALIGNED
    )[:3]
    J_arm = J[:, dof_mask(model, robot.arm_joints("right"))]
    assert arm(data) == pytest.approx(np.prod(np.linalg.svd(J_arm, compute_uv=False)), rel=1e-9)
    assert manipulability(np.eye(3)[:2]) == pytest.approx(1.0)
    # a stretched arm is (nearly) singular
    q = q0.copy()
    for name in robot.arm_joints("right"):
        q[robot.joint_index(name).idx_q] = 0.0
    compute_kinematics(model, data, q, True)
    assert arm(data) < 0.2 * ArmManipulability(model, robot.frames.right_grasp, robot.arm_joints("right")[0])(
        _data_at(model, q0)
    )


def _data_at(model: pin.Model, q: np.ndarray) -> pin.Data:
    data = model.createData()
    compute_kinematics(model, data, q, True)
    return data


def test_loop_reasons_and_input_errors() -> None:
    robot = load_robot("talos")
    model = robot.model
    q0, feet, _, _ = standing(robot)
    far = Level((FramePositionTask(model, robot.frames.right_grasp, [5.0, 0.0, 1.0]),))
    solver = HierarchicalSolver(model, robot.q_lower, robot.q_upper)
    assert solver.run([feet, far], q0, max_iters=2).reason == "max_iters"
    assert solver.run([feet, far], q0, time_budget_s=0.0).reason == "time_budget"
    assert solver.run([feet], q0).reason == "converged"
    with pytest.raises(InvalidRequestError, match=f"q must be {model.nq} finite numbers"):
        solver.solve([feet], q0[:-1])
    with pytest.raises(InvalidRequestError, match="alpha must be positive"):
        solver.run([feet], q0, alpha=0.0)
    with pytest.raises(InvalidRequestError, match="tasks must be a non-empty sequence"):
        Level(())
    with pytest.raises(InvalidRequestError, match="selection needs"):
        solver.solve([Level(feet.tasks, selection=np.ones(3, dtype=bool))], q0)
