"""The navigation service over a real zenoh bus: ``python -m services.navigation.service`` spawned on a
private hub, ``navigation/goto`` called with the bar scenario (reshaped plan in the reply) and with an
enclosed goal (an ``infeasible`` error reply)."""

from __future__ import annotations

import numpy as np
import pytest

from services.bus.schemas import navigation as msg
from services.collision import BoxObstacle, CylinderObstacle, Obstacle
from services.errors import InfeasibleError, InvalidRequestError
from services.model import load_robot
from services.navigation.demo_scenes import (
    BAR_BOX_TOP_M,
    bar_scenario,
    bar_scenario_start,
    enclosed_goal_room,
)
from services.navigation.service import goto_options

pytestmark = pytest.mark.integration

ROBOT = load_robot("hrp2_like")


def _obstacle_msg(o: Obstacle) -> msg.ObstacleMsg:
    if isinstance(o, BoxObstacle):
        return msg.ObstacleMsg(
            name=o.name, kind="box", center=list(o.center_xyz_m), size=list(o.size_xyz_m), yaw=o.yaw_rad
        )
    assert isinstance(o, CylinderObstacle)
    return msg.ObstacleMsg(
        name=o.name, kind="cylinder", center=list(o.center_xyz_m), radius=o.radius_m, height=o.height_m
    )


def test_goto_over_the_bus(module_bus_harness) -> None:
    harness = module_bus_harness
    harness.spawn_service("services.navigation.service", name="navigation", timeout_s=60.0)
    client = harness.client

    scene, _, goal = bar_scenario()
    q_start = bar_scenario_start(ROBOT)
    request = msg.GotoRequest(
        q_start=q_start,
        obstacles=[_obstacle_msg(o) for o in scene.obstacles],
        goal_pose=[goal.x_m, goal.y_m, goal.theta_rad],
        carried=msg.CarriedBarMsg(),
        carry_height_m=0.8,
    )
    reply = client.call(msg.GOTO, request, timeout_s=120.0)
    assert isinstance(reply, msg.GotoReply) and reply.model == "hrp2_like"
    assert reply.goal == pytest.approx([goal.x_m, goal.y_m, goal.theta_rad], abs=1e-6)
    n = reply.q.shape[0]
    assert reply.q.shape == (n, ROBOT.nq) and reply.dt_s == 0.005
    assert reply.duration_s == pytest.approx((n - 1) * reply.dt_s)
    assert np.allclose(reply.q[0], q_start, atol=1e-9)
    assert reply.com_m.shape == (n, 3) and reply.zmp_m.shape == (n, 2)
    assert reply.path_xy_m.shape[1] == 2 and reply.path_xy_m.shape[0] == reply.path_s_m.shape[0]
    assert reply.path_forward.all() and reply.path_curve == "dubins"
    assert reply.step_poses.shape == (len(reply.step_sides), 3) and len(reply.step_sides) > 10
    # the reshaping report: the box lifted over, before/after heights on the trajectory's grid
    report = reply.reshaping
    assert report.iterations >= 2 and report.collisions_per_iteration[0] >= 1
    assert report.collisions_per_iteration[-1] == 0
    assert [s.obstacles for s in report.segments] == [["box"]]
    assert report.min_clearance_m >= 0.02 and report.zmp_margin_m > 0.0
    for heights in (report.bar_height_nominal_m, report.bar_height_before_m, report.bar_height_planned_m):
        assert heights.shape == (n,)
    assert report.bar_height_before_m.max() < BAR_BOX_TOP_M
    # the sampled reshaping may tilt or turn the bar instead of lifting its centre over the box: its
    # key frames bracket the collision, and the final motion keeps the clearance (above)
    (segment,) = report.segments
    assert segment.t_anticipate_s < segment.t_collide_s <= segment.t_collide_end_s < segment.t_regain_s
    assert set(reply.timings_s) == {"path_s", "footsteps_s", "stage2_s", "total_s"}

    # an enclosed goal: an error reply with the code and the enclosing obstacles, within the budget
    room, _, enclosed = enclosed_goal_room()
    q = ROBOT.half_sitting_at(-2.3, -2.3, 0.0)
    with pytest.raises(InfeasibleError, match="enclosed") as info:
        client.call(
            msg.GOTO,
            msg.GotoRequest(
                q_start=q,
                obstacles=[_obstacle_msg(o) for o in room.obstacles],
                goal_pose=[enclosed.x_m, enclosed.y_m, enclosed.theta_rad],
                bounds=list(room.bounds_xy_m),
            ),
            timeout_s=30.0,
        )
    assert info.value.details["reason"] == "goal_enclosed"
    assert "pen_north" in info.value.details["enclosing_obstacles"]

    # on free floor there is no clearance to report (infinite): null, not a reply that cannot be decoded
    free = client.call(msg.GOTO, msg.GotoRequest(q_start=q, goal_pose=[-1.5, -2.3, 0.0]), timeout_s=60.0)
    assert free.reshaping.min_clearance_m is None and free.reshaping.iterations == 1

    # a malformed request names the field
    with pytest.raises(InvalidRequestError, match="exactly one goal"):
        client.call(msg.GOTO, msg.GotoRequest(q_start=q, goal_pose=[1.0, 0.0, 0.0], goal_object="crate"))
    with pytest.raises(InvalidRequestError, match="reshape_mode"):
        bad = msg.GotoRequest(q_start=q, goal_pose=[1.0, 0.0, 0.0], reshape_mode="tilt")  # type: ignore[arg-type]
        client.call(msg.GOTO, bad)


