"""Contacts the robot is in when a motion starts (sim/start_contacts.py): a motion may leave them or
rest on them, not push further into them."""

from __future__ import annotations

import numpy as np

from sim import motions
from sim.scene import COLOURS, ObjectSpec, load_scene, with_object
from sim.world import World


def test_a_motion_starting_in_contact_may_leave_it_not_push_into_it():
    """The right arm stopped on a crate (RARM_LINK5 on it). Holding the command it was stopped short of
    presses on: a collision. Planned from the measured state: holding still, or turning the head, is
    allowed (the old dead end: every motion stopped at 5 ms); lowering the arm further into the crate
    stops; swinging the arm back off it completes; swinging into it again afterwards is a collision."""
    scene = with_object(
        load_scene("empty"),
        ObjectSpec(name="crate", kind="box", colour=COLOURS["blue"], xy=(0.45, -0.3), size_m=(0.3, 0.3, 1.0)),
    )
    with World("hrp2_like", scene) as world:
        robot = world.robot
        shoulder = robot.joint_index("RARM_JOINT0").idx_q
        swing = motions.joint_motion(robot, world.state().q, {"RARM_JOINT0": -1.2}, 1.0)
        stopped = world.execute(swing)
        assert stopped.outcome == "collision" and {c.other for c in stopped.collisions} == {"crate"}
        pressing = world.execute(np.repeat(swing[stopped.samples_executed - 1][None], 3, axis=0))
        assert pressing.outcome == "collision", pressing.message
        q = world.state().q
        assert world.collisions(), "the arm should still rest on the crate"
        assert world.execute(np.repeat(q[None], 60, axis=0)).outcome == "completed"
        head = world.execute(motions.joint_motion(robot, world.state().q, {"HEAD_JOINT0": 0.5}, 0.5))
        assert head.outcome == "completed", head.message
        q = world.state().q
        deeper = world.execute(motions.joint_motion(robot, q, {"RARM_JOINT0": q[shoulder] - 0.1}, 0.5))
        assert deeper.outcome == "collision", deeper.message
        assert {c.other for c in deeper.collisions} == {"crate"}
        away = world.execute(motions.joint_motion(robot, world.state().q, {"RARM_JOINT0": 0.0}, 1.0))
        assert away.outcome == "completed", away.message
        assert not world.collisions()
        again = world.execute(motions.joint_motion(robot, world.state().q, {"RARM_JOINT0": -1.2}, 1.0))
        assert again.outcome == "collision", again.message
