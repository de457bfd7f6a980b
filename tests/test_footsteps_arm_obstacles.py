"""The footstep IK keeps the reaching arm out of spheres (services/footsteps/arm_obstacles.py): a ball
beside the one to grasp (issue 15), eqs. (12)-(13) on the upper arm, forearm and gripper capsules
(services/ik/hand_obstacles.py)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from services.bus.schemas import common
from services.bus.schemas import footsteps as msg
from services.errors import InvalidRequestError
from services.footsteps.arm_obstacles import arm_obstacle_distances
from services.footsteps.planner import plan_footsteps, plan_footsteps_best
from services.footsteps.request import FootstepPlanRequest, FootstepTask, SphereObstacle
from services.footsteps.service import to_planner_request
from services.ik.hand_obstacles import gripper_capsules, hand_capsules
from services.model import load_robot
from services.model.geometry import segment_distance

TARGET = (0.9, -0.3, 0.75)  # a ball on a box ahead to the right: a step or two


@pytest.fixture(scope="module")
def robot():
    return load_robot("hrp2_like")


def _request(spheres: tuple[SphereObstacle, ...] = ()) -> FootstepPlanRequest:
    return FootstepPlanRequest(
        tasks=(FootstepTask("reach", TARGET), FootstepTask("gaze", TARGET), FootstepTask("posture")),
        hand_obstacles=spheres,
    )


def test_the_arm_capsules_are_the_upper_arm_forearm_and_the_grippers_fitted_shapes(robot):
    arm = hand_capsules(robot, "right")
    names = [c.name for c in arm.capsules]
    assert names[:2] == ["r_upper_arm", "r_forearm"]  # not the robot's one capsule round the whole hand
    assert "r_hand" not in names
    gripper = gripper_capsules(robot, "right")
    assert arm.capsules[2:] == gripper and arm.gripper == frozenset(range(2, len(names)))
    # one per collision shape of the palm link and the moving finger: palm, jaws' bar, two fingers
    assert sorted({c.frame for c in gripper}) == ["RARM_LINK5", "RARM_LINK6"] and len(gripper) == 4
    geometry = robot.build_geometry_model("collision")
    q = robot.q_half_sitting
    data = robot.forward(q)
    shapes = [g for g in geometry.geometryObjects if g.parentJoint in _gripper_joints(robot)]
    for capsule, g in zip(gripper, shapes, strict=True):
        # every corner of its box lies inside the capsule (world, at half-sitting) ...
        T_joint = data.oMi[g.parentJoint] * g.placement
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        corners = corners * np.asarray(g.geometry.halfSide)
        T_frame = robot.frame_pose(q, capsule.frame)
        p0, p1 = T_frame.act(np.array(capsule.p0_local)), T_frame.act(np.array(capsule.p1_local))
        for corner in corners:
            point = T_joint.act(corner)
            assert segment_distance(p0, p1, point, point) <= capsule.radius_m + 1e-9
        # ... and it is tighter than the hand's capsule: a finger plate 19 mm, the palm 50 mm
        assert capsule.radius_m < robot.capsule("r_hand").radius_m
    assert min(c.radius_m for c in gripper) < 0.02


def _gripper_joints(robot) -> set[int]:
    model = robot.model
    wrist = model.frames[robot.frame_id(robot.frames.grasp("right"))].parentJoint
    return {wrist, model.getJointId(robot.gripper_joint("right"))}


def test_a_sphere_on_the_planned_forearm_moves_the_arm_off_it(robot):
    free = plan_footsteps(_request(), robot)
    q_free = np.asarray(free.q_final)
    # a ball where the unconstrained plan's forearm passes (its capsule's middle)
    p0, p1 = robot.capsule_segments(q_free)["r_forearm"]
    middle = (p0 + p1) / 2.0
    sphere = SphereObstacle(float(middle[0]), float(middle[1]), float(middle[2]), 0.04)
    assert arm_obstacle_distances(robot, q_free, "right", (sphere,)).min() < 0.0

    kept = plan_footsteps(_request((sphere,)), robot)
    q_kept = np.asarray(kept.q_final)
    margin = _request().options.arm_obstacle_margin_m
    assert arm_obstacle_distances(robot, q_kept, "right", (sphere,)).min() >= margin - 5e-3
    assert kept.residual("reach:right").solved  # the hand still on the target


def test_the_bus_request_carries_the_spheres(robot):
    request = msg.PlanRequest(
        tasks=[msg.Task(kind="reach", target=list(TARGET))],
        hand_obstacles=[msg.Sphere(center=[1.0, -0.2, 0.75], radius=0.05)],
        options=msg.Options(arm_obstacle_margin_m=0.03),
    )
    assert msg.Sphere is common.Sphere  # one sphere type, shared with reaching/reach
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


def test_a_ball_beside_the_target_keeps_the_gripper_clear_not_off_the_ball_it_closes_on(robot):
    ball = SphereObstacle(*TARGET, 0.05)  # the object itself: its sphere does not keep the gripper off
    free = plan_footsteps(_request((ball,)), robot)
    assert free.residual("reach:right").solved
    q_free = np.asarray(free.q_final)
    # a neighbour 0.115 m from it (two touching balls), on the side of a finger plate of that posture
    arm = hand_capsules(robot, "right")
    finger = min((arm.capsules[i] for i in arm.gripper), key=lambda c: c.radius_m)
    T = robot.frame_pose(q_free, finger.frame)
    middle = T.act((np.array(finger.p0_local) + np.array(finger.p1_local)) / 2.0)
    side = (middle - np.array(TARGET))[:2]
    centre = np.array(TARGET) + 0.115 * np.append(side / np.linalg.norm(side), 0.0)
    neighbour = SphereObstacle(*map(float, centre), 0.05)
    spheres = (ball, neighbour)
    before = arm_obstacle_distances(robot, q_free, "right", spheres, np.array(TARGET))
    assert before[sorted(arm.gripper), 1].min() < 0.0  # that posture's gripper is in the neighbour

    kept = plan_footsteps(_request(spheres), robot)
    assert kept.residual("reach:right").solved  # the hand still on the target ...
    after = arm_obstacle_distances(robot, np.asarray(kept.q_final), "right", spheres, np.array(TARGET))
    margin = _request().options.arm_obstacle_margin_m
    assert after[:, 1].min() >= margin - 5e-3  # ... every capsule, the gripper's too, clear of the neighbour
    assert np.isinf(after[sorted(arm.gripper), 0]).all()  # the gripper is not kept off the ball itself
    assert after[:2, 0].min() >= margin - 5e-3  # the upper arm and forearm are


def test_a_sphere_far_from_the_arm_changes_nothing(robot):
    far = SphereObstacle(TARGET[0] + 1.5, TARGET[1] + 1.5, 0.5, 0.05)
    without = plan_footsteps(_request(), robot)
    with_far = plan_footsteps(_request((far,)), robot)
    assert np.array_equal(np.asarray(without.q_final), np.asarray(with_far.q_final))
    assert without.footsteps == with_far.footsteps


def test_with_a_free_yaw_the_planner_turns_the_jaws_clear_of_a_neighbour(robot):
    # fingers down with the jaws' line (the hand's y axis) at -0.6 rad; a neighbour on that line
    yaw = -0.6
    quat = (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))
    jaws_line = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    ball = SphereObstacle(*TARGET, 0.05)
    neighbour = SphereObstacle(*map(float, np.array(TARGET) + 0.115 * jaws_line), 0.05)

    def request(free_yaw: bool) -> FootstepPlanRequest:
        return FootstepPlanRequest(
            tasks=(
                FootstepTask("reach", TARGET),
                FootstepTask("orient", orientation=quat, free_yaw=free_yaw),
                FootstepTask("gaze", TARGET),
                FootstepTask("posture"),
            ),
            hand_obstacles=(ball, neighbour),
        )

    held, error = plan_footsteps_best(request(False), robot)
    assert error is not None and not held.residual("orient:right").solved  # the jaws there: in the neighbour

    free = plan_footsteps(request(True), robot)
    q = np.asarray(free.q_final)
    assert free.residual("reach:right").solved and free.residual("orient:right").solved
    R = robot.frame_pose(q, robot.frames.grasp("right")).rotation
    assert R[2, 2] > math.cos(request(True).tasks[1].tol())  # fingers down ...
    chosen = math.atan2(R[1, 0], R[0, 0])
    assert abs(math.remainder(chosen - yaw, math.pi)) > 0.3  # ... the jaws turned off that line
    distances = arm_obstacle_distances(robot, q, "right", (ball, neighbour), np.array(TARGET))
    assert distances[:, 1].min() >= request(True).options.arm_obstacle_margin_m - 5e-3
    with pytest.raises(InvalidRequestError, match="free_yaw"):
        plan_footsteps(FootstepPlanRequest(tasks=(FootstepTask("reach", TARGET, free_yaw=True),)), robot)
