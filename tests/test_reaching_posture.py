"""Reaching toward a requested final posture (``ReachRequest.q_posture``: a footstep plan's final posture,
paper 000 §7): the motion ends in it (joints and CoM) below the hand task; malformed postures are refused."""

from __future__ import annotations

import numpy as np
import pytest

from services.errors import InvalidRequestError
from services.model import load_robot
from services.reaching import ReachRequest, plan_reach

TARGET = np.array([0.45, 0.30, 0.90])  # within the left hand's reach of hrp2_like at the origin [m]


@pytest.fixture(scope="module")
def robot():
    return load_robot("hrp2_like")


@pytest.fixture(scope="module")
def other_posture(robot) -> np.ndarray:
    """A posture with the left hand at TARGET that reaching does not choose from the half-sitting one:
    its end from a start with the chest turned by 0.3 rad (no task turns it back)."""
    q = robot.q_half_sitting.copy()
    q[robot.joint_index("CHEST_JOINT0").idx_q] += 0.3
    return plan_reach(robot, ReachRequest("left", TARGET, q, allow_stepping=False)).q[-1]


def test_the_motion_ends_in_the_requested_posture(robot, other_posture):
    joints = slice(7, None)
    own = plan_reach(robot, ReachRequest("left", TARGET, robot.q_half_sitting, allow_stepping=False))
    asked = plan_reach(
        robot,
        ReachRequest("left", TARGET, robot.q_half_sitting, allow_stepping=False, q_posture=other_posture),
    )
    apart = np.abs(own.q[-1][joints] - other_posture[joints]).max()
    off = np.abs(asked.q[-1][joints] - other_posture[joints]).max()
    assert apart > 0.1  # the two IKs end in different postures ...
    assert off < 0.02  # ... and asked for it, reaching ends in the other one [rad]
    assert asked.hand_error_m < 1e-3  # the hand task above it still met
    assert not asked.stepped
    com_asked, com_wanted = robot.com(asked.q[-1])[:2], robot.com(other_posture)[:2]
    assert np.linalg.norm(com_asked - com_wanted) < 0.01  # its CoM too [m]


def test_a_malformed_posture_is_invalid(robot):
    q = robot.q_half_sitting
    with pytest.raises(InvalidRequestError, match="posture must be"):
        plan_reach(robot, ReachRequest("left", TARGET, q, q_posture=q[:-1]))
    beyond = q.copy()
    beyond[robot.joint_index(robot.arm_joints("left")[0]).idx_q] = 10.0
    with pytest.raises(InvalidRequestError, match="outside its limits"):
        plan_reach(robot, ReachRequest("left", TARGET, q, q_posture=beyond))
