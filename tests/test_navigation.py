"""Stage 1 of the navigation planner (services/navigation): footprint checker, OMPL car-like paths, goals,
the carried bar's 3D sweep, footsteps along the path. Pure algorithm tests, no bus."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.collision import BoxObstacle, CarriedBar, CylinderObstacle, Scene
from services.errors import InfeasibleError, InvalidRequestError, NotFoundError
from services.model import load_robot
from services.navigation.body_extents import with_arms_of
from services.navigation.demo_scenes import (
    BAR_BOX_TOP_M,
    BAR_GOAL_X_M,
    bar_scenario,
    bar_scenario_start,
    demo_room,
    enclosed_goal_room,
    random_clutter,
    walls,
)
from services.navigation.footsteps_along_path import footsteps_along_path
from services.navigation.geometry import FootprintChecker, Pose2D, body_model
from services.navigation.goals import ObjectGoal
from services.navigation.path import PlannerConfig, SampledPath, escape_pose, plan_path, stage1_checker
from services.navigation.upper_body import sweep_carried_object
from services.walking.footsteps import FootstepBounds, wrap_angle

BODY = body_model("hrp2_like")


def _assert_path_valid(scene: Scene, path: SampledPath, config: PlannerConfig) -> None:
    """Every sample is free for the nominal footprint, the curvature never exceeds 1/R, the samples are
    dense and ordered."""
    checker = FootprintChecker(scene, BODY)
    for (x, y), theta in zip(path.xy_m, path.theta_rad, strict=True):
        assert checker.colliding_obstacles(float(x), float(y), float(theta)) == []
    kappa_max = 1.0 / config.turning_radius_m
    assert path.curvature().max() <= kappa_max * (1.0 + 1e-6)
    ds = np.diff(path.s_m)
    assert np.all(ds > 0.0) and ds.max() <= config.sample_step_m + 1e-9
    # arc length matches the chord length of the dense samples (up to the arcs' sagitta)
    chords = np.linalg.norm(np.diff(path.xy_m, axis=0), axis=1)
    assert np.allclose(chords, ds, atol=ds.max() ** 2 * kappa_max)


# ------------------------------------------------------------------------------------------------ geometry


def test_footprint_checker_agrees_with_point_sampling() -> None:
    """Grid shortcuts agree with the exact test, and the exact test agrees with dense point sampling of the
    footprint against the obstacles (seeded random poses in the cluttered scene)."""
    scene, _, _ = random_clutter(20, seed=3)
    checker = FootprintChecker(scene, BODY)
    rng = np.random.default_rng(0)
    hx, hy = BODY.half_extents_m
    u, v = np.meshgrid(np.linspace(-hx, hx, 25), np.linspace(-hy, hy, 25))
    legs = np.column_stack([u.ravel(), v.ravel()])
    ax, ay = BODY.arms_half_extents_m
    u, v = np.meshgrid(np.linspace(-ax, ax, 15), np.linspace(-ay, ay, 35))
    arms = np.column_stack([u.ravel() + BODY.arms_offset_m, v.ravel()])
    arm_z0, arm_z1 = BODY.arms_z_range_m
    n_hit = 0
    for _ in range(400):
        x, y = rng.uniform(-3.7, 3.7, size=2)
        theta = rng.uniform(-math.pi, math.pi)
        hits = checker.colliding_obstacles(x, y, theta)
        assert checker.is_free(x, y, theta) == (not hits)
        c, s = math.cos(theta), math.sin(theta)
        inside_any = set()
        for o in scene.obstacles:
            z0, z1 = o.z_range_m
            # the legs' rectangle sees every obstacle here (all start on the floor), the arms' one those
            # reaching into the arms' height range
            local = legs if z1 < arm_z0 or z0 > arm_z1 else np.vstack([legs, arms])
            d = local @ np.array([[c, s], [-s, c]]) + np.array([x, y]) - np.asarray(o.center_xyz_m[:2])
            if isinstance(o, BoxObstacle):
                co, so = math.cos(o.yaw_rad), math.sin(o.yaw_rad)
                lx, ly = d[:, 0] * co + d[:, 1] * so, -d[:, 0] * so + d[:, 1] * co
                inside = (np.abs(lx) <= 0.5 * o.size_xyz_m[0]) & (np.abs(ly) <= 0.5 * o.size_xyz_m[1])
            else:
                inside = np.hypot(d[:, 0], d[:, 1]) <= o.radius_m
            if inside.any():
                inside_any.add(o.name)
        # sampled points inside an obstacle => the exact test reports it
        assert inside_any <= set(hits)
        n_hit += bool(hits)
    assert 40 < n_hit < 360  # the poses exercise both answers


def test_the_arms_box_sees_obstacles_at_arm_height_only() -> None:
    """A crate beside the robot: 0.42 m from the base (outside the legs' 0.27 m half width, inside the
    hanging arms' 0.49 m) blocks it when it reaches the hands (0.8 m high), not when it is low (0.3 m)."""
    for height, blocked in ((0.8, True), (0.3, False)):
        crate = BoxObstacle("crate", (0.0, 0.42 + 0.1, 0.5 * height), (0.4, 0.2, height))
        checker = FootprintChecker(Scene((crate,), (-2.0, 2.0, -2.0, 2.0)), BODY)
        assert checker.colliding_obstacles(0.0, 0.0, 0.0) == (["crate"] if blocked else [])
        assert checker.is_free(0.0, 0.0, 0.0) is not blocked
        assert checker.arm_obstacles == (["crate"] if blocked else [])


def test_footprint_ignores_obstacles_above_the_lower_body() -> None:
    shelf = BoxObstacle("high_shelf", (0.0, 0.0, 1.5), (1.0, 1.0, 0.2))
    checker = FootprintChecker(Scene((shelf,), (-2.0, 2.0, -2.0, 2.0)), BODY)
    assert checker.is_free(0.0, 0.0, 0.0)
    assert checker.lower_body_obstacles == []


def test_scene_and_obstacle_validation() -> None:
    with pytest.raises(InvalidRequestError, match="unique"):
        Scene((CylinderObstacle("a", (0, 0, 0.5), 0.1, 1.0),) * 2, (-1.0, 1.0, -1.0, 1.0))
    with pytest.raises(InvalidRequestError, match="sizes must be > 0"):
        BoxObstacle("b", (0, 0, 0), (0.0, 1.0, 1.0))
    with pytest.raises(NotFoundError, match="known robots"):
        body_model("asimo")


# ------------------------------------------------------------------------------------------------- paths


@pytest.mark.parametrize("name", ["room", "clutter"])
def test_path_avoids_obstacles_and_respects_turning_radius(name: str) -> None:
    scene, start, goal = demo_room() if name == "room" else random_clutter(20, seed=0)
    # The forward (Dubins) search gets 5 s, its improvement 2 of BIT*'s batches: what it finds must not
    # depend on the machine's load (with the default 1 s at load 8 the clutter's Dubins search ran out
    # and forward_preferred fell back to a Reeds-Shepp path with cusps)
    config = PlannerConfig(time_budget_s=5.0, optimize_batches=2)
    path = plan_path(scene, BODY, start, goal, config)
    _assert_path_valid(scene, path, config)
    assert path.curve == "dubins"  # forward preferred: a forward path exists here
    assert path.forward.all() and path.reverse_length_m == 0.0
    for end, pose in ((path.start, start), (path.goal, goal)):
        assert math.hypot(end.x_m - pose.x_m, end.y_m - pose.y_m) < 1e-9
        assert abs(wrap_angle(end.theta_rad - pose.theta_rad)) < 1e-9


def test_larger_turning_radius_is_respected() -> None:
    scene = Scene(tuple(walls(-4.0, 4.0, -4.0, 4.0)), (-4.0, 4.0, -4.0, 4.0))
    config = PlannerConfig(turning_radius_m=1.2)
    path = plan_path(scene, BODY, Pose2D(-2.0, 0.0, 0.0), Pose2D(0.0, 0.5, math.pi), config)
    _assert_path_valid(scene, path, config)
    assert path.curvature().max() > 0.9 / 1.2  # the U-turn really uses the minimum radius


def test_walking_forward_is_preferred_over_reeds_shepp() -> None:
    """Goal 1 m straight behind: Reeds-Shepp backs up 1 m, forward_preferred loops around forward."""
    scene = Scene((), (-3.0, 3.0, -3.0, 3.0))
    start, goal = Pose2D(0.0, 0.0, 0.0), Pose2D(-1.0, 0.0, 0.0)
    backward = plan_path(scene, BODY, start, goal, PlannerConfig(curve="reeds_shepp"))
    assert backward.reverse_length_m == pytest.approx(1.0, abs=0.05)
    assert backward.length_m == pytest.approx(1.0, abs=0.05)
    forward = plan_path(scene, BODY, start, goal, PlannerConfig())
    assert forward.curve == "dubins" and forward.reverse_length_m == 0.0
    assert forward.length_m > 2.0 * math.pi * 0.5  # it has to turn around


def test_forward_preferred_falls_back_to_reeds_shepp() -> None:
    """A dead-end corridor 0.8 m wide between walls below the hands (0.45 m) with the goal facing out: no
    forward path, backing in works."""
    corridor = [
        BoxObstacle("left_wall", (1.5, 0.45, 0.225), (3.0, 0.1, 0.45)),
        BoxObstacle("right_wall", (1.5, -0.45, 0.225), (3.0, 0.1, 0.45)),
        BoxObstacle("end_wall", (3.05, 0.0, 0.225), (0.1, 1.0, 0.45)),
    ]
    scene = Scene(tuple(corridor), (-3.0, 3.0, -3.0, 3.0))
    config = PlannerConfig(time_budget_s=1.5)
    path = plan_path(scene, BODY, Pose2D(-2.0, 0.0, math.pi), Pose2D(2.0, 0.0, math.pi), config)
    assert path.curve == "reeds_shepp" and path.reverse_length_m > 1.0
    _assert_path_valid(scene, path, config)
    with pytest.raises(InfeasibleError, match="no dubins path") as info:
        plan_path(
            scene,
            BODY,
            Pose2D(-2.0, 0.0, math.pi),
            Pose2D(2.0, 0.0, math.pi),
            PlannerConfig(curve="dubins", time_budget_s=0.3),
        )
    assert info.value.details["reason"] == "no_path_within_budget"
    assert info.value.details["goals"] == [[2.0, 0.0, math.pi]]  # what was tried, for a fallback


def test_enclosed_goal_is_infeasible_and_names_the_enclosure() -> None:
    scene, start, goal = enclosed_goal_room()
    with pytest.raises(InfeasibleError, match="enclosed") as info:
        plan_path(scene, BODY, start, goal, PlannerConfig(time_budget_s=5.0))
    assert info.value.details["reason"] == "goal_enclosed"
    assert set(info.value.details["enclosing_obstacles"]) == {
        "pen_north",
        "pen_south",
        "pen_east",
        "pen_west",
    }


def test_colliding_start_and_goal_and_bad_requests() -> None:
    scene, start, _ = demo_room()
    with pytest.raises(InfeasibleError, match="yellow_table") as info:
        plan_path(scene, BODY, start, Pose2D(1.6, 1.5, 0.0))
    assert info.value.details == {"reason": "goal_in_collision", "obstacles": ["yellow_table"]}
    with pytest.raises(InvalidRequestError, match="outside the scene bounds"):
        plan_path(scene, BODY, start, Pose2D(9.0, 0.0, 0.0))
    with pytest.raises(InvalidRequestError, match="forward_preferred"):
        PlannerConfig(curve="bezier")
    with pytest.raises(InvalidRequestError, match="turning_radius_m"):
        PlannerConfig(turning_radius_m=0.0)


def test_a_start_overlapping_a_box_escapes_to_the_nearest_free_pose() -> None:
    """Fetch seed 49: the robot stood beside the chair, its footprint (margin included) over it; stepping
    back did not clear it. The way out is computed from the overlap: the nearest free pose, same
    heading, is free for stage 1's checker, and no free pose is much nearer."""
    chair = BoxObstacle("chair", (0.0, 0.0, 0.45), (0.45, 0.45, 0.9), 0.3)
    scene = Scene((chair,), (-3.0, 3.0, -3.0, 3.0))
    checker = stage1_checker(scene, BODY, PlannerConfig())
    start = Pose2D(0.45, 0.1, -math.pi / 2)  # the chair on the robot's right, beside the arm
    assert not checker.is_free(start.x_m, start.y_m, start.theta_rad)
    free = escape_pose(checker, start)
    assert free is not None and free.theta_rad == start.theta_rad
    assert checker.is_free(free.x_m, free.y_m, free.theta_rad)
    moved = math.hypot(free.x_m - start.x_m, free.y_m - start.y_m)
    assert 0.0 < moved < 0.6
    for angle in np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False):  # nothing free 3 cm nearer
        d = moved - 0.03
        assert not checker.is_free(
            start.x_m + d * math.cos(angle), start.y_m + d * math.sin(angle), start.theta_rad
        )
    assert escape_pose(checker, free) == free  # a free start stays
    assert escape_pose(checker, Pose2D(0.0, 0.0, 0.0)) is None  # inside the chair: nothing within reach


