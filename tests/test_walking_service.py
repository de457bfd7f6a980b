"""The walking service (services/walking/service.py): its adapter without the bus (request -> reply,
errors, upper-body tasks), then over a real zenoh bus with the sim service: plan through
``walking/plan``, execute through ``sim/execute``, and ``humanoid call walking/plan``."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from services.bus.codec import encode, from_builtins
from services.bus.schemas import sim as sim_msg
from services.bus.schemas import walking as msg
from services.errors import InfeasibleError, InvalidRequestError
from services.model import load_robot
from services.model.ground import mid_feet
from services.walking.footsteps import SolePose, straight_walk
from services.walking.goals import soles_on, square_up
from services.walking.service import goal_reply, goal_steps, plan_reply

REPO = Path(__file__).resolve().parent.parent

TWO_STEPS = [{"pose": [0.2, -0.095, 0.0]}, {"pose": [0.2, 0.095, 0.0]}]


def _request(**fields) -> msg.PlanRequest:
    return from_builtins({"steps": TWO_STEPS, **fields}, msg.PlanRequest)


# ------------------------------------------------------------------------------------- adapter, no bus


def test_plain_json_request_gives_the_whole_walk():
    reply = plan_reply(_request())
    robot = load_robot("hrp2_like")
    n = reply.times_s.shape[0]
    assert reply.q.shape == (n, robot.nq) and reply.joint_names == list(robot.joint_names)
    for name, cols in (("com_m", 3), ("zmp_ref_m", 2), ("zmp_multibody_m", 2), ("left_sole", 4)):
        assert getattr(reply, name).shape == (n, cols), name
    assert reply.phase.dtype == np.int8 and set(np.unique(reply.phase)) == {0, 1, 2}
    np.testing.assert_allclose(reply.q[0], robot.q_half_sitting)  # q_start omitted: half-sitting
    assert [s.side for s in reply.steps] == ["right", "left"]  # alternating from first_side
    assert reply.steps[0].lift_off_s < reply.steps[0].touch_down_s <= reply.steps[1].lift_off_s
    assert reply.final_left_sole == [0.2, 0.095, 0.0]
    f = reply.figures
    assert f.min_zmp_margin_m >= 0.010 and f.worst_zmp_outside_m == 0.0
    assert f.second_stage_acted == (f.second_stage_passes > 0)
    np.testing.assert_allclose(reply.zmp_margin_m.min(), f.min_zmp_margin_m)
    # Stateless and deterministic: the same request gives the same bytes.
    assert encode(plan_reply(_request())) == encode(reply)


def test_stop_at_end_adds_the_final_hold():
    held, brief = plan_reply(_request()), plan_reply(_request(stop_at_end=False))
    assert held.figures.duration_s == pytest.approx(brief.figures.duration_s + _request().final_hold_s)
    assert np.abs(held.q[-1] - held.q[-2]).max() < 1e-6  # at rest at the end
    # Without the hold, nearly: the joints follow the CoM's end blend with the whole-body IK's lag after
    # the 0.5 s last transfer (5.5e-6 rad per sample measured; 8.8e-7 after 0.7 s).
    assert np.abs(brief.q[-1] - brief.q[-2]).max() < 1e-5


def test_step_beyond_the_bounds_is_infeasible_and_named():
    steps = [*TWO_STEPS, {"pose": [0.5, -0.095, 0.0]}]
    with pytest.raises(InfeasibleError) as err:
        plan_reply(from_builtins({"steps": steps}, msg.PlanRequest))
    assert err.value.message.startswith("step 2 (right foot): dx=0.3000 m relative to the left sole")
    assert err.value.details["step_index"] == 2


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"steps": [{"pose": [0.0, 0.0, 0.0]}]}, r"feet overlap after step 0 \(right foot\)"),
        ({"double_support_s": 0.0}, "double_support_s must be > 0 s"),
        ({"steps": []}, "no step"),
        ({"first_side": "middle"}, "first_side must be one of"),
        ({"steps": [{"pose": [0.2, -0.095]}]}, r"length >= 3 - at `\$\.steps\[0\]\.pose`"),
        ({"model": "nao"}, "unknown robot 'nao'"),
        ({"q_start": [0.0] * 5}, r"q_start must have shape \(37,\)"),
        ({"left_start": [0.0, 0.3, 0.0]}, "give both left_start and right_start"),
        ({"hands": [{"side": "middle"}]}, "side must be one of"),
        ({"gaze": {"point_m": [-3.0, 0.0, 1.0]}}, "behind the robot's head"),
    ],
)
def test_malformed_requests_are_invalid(fields, message):
    with pytest.raises(InvalidRequestError, match=message):
        plan_reply(_request(**fields))


def test_starting_soles_must_match_q_start():
    robot = load_robot("hrp2_like")
    request = _request(
        q_start=robot.q_half_sitting.tolist(), left_start=[0.01, 0.1, 0.0], right_start=[0.0, -0.095, 0.0]
    )
    with pytest.raises(InvalidRequestError, match="the left sole of q_start"):
        plan_reply(request)


def test_upper_body_tasks_hold_the_hands_and_the_gaze():
    """Carry with both hands (held in the walk frame), the left hand raised along a path, looking at a
    point 3 m ahead: every task met within a millimetre while the ZMP stays inside."""
    robot = load_robot("hrp2_like")
    steps = [
        {"side": s.side, "pose": s.pose.as_array().tolist()}
        for s in straight_walk(
            4, 0.15, left_start=SolePose(0, 0.095, 0), right_start=SolePose(0, -0.095, 0)
        ).steps
    ]
    hand_start = robot.frame_pose(robot.q_half_sitting, robot.frames.grasp("left")).translation
    com_start = robot.com(robot.q_half_sitting)
    raised = (hand_start - [com_start[0], com_start[1], 0.0] + [0.1, -0.05, 0.15]).tolist()
    request = from_builtins(
        {
            "steps": steps,
            "hands": [{"side": "right"}, {"side": "left", "times_s": [2.5], "positions_m": [raised]}],
            "gaze": {"point_m": [3.0, 0.0, 0.8]},
        },
        msg.PlanRequest,
    )
    reply = plan_reply(request)
    errors = reply.figures.task_errors
    assert set(errors) == {"right_hand", "right_hand_rotation", "left_hand", "left_hand_rotation", "gaze"}
    assert errors["right_hand"] < 1e-3 and errors["left_hand"] < 1e-3 and errors["gaze"] < 1e-3, errors
    assert reply.figures.worst_zmp_outside_m == 0.0
    # The left hand really went up by 0.15 m (in the walk frame, which stays at the ground).
    data = robot.new_data()
    k = int(np.searchsorted(reply.times_s, 3.0))
    z = robot.frame_pose(reply.q[k], robot.frames.grasp("left"), data).translation[2]
    assert z == pytest.approx(hand_start[2] + 0.15, abs=2e-3)


def test_unreachable_hand_target_is_infeasible_and_named():
    far = {"side": "left", "frame": "walk", "times_s": [2.0], "positions_m": [[0.9, 0.3, 1.0]]}
    with pytest.raises(
        InfeasibleError, match=r"upper-body task left_hand cannot be met: it stays \d+ mm from its target"
    ):
        plan_reply(_request(hands=[far]))


# ------------------------------------------------------------------------------- walks to a goal, no bus


def _goal(**fields) -> msg.GoalRequest:
    robot = load_robot("hrp2_like")
    return from_builtins({"q_start": list(robot.q_half_sitting), **fields}, msg.GoalRequest)


def _box(name: str, x: float, y: float, sx: float = 0.4, sy: float = 0.4) -> dict:
    return {"name": name, "center": [x, y, 0.3], "size": [sx, sy, 0.6], "yaw": 0.0}


def _final_mid(sequence) -> SolePose:
    left, right = sequence.final_stance()
    return mid_feet(left, right)


def test_goal_pose_relative_to_the_robot_is_reached_within_the_bounds():
    robot = load_robot("hrp2_like")
    # One metre forward, 0.2 m to the left, turned by 30 deg: the planner picks the steps.
    _q, seq = goal_steps(_goal(pose=[1.0, 0.2, math.radians(30)]), robot)
    end = _final_mid(seq)
    assert (end.x_m, end.y_m) == pytest.approx((1.0, 0.2), abs=1e-6)
    assert end.yaw_rad == pytest.approx(math.radians(30), abs=1e-6)
    assert len(seq.steps) >= 6  # 1 m does not fit in fewer steps of at most 0.22 m
    # Stepping back: the same in the other direction; a world-frame goal is the same walk.
    _q, back = goal_steps(_goal(pose=[-0.3, 0.0, 0.0]), robot)
    assert _final_mid(back).x_m == pytest.approx(-0.3, abs=1e-6)
    _q, world = goal_steps(_goal(pose=[-0.3, 0.0, 0.0], frame="world"), robot)
    assert [s.pose for s in world.steps] == pytest.approx([s.pose for s in back.steps])


def test_a_walk_there_then_a_turn_turns_in_few_steps_and_may_face_the_way():
    """Fetch seed 16's walk to the box: 1.02 m forward, 0.51 m left, -32 deg. Together the feet would
    cross; walked there first, its turn took as many steps as the walk (24 steps, 12 of them turning
    by 2.9 deg): now the turn takes the fewest pairs (2 steps), and facing the way (turn toward the
    goal, walk straight, turn there: navigation's straight walks) is taken when it has fewer steps.
    Both end at the goal, within the bounds."""
    from services.model.ground import FootstepBounds, validate_footsteps
    from services.walking.goals import walk_to_steps

    robot = load_robot("hrp2_like")
    soles = soles_on(robot, np.array(robot.q_half_sitting))
    limits = FootstepBounds.from_robot(robot)
    goal = (1.02, 0.51, math.radians(-32.0))
    start = mid_feet(soles["left"], soles["right"])
    for face, most in ((False, 14), (True, 13)):
        seq = walk_to_steps(soles, *goal, limits, face_the_way=face)
        validate_footsteps(seq, limits)
        assert len(seq.steps) <= most
        end = mid_feet(*seq.final_stance()).relative_to(start)
        assert end == pytest.approx(goal, abs=1e-3)
    turns = [
        s for s in walk_to_steps(soles, *goal, limits).steps if abs(s.pose.yaw_rad - start.yaw_rad) > 1e-6
    ]
    assert len(turns) == 2
    # 0.9 m to the left and 0.4 m forward: facing the way is shortest,
    # in forward strides of at most MAX_STRIDE_M (fetch seed 9: 0.214 m, ball held: knee at 7.5 rad/s).
    from services.walking.goals import MAX_STRIDE_M

    seq = walk_to_steps(soles, 0.4, 0.9, 0.3, limits, face_the_way=True)
    assert len(seq.steps) <= min(14, len(walk_to_steps(soles, 0.4, 0.9, 0.3, limits).steps))
    stances = seq.stances()
    for i, step in enumerate(seq.steps):
        before = stances[i][0] if step.side == "left" else stances[i][1]
        assert step.pose.relative_to(before)[0] <= 2 * MAX_STRIDE_M + 1e-6  # the foot moves 2 strides


def test_goal_turn_on_the_spot_and_the_walk_it_plans():
    robot = load_robot("hrp2_like")
    reply = goal_reply(_goal(kind="turn", angle_rad=math.radians(90)))
    assert len(reply.steps) == 6 and reply.figures.worst_zmp_outside_m == 0.0  # pairs of <= 0.98 pi/4
    left, right = reply.final_left_sole, reply.final_right_sole
    assert [left[2], right[2]] == pytest.approx([math.pi / 2] * 2, abs=1e-6)
    soles = soles_on(robot, np.array(robot.q_half_sitting))
    start = mid_feet(soles["left"], soles["right"])
    assert 0.5 * (left[0] + right[0]) == pytest.approx(start.x_m, abs=0.03)  # on the spot


@pytest.mark.parametrize("front", ["left", "right"])
def test_a_turn_from_a_staggered_stance_squares_up_first_and_stays_within_the_bounds(front):
    """After a reaching step one foot is 0.2 m ahead: the rear foot first steps beside it (parallel, at the
    same lateral distance), then every step of the turn is within HRP-2's bounds."""
    from services.model.ground import FootstepBounds, validate_footsteps
    from services.walking.goals import turn_steps

    limits = FootstepBounds()
    yaw = 0.7
    c, s = math.cos(yaw), math.sin(yaw)

    def sole(ahead: float, left: float) -> SolePose:
        return SolePose(1.0 + c * ahead - s * left, 2.0 + s * ahead + c * left, yaw)

    soles = {"left": sole(0.2 if front == "left" else 0.0, 0.095)}
    soles["right"] = sole(0.2 if front == "right" else 0.0, -0.095)
    step = square_up(soles, limits)
    rear = "right" if front == "left" else "left"
    assert step is not None and step.side == rear
    squared = {**soles, rear: step.pose}
    assert square_up(squared, limits) is None
    left, right = squared["left"], squared["right"]
    assert math.dist((left.x_m, left.y_m), (right.x_m, right.y_m)) == pytest.approx(0.19)
    turn = turn_steps(soles, -2.1, limits)
    assert turn.steps[0] == step
    validate_footsteps(turn, limits)
    end = _final_mid(turn)
    assert end.yaw_rad == pytest.approx(math.remainder(yaw - 2.1, 2 * math.pi), abs=1e-6)


def test_goal_walks_are_checked_against_the_map_boxes():
    robot = load_robot("hrp2_like")
    # A box right behind: stepping back 0.5 m would put the heels in it.
    with pytest.raises(InfeasibleError) as err:
        goal_steps(_goal(pose=[-0.5, 0.0, 0.0], obstacles=[_box("chair", -0.6, 0.0)]), robot)
    assert err.value.details["reason"] == msg.REASON_BLOCKED and err.value.details["obstacle"] == "chair"
    assert "chair" in err.value.message
    # A walk forward past a box beside the line: it keeps clear by less than the clearance.
    with pytest.raises(InfeasibleError) as err:
        goal_steps(_goal(pose=[1.2, 0.0, 0.0], obstacles=[_box("box", 0.6, 0.35)]), robot)
    assert err.value.details["reason"] == msg.REASON_BLOCKED
    # The same box far enough to the side is no obstacle; nor is a table ahead stepped away from.
    goal_steps(_goal(pose=[1.2, 0.0, 0.0], obstacles=[_box("box", 0.6, 0.8)]), robot)
    goal_steps(_goal(pose=[-0.3, 0.0, 0.0], obstacles=[_box("table", 0.45, 0.0)]), robot)
    # No room to turn next to a box; room enough a step away.
    with pytest.raises(InfeasibleError) as err:
        goal_steps(_goal(kind="turn", angle_rad=1.0, obstacles=[_box("table", 0.4, 0.0)]), robot)
    assert err.value.details["reason"] == msg.REASON_NO_ROOM_TO_TURN and "table" in err.value.message
    goal_steps(_goal(kind="turn", angle_rad=1.0, obstacles=[_box("table", 0.6, 0.0)]), robot)


def test_goal_turn_with_a_step_back_is_one_walk_checked_where_each_part_is():
    """Stepping back for room and turning: one walk (one start, one stop), the turn's room checked
    where it starts (after the step back), not where the robot stands now."""
    robot = load_robot("hrp2_like")
    table = [_box("table", 0.45, 0.0)]
    with pytest.raises(InfeasibleError) as err:  # no room to turn here
        goal_steps(_goal(kind="turn", angle_rad=-2.0, obstacles=table), robot)
    assert err.value.details["reason"] == msg.REASON_NO_ROOM_TO_TURN
    _q, both = goal_steps(_goal(kind="turn", angle_rad=-2.0, back_m=0.3, obstacles=table), robot)
    _q, back = goal_steps(_goal(pose=[-0.3, 0.0, 0.0]), robot)
    assert both.steps[: len(back.steps)] == back.steps
    end = _final_mid(both)
    assert end.x_m == pytest.approx(-0.3, abs=0.03) and end.yaw_rad == pytest.approx(-2.0, abs=1e-6)
    # The stand-still between the two is gone: shorter than the two walks by a start and a stop.
    one = goal_reply(_goal(kind="turn", angle_rad=-2.0, back_m=0.3, obstacles=table))
    turn = goal_reply(_goal(kind="turn", angle_rad=-2.0))
    two = goal_reply(_goal(pose=[-0.3, 0.0, 0.0])).figures.duration_s + turn.figures.duration_s
    timing = msg.PlanRequest(steps=[])
    stand_still = (
        timing.initial_hold_s
        + timing.initial_double_support_s
        + timing.final_double_support_s
        + timing.final_hold_s
        - timing.double_support_s
    )
    assert one.figures.duration_s == pytest.approx(two - stand_still, abs=0.01)
    assert one.figures.worst_zmp_outside_m == 0.0


def test_stepping_back_from_beside_a_box_keeps_the_legs_out_of_it():
    """Fetch seed 37: after reaching into a box the left foot stood 6 cm ahead of the right, whose toe
    was 4 cm from the box. Stepping back led by the rear (right) foot, the weight went forward onto the
    left and the right thigh came forward as its foot lifted: it touched the box (every footprint
    clear of it). The planner checks the legs' swept volume (3D) and leads with the front foot."""
    from services.collision import obstacle_from_msg
    from services.walking.sweep import check_legs_clear

    robot = load_robot("hrp2_like")
    staggered = plan_reply(_request(steps=[{"pose": [0.06, 0.126, 0.033], "side": "left"}]))
    q = list(staggered.q[-1])
    box = {"name": "green_box", "center": [0.47, -0.275, 0.355], "size": [0.605, 0.511, 0.71], "yaw": 1.643}
    request = _goal(q_start=q, pose=[-0.45, 0.0, 0.0], obstacles=[box])
    reply = goal_reply(request)
    assert reply.steps[0].side == "left"
    # Led by the rear foot, the same step back sweeps the right thigh toward the box: refused.
    _q, rear_first = goal_steps(request, robot, "right")
    walked = plan_reply(
        msg.PlanRequest(
            steps=[msg.Step(pose=s.pose.as_array().tolist(), side=s.side) for s in rear_first.steps],
            q_start=np.asarray(q),
            left_start=rear_first.left_start.as_array().tolist(),
            right_start=rear_first.right_start.as_array().tolist(),
        )
    )
    boxes = [obstacle_from_msg(from_builtins(box, msg.ObstacleMsg))]
    with pytest.raises(InfeasibleError) as err:
        check_legs_clear(robot, np.asarray(walked.q), walked.dt_s, boxes, clearance_m=0.02)
    assert err.value.details["reason"] == msg.REASON_BLOCKED and err.value.details["link"].startswith("RLEG")
    assert "green_box" in err.value.message
    check_legs_clear(robot, np.asarray(reply.q), reply.dt_s, boxes, clearance_m=0.02)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"kind": "jump"}, "kind must be one of"),
        ({"pose": [1.0, 0.0]}, r"pose must be \[x, y, yaw\]"),
        ({"pose": [1.0, 0.0, 0.0], "frame": "moon"}, "frame must be 'robot' or 'world'"),
        ({"kind": "square"}, "already square"),
        ({"pose": [0.1, 0.0, 0.0], "back_m": 0.2}, "back_m is for kind 'turn'"),
        ({"pose": [0.1, 0.0, 0.0], "clearance_m": -1.0}, r">= 0\.0 - at `\$\.clearance_m`"),
        (
            {"pose": [0.1, 0.0, 0.0], "obstacles": [{"name": "b", "center": [1.0, 0.0, 0.0], "size": [1.0]}]},
            r"obstacles\[0\]\.size",
        ),
    ],
)
def test_malformed_goal_requests_are_invalid(fields, message):
    with pytest.raises(InvalidRequestError, match=message):
        goal_steps(_goal(**fields), load_robot("hrp2_like"))


