"""The footstep IK keeps the reaching arm out of spheres (services/footsteps/arm_obstacles.py): a ball
beside the one to grasp (issue 15), eqs. (12)-(13) on the forearm and upper arm capsules."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from services.bus.schemas import footsteps as msg
from services.errors import InvalidRequestError
from services.footsteps.arm_obstacles import arm_capsules, arm_obstacle_distances
from services.footsteps.planner import plan_footsteps
from services.footsteps.request import FootstepPlanRequest, FootstepTask, SphereObstacle
from services.footsteps.service import to_planner_request
from services.model import load_robot

TARGET = (0.9, -0.3, 0.75)  # a ball on a box ahead to the right: a step or two


@pytest.fixture(scope="module")
def robot():
    return load_robot("hrp2_like")


def _request(spheres: tuple[SphereObstacle, ...] = ()) -> FootstepPlanRequest:
    return FootstepPlanRequest(
        tasks=(FootstepTask("reach", TARGET), FootstepTask("gaze", TARGET), FootstepTask("posture")),
        hand_obstacles=spheres,
    )


def test_arm_capsules_are_the_upper_arm_and_forearm_not_the_gripper(robot):
    names = {c.name for c in arm_capsules(robot, "right")}
    assert names == {"r_upper_arm", "r_forearm"}


def test_a_sphere_on_the_planned_forearm_moves_the_arm_off_it(robot):
    free = plan_footsteps(_request(), robot)
    q_free = np.asarray(free.q_final)
    # a ball where the unconstrained plan's forearm passes (its capsule's middle)
    p0, p1 = robot.capsule_segments(q_free)["r_forearm"]
    middle = (p0 + p1) / 2.0
    sphere = SphereObstacle(float(middle[0]), float(middle[1]), float(middle[2]), 0.04)
    assert arm_obstacle_distances(robot, q_free, ["right"], (sphere,)).min() < 0.0

    kept = plan_footsteps(_request((sphere,)), robot)
    q_kept = np.asarray(kept.q_final)
    margin = _request().options.arm_obstacle_margin_m
    assert arm_obstacle_distances(robot, q_kept, ["right"], (sphere,)).min() >= margin - 5e-3
    assert kept.residual("reach:right").solved  # the hand still on the target


def test_the_bus_request_carries_the_spheres(robot):
    request = msg.PlanRequest(
        tasks=[msg.Task(kind="reach", target=list(TARGET))],
        hand_obstacles=[msg.Sphere(center=[1.0, -0.2, 0.75], radius=0.05)],
        options=msg.Options(arm_obstacle_margin_m=0.03),
    )
    planner_request = to_planner_request(request, robot, 10.0)
    assert planner_request.hand_obstacles == (SphereObstacle(1.0, -0.2, 0.75, 0.05),)
    assert planner_request.options.arm_obstacle_margin_m == 0.03


def test_a_sphere_needs_a_positive_radius(robot):
    with pytest.raises(InvalidRequestError, match=r"hand_obstacles\[0\]"):
        plan_footsteps(_request((SphereObstacle(1.0, 0.0, 0.8, 0.0),)), robot)


def test_an_orient_task_turns_the_hand_fingers_down_at_a_yaw(robot):
    yaw = -0.6  # fingers down, the jaws turned: a grasp between neighbouring balls
    quat = (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))
    request = FootstepPlanRequest(
        tasks=(
            FootstepTask("reach", TARGET),
            FootstepTask("orient", orientation=quat),
            FootstepTask("gaze", TARGET),
            FootstepTask("posture"),
        ),
    )
    result = plan_footsteps(request, robot)
    assert result.residual("orient:right").solved
    R = robot.frame_pose(np.asarray(result.q_final), robot.frames.grasp("right")).rotation
    angle = np.linalg.norm(pin.log3(R @ pin.rpy.rpyToMatrix(0.0, 0.0, yaw).T))
    assert angle < request.tasks[1].tol() + 1e-6
    assert result.residual("reach:right").solved
    with pytest.raises(InvalidRequestError, match="unit quaternion"):
        plan_footsteps(replace(request, tasks=(FootstepTask("orient", orientation=(0, 0, 0, 2.0)),)), robot)
