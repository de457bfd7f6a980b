"""Walks planned by the pattern generator (services/walking) and executed in the simulated world
(sim.world.World, pybullet DIRECT, no bus): on both robots, 10 steps forward of 0.2 m, a 90-degree turn
in place in 4 steps, side steps and a 90-degree arc end without falling within 2 cm and 2 degrees of the
planned final sole poses, measured on the pybullet links. On hrp2_like, a 90-degree curve of 1 m radius
asked in 10 steps (the generator splits it to stay within the bounds) and a backward walk do too, also
with Kajita's 0.1 s of double support.

The planner starts from the state the sim reports (q read back from pybullet after the robot settled),
as the supervisor does over the bus.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from services.walking.footsteps import (
    FootstepBounds,
    FootstepSequence,
    SolePose,
    arc_walk,
    side_steps,
    straight_walk,
    turn_in_place,
)
from services.walking.timing import WalkTiming
from services.walking.wholebody import plan_walk
from sim.world import World

pytestmark = pytest.mark.integration

POSITION_TOLERANCE_M = 0.02
YAW_TOLERANCE_RAD = math.radians(2.0)


def flat_soles(world: World) -> bool:
    """True if both feet collide with the floor through a box (pybullet GEOM_BOX) in the sim."""
    for link in world.foot_links.values():
        shapes = p.getCollisionShapeData(world.robot_id, link, physicsClientId=world.client)
        if not shapes or any(shape[2] != p.GEOM_BOX for shape in shapes):
            return False
    return True


def _sole(robot, q: np.ndarray, side: str) -> SolePose:
    T = robot.sole_pose(q, side)
    return SolePose(
        float(T.translation[0]), float(T.translation[1]), math.atan2(T.rotation[1, 0], T.rotation[0, 0])
    )


def make_walk(robot, name: str, q: np.ndarray) -> FootstepSequence:
    """The walks of issue 5 from the soles of ``q``."""
    kw = {"left_start": _sole(robot, q, "left"), "right_start": _sole(robot, q, "right")}
    if name == "straight":
        return straight_walk(10, 0.2, **kw)
    if name == "turn":
        return turn_in_place(math.pi / 2, 4, sole_size_m=robot.sole_size_m, **kw)
    if name == "side":
        return side_steps(6, 0.05, **kw)
    if name == "arc":
        return arc_walk(1.0, math.pi / 2, 18, **kw)  # 0.1 rad per step: the bound on turning inwards
    limits = FootstepBounds.from_robot(robot)
    if name == "curve":
        # Asked in 10 steps (0.17 rad per step, beyond the outer foot's 0.1 rad): 17 steps.
        seq = arc_walk(1.0, math.pi / 2, 10, limits=limits, **kw)
        assert len(seq.steps) == 17
        return seq
    if name == "backward":
        return straight_walk(10, -0.1, limits=limits, **kw)
    raise ValueError(name)


def measured_sole(world: World, side: str) -> np.ndarray:
    """(x, y, z, yaw) of a sole measured on the pybullet link that carries it (world frame)."""
    robot = world.robot
    link = world.foot_links[side]
    state = p.getLinkState(world.robot_id, link, computeForwardKinematics=True, physicsClientId=world.client)
    T_world_link = pin.XYZQUATToSE3(np.array([*state[4], *state[5]]))
    q = world.state().q
    host = world.pyrobot.link_name(link)
    T_link_sole = robot.frame_pose(q, host).inverse() * robot.sole_pose(q, side)  # fixed offset
    T = T_world_link * T_link_sole
    return np.array([*T.translation, math.atan2(T.rotation[1, 0], T.rotation[0, 0])])


def walk_in_sim(robot_name: str, walk: str, timing: WalkTiming | None = None) -> dict[str, float]:
    """Plan ``walk`` from the sim's state, execute it, return the final errors; asserts on the way."""
    with World(robot_name, "empty") as world:
        # Both feet stand on flat boxes (talos: sole boxes replace its non-flat foot mesh in pybullet).
        assert flat_soles(world)
        robot = world.robot
        q0 = world.state().q
        seq = make_walk(robot, walk, q0)
        plan = plan_walk(robot, seq, q0, timing=timing)
        assert plan.worst_zmp_outside_m == 0.0, plan.figures()
        result = world.execute(plan.q, hold_s=0.5)
        assert result.outcome == "completed", result.message
        left, right = seq.final_stance()
        figures = {"foot_slip_mm": 1e3 * result.foot_slip_m}
        for side, planned in (("left", left), ("right", right)):
            x, y, z, yaw = measured_sole(world, side)
            figures[f"{side}_error_mm"] = 1e3 * math.hypot(x - planned.x_m, y - planned.y_m)
            figures[f"{side}_yaw_error_deg"] = math.degrees(
                abs(math.remainder(yaw - planned.yaw_rad, 2 * math.pi))
            )
            figures[f"{side}_height_mm"] = 1e3 * z
            # Cross-check the link measurement against the kinematics of the q pybullet reports.
            np.testing.assert_allclose(
                [x, y, z], robot.sole_pose(world.state().q, side).translation, atol=1e-6
            )
        return figures


def _params():
    out = []
    for robot_name in ("hrp2_like", "talos"):
        for walk in ("straight", "turn", "side", "arc"):
            marks = []
            if (robot_name, walk) in {("hrp2_like", "arc"), ("talos", "straight"), ("talos", "arc")}:
                marks.append(pytest.mark.slow)  # 20-45 s of wall time each
            out.append(pytest.param(robot_name, walk, marks=marks, id=f"{robot_name}-{walk}"))
    return out


def _assert_ends_where_planned(figures: dict[str, float]) -> None:
    for side in ("left", "right"):
        assert figures[f"{side}_error_mm"] < 1e3 * POSITION_TOLERANCE_M, figures
        assert figures[f"{side}_yaw_error_deg"] < math.degrees(YAW_TOLERANCE_RAD), figures
        assert abs(figures[f"{side}_height_mm"]) < 5.0, figures  # both soles back on the floor
    assert figures["foot_slip_mm"] < 3.0, figures  # no loaded sole slid on the way


@pytest.mark.parametrize(("robot_name", "walk"), _params())
def test_walk_ends_where_planned_in_the_sim(robot_name, walk):
    _assert_ends_where_planned(walk_in_sim(robot_name, walk))


@pytest.mark.parametrize("double_support_s", [0.1, 0.3])
@pytest.mark.parametrize("walk", ["curve", "backward"])
def test_curved_and_backward_walks_end_where_planned_in_the_sim(walk, double_support_s):
    """With 0.1 s of double support these fell on pybullet's rigid, undamped sole contact (the weight
    transfer excites the robot's rocking on its soles); the soles' spring-damper contact
    (services.model.pybullet_robot) keeps them up."""
    timing = WalkTiming(double_support_s=double_support_s)
    _assert_ends_where_planned(walk_in_sim("hrp2_like", walk, timing))
