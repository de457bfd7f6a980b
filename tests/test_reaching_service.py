"""The reaching service over a real zenoh bus, with the sim service: plan a reach from the sim's state,
execute it in the sim, check the hand; and the error replies."""

from __future__ import annotations

import numpy as np
import pytest

from services.bus.schemas import reaching as reach_msg
from services.bus.schemas import sim as sim_msg
from services.bus.schemas.common import Sphere
from services.errors import InfeasibleError, InvalidRequestError
from services.model import load_robot

pytestmark = [pytest.mark.integration, pytest.mark.slow]


@pytest.fixture(scope="module")
def services(module_bus_harness):
    module_bus_harness.spawn_service("sim.service", "--scene", "empty", name="sim", timeout_s=60)
    module_bus_harness.spawn_service("services.reaching.service", name="reaching", timeout_s=120)
    return module_bus_harness.client


def test_reach_beyond_the_arm_steps_and_is_reached_in_the_sim(services):
    client = services
    robot = load_robot("hrp2_like")
    state = client.call(sim_msg.STATE, sim_msg.StateRequest(), timeout_s=30)
    target = [0.9, 0.3, 0.9]
    reply = client.call(
        reach_msg.REACH,
        reach_msg.ReachRequest(hand="left", target=target, q_start=state.q),
        timeout_s=120,
    )
    assert reply.model == "hrp2_like" and reply.q.shape[1] == robot.nq
    assert reply.stepped and reply.footsteps and reply.attempts[0].violation
    assert reply.monitors.manipulability.shape == reply.monitors.times_s.shape
    assert reply.zmp_distance_m.max() < 0.0 and reply.phase.dtype == np.int8
    result = client.call(
        sim_msg.EXECUTE, sim_msg.ExecuteRequest(q=reply.q, dt_s=reply.dt_s, hold_s=1.0), timeout_s=300
    )
    assert result.outcome == "completed", result.message
    hand = robot.frame_pose(result.q, robot.frames.grasp("left")).translation
    assert np.linalg.norm(hand - np.array(target)) < 0.01


def test_impossible_target_is_an_infeasible_error_naming_the_criterion(services):
    client = services
    robot = load_robot("hrp2_like")
    with pytest.raises(InfeasibleError, match="criterion") as info:
        client.call(
            reach_msg.REACH,
            reach_msg.ReachRequest(hand="left", target=[3.0, 0.3, 0.8], q_start=robot.q_half_sitting),
            timeout_s=60,
        )
    assert info.value.details["criterion"] in ("manipulability", "ee_error", "joint_speed", "joint_torque")


def test_a_configuration_of_another_robot_is_invalid(services):
    with pytest.raises(InvalidRequestError, match="nq="):
        services.call(
            reach_msg.REACH,
            reach_msg.ReachRequest(hand="left", target=[0.5, 0.3, 0.9], q_start=np.zeros(10)),
            timeout_s=30,
        )


def test_a_reach_timing_out_of_range_is_invalid_naming_the_field(services):
    robot = load_robot("hrp2_like")
    with pytest.raises(InvalidRequestError, match="hand_speed_m_s"):
        services.call(
            reach_msg.REACH,
            reach_msg.ReachRequest(
                hand="left", target=[0.5, 0.3, 0.9], q_start=robot.q_half_sitting, hand_speed_m_s=2.0
            ),
            timeout_s=30,
        )


def test_a_sphere_the_gripper_cannot_clear_is_refused_over_the_bus_naming_sphere_and_link(services):
    # fingers down at the target, the jaws along x, a ball 8 cm to its left: the palm above it is in it
    robot = load_robot("hrp2_like")
    target = [0.40, -0.22, 0.80]
    ball = Sphere(center=[0.40, -0.14, 0.80], radius=0.06)
    with pytest.raises(InfeasibleError, match=r"hand_obstacles\[0\]") as info:
        services.call(
            reach_msg.REACH,
            reach_msg.ReachRequest(
                hand="right",
                target=target,
                q_start=robot.q_half_sitting,
                orientation=[0.0, 0.0, float(np.sin(np.pi / 4)), float(np.cos(np.pi / 4))],
                allow_stepping=False,
                hand_obstacles=[ball],
                hand_clearance_m=0.02,
            ),
            timeout_s=60,
        )
    details = info.value.details
    assert details["reason"] == reach_msg.REASON_HAND_OBSTACLE and details["sphere"] == 0
    assert details["link"].startswith("right_gripper")
