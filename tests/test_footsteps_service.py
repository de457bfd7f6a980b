"""The footsteps service over a real zenoh bus: a plan (footsteps, final configuration, residuals),
malformed requests answered with ``invalid_request`` while the service keeps serving, and an
unreachable target answered with ``infeasible`` and the residuals within the request's budget."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from services.bus.schemas import footsteps as msg
from services.bus.schemas.navigation import ObstacleMsg
from services.errors import InfeasibleError, InvalidRequestError, RequestTimeoutError
from services.footsteps.geometry import disks_covering
from services.footsteps.service import plan_reply, planner_options
from services.model import load_robot
from services.model.ground import Rectangle
from services.walking.footsteps import (
    Footstep,
    FootstepBounds,
    FootstepSequence,
    SolePose,
    validate_footsteps,
)

pytestmark = [pytest.mark.integration, pytest.mark.slow]

TARGET = [1.2, -0.2, 0.8]
REQUEST = msg.PlanRequest(
    tasks=[msg.Task(kind="reach", target=TARGET, hand="right"), msg.Task(kind="posture")],
    disks=[msg.Disk(x=0.6, y=0.0, radius=0.15)],
)


@pytest.fixture(scope="module")
def client(module_bus_harness):
    module_bus_harness.spawn_service("services.footsteps.service", name="footsteps", timeout_s=120)
    return module_bus_harness.client


@pytest.fixture(scope="module")
def robot():
    return load_robot("hrp2_like")


def test_plan_over_the_bus_returns_footsteps_and_the_final_configuration(client, robot):
    reply = client.call(msg.PLAN, REQUEST, timeout_s=120)
    assert reply.model == "hrp2_like" and reply.joint_names == list(robot.joint_names)
    assert reply.q_final.shape == (robot.nq,) and reply.q_final.dtype == np.float64
    assert len(reply.footsteps) >= 1 and reply.iterations > 0 and reply.solve_time_s > 0.0
    assert len(reply.steps_added_at) == reply.chain_steps - 1  # the chain starts with one step
    assert {a.front_foot for a in reply.alternatives} <= {"left", "right"}
    reach, posture = reply.residuals
    assert reach.name == "reach:right" and reach.solved and reach.value <= reach.tolerance == 2e-3
    assert posture.name == "posture" and posture.tolerance is None  # an objective
    # the footsteps are a sequence the walking pattern generator accepts, outside the disk
    sequence = FootstepSequence(
        SolePose(*reply.left_start),
        SolePose(*reply.right_start),
        tuple(Footstep(s.side, SolePose(s.x, s.y, s.yaw)) for s in reply.footsteps),  # type: ignore[arg-type]
    )
    validate_footsteps(sequence, FootstepBounds.from_robot(robot))
    for step in reply.footsteps:
        distance = Rectangle((step.x, step.y), robot.sole_size_m, step.yaw).signed_distance((0.6, 0.0))[0]
        assert distance >= 0.15 - 1e-3
    # the final configuration stands on the last footprints with the hand on the target
    hand = robot.frame_pose(reply.q_final, robot.frames.grasp("right")).translation
    assert np.linalg.norm(hand - np.array(TARGET)) <= 2e-3
    last = {s.side: s for s in reply.footsteps}
    for side, step in last.items():
        sole = robot.sole_pose(reply.q_final, side).translation
        assert np.allclose(sole[:2], [step.x, step.y], atol=2e-3) and abs(sole[2]) < 2e-3
    # stateless and reproducible: the same plan as in this process, bit for bit
    local = plan_reply(REQUEST)
    assert local.footsteps == reply.footsteps
    np.testing.assert_array_equal(local.q_final, reply.q_final)


def test_trace_returns_the_task_values_per_iteration(client):
    reply = client.call(msg.PLAN, msgspec.structs.replace(REQUEST, trace=True), timeout_s=120)
    assert reply.task_values is not None and reply.task_values.shape == (reply.iterations + 1, 2)
    assert reply.task_values[-1, 0] == pytest.approx(reply.residuals[0].value)


@pytest.mark.parametrize(
    ("request_", "field"),
    [
        (msg.PlanRequest(tasks=[msg.Task(kind="wave", target=[1, 0, 1])]), r"tasks\[0\]\.kind"),
        (msg.PlanRequest(tasks=[msg.Task(kind="reach")]), r"tasks\[0\]\.target"),
        (
            msg.PlanRequest(tasks=[msg.Task(kind="reach", target=[1, 0, 1], hand="middle")]),
            r"tasks\[0\]\.hand",
        ),
        (msg.PlanRequest(tasks=[]), "tasks"),
        (msg.PlanRequest(tasks=[msg.Task(kind="posture")], q_start=np.zeros(10)), "q_start"),
        (
            msg.PlanRequest(tasks=[msg.Task(kind="posture")], disks=[msg.Disk(x=1, y=0, radius=-1)]),
            r"disks\[0\]",
        ),
        (msg.PlanRequest(tasks=[msg.Task(kind="posture")], front_foot="both"), "front_foot"),
        (
            msg.PlanRequest(
                tasks=[msg.Task(kind="posture")],
                boxes=[ObstacleMsg(name="box", center=[1.0, 0.0, 0.3], size=[0.0, 0.5, 0.6])],
            ),
            r"boxes\[0\]",
        ),
        (msg.PlanRequest(tasks=[msg.Task(kind="posture")], model="nao"), "nao"),
        (msg.PlanRequest(tasks="oops"), r"\$\.tasks"),  # type: ignore[arg-type]  (wrong type on the wire)
        (
            msg.PlanRequest(tasks=[msg.Task(kind="posture")], options=msg.Options(damping=-1.0)),
            r"options\.damping",
        ),
        (
            msg.PlanRequest(tasks=[msg.Task(kind="posture")], options=msg.Options(polish_iterations=5000)),
            r"options\.polish_iterations",
        ),
    ],
)
def test_malformed_requests_are_invalid_and_the_service_keeps_serving(client, request_, field):
    with pytest.raises(InvalidRequestError, match=field):
        client.call(msg.PLAN, request_, timeout_s=60)
    # still serving: a small plan right after
    reply = client.call(
        msg.PLAN, msg.PlanRequest(tasks=[msg.Task(kind="reach", target=[0.3, -0.25, 0.8])]), timeout_s=60
    )
    assert reply.footsteps == [] and reply.residuals[0].solved


def test_algorithm_1_numerics_switched_to_the_papers_form_over_the_bus(client):
    """The request's options turn each numerical device of Algorithm 1 off (eqs. 2, 7, 15 as written):
    the planner runs without them (another plan). Undamped, it usually still solves this reach, but it
    once stalled 2.5 mm short in a full suite run (a local minimum: the pseudo-inverse without damping
    is that fragile): either way the reply shows the options were honoured."""
    paper = msg.Options(saturation=False, dq_cap=False, epsilon_rule=False, polish_iterations=0)
    paper = msgspec.structs.replace(paper, damping=0.0, error_damping=0.0)
    options = planner_options(paper)
    assert math.isinf(options.dq_max) and math.isinf(options.max_rate_m) and math.isinf(options.max_rate_rad)
    assert math.isinf(options.relative_epsilon) and options.polish_iterations == 0 and options.damping == 0
    default = client.call(msg.PLAN, REQUEST, timeout_s=120)
    try:
        reply = client.call(msg.PLAN, msgspec.structs.replace(REQUEST, options=paper), timeout_s=120)
    except InfeasibleError as exc:  # the undamped descent stalled: a typed answer naming why
        assert exc.details["reason"] == "stalled" and exc.details["residuals"]["reach:right"] < 0.05
        assert exc.details["iterations"] != default.iterations
        return
    assert reply.residuals[0].solved
    assert (reply.iterations, len(reply.footsteps)) != (default.iterations, len(default.footsteps))


def test_a_payload_that_is_not_a_request_is_invalid(client):
    with pytest.raises(InvalidRequestError):
        client.call_raw("footsteps", "plan", b"not json", timeout_s=30)


def test_unreachable_target_is_infeasible_with_the_residuals_within_the_budget(client):
    budget_s = 20.0
    request = msg.PlanRequest(tasks=[msg.Task(kind="reach", target=[0.5, 0.0, 5.0])], time_budget_s=budget_s)
    # infeasible when Algorithm 1 stops, timeout (same details) when the budget stops it first
    with pytest.raises((InfeasibleError, RequestTimeoutError), match="reach:right") as info:
        client.call(msg.PLAN, request, timeout_s=budget_s + 60)
    details = info.value.details
    assert details["residuals"]["reach:right"] > 3.0  # 5 m up, the hand stays below 2 m
    assert details["reason"] in ("stalled", "max_steps", "time_budget")
    assert (details["reason"] == "time_budget") == isinstance(info.value, RequestTimeoutError)
    assert details["solve_time_s"] <= budget_s + 2.0  # the budget is checked between iterations
    assert details["steps"] >= 0 and details["iterations"] > 0


def test_boxes_are_obstacles_covered_by_disks(robot):
    """A map's box (as navigation takes it) between the robot and the target: the footsteps keep out of
    its rectangle, and the plan is the one of the disks that cover it (no bus: the service's adapter)."""
    box = ObstacleMsg(name="green_box", center=[0.9, -0.1, 0.35], size=[0.5, 0.6, 0.7], yaw=0.3)
    tasks = [msg.Task(kind="reach", target=[1.1, -0.1, 0.8], hand="right"), msg.Task(kind="posture")]
    reply = plan_reply(msg.PlanRequest(tasks=tasks, boxes=[box]))
    rect = Rectangle((0.9, -0.1), (0.5, 0.6), 0.3)
    disks = disks_covering(rect)
    assert len(disks) == 2  # 0.6 m by 0.5 m: two cells along its length
    for corner in rect.corners():  # every corner inside a disk
        assert any(np.hypot(corner[0] - x, corner[1] - y) <= r + 1e-9 for x, y, r in disks)
    assert reply.footsteps and reply.residuals[0].solved
    for step in reply.footsteps:
        sole = Rectangle((step.x, step.y), robot.sole_size_m, step.yaw)
        assert min(rect.signed_distance(sole.corners())) > 0.0
    same = plan_reply(msg.PlanRequest(tasks=tasks, disks=[msg.Disk(x=x, y=y, radius=r) for x, y, r in disks]))
    assert same.footsteps == reply.footsteps