def test_same_request_same_path() -> None:
    """OMPL is reseeded per call: a planner that stops at its first solution replies identically."""
    scene, start, goal = demo_room()
    config = PlannerConfig(planner="rrt", seed=7)
    a = plan_path(scene, BODY, start, goal, config)
    plan_path(scene, BODY, start, goal, PlannerConfig(planner="rrt", seed=8))
    b = plan_path(scene, BODY, start, goal, config)
    assert np.array_equal(a.waypoints, b.waypoints)
    # BIT* improving for a number of its batches instead of a wall-clock window (Fig. 10's example):
    # the same path whatever the load, and the short one (its first solution loops: 8.13 m)
    config = PlannerConfig(optimize_batches=2, time_budget_s=10.0)
    a, b = (plan_path(scene, BODY, start, ObjectGoal("yellow_table", 0.4), config) for _ in range(2))
    assert np.array_equal(a.waypoints, b.waypoints)
    assert a.length_m < 5.5
    with pytest.raises(InvalidRequestError, match="optimize_batches"):
        PlannerConfig(planner="rrtstar", optimize_batches=2)


# ------------------------------------------------------------------------------------------------- goals


def _face_distance(box: BoxObstacle, pose: Pose2D) -> tuple[float, float]:
    """(distance [m] from the box to the base, angle [rad] from the heading to the box's nearest point)."""
    c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
    dx, dy = pose.x_m - box.center_xyz_m[0], pose.y_m - box.center_xyz_m[1]
    lx, ly = dx * c + dy * s, -dx * s + dy * c
    qx = max(abs(lx) - 0.5 * box.size_xyz_m[0], 0.0)
    qy = max(abs(ly) - 0.5 * box.size_xyz_m[1], 0.0)
    # the nearest point of the box, back in world
    px = max(min(lx, 0.5 * box.size_xyz_m[0]), -0.5 * box.size_xyz_m[0])
    py = max(min(ly, 0.5 * box.size_xyz_m[1]), -0.5 * box.size_xyz_m[1])
    nx, ny = box.center_xyz_m[0] + c * px - s * py, box.center_xyz_m[1] + s * px + c * py
    bearing = math.atan2(ny - pose.y_m, nx - pose.x_m)
    return math.hypot(qx, qy), wrap_angle(bearing - pose.theta_rad)


