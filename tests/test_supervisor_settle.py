"""Dead ends after an unplanned contact, on a real bus (sim, walking, reaching, perception): a hand left
resting on a crate is freed by the ``replan`` remedy (the sim lets a motion leave a contact it starts
in); a sole left up and tilted by a stopped step is settled (``walking/goal`` ``kind: settle``), after
which walking plans again; a robot held up by something is refused with ``leaning``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.bus.schemas import sim as sim_msg
from services.bus.schemas import walking as walk_msg
from services.errors import CollisionError, InfeasibleError, InvalidRequestError
from services.model import load_robot
from sim import motions
from supervisor.core import Supervisor
from supervisor.report import ActionReport
from supervisor.script import Step

CRATE = (
    "name: crate\ndescription: a crate beside the right arm\nrobot: {x: 0.0, y: 0.0, yaw: 0.0}\n"
    "floor: {colour: light_grey, friction: 1.0}\nobjects:\n"
    "  - {name: crate, kind: box, size: [0.3, 0.3, 1.0], colour: blue, xy: [0.45, -0.3], yaw: 0.0}\n"
)


@pytest.fixture(scope="module")
def stack(module_bus_harness, tmp_path_factory):
    h = module_bus_harness
    h.scene_dir = tmp_path_factory.mktemp("scenes")
    (h.scene_dir / "crate.yaml").write_text(CRATE)
    h.spawn_service("sim.service", "--scene", "empty", "--scene-dir", str(h.scene_dir), name="sim")
    h.spawn_service("services.walking.service", name="walking")
    h.spawn_service("services.reaching.service", name="reaching")
    h.spawn_service("services.perception.service", name="perception")
    return h


@pytest.fixture(scope="module")
def sup(stack):
    s = Supervisor(stack.session, stack.bus.robot)
    try:
        yield s
    finally:
        s.close()


def _soles(model, q):
    """{side: (height [m], tilt [rad])} of the soles at ``q``."""
    out = {}
    for side in ("left", "right"):
        T = model.sole_pose(q, side)
        out[side] = (float(T.translation[2]), math.acos(min(1.0, float(T.rotation[2, 2]))))
    return out


def test_a_hand_left_on_a_crate_is_freed_by_the_replan_remedy(stack, sup) -> None:
    """The right arm swings into the crate and stops on it (RARM_LINK5 pressing): the replan remedy
    backs the hand off (reaching, the motion starting in that contact) and maps the crate; the robot
    then holds still touching nothing. Before, every motion from there stopped at 5 ms."""
    stack.client.call(sim_msg.RESET, sim_msg.ResetRequest(scene="crate"), 30)
    actions = sup.actions
    body = actions.body
    model = load_robot(body.robot.name)
    swing = motions.joint_motion(model, body.q(), {"RARM_JOINT0": -1.2}, 1.0)
    with pytest.raises(CollisionError) as stopped:
        body.execute(swing, what="swing")
    body.interrupted = None  # not backed out: the hand stays on the crate (a back-off left it there)
    details = stopped.value.details
    assert {c.other for c in details["collisions"]} == {"crate"}
    report = ActionReport("walk", ("0.2", "0"), ok=False, reason="collision", details=details)
    said: list[str] = []
    progress, actions.progress = actions.progress, said.append
    try:
        actions.replan(Step(1, "walk", ("0.2", "0")), report)
    finally:
        actions.progress = progress
    assert any("backing the right hand off crate" in line for line in said), said
    q = body.q()
    done = body.execute(np.repeat(q[None, :], 20, axis=0), what="hold still")  # no contact left
    assert done.duration_s > 0.09


def test_a_sole_left_up_and_tilted_is_settled_and_walking_plans_again(stack, sup) -> None:
    """A step stopped 1.4 cm above the ground on its way down, the foot then tilted 0.1 rad: walking
    refuses to plan from there; the settle brings both soles flat (measured) and the body over them,
    and the same walk is then planned."""
    stack.client.call(sim_msg.RESET, sim_msg.ResetRequest(scene="empty"), 30)
    actions = sup.actions
    body = actions.body
    model = load_robot(body.robot.name)
    step = walk_msg.PlanRequest(q_start=body.q(), steps=[walk_msg.Step(pose=[0.15, 0.095, 0.0], side="left")])
    walk = stack.client.call(walk_msg.PLAN, step, 60)
    left = np.asarray(walk.left_sole)
    k = next(i for i in range(1, len(left)) if left[i, 2] < left[i - 1, 2] and left[i, 2] < 0.015)
    body.execute(np.asarray(walk.q)[: k + 1], what="a step stopped short", hold_s=0.3)
    ankle = body.robot.index("LLEG_JOINT4")
    q = body.q()
    tilt = motions.joint_motion(model, q, {"LLEG_JOINT4": q[ankle] + 0.1}, 0.5)
    body.execute(tilt, what="tilt the raised foot", hold_s=0.3)
    before = _soles(model, body.q())
    assert before["left"][0] > 0.01 and before["left"][1] > 0.05, before
    with pytest.raises(InvalidRequestError):
        actions.planners.walk(0.1, 0.0, 0.0)
    actions.settle()
    after = _soles(model, body.q())
    for side, (height, tilt) in after.items():
        assert abs(height) < 0.002 and tilt < 0.01, (side, after)
    x, y, _ = body.base_xy_yaw()
    com = model.com(body.q())
    assert math.hypot(com[0] - x, com[1] - y) < 0.03  # the body over the middle of the feet
    assert actions.planners.walk(0.1, 0.0, 0.0).n_steps >= 2  # planned from there now
    with pytest.raises(InvalidRequestError) as settled:  # standing flat: nothing to settle
        stack.client.call(walk_msg.GOAL, walk_msg.GoalRequest(q_start=body.q(), kind="settle"), 30)
    assert settled.value.details["reason"] == walk_msg.REASON_ALREADY_SETTLED


def test_a_robot_held_up_by_something_cannot_settle(stack) -> None:
    """The CoM 0.2 m ahead of the toes (the robot pitched forward, as if leaning on a table): no motion of
    the feet can settle it: ``infeasible`` with reason ``leaning``."""
    model = load_robot("hrp2_like")
    q = model.half_sitting_at(0.0, 0.0, 0.0)
    import pinocchio as pin

    pitch = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.35, 0.0), np.array([0.12, 0.0, 0.0]))
    toes = pin.SE3(np.eye(3), np.array([-0.12, 0.0, 0.0]))
    q[:7] = pin.SE3ToXYZQUAT(pitch * toes * pin.XYZQUATToSE3(q[:7]))
    assert model.com(q)[0] > 0.2
    with pytest.raises(InfeasibleError, match="leans on something") as leaning:
        stack.client.call(walk_msg.GOAL, walk_msg.GoalRequest(q_start=q, kind="settle"), 30)
    assert leaning.value.details["reason"] == walk_msg.REASON_LEANING


def test_the_anchor_is_the_sole_on_the_ground_not_the_flatter_one() -> None:
    """A step stopped mid-swing keeps its foot flat in the air while the standing foot rolls a little:
    the settle stands on the foot on the ground (before, the flatter sole, the one in the air, was taken
    for the support and the CoM moved toward it before it landed)."""
    import pinocchio as pin

    from services.walking.settle import anchor_side

    model = load_robot("hrp2_like")
    q = model.half_sitting_at(0.0, 0.0, 0.0)
    lift = 0.05  # hip -a, knee +2a, ankle -a: the foot rises about 7 mm, kept flat (equal thigh and shank)
    for joint, factor in (("LLEG_JOINT2", -1.0), ("LLEG_JOINT3", 2.0), ("LLEG_JOINT4", -1.0)):
        q[model.joint_index(joint).idx_q] += factor * lift
    q[model.joint_index("RLEG_JOINT5").idx_q] += 0.005  # the standing sole rolled onto an edge
    soles = {side: model.sole_pose(q, side) for side in ("left", "right")}
    length, width = (float(v) for v in model.sole_size_m)
    up = {side: float(T.translation[2]) for side, T in soles.items()}
    tilt = {side: math.acos(min(1.0, float(T.rotation[2, 2]))) for side, T in soles.items()}
    assert up["left"] > 0.004 and tilt["left"] < tilt["right"], (up, tilt)  # in the air, the flatter one
    assert anchor_side(soles, length, width) == "right"
    flat = {side: pin.SE3(np.eye(3), T.translation * [1, 1, 0]) for side, T in soles.items()}
    assert anchor_side({**flat, "left": soles["left"]}, length, width) == "right"