# ------------------------------------------------------------------------------------------- over the bus


@pytest.fixture(scope="module")
def services(module_bus_harness):
    module_bus_harness.spawn_service("services.walking.service", name="walking", timeout_s=60)
    module_bus_harness.spawn_service("sim.service", "--scene", "empty", name="sim", timeout_s=60)
    return module_bus_harness


def _yaw(robot, q, side) -> tuple[np.ndarray, float]:
    T = robot.sole_pose(q, side)
    return T.translation, math.atan2(T.rotation[1, 0], T.rotation[0, 0])


@pytest.mark.integration
def test_plan_over_the_bus_and_walk_in_the_sim(services):
    client = services.client
    state = client.call(sim_msg.STATE, sim_msg.StateRequest(), timeout_s=30)
    robot = load_robot(state.model)
    # Six steps of 0.2 m from where the robot stands (its soles measured on the sim's q).
    request = msg.PlanRequest(
        steps=[msg.Step(pose=[0.2 * min(k, 5), -0.095 if k % 2 else 0.095, 0.0]) for k in range(1, 7)],
        first_side="right",
        q_start=state.q,
    )
    plan = client.call(msg.PLAN, request, timeout_s=120)
    assert plan.q.shape[1] == robot.nq and plan.figures.worst_zmp_outside_m == 0.0
    # The plan starts at the state, joints clipped to their limits (a gripper reads -1e-9 at its 0 limit).
    np.testing.assert_allclose(plan.q[0], state.q, rtol=0.0, atol=1e-6)
    result = client.call(sim_msg.EXECUTE, sim_msg.ExecuteRequest(q=plan.q, hold_s=0.5), timeout_s=300)
    assert result.outcome == "completed", result.message
    for side, planned in (("left", plan.final_left_sole), ("right", plan.final_right_sole)):
        p, yaw = _yaw(robot, result.q, side)
        assert math.hypot(p[0] - planned[0], p[1] - planned[1]) < 0.02, (side, p, planned)
        assert abs(math.remainder(yaw - planned[2], 2 * math.pi)) < math.radians(2.0)
    # Errors come back typed, naming the step.
    far = msg.PlanRequest(steps=[msg.Step(pose=[0.6, -0.095, 0.0])], q_start=result.q)
    with pytest.raises(InfeasibleError) as err:
        client.call(msg.PLAN, far, timeout_s=60)
    assert err.value.details["step_index"] == 0
    # A goal instead of footsteps: turn on the spot by 45 deg, walked in the sim.
    turn = client.call(msg.GOAL, msg.GoalRequest(q_start=result.q, kind="turn", angle_rad=math.pi / 4), 120)
    done = client.call(sim_msg.EXECUTE, sim_msg.ExecuteRequest(q=turn.q, hold_s=0.5), timeout_s=300)
    assert done.outcome == "completed", done.message
    yaws = [_yaw(robot, done.q, side)[1] for side in ("left", "right")]
    assert yaws == pytest.approx([math.pi / 4] * 2, abs=math.radians(3.0))


