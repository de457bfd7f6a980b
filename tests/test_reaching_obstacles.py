"""Reaching keeps the arm, its gripper and wrist included, out of the request's spheres
(``ReachRequest.hand_obstacles``: a ball beside the one to grasp; paper 000 eqs. 12-13 on the arm's
capsules, services/reaching/obstacles.py): the whole motion keeps the clearance, a far sphere changes
nothing, a path through a sphere is planned again from above, and a sphere the gripper cannot clear
is refused naming the sphere and the link."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.bus.codec import from_builtins
from services.bus.schemas import reaching as msg
from services.bus.schemas.common import Sphere
from services.errors import InfeasibleError, InvalidRequestError
from services.ik.hand_obstacles import SphereObstacle
from services.model import load_robot
from services.reaching import ReachRequest, plan_reach
from services.reaching.obstacles import ArmClearance
from services.reaching.options import ReachingOptions

TARGET = np.array([0.40, -0.22, 0.80])  # within the right hand's reach of hrp2_like at the origin [m]
CLEARANCE_M = ReachingOptions().hand_clearance_m


@pytest.fixture(scope="module")
def robot():
    return load_robot("hrp2_like")


@pytest.fixture(scope="module")
def free(robot):
    """The motion without spheres."""
    return plan_reach(robot, ReachRequest("right", TARGET, robot.q_half_sitting, allow_stepping=False))


def _closest(robot, request: ReachRequest, q: np.ndarray) -> np.ndarray:
    """(samples, pairs) surface distances [m] of the motion ``q`` to the request's spheres."""
    clearance = ArmClearance.of(robot, request.validated(robot), ReachingOptions())
    assert clearance is not None
    check = clearance.distances(robot.model)
    return np.array([check.at(qk) for qk in q])


def _fingers_down(yaw_rad: float) -> np.ndarray:
    """The grasp frame fingers down (its orientation with the arm hanging) turned by ``yaw_rad``."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _hand_path(robot, q: np.ndarray) -> np.ndarray:
    """(samples, 3) grasp frame positions [m] of the motion ``q``."""
    return np.array([robot.frame_pose(qk, robot.frames.grasp("right")).translation for qk in q])


def test_a_sphere_beside_the_path_is_kept_clear_by_the_whole_arm(robot, free):
    # a ball 8 cm beside the free motion's hand path, 40 % of the way: its moving finger goes through it
    path = _hand_path(robot, free.q)
    k = int(0.4 * (len(path) - 1))
    along = path[k + 5] - path[k - 5]
    beside = np.cross(along, (0.0, 0.0, 1.0))
    ball = SphereObstacle(*map(float, path[k] + 0.08 * beside / np.linalg.norm(beside)), 0.04)
    request = ReachRequest(
        "right", TARGET, robot.q_half_sitting, allow_stepping=False, hand_obstacles=(ball,)
    )
    free_distances = _closest(robot, request, free.q)
    assert free_distances[0].min() > CLEARANCE_M  # clear at the start ...
    assert free_distances.min() < -0.03  # ... the free motion's gripper goes through it

    kept = plan_reach(robot, request)
    assert kept.hand_error_m < 1e-3  # the hand still reaches the target ...
    assert _closest(robot, request, kept.q).min() >= CLEARANCE_M  # ... and every capsule keeps clear


def test_without_spheres_or_with_a_far_one_the_motion_is_unchanged(robot, free):
    far = SphereObstacle(2.0, 2.0, 0.5, 0.05)
    request = ReachRequest("right", TARGET, robot.q_half_sitting, allow_stepping=False, hand_obstacles=(far,))
    assert np.array_equal(plan_reach(robot, request).q, free.q)


def test_a_path_through_a_sphere_is_planned_again_from_above(robot, free):
    # a ball on the free motion's hand path, 55 % of the way: the hand cannot pass it straight
    path = _hand_path(robot, free.q)
    ball = SphereObstacle(*map(float, path[int(0.55 * (len(path) - 1))]), 0.03)
    request = ReachRequest(
        "right", TARGET, robot.q_half_sitting, allow_stepping=False, hand_obstacles=(ball,)
    )
    result = plan_reach(robot, request)
    assert result.hand_error_m < 1e-3
    assert _closest(robot, request, result.q).min() >= CLEARANCE_M
    assert _hand_path(robot, result.q)[:, 2].max() > TARGET[2] + 0.09  # the hand came from above


def test_a_sphere_the_gripper_cannot_clear_is_refused_naming_sphere_and_link(robot):
    # fingers down at the target, a ball 1 cm beside the jaws' plane: the palm above the target is in it
    far = SphereObstacle(2.0, 2.0, 0.5, 0.05)
    ball = SphereObstacle(float(TARGET[0]), float(TARGET[1] + 0.08), float(TARGET[2]), 0.06)
    request = ReachRequest(
        "right",
        TARGET,
        robot.q_half_sitting,
        R_world_hand=_fingers_down(math.pi / 2),
        allow_stepping=False,
        hand_obstacles=(far, ball),
    )
    with pytest.raises(InfeasibleError, match=r"hand_obstacles\[1\]") as refused:
        plan_reach(robot, request)
    details = refused.value.details
    assert (
        details["reason"] == msg.REASON_HAND_OBSTACLE and details["criterion"] == msg.CRITERION_HAND_OBSTACLE
    )
    assert details["sphere"] == 1 and details["link"].startswith("right_gripper")
    # the rows held the palm off the ball (the hand fell behind its path: ee_error), not into it
    assert details["held_back"] == msg.CRITERION_EE_ERROR and details["clearance_m"] == CLEARANCE_M
    assert CLEARANCE_M <= details["distance_m"] < CLEARANCE_M + 0.01


def test_malformed_spheres_and_clearances_are_invalid(robot):
    q = robot.q_half_sitting
    with pytest.raises(InvalidRequestError, match=r"hand_obstacles\[0\]"):
        plan_reach(
            robot, ReachRequest("right", TARGET, q, hand_obstacles=(SphereObstacle(1.0, 0.0, 0.8, 0.0),))
        )
    with pytest.raises(InvalidRequestError, match="hand_clearance_m"):
        plan_reach(robot, ReachRequest("right", TARGET, q, hand_clearance_m=-0.01))
    # on the bus: the field is the footstep planner's sphere type, its radius not negative
    raw = {"hand": "right", "target": TARGET.tolist(), "q_start": q.tolist()}
    decoded = from_builtins(
        {**raw, "hand_obstacles": [{"center": [1, 0, 0.8], "radius": 0.05}]}, msg.ReachRequest
    )
    assert decoded.hand_obstacles == [Sphere(center=[1.0, 0.0, 0.8], radius=0.05)]
    with pytest.raises(InvalidRequestError, match="radius"):
        from_builtins({**raw, "hand_obstacles": [{"center": [1, 0, 0.8], "radius": -1}]}, msg.ReachRequest)
