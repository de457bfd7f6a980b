"""The reaching arm kept out of obstacles above the ground (balls beside the one to grasp, the object
itself): paper 000 treats obstacles as inequality constraints (eqs. 11/13; §4.1 for disks on the
ground); here the arm's capsules (the forearm and upper arm of each reaching hand: :func:`arm_capsules`)
against spheres, with the same inequality as the self-collision of eqs. (12)-(13) and the
environment boxes of ``services.ik.tasks.capsule_box``:

    G = r_capsule + r_sphere + d - |A B| <= 0

A sphere is a box with no extent whose radius is added to the margin d, so the rows, the closest points
and the Jacobians are :class:`services.ik.tasks.capsule_box.CapsuleBoxTask`'s (one concept, one place).
Without these rows the footstep IK chose final postures whose wrist or forearm lay on the neighbouring
ball (fetch seeds 6 and 12, issue 15).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from services.footsteps.chain import VirtualChain
from services.footsteps.request import FootstepPlanRequest, SphereObstacle
from services.ik.capsule import CapsuleLike
from services.ik.task import Task
from services.ik.tasks.capsule_box import CapsuleBoxTask, ObstacleBox
from services.model import RobotModel


def arm_capsules(robot: RobotModel, hand: str) -> list[CapsuleLike]:
    """The capsules of ``robot`` carried by the ``hand``'s arm joints (the upper arm and forearm), but
    not the one carried with the grasp frame: that capsule wraps the whole gripper, which closes on the
    object and whose jaws pass within centimetres of a neighbour (a 0.115 m gap between ball centres is
    less than its radius plus a ball's)."""
    model = robot.model
    joints = {model.getJointId(name) for name in robot.arm_joints(hand)}
    wrist = model.frames[robot.frame_id(robot.frames.grasp(hand))].parentJoint
    return [
        c for c in robot.capsules if model.frames[robot.frame_id(c.frame)].parentJoint in joints - {wrist}
    ]


def arm_obstacle_tasks(chain: VirtualChain, request: FootstepPlanRequest) -> list[Task]:
    """Level-0 inequalities keeping the capsules of every reaching hand's arm ``options.
    arm_obstacle_margin_m`` (surface to surface) away from each of ``request.hand_obstacles``
    (spheres, world [m], brought into the chain model's frame); one task per sphere radius (the
    radius is part of the task's margin). [] when there are none."""
    if not request.hand_obstacles:
        return []
    hands = sorted({t.hand for t in request.tasks if t.kind == "reach"})
    capsules = [c for hand in hands for c in arm_capsules(chain.robot, hand)]
    if not capsules:
        return []
    by_radius: dict[float, list[SphereObstacle]] = {}
    for sphere in request.hand_obstacles:
        by_radius.setdefault(float(sphere.radius_m), []).append(sphere)
    margin = request.options.arm_obstacle_margin_m
    tasks: list[Task] = []
    for k, (radius, spheres) in enumerate(sorted(by_radius.items())):
        boxes = [
            ObstacleBox(
                f"sphere{k}_{i}",
                pin.SE3(np.eye(3), chain.model_point((s.x_m, s.y_m, s.z_m))),
                np.zeros(3),
            )
            for i, s in enumerate(spheres)
        ]
        pairs = [(i, j) for i in range(len(capsules)) for j in range(len(boxes))]
        tasks.append(
            CapsuleBoxTask(
                chain.model,
                capsules,
                boxes,
                pairs,
                margin_m=margin + radius,
                gain=request.options.gain,
                name=f"arm_out_of_spheres_r{radius:.3f}",
            )
        )
    return tasks


def arm_obstacle_distances(
    robot: RobotModel, q: np.ndarray, hands: list[str], spheres: tuple[SphereObstacle, ...]
) -> np.ndarray:
    """Surface distances [m] (negative: penetration) between the arm capsules of ``hands`` (rows, in
    :func:`arm_capsules` order) and ``spheres`` (columns) at the robot's world configuration ``q``:
    the same distances as the planner's rows (:class:`CapsuleBoxTask` with point boxes)."""
    capsules = [c for hand in hands for c in arm_capsules(robot, hand)]
    boxes = [
        ObstacleBox(f"sphere{j}", pin.SE3(np.eye(3), np.array([s.x_m, s.y_m, s.z_m])), np.zeros(3))
        for j, s in enumerate(spheres)
    ]
    pairs = [(i, j) for i in range(len(capsules)) for j in range(len(boxes))]
    task = CapsuleBoxTask(robot.model, capsules, boxes, pairs, margin_m=0.0)
    radii = np.array([spheres[j].radius_m for _, j in pairs])
    return (task.distances(robot.forward(q)) - radii).reshape(len(capsules), len(boxes))