@pytest.mark.parametrize("name", ["yellow_table", "blue_table"])
def test_object_goal_faces_the_object_at_the_distance(name: str) -> None:
    scene, start, _ = demo_room()
    path = plan_path(scene, BODY, start, ObjectGoal(name, distance_m=0.45))
    distance, bearing = _face_distance(scene.find(name), path.goal)  # type: ignore[arg-type]
    assert distance == pytest.approx(0.45, abs=1e-9)
    assert abs(bearing) < 1e-9
    _assert_path_valid(scene, path, PlannerConfig())


def test_object_goal_picks_a_free_side() -> None:
    """The face nearest the start is blocked by a crate: the pose goes to another face, still free."""
    table = BoxObstacle("table", (0.0, 0.0, 0.35), (1.0, 0.6, 0.7))
    crate = BoxObstacle("crate", (-1.0, 0.0, 0.3), (0.4, 0.8, 0.6))
    scene = Scene((table, crate), (-3.0, 3.0, -3.0, 3.0))
    start = Pose2D(-2.5, 0.0, 0.0)
    path = plan_path(scene, BODY, start, ObjectGoal("table", 0.4))
    distance, bearing = _face_distance(table, path.goal)
    assert distance == pytest.approx(0.4, abs=1e-9) and abs(bearing) < 1e-9
    assert path.goal.x_m > -0.5 - 1e-9  # not on the -x face, where the crate is
    assert (
        FootprintChecker(scene, BODY).colliding_obstacles(path.goal.x_m, path.goal.y_m, path.goal.theta_rad)
        == []
    )