def test_reshaping_mode_and_seed_of_a_request_reach_the_planner() -> None:
    """``reshape_mode`` (the paper's random sampling, or lift only) and ``reshape_seed`` of a request are
    the smooth reshaping's options."""
    q = ROBOT.half_sitting_at(0.0, 0.0, 0.0)
    default = goto_options(msg.GotoRequest(q_start=q, goal_pose=[1.0, 0.0, 0.0])).stage2.reshape
    assert default.mode == "sample" and default.sampling.seed == 0
    request = msg.GotoRequest(q_start=q, goal_pose=[1.0, 0.0, 0.0], reshape_mode="lift", reshape_seed=7)
    reshape = goto_options(request).stage2.reshape
    assert reshape.mode == "lift" and reshape.sampling.seed == 7 and reshape.max_iterations == 5


def test_a_near_goal_beside_the_robot_is_walked_straight_and_planned_once() -> None:
    """Half a metre to the left and 0.3 m ahead, turned by 20 deg: the forward car-like path loops
    around, so navigation walks there straight (sideways, forward and turning in the same steps) and
    stage 2 plans that walk: the reply's q ends standing at the goal. A box on the line: no straight
    walk (navigation keeps its path)."""
    import math

    from services.collision import Scene
    from services.navigation.geometry import Pose2D
    from services.navigation.goto import plan_goto, start_soles
    from services.navigation.straight import StraightWalkOptions, straight_walk

    q = np.array(ROBOT.q_half_sitting)
    x, y, yaw = ROBOT.mid_feet_pose(q)
    goal = Pose2D(x + 0.3, y + 0.5, yaw + math.radians(20.0))
    scene = Scene((), (x - 3.0, x + 3.0, y - 3.0, y + 3.0))
    result = plan_goto(ROBOT, scene, q, goal)
    assert result.path.curve == "straight"
    gx, gy, gyaw = ROBOT.mid_feet_pose(result.motion.q[-1])
    assert math.hypot(gx - goal.x_m, gy - goal.y_m) < 0.01
    assert abs(math.remainder(gyaw - goal.theta_rad, 2 * math.pi)) < math.radians(1.0)
    blocked = Scene((BoxObstacle("crate", (x + 0.15, y + 0.25, 0.3), (0.2, 0.2, 0.6)),), scene.bounds_xy_m)
    start = Pose2D(x, y, yaw)
    soles = start_soles(ROBOT, q)
    assert straight_walk(ROBOT, blocked, soles, start, goal, StraightWalkOptions()) is None
    assert straight_walk(ROBOT, scene, soles, start, goal, StraightWalkOptions()) is not None


def test_a_goto_from_a_start_overlapping_a_box_walks_out_first_in_the_same_motion() -> None:
    """Fetch seed 49: navigation refused a start whose footprint overlapped the chair. Now its footsteps
    begin with a straight walk to the nearest free pose (computed from the overlap), then the path: one
    stage-2 motion from the robot's configuration to the goal."""
    import math

    from services.collision import Scene
    from services.navigation.geometry import Pose2D
    from services.navigation.goto import plan_goto

    q = np.array(ROBOT.q_half_sitting)
    x, y, yaw = ROBOT.mid_feet_pose(q)
    back = (-math.cos(yaw), -math.sin(yaw))
    # the chair 8 cm into the footprint's margin behind the heels (clear in 3D), the goal 2 m ahead
    chair = BoxObstacle("chair", (x + 0.45 * back[0], y + 0.45 * back[1], 0.45), (0.45, 0.45, 0.9), yaw)
    scene = Scene((chair,), (x - 4.0, x + 4.0, y - 4.0, y + 4.0))
    goal = Pose2D(x + 2.0 * math.cos(yaw), y + 2.0 * math.sin(yaw), yaw)
    with pytest.raises(InfeasibleError, match="start pose"):  # stage 1 alone refuses that start
        from services.navigation.body_extents import with_arms_of
        from services.navigation.geometry import body_model
        from services.navigation.path import plan_path

        plan_path(scene, with_arms_of(body_model(ROBOT.name), ROBOT, q), Pose2D(x, y, yaw), goal)
    result = plan_goto(ROBOT, scene, q, goal)
    assert result.path.curve.startswith("escape+")
    first = result.footsteps.sequence.steps[0].pose
    assert (first.x_m - x) * back[0] + (first.y_m - y) * back[1] < 0.0  # the first step away from the chair
    gx, gy, _ = ROBOT.mid_feet_pose(result.motion.q[-1])
    assert math.hypot(gx - goal.x_m, gy - goal.y_m) < 0.05
    assert result.path.start.x_m == pytest.approx(x, abs=0.01) and result.path.start.y_m == pytest.approx(
        y, abs=0.01
    )
