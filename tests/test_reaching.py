"""Whole-body reaching with task-driven support polygon reshaping (services/reaching), on both robots.

Planning tests run the pure planner; the ``slow`` ones also execute the motions in ``sim.world.World``
(pybullet, DIRECT) and measure the hand there.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from services.bus.schemas.reaching import REASON_STEPPING_NOT_ALLOWED, REASON_TOO_MANY_STEPS
from services.errors import InfeasibleError, InvalidRequestError
from services.model import load_robot
from services.reaching import CRITERIA, ReachingOptions, ReachRequest, ReachTiming, plan_reach
from services.reaching.monitors import ArmMonitor
from services.reaching.options import PAPER_CRITERIA
from services.reaching.planner import planner_for
from services.reaching.support_polygon import SupportPolygonPlanner
from services.walking.footsteps import FootstepBounds, FootstepSequence, SolePose, validate_footsteps
from services.walking.timing import DOUBLE, LEFT, RIGHT

ROBOTS = ("hrp2_like", "talos")
# Targets in the frame of the robot standing at the origin (x forward, y left) [m].
WITHIN_REACH = {"hrp2_like": (0.45, 0.30, 0.90), "talos": (0.45, 0.30, 1.00)}
FORWARD_BEYOND = {"hrp2_like": (0.90, 0.30, 0.90), "talos": (0.90, 0.30, 1.00)}
# (0.2, 0.75, 0.9) is within hrp2_like's whole-body reach with S = I (the other arm balancing).
SIDEWAYS_BEYOND = {"hrp2_like": (0.30, 0.85, 0.90), "talos": (0.20, 0.80, 1.00)}
FAR_AWAY = (3.0, 0.3, 0.8)  # 3 m away


def _request(robot, target, **kw) -> ReachRequest:
    hand = "left" if target[1] >= 0 else "right"
    return ReachRequest(hand, np.array(target, dtype=float), robot.q_half_sitting, **kw)


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request):
    return load_robot(request.param)


# ------------------------------------------------------------------------------------------ monitors
def test_manipulability_is_eq5_of_the_finite_difference_arm_jacobian():
    """w = sqrt(det(J J^T)) of the arm's whole Jacobian (``pose``: translation and rotation, the default)
    and of its translation rows (``position``), against finite differences."""
    robot = load_robot("hrp2_like")
    model = robot.model
    arm = robot.arm_joints("left")
    monitors = {
        of: ArmMonitor(
            model,
            robot.frames.grasp("left"),
            arm,
            robot.q_lower,
            robot.q_upper,
            robot.effort_max,
            (robot.frames.left_sole, robot.frames.right_sole),
            of,
        )
        for of in ("pose", "position")
    }
    grasp = robot.frames.grasp("left")
    rng = np.random.default_rng(3)
    step = 1e-6
    for _ in range(3):
        q = robot.q_half_sitting.copy()
        idx = [robot.joint_index(j).idx_q for j in arm]
        q[idx] += rng.uniform(-0.4, 0.4, len(idx))
        q[idx] = np.clip(q[idx], robot.q_lower[idx] + 0.01, robot.q_upper[idx] - 0.01)
        T0 = robot.frame_pose(q, grasp)
        J = np.empty((6, len(idx)))
        for c, i in enumerate(idx):
            dq = q.copy()
            dq[i] += step
            T1 = robot.frame_pose(dq, grasp)
            J[:3, c] = (T1.translation - T0.translation) / step
            J[3:, c] = pin.log3(T1.rotation @ T0.rotation.T) / step  # angular velocity, world axes
        w_pose = monitors["pose"].evaluate(q)[1]
        w_position = monitors["position"].evaluate(q)[1]
        assert w_pose == pytest.approx(math.sqrt(np.linalg.det(J @ J.T)), rel=1e-4)
        assert w_position == pytest.approx(math.sqrt(np.linalg.det(J[:3] @ J[:3].T)), rel=1e-4)


# ------------------------------------------------------------------------------------------ planning
def _check_plan(robot, result) -> None:
    """Properties every returned motion has: ZMP inside the support polygon, soles not sliding, the
    hand on the target, the criteria in their admissible ranges, 5 ms samples within the limits."""
    assert result.dt_s == pytest.approx(0.005)
    assert result.q.shape == (result.times_s.shape[0], robot.nq)
    np.testing.assert_allclose(result.q[0], robot.q_half_sitting, atol=1e-9)
    assert result.min_zmp_margin_m > 0.0, "the multibody ZMP leaves the support polygon"
    assert result.max_sole_slide_m < 1e-3, "a supporting sole slides in the plan"
    assert result.hand_error_m < 1e-4
    limits = result.thresholds
    assert result.monitors.manipulability.min() >= limits.manipulability
    assert result.monitors.ee_error_m.max() <= limits.ee_error_m
    joints = result.q[:, 7:]
    assert np.all(joints >= robot.q_lower[7:] - 1e-9) and np.all(joints <= robot.q_upper[7:] + 1e-9)


def test_target_within_reach_takes_no_step(robot):
    result = plan_reach(robot, _request(robot, WITHIN_REACH[robot.name]))
    assert not result.stepped and result.footsteps == ()
    assert [a.kind for a in result.attempts] == ["no_step"]
    assert np.all(result.phase == DOUBLE)
    _check_plan(robot, result)


@pytest.mark.parametrize("where", ["forward", "sideways"])
def test_target_beyond_reach_reshapes_the_support_polygon(robot, where):
    target = (FORWARD_BEYOND if where == "forward" else SIDEWAYS_BEYOND)[robot.name]
    result = plan_reach(robot, _request(robot, target))
    assert result.stepped and len(result.footsteps) >= 1
    first = result.attempts[0]
    assert first.kind == "no_step" and first.violation is not None  # the initial polygon was discarded
    assert result.attempts[-1].violation is None
    assert result.no_step_monitors.times_s[-1] == pytest.approx(first.violation.time_s)
    _check_plan(robot, result)
    # The steps respect the robot's stepping bounds, and the support phases follow them.
    q0 = robot.q_half_sitting
    starts = {}
    for side in ("left", "right"):
        T = robot.sole_pose(q0, side)
        starts[side] = SolePose(T.translation[0], T.translation[1], 0.0)
    validate_footsteps(
        FootstepSequence(starts["left"], starts["right"], result.footsteps), FootstepBounds.from_robot(robot)
    )
    assert {LEFT, RIGHT} & set(np.unique(result.phase))
    # The robot ends facing the target more than it started (Fig. 5: the upper body turns to it).
    bearing = math.atan2(target[1], target[0])
    final_yaw = 0.5 * (result.left_sole[-1, 3] + result.right_sole[-1, 3])
    assert abs(math.remainder(bearing - final_yaw, 2 * math.pi)) < abs(bearing)


def test_impossible_target_is_infeasible_naming_the_criterion(robot):
    with pytest.raises(InfeasibleError) as info:
        plan_reach(robot, _request(robot, FAR_AWAY))
    details = info.value.details
    assert details["criterion"] in CRITERIA
    assert f"criterion '{details['criterion']}' failed" in info.value.message
    assert details["steps_needed"] > ReachingOptions().max_steps
    assert details["reason"] == REASON_TOO_MANY_STEPS


def test_without_stepping_a_far_target_is_infeasible(robot):
    with pytest.raises(InfeasibleError, match="stepping is not allowed") as info:
        plan_reach(robot, _request(robot, FORWARD_BEYOND[robot.name], allow_stepping=False))
    assert info.value.details["criterion"] in CRITERIA
    assert info.value.details["reason"] == REASON_STEPPING_NOT_ALLOWED


def test_without_stepping_the_manipulability_trigger_does_not_veto_a_reachable_target():
    """Paper 001, Fig. 4: a manipulability below its threshold triggers the reshaping of the support
    polygon. With stepping not allowed there is nothing to reshape: a target the hand reaches with every
    other criterion in range is planned on the current polygon (the trigger's violation kept in the
    attempts), while with stepping allowed the same trigger still reshapes."""
    robot = load_robot("hrp2_like")
    target = (0.6, 0.3, 0.7)  # forward and low: the arm stretches on the way
    free = plan_reach(robot, _request(robot, target))
    w = free.monitors.manipulability
    assert w.min() < 0.5 * w[0]
    # A threshold between the manipulability at the start and the lowest of that motion: the trigger
    # fires on the way, not at the start.
    options = ReachingOptions(manipulability_threshold=float(np.sqrt(w.min() * w[0])))
    kept = plan_reach(robot, _request(robot, target, allow_stepping=False), options)
    assert not kept.stepped and np.all(kept.phase == DOUBLE)
    assert [a.kind for a in kept.attempts] == ["no_step", "no_step"]
    assert kept.attempts[0].violation.criterion == "manipulability"
    assert kept.attempts[-1].violation is None
    assert kept.monitors.manipulability.min() < kept.thresholds.manipulability
    assert kept.monitors.ee_error_m.max() <= kept.thresholds.ee_error_m
    assert kept.hand_error_m < 1e-4 and kept.min_zmp_margin_m > 0.0
    try:  # with stepping allowed the trigger reshapes the support polygon (or the reshapings fail)
        stepping = plan_reach(robot, _request(robot, target), options)
    except InfeasibleError as exc:
        assert "reshaping" in exc.message and exc.details["criterion"] in CRITERIA
    else:
        assert stepping.stepped and stepping.attempts[0].violation.criterion == "manipulability"


def test_hand_orientation_is_reached_when_asked():
    robot = load_robot("hrp2_like")
    target = WITHIN_REACH[robot.name]
    free = plan_reach(robot, _request(robot, target))
    # The orientation the hand had without asking for one, turned by 0.3 rad about the vertical.
    R_free = robot.frame_pose(free.q[-1], robot.frames.grasp("left")).rotation
    R = pin.rpy.rpyToMatrix(0.0, 0.0, 0.3) @ R_free
    result = plan_reach(robot, _request(robot, target, R_world_hand=R))
    T = robot.frame_pose(result.q[-1], robot.frames.grasp("left"))
    assert np.linalg.norm(pin.log3(T.rotation.T @ R)) < 1e-3
    assert result.hand_error_m < 1e-4


def test_a_large_turn_of_the_hand_sets_the_reach_duration():
    planner = planner_for("hrp2_like")
    opt = planner.options
    assert planner._reach_duration(0.05) == opt.min_reach_s  # a short travel, no turn
    turn = 2.0 * opt.min_reach_s * opt.hand_turn_rad_s  # fingers down from a hand pointing forward
    assert planner._reach_duration(0.05, turn) == pytest.approx(2.0 * opt.min_reach_s)
    assert planner._reach_duration(0.05, 100.0) == opt.max_reach_s


def test_a_request_timing_shortens_the_motion_within_the_joint_speed_limits():
    """A reach with its own timing (a faster hand, a shorter minimum and hold) is shorter than at the
    defaults, its joints within ``timed_velocity_ratio`` of their limits, and does not step even when
    stepping is allowed (a timed motion is planned on the current polygon)."""
    robot = load_robot("hrp2_like")
    planner = planner_for("hrp2_like")
    target = (0.45, -0.2, 0.8)
    slow = plan_reach(robot, _request(robot, target))
    timing = ReachTiming(hand_speed_m_s=0.4, min_duration_s=0.6, final_hold_s=0.15)
    fast = plan_reach(robot, _request(robot, target, timing=timing))
    assert fast.duration_s < 0.6 * slow.duration_s
    assert not fast.stepped and fast.hand_error_m < 1e-3
    assert planner._joint_speed_ratio(fast.q) <= planner.options.timed_velocity_ratio
    assert fast.duration_s - fast.reach_end_s == pytest.approx(0.15, abs=0.011)


def test_a_request_timing_the_joints_cannot_follow_is_slowed_not_refused():
    """Lifting the hanging hand by 0.1 m in 0.6 s: the hand lags (``ee_error``) or a joint is too fast;
    the planner slows the motion down (or takes the defaults' timing) instead of refusing it."""
    robot = load_robot("hrp2_like")
    planner = planner_for("hrp2_like")
    hand0 = robot.frame_pose(robot.q_half_sitting, robot.frames.grasp("right")).translation
    timing = ReachTiming(hand_speed_m_s=0.5, min_duration_s=0.6, final_hold_s=0.15)
    lifted = hand0 + np.array([0.0, 0.0, 0.1])
    with pytest.raises(InfeasibleError):  # at that timing the hand falls behind its reference
        planner._plan(_request(robot, lifted, timing=timing, allow_stepping=False))
    result = plan_reach(robot, _request(robot, lifted, timing=timing))
    assert result.reach_end_s > 0.6 and result.hand_error_m < 1e-3 and not result.stepped


@pytest.mark.parametrize(
    ("timing", "field"),
    [
        (ReachTiming(hand_speed_m_s=0.0), "hand_speed_m_s"),
        (ReachTiming(hand_speed_m_s=2.0), "hand_speed_m_s"),
        (ReachTiming(min_duration_s=0.1), "min_duration_s"),
        (ReachTiming(final_hold_s=-0.1), "final_hold_s"),
        (ReachTiming(final_hold_s=float("nan")), "final_hold_s"),
    ],
)
def test_a_request_timing_out_of_range_is_invalid_naming_the_field(timing, field):
    robot = load_robot("hrp2_like")
    with pytest.raises(InvalidRequestError, match=field) as info:
        plan_reach(robot, _request(robot, WITHIN_REACH["hrp2_like"], timing=timing))
    assert info.value.details["field"] == field


def test_weighted_pseudo_inverse_moves_the_light_arm_more_and_the_heavy_legs_less():
    robot = load_robot("talos")
    request = _request(robot, (0.5, 0.3, 0.9), gaze=False)
    moves = {}
    for weighted in (True, False):
        q = plan_reach(robot, request, ReachingOptions(weighted=weighted)).q[-1] - robot.q_half_sitting
        arm = [robot.joint_index(j).idx_q for j in robot.arm_joints("left")]
        legs = [robot.joint_index(j).idx_q for j in robot.joint_names if j.startswith("leg_")]
        moves[weighted] = (np.abs(q[arm]).sum(), np.abs(q[legs]).sum())
    assert moves[True][0] > moves[False][0]
    assert moves[True][1] < moves[False][1]


def test_the_free_arm_ends_where_it_started():
    """S = I: the arm without a task helps the CoM, and the rest level brings it back (the robot's width
    after a reach: navigation plans with the arms' footprint)."""
    robot = load_robot("hrp2_like")
    request = _request(robot, (0.6, -0.6, 1.1))
    other = [robot.joint_index(j).idx_q for j in robot.arm_joints("left")]
    moved = {}
    for rest in (True, False):
        result = plan_reach(robot, request, ReachingOptions(other_arm_rest=rest))
        moved[rest] = np.abs(result.q[-1, other] - robot.q_half_sitting[other]).max()
    assert moved[True] < 0.01 < 0.1 < moved[False]


def test_joint_limit_selection_matrix_keeps_arm_joints_off_their_limits():
    robot = load_robot("talos")
    request = _request(robot, (0.62, 0.3, 1.0))
    free = plan_reach(robot, request, ReachingOptions())
    margin = 0.15
    selected = plan_reach(robot, request, ReachingOptions(joint_limit_selection_rad=margin))
    assert free.monitors.joint_limit_margin_rad.min() < margin
    assert selected.monitors.joint_limit_margin_rad.min() > margin - 0.01


@pytest.mark.parametrize(("name", "target"), [("talos", (0.5, 0.65, 1.1)), ("hrp2_like", (0.6, 0.6, 1.1))])
def test_single_step_reshaping(name, target):
    """The paper's case (Figs. 6-7): the arm's manipulability falls below 1.5e-4 on the initial polygon
    (TALOS: its shoulders' torque first), then one step of the foot on the target side, turning
    towards the target."""
    robot = load_robot(name)
    result = plan_reach(robot, _request(robot, target))
    assert [a.kind for a in result.attempts] == ["no_step", "single"]
    expected = "manipulability" if name == "hrp2_like" else "joint_torque"
    assert result.attempts[0].violation.criterion == expected
    assert len(result.footsteps) == 1 and result.footsteps[0].side == "left"
    assert result.footsteps[0].pose.yaw_rad > 0.1
    _check_plan(robot, result)


def test_the_reach_envelope_is_what_the_no_step_motion_reaches_and_one_step_suffices_just_beyond():
    """Fig. 5 needs to know where the task becomes feasible: the envelope straight ahead of the shoulder
    is the farthest target the planner's own no-step motion reaches (a target 2 cm inside takes no step);
    4 cm beyond it one step suffices and is the outcome (paper: one step towards the target)."""
    robot = load_robot("hrp2_like")
    planner = planner_for(robot.name, ReachingOptions())
    sx, sy = planner.support.shoulder_in_mid["left"]
    reach = planner.envelope("left").at(1.0)
    assert planner.envelope("left").heights_m[3] == 1.0
    assert 0.6 < reach < planner.envelope("left").grid(3)[1]  # the probe alone overestimates it
    inside = plan_reach(robot, _request(robot, (sx + reach - 0.02, sy, 1.0)))
    assert not inside.stepped
    beyond = plan_reach(robot, _request(robot, (sx + reach + 0.04, sy, 1.0)))
    assert [a.kind for a in beyond.attempts] == ["no_step", "single"]
    assert beyond.attempts[0].violation.criterion in PAPER_CRITERIA
    _check_plan(robot, beyond)


def test_support_polygon_planner_faces_the_target_and_respects_the_bounds(robot):
    planner = SupportPolygonPlanner(robot)
    q0 = robot.q_half_sitting
    left = SolePose(*robot.sole_pose(q0, "left").translation[:2], 0.0)
    right = SolePose(*robot.sole_pose(q0, "right").translation[:2], 0.0)
    target = np.array([-0.8, 1.0, 0.9])
    goal = planner.comfort_stance(left, right, target, "left")
    distance, bearing = planner.from_shoulder(goal, target, "left")
    assert distance == pytest.approx(planner.comfort_reach_m["left"], abs=1e-9)
    assert bearing == pytest.approx(0.0, abs=1e-9)
    walk = planner.walk(left, right, goal, "left", max_steps=20)
    assert walk is not None and walk.n_steps >= planner.steps_needed(left, right, goal)
    validate_footsteps(walk.footsteps, planner.limits)
    assert walk.final_mid == pytest.approx(goal, abs=1e-9)
    assert planner.walk(left, right, goal, "left", max_steps=2) is None


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"hand": "middle"}, "side must be"),
        ({"target_world_m": np.array([0.5, 0.3])}, "target must be 3 finite numbers"),
        ({"target_world_m": np.array([0.5, 0.3, -0.1])}, "below the ground"),
        ({"R_world_hand": np.ones((3, 3))}, "not a rotation"),
    ],
)
def test_malformed_requests_are_invalid(change, message):
    robot = load_robot("hrp2_like")
    fields = {"hand": "left", "target_world_m": np.array([0.5, 0.3, 0.9]), "q_start": robot.q_half_sitting}
    fields.update(change)
    with pytest.raises(InvalidRequestError, match=message):
        plan_reach(robot, ReachRequest(**fields))