def test_object_goal_cylinder_and_errors() -> None:
    scene, start, _ = demo_room()
    path = plan_path(scene, BODY, start, ObjectGoal("pillar", 0.5))
    pillar = scene.find("pillar")
    to_centre = math.atan2(pillar.center_xyz_m[1] - path.goal.y_m, pillar.center_xyz_m[0] - path.goal.x_m)
    assert math.hypot(pillar.center_xyz_m[0] - path.goal.x_m, pillar.center_xyz_m[1] - path.goal.y_m) == (
        pytest.approx(0.2 + 0.5)
    )
    assert abs(wrap_angle(to_centre - path.goal.theta_rad)) < 1e-9
    with pytest.raises(NotFoundError, match=r"known objects.*yellow_table"):
        plan_path(scene, BODY, start, ObjectGoal("red_table"))
    with pytest.raises(InfeasibleError, match="no free place to stand") as info:
        plan_path(scene, BODY, start, ObjectGoal("yellow_table", distance_m=0.1))
    assert info.value.details["reason"] == "no_free_approach_pose"


# ------------------------------------------------------------------------------------------- carried bar


def test_bar_sweep_detects_the_box_on_the_table_and_clears_when_lifted() -> None:
    scene, start, goal = bar_scenario()
    robot = load_robot("hrp2_like")
    holding = with_arms_of(BODY, robot, bar_scenario_start(robot))  # the arms ahead, holding the bar
    assert holding.arms_x_range_m[1] > 0.4 and holding.arms_width_m < BODY.arms_width_m
    path = plan_path(scene, holding, start, goal)
    assert path.length_m == pytest.approx(BAR_GOAL_X_M, abs=1e-6)  # free floor: straight through
    bar = CarriedBar(height_m=0.9)
    sweep = sweep_carried_object(scene, path, bar, BODY)
    assert len(sweep.segments) == 1
    seg = sweep.segments[0]
    assert seg.part == "bar" and seg.obstacles == ("box",)
    # the bar (centre 0.35 m ahead of the base) meets the box's x range [1.85, 2.15] m, widened by its radius
    box = scene.find("box")
    first_x = box.center_xyz_m[0] - 0.5 * box.size_xyz_m[0] - bar.radius_m - bar.forward_m
    last_x = box.center_xyz_m[0] + 0.5 * box.size_xyz_m[0] + bar.radius_m - bar.forward_m
    step = float(np.diff(path.s_m).max())
    assert first_x - 1e-9 <= seg.s_collide_m <= first_x + step
    assert last_x - step <= seg.s_collide_end_m <= last_x + 1e-9
    assert seg.s_anticipate_m < seg.s_collide_m and seg.s_regain_m > seg.s_collide_end_m
    assert seg.min_distance_m == pytest.approx(-(BAR_BOX_TOP_M - 0.9 + bar.radius_m), abs=1e-3)
    assert seg.clear_height_m == pytest.approx(BAR_BOX_TOP_M + bar.radius_m + 0.05)
    # the bar overhangs the table top (0.72 m) and passes above the stands (0.75 m) without touching them;
    # the torso passes the table
    assert not any(s.part == "upper_body" for s in sweep.segments)

    higher = sweep_carried_object(scene, path, CarriedBar(height_m=1.1), BODY)
    assert higher.collision_free and higher.sweep_free

    # the height profile lifted to clear_height between the anticipating and regaining limits is free
    lifted = np.where(
        (path.s_m >= seg.s_anticipate_m) & (path.s_m <= seg.s_regain_m), seg.clear_height_m, 0.9
    )
    assert sweep_carried_object(scene, path, bar, BODY, bar_height_m=lifted).collision_free


