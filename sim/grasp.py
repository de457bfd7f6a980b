"""Grasping in pybullet: the links of each gripper, which object the fingers touch, and the fixed
constraint that holds a grasped object.

A grasp is made only once the object is squeezed between the jaws: it touches the moving finger and the
opposite jaw (contact points from the physics engine). Only then does a fixed constraint attach the
object to the hand (pybullet friction alone does not hold objects reliably). Static objects (mass 0)
are never grasped.
"""

from __future__ import annotations

from dataclasses import dataclass

import pybullet as p

_BODY_B, _LINK_A, _NORMAL_FORCE = 2, 3, 9


@dataclass(frozen=True)
class GripperLinks:
    """pybullet indices of one gripper: its joint, the links moved by it, and the rest of the hand."""

    side: str
    joint_id: int
    palm_link: int  # parent link of the gripper joint (holds the fixed jaw)
    moving_links: frozenset[int]  # the gripper joint's child link and its descendants
    jaw_links: frozenset[int]  # the palm and its other descendants (the opposite jaw)

    @property
    def hand_links(self) -> frozenset[int]:
        return self.moving_links | self.jaw_links


def gripper_links(client: int, body: int, side: str, joint_id: int) -> GripperLinks:
    """Find the links of the gripper driven by ``joint_id`` from the kinematic tree."""
    parents = {
        j: p.getJointInfo(body, j, physicsClientId=client)[16]
        for j in range(p.getNumJoints(body, physicsClientId=client))
    }

    def subtree(root: int) -> set[int]:
        out = {root}
        grew = True
        while grew:
            grew = False
            for child, parent in parents.items():
                if parent in out and child not in out:
                    out.add(child)
                    grew = True
        return out

    palm = parents[joint_id]
    moving = subtree(joint_id)
    return GripperLinks(side, joint_id, palm, frozenset(moving), frozenset(subtree(palm) - moving))


def squeezed_objects(
    client: int, robot: int, gripper: GripperLinks, movable: dict[int, str], min_force_n: float
) -> list[str]:
    """Names of the movable objects touching both the moving finger and the opposite jaw now."""
    touch_moving: set[int] = set()
    touch_jaw: set[int] = set()
    for c in p.getContactPoints(bodyA=robot, physicsClientId=client):
        body = c[_BODY_B]
        if body not in movable or c[_NORMAL_FORCE] < min_force_n:
            continue
        if c[_LINK_A] in gripper.moving_links:
            touch_moving.add(body)
        elif c[_LINK_A] in gripper.jaw_links:
            touch_jaw.add(body)
    return sorted(movable[b] for b in touch_moving & touch_jaw)


def attach(client: int, robot: int, link: int, obj: int) -> int:
    """A fixed constraint holding ``obj`` at its current pose relative to robot ``link``; its id."""
    state = p.getLinkState(robot, link, computeForwardKinematics=True, physicsClientId=client)
    link_pos, link_orn = state[0], state[1]  # link inertial frame (the frame constraints use)
    obj_pos, obj_orn = p.getBasePositionAndOrientation(obj, physicsClientId=client)
    inv_pos, inv_orn = p.invertTransform(link_pos, link_orn)
    rel_pos, rel_orn = p.multiplyTransforms(inv_pos, inv_orn, obj_pos, obj_orn)
    # The object's base frame is its inertial frame (objects are built without an inertial offset).
    cid = p.createConstraint(
        robot,
        link,
        obj,
        -1,
        p.JOINT_FIXED,
        [0.0, 0.0, 0.0],
        parentFramePosition=rel_pos,
        childFramePosition=[0.0, 0.0, 0.0],
        parentFrameOrientation=rel_orn,
        childFrameOrientation=[0.0, 0.0, 0.0, 1.0],
        physicsClientId=client,
    )
    p.changeConstraint(cid, maxForce=2000.0, physicsClientId=client)
    return cid


def detach(client: int, constraint_id: int) -> None:
    p.removeConstraint(constraint_id, physicsClientId=client)