def test_a_start_not_standing_on_the_ground_is_invalid():
    robot = load_robot("hrp2_like")
    q = robot.q_half_sitting.copy()
    q[2] += 0.05
    with pytest.raises(InvalidRequestError, match="does not stand on flat ground"):
        plan_reach(robot, ReachRequest("left", np.array([0.5, 0.3, 0.9]), q))
    with pytest.raises(InvalidRequestError, match="q must have shape"):
        plan_reach(robot, ReachRequest("left", np.array([0.5, 0.3, 0.9]), q[:-1]))


def test_options_are_validated():
    with pytest.raises(InvalidRequestError, match="unknown criteria"):
        ReachingOptions(criteria=("manipulability", "luck"))
    with pytest.raises(InvalidRequestError, match="knot_stride"):
        ReachingOptions(knot_stride=0)
    with pytest.raises(InvalidRequestError, match="recovery_iterations"):
        ReachingOptions(recovery_iterations=-1)
    with pytest.raises(InvalidRequestError, match="manipulability_of"):
        ReachingOptions(manipulability_of="wrist")


def test_the_papers_experiment_triggers_on_its_two_criteria_and_keeps_a_stable_reshaping():
    """ "Experimental Results": only the manipulability and the end-effector error trigger, S = I; a
    reshaping whose motion has no ZMP inside the polygon is discarded, the kept one is inside."""
    options = ReachingOptions.paper_experiment()
    assert options.criteria == ("manipulability", "ee_error") and not options.other_arm_still
    assert options.joint_limit_selection_rad is None and options.weighted
    robot = load_robot("hrp2_like")
    # The defaults are the paper's on hrp2_like; TALOS adds the static torque (its weak shoulders).
    defaults = ReachingOptions()
    assert defaults.criteria_for(robot) == PAPER_CRITERIA and not defaults.other_arm_still
    assert defaults.criteria_for(load_robot("talos")) == (*PAPER_CRITERIA, "joint_torque")
    result = plan_reach(robot, _request(robot, FORWARD_BEYOND[robot.name]), options)
    first = result.attempts[0]
    assert result.stepped and first.violation.criterion in ("manipulability", "ee_error", "multibody_zmp")
    for attempt in result.attempts[:-1]:
        assert attempt.violation is not None
    assert result.attempts[-1].violation is None
    _check_plan(robot, result)


# ------------------------------------------------------------------------------------------ in the sim
def _execute(robot, target) -> tuple:
    from sim.world import World

    with World(robot, "empty") as world:
        q0 = world.state().q
        hand = "left" if target[1] >= 0 else "right"
        result = plan_reach(robot, ReachRequest(hand, np.array(target, dtype=float), q0))
        execution = world.execute(result.q, hold_s=1.0)
        q = world.state().q
        hand_error = float(np.linalg.norm(robot.frame_pose(q, robot.frames.grasp(hand)).translation - target))
        return result, execution, hand_error, world.fallen()


@pytest.mark.slow
@pytest.mark.integration
@pytest.mark.parametrize("case", ["within", "forward", "sideways"])
def test_reaching_in_the_sim(robot, case):
    target = {"within": WITHIN_REACH, "forward": FORWARD_BEYOND, "sideways": SIDEWAYS_BEYOND}[case][
        robot.name
    ]
    result, execution, hand_error, fallen = _execute(robot, target)
    assert result.stepped == (case != "within")
    assert execution.outcome == "completed", execution.message
    assert not fallen
    assert hand_error < 0.01, f"hand {1e3 * hand_error:.1f} mm from the target"
    assert execution.foot_slip_m < 0.01
