"""Footstep planning as inverse kinematics (services/footsteps): the virtual chain, the footstep
constraints' Jacobians, Algorithm 1 on the paper's three scenarios, infeasibility, execution."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from services.errors import InfeasibleError, InvalidRequestError, RequestTimeoutError
from services.footsteps import scenarios
from services.footsteps.chain import Stance, VirtualChain, footprint_frame
from services.footsteps.constraints import (
    FootprintDisksTask,
    FrontStepBoundsTask,
    NonOverlapTask,
    RootSoleOnFootprintTask,
    relative_planar_pose,
)
from services.footsteps.geometry import non_overlap_rows
from services.footsteps.hand_floor import hand_floor_task
from services.footsteps.planner import initial_stance, plan_footsteps
from services.footsteps.problem import self_collision_task
from services.footsteps.request import DiskObstacle, FootstepPlanRequest, FootstepTask, PlannerOptions
from services.ik.kinematics import compute_kinematics
from services.ik.tasks.foot_outside_disk import FootOutsideDiskTask
from services.ik.tasks.self_collision import SelfCollisionTask
from services.model import load_robot
from services.model.ground import (
    Rectangle,
    rectangles_overlap_depth,
    signed_distance,
    sole_corners,
    sole_pose_of,
)
from services.walking.footsteps import FootstepBounds, SolePose, validate_footsteps


@pytest.fixture(scope="module")
def robot():
    return load_robot("hrp2_like")


@pytest.fixture(scope="module")
def stance(robot):
    return initial_stance(robot, robot.q_half_sitting)


def grown_chain(robot, stance, front: str, n_steps: int):
    chain = VirtualChain(robot, front, 0, stance)
    q = chain.folded_q(robot.q_half_sitting)
    for _ in range(n_steps):
        chain, q = chain.with_root_footprint(q)
    return chain, q


# ------------------------------------------------------------------------------------------ the chain


@pytest.mark.parametrize("front", ["left", "right"])
def test_folded_chain_carries_the_robot_and_alternates_sides(robot, stance, front):
    chain, q = grown_chain(robot, stance, front, 4)
    assert chain.n_steps == 4 and chain.model.nq == 3 * 3 + robot.nq
    # F_{p-1} is the root foot, sides alternate backwards, every footprint on its initial sole
    assert chain.sides[-1] != front and all(
        a != b for a, b in zip(chain.sides, chain.sides[1:], strict=False)
    )
    for side, pose in zip(chain.sides, chain.footprint_poses(q), strict=True):
        assert np.allclose(pose.as_array(), stance.of(side).as_array(), atol=1e-12)
    np.testing.assert_allclose(chain.robot_q_world(q), robot.q_half_sitting, atol=1e-12)
    # the robot's joints follow the chain's in q~ (eq. 9) with the same names
    for jid in range(2, robot.model.njoints):
        assert chain.model.names[3 * 3 + jid] == robot.model.names[jid]


def test_root_insertion_keeps_the_world_state(robot, stance):
    rng = np.random.default_rng(3)
    chain, q = grown_chain(robot, stance, "left", 3)
    q = pin.integrate(chain.model, q, 0.05 * rng.standard_normal(chain.model.nv))
    data = chain.model.createData()
    pin.framesForwardKinematics(chain.model, data, q)
    frames = ("left_sole", "right_sole", "right_grasp")
    before = {f: chain.world_placement(data.oMf[chain.model.getFrameId(f)]) for f in frames}
    poses_before = chain.footprint_poses(q)
    grown, q2 = chain.with_root_footprint(q)
    assert grown.n_steps == 4 and grown.sides[1:] == chain.sides
    data2 = grown.model.createData()
    pin.framesForwardKinematics(grown.model, data2, q2)
    for f, T in before.items():
        assert (grown.world_placement(data2.oMf[grown.model.getFrameId(f)]).inverse() * T).isIdentity(1e-10)
    for a, b in zip(poses_before, grown.footprint_poses(q2)[1:], strict=True):
        assert np.allclose(a.as_array(), b.as_array(), atol=1e-12)
    # the new root footprint is the other initial sole
    assert np.allclose(grown.footprint_poses(q2)[0].as_array(), stance.of(grown.sides[0]).as_array())


def test_chain_limits_are_the_step_bounds(robot, stance):
    chain, _ = grown_chain(robot, stance, "right", 3)
    bounds = robot.params.footstep_bounds
    for i in (1, 2):
        idx = [chain.model.getJointId(n) for n in chain.chain_joint_names(i)]
        lo = [chain.model.lowerPositionLimit[chain.model.joints[j].idx_q] for j in idx]
        hi = [chain.model.upperPositionLimit[chain.model.joints[j].idx_q] for j in idx]
        expected = bounds.for_swing(chain.sides[i])
        assert np.allclose(lo, [e[0] for e in expected]) and np.allclose(hi, [e[1] for e in expected])


# --------------------------------------------------------------------------------- constraint Jacobians


def _numeric_jacobian(task, model, data, q, h=1e-6):
    J = np.zeros((task.compute_error(q, data).shape[0], model.nv))
    for k in range(model.nv):
        e = np.zeros(model.nv)
        e[k] = h
        qp, qm = pin.integrate(model, q, e), pin.integrate(model, q, -e)
        compute_kinematics(model, data, qp, False)
        fp = task.compute_error(qp, data)
        compute_kinematics(model, data, qm, False)
        fm = task.compute_error(qm, data)
        J[:, k] = (fp - fm) / (2 * h)
    compute_kinematics(model, data, q, False)
    return J


@pytest.mark.parametrize("seed", [0, 1])
def test_footstep_constraint_jacobians_match_finite_differences(robot, stance, seed):
    rng = np.random.default_rng(seed)
    chain, q0 = grown_chain(robot, stance, "left" if seed else "right", 3)
    q = pin.integrate(chain.model, q0, 0.2 * rng.standard_normal(chain.model.nv))
    data = chain.model.createData()
    for task in (
        RootSoleOnFootprintTask(chain),
        FrontStepBoundsTask(chain),
        NonOverlapTask(chain, robot.sole_size_m),
    ):
        compute_kinematics(chain.model, data, q, False)
        F, J = task.compute(q, data)
        J_num = _numeric_jacobian(task, chain.model, data, q)
        # central differences: error O(h^2 |F'''|) + rounding O(eps / h)
        np.testing.assert_allclose(J, J_num, atol=1e-6, err_msg=task.name)
        assert F.shape[0] == J.shape[0]


def test_self_collision_task_is_shared_per_chain_model(robot, stance):
    """The self-collision task holds no state between evaluations: one per chain model, margin and
    gain, and a task built anew gives the same rows."""
    chain, q = grown_chain(robot, stance, "left", 2)
    task = self_collision_task(chain, 0.01, 1.0)
    assert self_collision_task(VirtualChain(robot, "left", 2, stance), 0.01, 1.0) is task
    assert self_collision_task(chain, 0.02, 1.0) is not task
    data = chain.model.createData()
    q = q.copy()
    q[chain.robot_slice()][7:] += 0.6  # every joint turned: capsules come close, some overlap
    compute_kinematics(chain.model, data, q, False)
    fresh = SelfCollisionTask(chain.model, task.capsules, list(zip(task.pair_a, task.pair_b, strict=True)))
    G, J = task.compute(q, data)
    assert G.shape[0] >= 3 and task.value_of(G) > 0.0  # rows, some violated
    G_fresh, J_fresh = fresh.compute(q, data)
    np.testing.assert_array_equal(G, G_fresh)
    np.testing.assert_array_equal(J, J_fresh)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_disk_rows_match_finite_differences_and_the_generic_disk_task(robot, stance, seed):
    """The vectorized disk rows of every movable footprint equal services.ik's FootOutsideDiskTask
    of each (disk, footprint), and their Jacobian matches finite differences, also with a disk
    centre under a footprint."""
    rng = np.random.default_rng(seed)
    chain, q0 = grown_chain(robot, stance, "right" if seed % 2 else "left", 4)
    q = pin.integrate(chain.model, q0, 0.3 * rng.standard_normal(chain.model.nv))
    data = chain.model.createData()
    compute_kinematics(chain.model, data, q, False)
    fp = chain.footprint_poses(q)[2]
    disks_world = [(fp.x_m + 0.01, fp.y_m - 0.02, 0.05), (0.8, -0.3, 0.25), (-0.4, 0.5, 0.1)]
    centers = [chain.model_point((x, y)) for x, y, _ in disks_world]
    task = FootprintDisksTask(chain, robot.sole_size_m, centers, [r for *_, r in disks_world], margin_m=0.01)
    G, J = task.compute(q, data)
    frames = [footprint_frame(i) for i in range(1, chain.n_footprints)] + [chain.front_sole_frame]
    assert G.shape == (len(disks_world) * len(frames),) and J.shape == (G.shape[0], chain.model.nv)
    k = 0
    for c, (*_, radius) in zip(centers, disks_world, strict=True):
        for frame in frames:
            generic = FootOutsideDiskTask(chain.model, frame, robot.sole_size_m, c, radius, margin_m=0.01)
            F_g, J_g = generic.compute(q, data)
            np.testing.assert_allclose(G[k], F_g[0], atol=1e-12)
            np.testing.assert_allclose(J[k], J_g[0], atol=1e-10)
            k += 1
    assert G[1] > 0.0  # the first disk centre is under F_2: that row is violated, the inside case
    np.testing.assert_allclose(J, _numeric_jacobian(task, chain.model, data, q), atol=1e-6)


def test_relative_planar_pose_is_the_chain_joint_value(robot, stance):
    chain, q = grown_chain(robot, stance, "left", 3)
    q[3:6] = [0.1, -0.2, -0.3]
    data = chain.model.createData()
    compute_kinematics(chain.model, data, q, False)
    r, J = relative_planar_pose(chain.model, data, *chain.footprint_frame_ids[1:3])
    np.testing.assert_allclose(r, [0.1, -0.2, -0.3], atol=1e-12)
    np.testing.assert_allclose(J[:, 3:6], np.eye(3), atol=1e-12)


def test_non_overlap_rows_keep_the_footprints_apart():
    """Fig. 5: when every row holds, the two rectangles are disjoint (by at least the margin)."""
    rng = np.random.default_rng(7)
    length, width, margin = 0.24, 0.14, 0.01
    parent = SolePose(0.0, 0.0, 0.0)
    held = 0
    for _ in range(3000):
        r = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-0.8, 0.8)])
        child_is_left = bool(rng.integers(2))
        G, dG = non_overlap_rows(r, child_is_left, length, width, margin)
        child = parent.compose(*r)
        if np.all(G <= 0.0):
            held += 1
            assert rectangles_disjoint_margin(parent, child, length, width) >= margin - 1e-9
        h = 1e-7
        num = np.stack(
            [
                (non_overlap_rows(r + h * e, child_is_left, length, width, margin)[0] - G) / h
                for e in np.eye(3)
            ],
            axis=1,
        )
        np.testing.assert_allclose(dG, num, atol=1e-5)
    assert held > 100


def rectangles_disjoint_margin(a: SolePose, b: SolePose, length_m: float, width_m: float) -> float:
    """Separation [m] of two footprint rectangles (> 0: disjoint): the validation counterpart of the
    non-overlap rows."""
    return -rectangles_overlap_depth(sole_corners(a, length_m, width_m), sole_corners(b, length_m, width_m))


def disk_signed_distance(pose: SolePose, length_m: float, width_m: float, center_xy: np.ndarray) -> float:
    """Signed distance [m] from a disk centre to a footprint rectangle (< 0 under the sole)."""
    return float(
        Rectangle((pose.x_m, pose.y_m), (length_m, width_m), pose.yaw_rad).signed_distance(center_xy)[0]
    )


def test_disk_signed_distance():
    pose = SolePose(1.0, 2.0, math.pi / 2)  # 0.24 along y, 0.14 along x
    assert disk_signed_distance(pose, 0.24, 0.14, np.array([1.0, 2.0])) == pytest.approx(-0.07)
    assert disk_signed_distance(pose, 0.24, 0.14, np.array([1.5, 2.0])) == pytest.approx(0.5 - 0.07)
    assert disk_signed_distance(pose, 0.24, 0.14, np.array([1.0, 2.5])) == pytest.approx(0.5 - 0.12)


# --------------------------------------------------------------------------------- plans and scenarios


def check_plan(robot, request, result):
    """The properties every plan must have: footprints inside the bounds of every support polygon,
    not overlapping, outside the disks; CoM over the final support polygon; tasks within tolerance;
    the robot standing on the last footprints."""
    seq = result.footstep_sequence()
    limits = FootstepBounds.from_robot(robot)
    if seq.steps:
        validate_footsteps(seq, limits)  # bounds (relative to the stance foot) and no overlap
    length, width = robot.sole_size_m
    for left, right in seq.stances():
        assert rectangles_disjoint_margin(left, right, length, width) > 0.0
    start = {"left": seq.left_start, "right": seq.right_start}
    for step in seq.steps:
        for disk in request.disks:
            distance = disk_signed_distance(step.pose, length, width, np.array([disk.x_m, disk.y_m]))
            assert distance >= disk.radius_m - 1e-3, f"footprint {step} enters disk {disk}"
        start[step.side] = step.pose
    q = np.asarray(result.q_final)
    data = robot.new_data()
    for side in ("left", "right"):
        T = robot.sole_pose(q, side, data)
        final = sole_pose_of(T)
        assert abs(T.translation[2]) < 2e-3 and T.rotation[2, 2] > math.cos(0.01)
        assert np.allclose(final.as_array()[:2], start[side].as_array()[:2], atol=2e-3)
    margin = -float(signed_distance(robot.com(q, data)[:2], robot.support_polygon(q, data=data))[0])
    assert margin > 0.0
    if request.options.hand_floor:  # the corners of the hands' collision boxes above the floor
        floor = hand_floor_task(robot, robot.model, 0.0)
        pin.framesForwardKinematics(robot.model, data, q)
        assert floor.heights(data).min() >= request.options.hand_floor_margin_m - 1e-3
    for task, residual in zip(request.tasks, result.residuals, strict=True):
        assert residual.name == task.name and residual.solved and residual.value <= task.tol()
        if task.kind == "reach":
            hand = robot.frame_pose(q, robot.frames.grasp(task.hand), data).translation
            assert np.linalg.norm(hand - np.asarray(task.target_m)) <= task.tol() + 1e-9


@pytest.mark.parametrize("name", ["reach", "pickup", "posture"])
def test_paper_scenarios_are_solved(robot, name):
    scenario = scenarios.SCENARIOS[name]()
    result = plan_footsteps(scenarios.with_trace(scenario.request), robot)
    check_plan(robot, scenario.request, result)
    trace = result.trace
    assert trace is not None and len(trace.values) >= result.iterations
    assert len(result.steps_added_at) == result.chain_steps - 1  # the structure starts with one step
    if name == "reach":
        assert result.n_steps >= 4  # 2 m away: the hand alone cannot reach it
    if name == "pickup":
        assert result.n_steps >= 1  # the object between the feet needs stepping (section 4.2)
    if name == "posture":
        assert result.n_steps >= 1
        # the rest posture is closer than at the awkward start
        start = np.asarray(scenario.request.q_start)[7:]
        rest = np.asarray(robot.q_half_sitting)[7:]
        assert result.residual("posture").value < np.linalg.norm(start - rest)


def test_target_within_reach_takes_no_step(robot):
    request = FootstepPlanRequest(tasks=(FootstepTask("reach", (0.3, -0.25, 0.8)),))
    result = plan_footsteps(request, robot)
    # one step in the structure (Fig. 11), never moved, hence discarded; no step added
    assert result.n_steps == 0 and result.chain_steps == 1 and result.steps_added_at == ()
    check_plan(robot, request, result)


def test_unreachable_target_is_infeasible_with_residuals(robot):
    request = FootstepPlanRequest(tasks=(FootstepTask("reach", (0.5, 0.0, 5.0)),), time_budget_s=20.0)
    with pytest.raises(InfeasibleError) as info:
        plan_footsteps(request, robot)
    details = info.value.details
    assert details["residuals"]["reach:right"] > 3.0
    assert details["reason"] in ("stalled", "max_steps")  # stopped by Algorithm 1, not by the budget
    assert "reach:right" in info.value.message


def test_tiny_time_budget_reports_timeout_with_the_partial_plan(robot):
    request = FootstepPlanRequest(tasks=(FootstepTask("reach", (2.0, 0.0, 0.8)),), time_budget_s=1e-3)
    with pytest.raises(RequestTimeoutError) as info:  # not infeasible: the budget cut the search short
        plan_footsteps(request, robot)
    details = info.value.details
    assert details["reason"] == "time_budget"
    assert details["residuals"]["reach:right"] > 0.5 and isinstance(details["footsteps"], list)


def test_both_front_feet_are_tried_and_the_fewest_steps_kept(robot):
    scenario = scenarios.posture()
    result = plan_footsteps(scenario.request, robot)
    assert {a[0] for a in result.alternatives} == {"left", "right"}
    solved = [a for a in result.alternatives if a[1]]
    best = min(solved, key=lambda a: (a[2], a[3]))
    assert result.front_foot == best[0] and result.n_steps == best[2]


def test_initial_guess_of_steps(robot):
    request = FootstepPlanRequest(
        tasks=(FootstepTask("reach", (1.0, -0.2, 0.8)),), initial_steps=3, front_foot="left"
    )
    result = plan_footsteps(request, robot)
    check_plan(robot, request, result)
    # the held footprints that did not move are discarded
    assert result.n_steps <= result.chain_steps


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"tasks": ()}, "tasks"),
        ({"tasks": (FootstepTask("wave", (0, 0, 1)),)}, "kind"),
        ({"tasks": (FootstepTask("reach", None),)}, "target_m"),
        ({"tasks": (FootstepTask("reach", (1, 0, 1), hand="middle"),)}, "hand"),
        ({"front_foot": "both"}, "front_foot"),
        ({"disks": (DiskObstacle(0, 0, -1),)}, "disks[0]"),
        ({"initial_steps": 30}, "initial_steps"),
        ({"options": PlannerOptions(alpha=2.0)}, "alpha"),
        ({"options": PlannerOptions(damping=-1.0)}, "damping"),
        ({"options": PlannerOptions(polish_iterations=-1)}, "polish_iterations"),
    ],
)
def test_invalid_requests_name_the_field(robot, change, field):
    request = replace(FootstepPlanRequest(tasks=(FootstepTask("reach", (1, 0, 1)),)), **change)
    with pytest.raises(InvalidRequestError, match=field.replace("[", r"\[").replace("]", r"\]")):
        plan_footsteps(request, robot)


def test_q_start_must_stand_on_the_ground(robot):
    q = np.array(robot.q_half_sitting)
    q[2] += 0.1
    request = FootstepPlanRequest(tasks=(FootstepTask("reach", (1, 0, 1)),), q_start=tuple(q))
    with pytest.raises(InvalidRequestError, match="flat on the ground"):
        plan_footsteps(request, robot)


def test_chain_from_a_turned_stance(robot):
    """The planner works from any standing pose (the chain's root is the initial support sole)."""
    q = robot.half_sitting_at(1.0, -0.5, 2.0)
    stance = initial_stance(robot, q)
    assert isinstance(stance, Stance)
    target = robot.frame_pose(q, "torso").act(np.array([1.2, 0.0, -0.2]))
    request = FootstepPlanRequest(tasks=(FootstepTask("reach", tuple(target)),), q_start=tuple(q))
    result = plan_footsteps(request, robot)
    check_plan(robot, request, result)
    assert result.n_steps >= 1


# ------------------------------------------------------------------------------------------ execution


def test_paper_scenarios_use_the_papers_task_sets():
    """Section 4: the reach and the pick-up with the reach alone (the disks are constraints), the
    posture recovery with gaze > posture; the rest posture objective only on request."""
    assert [t.kind for t in scenarios.reach().request.tasks] == ["reach"]
    assert [t.kind for t in scenarios.pickup().request.tasks] == ["reach"]
    assert [t.kind for t in scenarios.posture().request.tasks] == ["gaze", "posture"]
    assert [t.kind for t in scenarios.fig10().request.tasks] == ["reach", "gaze", "posture"]
    assert [t.kind for t in scenarios.reach(posture_objective=True).request.tasks] == ["reach", "posture"]


def test_fig10_threshold_study_higher_epsilon_reacts_earlier(robot):
    """Fig. 10 (b)-(e): with low thresholds the steps come late and the run is longer; with high ones
    the algorithm reacts faster and needs fewer iterations."""
    runs = {}
    for label in ("low", "high"):
        request = scenarios.fig10(robot.name, scenarios.EPSILON_STUDY[label]).request
        runs[label] = plan_footsteps(scenarios.with_trace(request), robot)
    assert runs["high"].iterations < runs["low"].iterations
    assert runs["high"].n_steps <= runs["low"].n_steps
    for result in runs.values():
        assert len(result.trace.steps_added_at) == result.chain_steps - 1


@pytest.fixture(scope="module")
def near_reach(robot):
    """A ball 1 m ahead at table height: a few steps, then the reach (rest posture as objective)."""
    request = FootstepPlanRequest(tasks=(FootstepTask("reach", (1.0, -0.3, 0.8)), FootstepTask("posture")))
    return request, plan_footsteps(request, robot)


def test_plan_becomes_a_walk_and_a_reach(robot, near_reach):
    from services.footsteps.execution import execute_plan

    request, result = near_reach
    assert result.n_steps >= 1
    motion = execute_plan(robot, request, result)
    assert motion.walk is not None and motion.walk.worst_zmp_outside_m == 0.0
    assert motion.q.shape == (motion.times_s.shape[0], robot.nq)
    np.testing.assert_allclose(motion.q[0], robot.q_half_sitting, atol=1e-9)
    # continuous at 5 ms: no joint jumps more than 0.05 rad between samples
    assert np.max(np.abs(np.diff(motion.q[:, 7:], axis=0))) < 0.05
    assert motion.final_errors_m["reach:right"] < 2e-3
    assert motion.reach_max_sole_drift_m < 1e-3 and motion.reach_min_com_margin_m > 0.0
    # the final reach keeps the self-collision constraints (Fig. 8): no capsule pair closer than 1 cm
    # (its margin) less what the 5 ms interpolation between IK knots may cut
    assert motion.reach_min_self_distance_m > 0.005
    # the walk ends on the planned footprints
    final = {s.side: s for s in result.footsteps}
    data = robot.new_data()
    k_end = round(motion.walk_end_s / motion.dt_s)
    for side, step in final.items():
        sole = sole_pose_of(robot.sole_pose(motion.q[k_end], side, data))
        assert np.allclose(sole.as_array()[:2], [step.x_m, step.y_m], atol=2e-3)


def test_the_papers_reach_is_walked_with_its_joints_within_their_speed_limits(robot):
    """Section 4.1's 7 steps put a foot at the corner of the step bounds: at the half-sitting CoM height
    and the default timing the knee stretches near its singular configuration and is refused for its
    speed (which joint exceeds first depends on the step timing); ``executable_walk`` lowers the CoM or
    slows the supports (``WALK_ADJUSTMENTS``, in order) until the joints stay within their limits."""
    from services.footsteps.execution import execute_plan
    from services.walking.two_stage import WalkAdjustment, executable_walk

    request = scenarios.reach(robot.name).request
    result = plan_footsteps(request, robot)
    with pytest.raises(InfeasibleError, match=r"JOINT\d+ would move at .* rad/s") as info:
        steps = result.footstep_sequence()
        executable_walk(robot, steps, robot.q_half_sitting, adjustments=(WalkAdjustment(),))
    assert info.value.details["adjustments_tried"] == [(0.0, 1.0)]
    motion = execute_plan(robot, request, result)
    assert motion.walk_adjustment is not None and motion.walk_adjustment != WalkAdjustment()
    speed = np.abs(np.diff(motion.q[:, 7:], axis=0)) / motion.dt_s
    assert np.all(speed <= robot.v_max[6:] + 1e-9)
    assert motion.final_errors_m["reach:right"] < 2e-3


@pytest.mark.integration
@pytest.mark.slow
def test_plan_executed_in_the_simulator(robot, near_reach):
    """The robot walks the planned steps and reaches the target in pybullet without falling."""
    pytest.importorskip("pybullet")
    from services.footsteps.execution import execute_plan
    from sim.world import World

    request, result = near_reach
    motion = execute_plan(robot, request, result)
    with World(robot, "empty") as world:
        outcome = world.execute(motion.q, hold_s=1.0)
        assert outcome.outcome == "completed", outcome.message
        hand = robot.frame_pose(outcome.state.q, robot.frames.grasp("right")).translation
    assert np.linalg.norm(hand - np.asarray(request.tasks[0].target_m)) < 0.02


@pytest.mark.integration
@pytest.mark.slow
def test_the_pickup_crouch_follows_its_plan_in_the_simulator(robot):
    """Section 4.2 with the paper's task set and CoM margin, walked and reached in pybullet, to its end:
    no unplanned contact (the hands' collision boxes kept 1 cm above the floor in the plan and in the
    reach; the gripper used to reach into it), no fall, the base within 1 cm of its planned height (it
    sank 15 cm and tipped over when eq. (13) stopped the right arm within one IK knot at its 1 cm margin
    to the right leg; it rocked onto its toes when the reach's multibody ZMP left the support polygon),
    the hand at the object."""
    pytest.importorskip("pybullet")
    from services.footsteps.execution import execute_plan
    from sim.world import World

    request = scenarios.pickup(robot.name).request
    motion = execute_plan(robot, request, plan_footsteps(request, robot))
    assert motion.reach_min_hand_floor_m >= 0.01 - 1e-3 and motion.reach_min_zmp_margin_m > 0.0
    sink = []
    with World(robot, "empty") as world:
        t0 = world.sim_time_s

        def follow(w) -> None:
            k = min(round((w.sim_time_s - t0) / motion.dt_s), motion.q.shape[0] - 1)
            sink.append(motion.q[k, 2] - w.base_pose().translation[2])

        world.on_tick = follow
        outcome = world.execute(motion.q, hold_s=0.5)
        assert outcome.outcome == "completed", outcome.message
        assert not world.fallen()
        hand = robot.frame_pose(world.state().q, robot.frames.grasp("right")).translation
    assert max(np.abs(sink)) < 0.01
    assert np.linalg.norm(hand - np.asarray(scenarios.PICKUP_OBJECT_M)) < 0.01


def test_the_same_planner_runs_on_talos():
    talos = load_robot("talos")
    request = FootstepPlanRequest(
        robot="talos", tasks=(FootstepTask("reach", (1.5, -0.3, 1.0)), FootstepTask("posture"))
    )
    result = plan_footsteps(request, talos)
    assert result.n_steps >= 2
    check_plan(talos, request, result)


# ------------------------------------------------------------------------------------ the QP method


def _random_qp(rng, r=12, m=30, n_slack=10):
    A = rng.standard_normal((r + 3, r))
    H = A.T @ A + 0.1 * np.eye(r)
    g = 3.0 * rng.standard_normal(r)
    D = rng.standard_normal((m, r))
    D[5] = D[4]  # a duplicated row: dependent normals
    lo, hi = -rng.uniform(0.05, 1.0, m), rng.uniform(0.05, 1.0, m)  # feasible at y = 0
    lo[::7], hi[1::7] = -1e20, 1e20  # one-sided rows
    return H, g, D, lo, hi, m - n_slack


def _proxsuite_reference(H, g, D, lo, hi, first_slack_row):
    from proxsuite import proxqp

    r, m = H.shape[0], D.shape[0]
    n_slack = m - first_slack_row
    H_qp = np.zeros((r + n_slack, r + n_slack))
    H_qp[:r, :r], H_qp[r:, r:] = H, np.eye(n_slack)
    C = np.zeros((m, r + n_slack))
    C[:, :r] = D
    C[first_slack_row:, r:] = -np.eye(n_slack)
    g_qp = np.concatenate((g, np.zeros(n_slack)))
    result = proxqp.dense.solve(H_qp, g_qp, None, None, C, lo, hi, eps_abs=1e-11, eps_rel=0.0)
    return result.x[:r]


@pytest.mark.parametrize("seed", range(6))
def test_dual_active_set_qp_is_the_exact_optimum_and_reproducible(seed):
    """The planner's QP method (services.ik.active_set, Goldfarb-Idnani) gives proxsuite's optimum,
    from any guess of the active set (right, wrong, dependent), with bitwise identical results."""
    from services.ik.active_set import solve_dual_active_set

    rng = np.random.default_rng(seed)
    H, g, D, lo, hi, fsr = _random_qp(rng)
    reference = _proxsuite_reference(H, g, D, lo, hi, fsr)
    cold = solve_dual_active_set(H, g, D, lo, hi, fsr, 1e-9)
    np.testing.assert_allclose(cold.y, reference, atol=1e-6)
    values = D[:fsr] @ cold.y
    assert np.all(values >= lo[:fsr] - 1e-9) and np.all(values <= hi[:fsr] + 1e-9)
    assert cold.rows.shape[0] >= 1  # the unconstrained minimizer violates some row here
    wrong = (np.arange(0, 30, 3), np.where(np.arange(0, 30, 3) % 2 == 0, 1.0, -1.0))
    dependent = (np.array([4, 5, 6]), np.array([1.0, 1.0, -1.0]))
    for guess in ((cold.rows, cold.signs), wrong, dependent):
        warm = solve_dual_active_set(H, g, D, lo, hi, fsr, 1e-9, guess=guess)
        np.testing.assert_allclose(warm.y, reference, atol=1e-6)
    again = solve_dual_active_set(H, g, D, lo, hi, fsr, 1e-9)
    assert again.y.tobytes() == cold.y.tobytes()


def test_planner_qp_method_gives_the_working_set_step(robot, stance):
    """One step of the hierarchy on the chain, with the planner's QP method and with the default
    (working set + proxsuite), from a configuration where limits and constraints are active."""
    from services.footsteps.planner import SOLVER_CONFIG
    from services.footsteps.problem import build_levels, joint_limits
    from services.ik.solver import HierarchicalSolver

    request = scenarios.reach().request
    chain, q = grown_chain(robot, stance, "left", 4)
    q = pin.integrate(chain.model, q, 0.05 * np.random.default_rng(5).standard_normal(chain.model.nv))
    levels = build_levels(chain, request, [])
    lower, upper = joint_limits(chain, request)
    steps = []
    for config in (SOLVER_CONFIG, None):
        solver = HierarchicalSolver(chain.model, lower, upper, dq_max=0.25 / 0.7, config=config)
        steps.append(solver.solve(levels, q, alpha=0.7))
        assert any(report.used_qp for report in solver.last_report)
    np.testing.assert_allclose(steps[0], steps[1], atol=1e-6)


def test_a_scenario_without_a_paper_time_prints_none_not_nan():
    """Fig. 10 has no solve time in the paper: the summary says so instead of printing 'nan s'."""
    from services.footsteps.demo import format_summary

    summary = {
        "scenario": "fig10",
        "title": "t",
        "solved": True,
        "error": None,
        "steps": 6,
        "paper_steps": None,
        "iterations": 40,
        "steps_added_at": [3],
        "solve_wall_s": 0.5,
        "solve_cpu_s": 0.5,
        "paper_s": scenarios.fig10("hrp2_like").paper_solve_s,
        "front_foot": "left",
        "residuals": {},
        "footsteps": [],
        "figures": [],
    }
    text = format_summary(summary)
    assert "nan" not in text and "(paper: -)" in text
    assert "paper: 3.2 s on a 2.13 GHz Core 2" in format_summary({**summary, "paper_s": 3.2})