@pytest.mark.integration
def test_humanoid_call_walking_plan_with_plain_json(services):
    request = json.dumps({"first_side": "right", "steps": TWO_STEPS})
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "services.cli",
            "call",
            "walking/plan",
            request,
            *services.bus_args(),
            "--timeout",
            "60",
            "--max-elements",
            "0",  # every array in full
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    reply = json.loads(out.stdout)
    assert len(reply["q"]) == len(reply["times_s"]) and len(reply["q"][0]) == 37
    assert reply["final_right_sole"] == [0.2, -0.095, 0.0]
    assert reply["figures"]["worst_zmp_outside_m"] == 0.0


def test_a_robot_standing_taller_walks_with_its_com_lowered():
    """After a reach the robot may stand a few cm higher than half-sitting (seed 6 of the fetch: 3.2 cm):
    walking 0.2 m steps at that CoM height stretches the front leg at heel strike near its straight knee,
    and a joint is refused for its speed (the knee, before session 10 a free arm ringing at 84-110
    rad/s); walking/plan then lowers the CoM (COM_LOWERINGS_M) and returns a walk within every joint's
    speed limit, unless the request fixes the CoM height."""
    from services.ik import ComPositionTask, FramePoseTask, HierarchicalSolver, Level, PostureTask

    robot = load_robot("hrp2_like")
    data, model, q0 = robot.new_data(), robot.model, robot.q_half_sitting
    feet = tuple(
        FramePoseTask(model, robot.frames.sole(s), robot.frame_pose(q0, robot.frames.sole(s), data), name=s)
        for s in ("left", "right")
    )
    com = ComPositionTask(model, robot.com(q0, data) + np.array([0.0, 0.0, 0.035]))
    levels = [Level(feet), Level((com,)), Level((PostureTask(model, q0),), damping=1e-6)]
    q_tall = HierarchicalSolver(model).run(levels, q0, max_iters=200).q
    standing_m = float(robot.com(q_tall, data)[2])
    steps = [
        {"side": "right", "pose": [0.1, -0.095, 0.0]},
        {"side": "left", "pose": [0.3, 0.095, 0.0]},
        {"side": "right", "pose": [0.5, -0.095, 0.0]},
        {"side": "left", "pose": [0.5, 0.095, 0.0]},
    ]
    request = {"steps": steps, "q_start": q_tall.tolist()}
    with pytest.raises(InfeasibleError, match=r"JOINT\d+ would move at .* rad/s"):
        plan_reply(from_builtins({**request, "com_height_m": standing_m}, msg.PlanRequest))
    reply = plan_reply(from_builtins(request, msg.PlanRequest))
    speed = np.abs(np.diff(reply.q[:, 7:], axis=0)) / (reply.times_s[1] - reply.times_s[0])
    assert np.all(speed <= robot.v_max[6:] + 1e-9)
    assert reply.com_m[-1, 2] < standing_m - 0.015  # it walked lower