# ---------------------------------------------------------------------------------------------- footsteps


def _check_bounds(seq, bounds: FootstepBounds) -> None:
    feet = {"left": seq.left_start, "right": seq.right_start}
    previous = None
    for step in seq.steps:
        assert step.side != previous  # alternating
        previous = step.side
        stance = feet["right" if step.side == "left" else "left"]
        dx, dy, dyaw = step.pose.relative_to(stance)
        sign = 1.0 if step.side == "left" else -1.0
        assert bounds.dx_min_m < dx < bounds.dx_max_m
        assert bounds.dy_min_m < sign * dy < bounds.dy_max_m
        assert bounds.dtheta_min_rad < sign * dyaw < bounds.dtheta_max_rad
        feet[step.side] = step.pose


@pytest.mark.parametrize("curve", ["dubins", "reeds_shepp"])
def test_footsteps_along_path_respect_the_bounds(curve: str) -> None:
    bounds = FootstepBounds()
    for scene, start, goal in (demo_room(), random_clutter(20, seed=0)):
        path = plan_path(scene, BODY, start, goal, PlannerConfig(curve=curve, time_budget_s=5.0))  # loaded CI
        result = footsteps_along_path(path, bounds)
        seq = result.sequence
        _check_bounds(seq, bounds)
        assert len(result.s_m) == len(seq.steps) and all(np.diff(result.s_m) >= 0.0)
        # each landing sits beside the path at its arc length, half the feet spacing (+ outward shift) off
        for step, s in zip(seq.steps, result.s_m, strict=True):
            p = path.pose_at(s)
            offset = math.hypot(step.pose.x_m - p.x_m, step.pose.y_m - p.y_m)
            assert 0.095 - 1e-9 <= offset <= 0.095 + 0.06 + 1e-9
        # ends with the feet side by side on the goal pose
        left, right = seq.final_stance()
        g = path.goal
        for foot, lateral in ((left, 0.095), (right, -0.095)):
            assert foot.x_m == pytest.approx(g.x_m - lateral * math.sin(g.theta_rad), abs=1e-9)
            assert foot.y_m == pytest.approx(g.y_m + lateral * math.cos(g.theta_rad), abs=1e-9)
            assert wrap_angle(foot.yaw_rad - g.theta_rad) == pytest.approx(0.0, abs=1e-9)
        # steps shorten in turns: no more than ~0.2 m of path per step
        assert np.diff(result.s_m).max() <= 0.2 + 1e-9


def test_upper_body_meets_a_beam_the_footprint_walks_under() -> None:
    """A beam at 1.2-1.4 m across the way: invisible to the footprint (above the hips), hit by the torso."""
    beam = BoxObstacle("beam", (2.0, 0.0, 1.3), (0.2, 3.0, 0.2))
    scene = Scene((beam,), (-1.0, 5.0, -2.0, 2.0))
    path = plan_path(scene, BODY, Pose2D(0.0, 0.0, 0.0), Pose2D(4.0, 0.0, 0.0))
    assert path.length_m == pytest.approx(4.0, abs=1e-6)
    sweep = sweep_carried_object(scene, path, CarriedBar(height_m=0.9), BODY)
    parts = {seg.part: seg for seg in sweep.segments}
    assert set(parts) == {"upper_body"} and parts["upper_body"].obstacles == ("beam",)
    assert parts["upper_body"].clear_height_m is None
    # the torso box (0.40 m long) meets the beam (0.2 m thick) while the base is within 0.3 m of x = 2
    assert parts["upper_body"].s_collide_m == pytest.approx(2.0 - 0.1 - 0.2, abs=0.021)
    assert parts["upper_body"].s_collide_end_m == pytest.approx(2.0 + 0.1 + 0.2, abs=0.021)
