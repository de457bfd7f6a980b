"""The sim's force-aware execution (sim/compliance.py): a hand pressed onto a box by position control
carries what the motors' errors give it; with a force target it carries the planned force."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from services.errors import InvalidRequestError
from sim import motions
from sim.compliance import ForceTarget
from sim.scene import COLOURS, ObjectSpec, load_scene, with_object
from sim.world import World

ARM = tuple(f"RARM_JOINT{i}" for i in (5, 4, 3, 2, 1, 0))  # the tip first
FORWARD = {"RARM_JOINT0": -1.4}  # the right arm held forward, the hand below the shoulder


BLOCK = ObjectSpec(name="block", kind="box", colour=COLOURS["blue"], xy=(3.0, 0.0), size_m=(0.08, 0.08, 0.5))


def _pressed_force(target_n: float | None) -> float:
    """Lift the right arm forward, put the block's top 5 mm under the hand, then command the shoulder
    0.04 rad lower (the hand about 2 cm into the block) for 2 s, with a force target of ``target_n`` [N]
    (None: none); the block's normal force on the arm at the end [N]."""
    with World("hrp2_like", with_object(load_scene("empty"), BLOCK)) as world:
        lift = motions.joint_motion(world.robot, world.state().q, FORWARD, 1.0)
        assert world.execute(lift).outcome == "completed"
        hand = [world.pyrobot.link_index(n) for n in ("RARM_LINK5", "RARM_LINK6")]  # under RARM_JOINT5
        boxes = np.array([p.getAABB(world.robot_id, i, physicsClientId=world.client) for i in hand])
        lo, hi = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
        centre = ((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2] - 0.005 - 0.25)
        world.set_object_pose("block", np.array(centre))
        press = motions.joint_motion(world.robot, world.state().q, {"RARM_JOINT0": -1.36}, 2.0)
        targets = ()
        if target_n is not None:
            point = (0.0, 0.0, -0.15)  # about the gripper's middle, in RARM_JOINT5's frame
            targets = (ForceTarget(ARM, "block", (0.0, 0.0, 1.0), np.full(len(press), target_n), point),)
        result = world.execute(press, supports=("block",), force_targets=targets, hold_s=0.5)
        assert result.outcome == "completed", result.message
        block = world.bodies["block"]
        contacts = p.getContactPoints(bodyA=world.robot_id, bodyB=block, physicsClientId=world.client)
        return float(sum(c[9] for c in contacts))


def test_a_hand_with_a_force_target_carries_the_planned_force():
    rigid = _pressed_force(None)
    followed = _pressed_force(30.0)
    assert rigid > 100.0, rigid  # position control: the motors push as hard as the error asks
    assert followed == pytest.approx(30.0, abs=15.0), (rigid, followed)


def test_force_targets_are_checked():
    with World("hrp2_like", "empty") as world:
        q = np.repeat(world.state().q[None, :], 3, axis=0)
        ok = ForceTarget(ARM, "nothing", (0.0, 0.0, 1.0), np.zeros(3))
        with pytest.raises(InvalidRequestError, match="no object"):
            world.execute(q, force_targets=(ok,))
