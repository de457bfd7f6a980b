"""The reaching arm, its gripper included, kept out of obstacles above the ground (balls beside the one to
grasp, the object itself) in the final posture: paper 000 treats obstacles as inequality constraints
(eqs. 11/13; §4.1 for disks on the ground); here the capsules of each reaching hand's arm (the upper
arm, the forearm and the gripper's: ``services.ik.hand_obstacles.hand_capsules``) against spheres, with
the inequality of the self-collision of eqs. (12)-(13):

    G = r_capsule + r_sphere + d - |A B| <= 0

The rows, the gripper's capsules and the rule that the gripper is not kept out of the object it closes
on (a sphere the hand's reach target lies in or straight above) are ``services.ik.hand_obstacles``'s,
shared with reaching (one concept, one place). Without these rows the footstep IK chose final postures
whose wrist or forearm lay on the neighbouring ball (fetch seeds 6 and 12, issue 15); without the
gripper in them, its fingers (every touch seen in the fetch was the gripper or the wrist).
"""

from __future__ import annotations

import numpy as np

from services.footsteps.chain import VirtualChain
from services.footsteps.request import FootstepPlanRequest, SphereObstacle
from services.ik.hand_obstacles import SphereDistances, hand_capsules, sphere_pairs, sphere_tasks
from services.ik.task import Task
from services.model import RobotModel


def _reach_targets(request: FootstepPlanRequest) -> dict[str, np.ndarray]:
    """The world target [m] of each reaching hand's reach task."""
    return {t.hand: np.asarray(t.target_m, dtype=float) for t in request.tasks if t.kind == "reach"}


def arm_obstacle_tasks(chain: VirtualChain, request: FootstepPlanRequest) -> list[Task]:
    """Level-0 inequalities keeping the capsules of every reaching hand's arm ``options.
    arm_obstacle_margin_m`` (surface to surface) away from each of ``request.hand_obstacles``
    (spheres, world [m], brought into the chain model's frame), the gripper's not from the sphere its
    reach target lies in or above; one task per hand and sphere radius. [] when there are none."""
    if not request.hand_obstacles:
        return []
    tasks: list[Task] = []
    for hand, target in sorted(_reach_targets(request).items()):
        arm = hand_capsules(chain.robot, hand)
        pairs = sphere_pairs(arm, request.hand_obstacles, target)
        tasks += sphere_tasks(
            chain.model,
            arm.capsules,
            request.hand_obstacles,
            pairs,
            request.options.arm_obstacle_margin_m,
            request.options.gain,
            chain.model_point,
        )
    return tasks


def arm_obstacle_distances(
    robot: RobotModel,
    q: np.ndarray,
    hand: str,
    spheres: tuple[SphereObstacle, ...],
    target_m: np.ndarray | None = None,
) -> np.ndarray:
    """Surface distances [m] (negative: penetration) between the capsules of ``hand``'s arm (rows, in
    ``hand_capsules`` order) and ``spheres`` (columns) at the robot's world configuration ``q``: the
    same distances as the planner's rows; +inf for the pairs the rows leave out (the gripper and the
    sphere ``target_m`` lies in or above)."""
    arm = hand_capsules(robot, hand)
    pairs = sphere_pairs(arm, spheres, target_m)
    out = np.full((len(arm.capsules), len(spheres)), np.inf)
    distances = SphereDistances(robot.model, arm.capsules, spheres, pairs).at(q)
    for (i, j), d in zip(pairs, distances, strict=True):
        out[i, j] = d
    return out
