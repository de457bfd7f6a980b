"""Contact-before-motion planning (services/contacts, Escande et al.): search volumes (§2.6, Fig. 1),
static stability with non-coplanar contacts (§2.2), the capsule-box collision task, the floating
contact tasks (Jacobians against finite differences), f_T (§2.7, eq. 1), the posture generator (§2.2)
and the best-first search's son generation (§2.3, §2.8) on the chair scene."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from services.contacts import chair_egress
from services.contacts.closed_loop import regenerate_witness
from services.contacts.contact_tasks import InVolumeTask, OnPlaneTask
from services.contacts.environment import environment_of
from services.contacts.interpolate import deepest_collision
from services.contacts.posture import Floating, PostureGenerator
from services.contacts.potential import PotentialTask, RoughTrajectory, base_point
from services.contacts.search import ContactPlanner, Goal, SearchConfig
from services.contacts.sets import Contact, contact_at, patch_of, sets_close, turn_moving_corners_by
from services.contacts.spots import robot_spots
from services.contacts.stability import ContactPatch, equilibrium_region, is_statically_stable
from services.contacts.volumes import SearchVolume, around, full_volume, subtract
from services.errors import InfeasibleError, InvalidRequestError
from services.ik import compute_kinematics
from services.ik.tasks.capsule_box import CapsuleBoxTask, ObstacleBox, segment_box_distances
from services.model import load_robot
from services.model.ground import signed_distance
from sim.scene import layout, load_scene
from sim.world import start_configuration

H = 1e-6
FD_TOL = 1e3 * (H**2 + np.finfo(float).eps / H)


@pytest.fixture(scope="module")
def chair():
    robot = load_robot("hrp2_like")
    lay = layout(load_scene("chair_egress"))
    env = environment_of(lay)
    gen = PostureGenerator(robot, env, robot_spots(robot))
    q0 = start_configuration(robot, lay)
    start = tuple(contact_at(gen.spots[s], e, env, gen.spot_pose(q0, s)) for s, e in chair_egress.START_PAIRS)
    return robot, env, gen, q0, start


# ------------------------------------------------------------------------------------------ volumes
def test_subtracting_v_leaves_convex_parts_that_cover_c_minus_v():
    C = full_volume(0.3, 0.2)
    V = around((0.1, -0.05, 0.5), (0.05, 0.05, 0.3))
    parts = subtract(C, V, (0.0, 0.0, 0.0))
    assert len(parts) == 6
    rng = np.random.default_rng(0)
    for point in rng.uniform(C.lower, C.upper, size=(2000, 3)):
        in_v, inside = V.contains(point, tol=0.0), [p.contains(point, tol=0.0) for p in parts]
        strictly_in_v = all(lo < v < hi for lo, v, hi in zip(V.lower, point, V.upper, strict=True))
        assert not (strictly_in_v and any(inside))  # parts never enter V's interior
        assert in_v or any(inside)  # and cover the rest of C
    volume = sum(math.prod(p.size) for p in parts)
    assert volume == pytest.approx(math.prod(C.size) - math.prod(V.size))


def test_a_volume_outside_c_changes_nothing_and_thin_parts_are_dropped():
    C = SearchVolume((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    assert subtract(C, around((5.0, 5.0, 5.0), (0.1, 0.1, 0.1)), (0.0, 0.0, 0.0)) == [C]
    parts = subtract(C, around((0.5, 0.99, 0.5), (0.2, 0.2, 2.0)), (0.05, 0.05, 0.05))
    assert all(min(p.size) >= 0.05 for p in parts)
    with pytest.raises(InvalidRequestError, match="above upper"):
        SearchVolume((1.0, 0.0, 0.0), (0.0, 1.0, 1.0))


# ------------------------------------------------------------------------------------------ stability
def _square(cx: float, cy: float, z: float, half: float = 0.05) -> np.ndarray:
    return np.array([[cx + a * half, cy + b * half, z] for a, b in ((1, 1), (-1, 1), (-1, -1), (1, -1))])


def test_coplanar_region_is_the_convex_hull_of_the_contacts():
    up = np.array([0.0, 0.0, 1.0])
    patches = [ContactPatch(_square(0.0, 0.1, 0.0), up, 0.8), ContactPatch(_square(0.0, -0.1, 0.0), up, 0.8)]
    region = equilibrium_region(patches)
    assert region[:, 0].min() == pytest.approx(-0.05, abs=3e-3)
    assert region[:, 0].max() == pytest.approx(0.05, abs=3e-3)
    assert region[:, 1].min() == pytest.approx(-0.15, abs=3e-3)
    assert region[:, 1].max() == pytest.approx(0.15, abs=3e-3)


def test_non_coplanar_region_differs_from_the_hull_and_the_force_qp_agrees_with_it():
    up = np.array([0.0, 0.0, 1.0])
    feet = [ContactPatch(_square(0.0, 0.1, 0.0), up, 0.8), ContactPatch(_square(0.0, -0.1, 0.0), up, 0.8)]
    hand_high = ContactPatch(_square(0.5, 0.0, 0.8), up, 0.8)
    region = equilibrium_region([*feet, hand_high])
    flat = equilibrium_region([*feet, ContactPatch(_square(0.5, 0.0, 0.0), up, 0.8)])
    # friction at a contact higher up moves the region beyond the flat hull (here wider at the feet)
    assert _area(region) > _area(flat) + 1e-2
    rng = np.random.default_rng(1)
    agree = 0
    for xy in rng.uniform((-0.2, -0.3), (0.7, 0.3), size=(200, 2)):
        margin = -float(signed_distance(xy, region)[0])  # > 0 inside
        if abs(margin) < 5e-3:
            continue  # on the boundary within the projection's tolerance
        feasible, _ = is_statically_stable([*feet, hand_high], np.array([xy[0], xy[1], 0.7]))
        assert feasible == (margin > 0.0), (xy, margin)
        agree += 1
    assert agree > 150


def test_the_warm_started_lps_give_the_regions_of_cold_ones():
    """The projection's LPs re-solved on one HiGHS model (stability._WarmLP) find the same region as
    each solved anew by linprog: flat, non-coplanar, and with a load bound on the high contact."""
    up = np.array([0.0, 0.0, 1.0])
    feet = [ContactPatch(_square(0.0, 0.1, 0.0), up, 0.8), ContactPatch(_square(0.0, -0.1, 0.0), up, 0.8)]
    tilted = np.array([0.0, -0.4, 1.0]) / math.hypot(0.4, 1.0)
    cases = (
        feet,
        [*feet, ContactPatch(_square(0.5, 0.0, 0.8), up, 0.8)],
        [*feet, ContactPatch(_square(0.5, 0.0, 0.8), tilted, 0.5, max_load=0.2)],
        [feet[0], ContactPatch(_square(0.4, 0.2, 0.7), up, 0.8, max_load=0.22)],
    )
    for patches in cases:
        warm = equilibrium_region(patches)
        cold = equilibrium_region(patches, warm=False)
        assert warm.shape == cold.shape
        assert max(np.linalg.norm(cold - v, axis=1).min() for v in warm) < 1e-7
        assert _area(warm) == pytest.approx(_area(cold), abs=1e-9)


def test_the_warm_lps_run_on_the_scipy_they_were_checked_against_only():
    """stability._WarmLP drives scipy's private HiGHS bindings: only on a scipy of WARM_LP_SCIPY (the
    installed one is, so the comparison above runs both paths), another goes through linprog."""
    import scipy

    from services.contacts import stability

    assert stability._scipy_highs(scipy.__version__) is not None
    assert stability._highs is not None
    for other in ("1.16.3", "1.18.0", "2.0.0rc1", "unknown"):
        assert stability._scipy_highs(other) is None


def _area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


# ------------------------------------------------------------------------------------------ tasks
def _fd_check(task, model, q, atol=FD_TOL):
    data = model.createData()
    compute_kinematics(model, data, q, True)
    F, J = task.compute(q, data)
    columns = []
    for i in range(model.nv):
        step = np.zeros(model.nv)
        step[i] = H
        values = []
        for sign in (1.0, -1.0):
            q_i = pin.integrate(model, q, sign * step)
            compute_kinematics(model, data, q_i, True)
            values.append(task.compute_error(q_i, data))
        columns.append((values[0] - values[1]) / (2.0 * H))
    np.testing.assert_allclose(J, np.column_stack(columns), atol=atol, rtol=0)
    return F


def test_floating_contact_task_jacobians(chair):
    robot, env, gen, q0, _ = chair
    rng = np.random.default_rng(3)
    volume = SearchVolume((-0.3, -0.3, -3.0), (0.3, 0.3, 3.0))
    for _ in range(3):
        q = pin.integrate(gen.model, q0, rng.normal(scale=0.3, size=gen.model.nv))
        q[7:] = np.clip(q[7:], robot.q_lower[7:] + 1e-3, robot.q_upper[7:] - 1e-3)
        for spot in ("left_sole", "right_hand", "left_thigh"):
            frame = gen.spots[spot].frame_name
            _fd_check(OnPlaneTask(gen.model, frame, env.surface("chair.seat")), gen.model, q)
            _fd_check(InVolumeTask(gen.model, frame, env.surface("table.top"), volume), gen.model, q)


def test_capsule_box_distances_and_jacobian(chair):
    robot, env, gen, _q0, _ = chair
    # segment above a unit box, and one through it (negative: the depth to the nearest face)
    R, t, half = np.eye(3)[None], np.zeros((1, 3)), np.full((1, 3), 0.5)
    d, _, n = segment_box_distances(np.array([[-1.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 1.0]]), R, t, half)
    assert d[0] == pytest.approx(0.5) and n[0] == pytest.approx([0.0, 0.0, 1.0])
    d, _, n = segment_box_distances(np.array([[-1.0, 0.0, 0.3]]), np.array([[1.0, 0.0, 0.3]]), R, t, half)
    assert d[0] == pytest.approx(-0.2) and n[0] == pytest.approx([0.0, 0.0, 1.0])
    boxes = [ObstacleBox(b.name, b.T_world_box, b.half_extents_m) for b in env.boxes]
    pairs = [(i, j) for i in range(len(robot.capsules)) for j in range(len(boxes))]
    task = CapsuleBoxTask(gen.model, robot.capsules, boxes, pairs, margin_m=0.01, activation_m=10.0)
    data = gen.model.createData()
    # standing beside the table's corner, arms forward: near the table, clear of it (separated pairs:
    # a penetrating pair's nearest face is a first-order direction out, not a derivative)
    q = robot.half_sitting_at(0.25, 0.5, 0.0)
    q[robot.joint_index("LARM_JOINT0").idx_q] = -1.0
    q[robot.joint_index("RARM_JOINT0").idx_q] = -1.0
    compute_kinematics(gen.model, data, q, False)
    separated = [p for p, d in zip(pairs, task.distances(data), strict=True) if d > 1e-3]
    assert min(d for d in task.distances(data) if d > 1e-3) < 0.3
    task = CapsuleBoxTask(gen.model, robot.capsules, boxes, separated, margin_m=0.01, activation_m=10.0)
    F = _fd_check(task, gen.model, q, atol=1e-4)
    compute_kinematics(gen.model, data, q, False)
    np.testing.assert_allclose(F, 0.01 - task.distances(data))


def test_the_broad_phase_leaves_out_only_pairs_beyond_the_activation_distance(chair):
    """compute() checks only the pairs the broad phase keeps: its rows must be those of every pair
    within margin + activation, bit for bit, in random postures near the chair and the table."""
    robot, env, gen, q0, start = chair
    boxes = [ObstacleBox(b.name, b.T_world_box, b.half_extents_m) for b in env.boxes]
    task = CapsuleBoxTask(gen.model, gen.capsules, boxes, gen.box_pairs([c.pair for c in start]), 0.015)
    data = gen.model.createData()
    rng = np.random.default_rng(3)
    rows = 0
    for _ in range(40):
        q = q0.copy()
        q[:3] += rng.normal(0.0, 0.15, 3)
        q[7:] = np.clip(q[7:] + rng.normal(0.0, 0.4, q.size - 7), robot.q_lower[7:], robot.q_upper[7:])
        compute_kinematics(gen.model, data, q, False)
        errors, J = task.compute(q, data)
        distances = task.distances(data)
        near = distances <= task.margin_m + task.activation_m
        np.testing.assert_array_equal(errors, task.margin_m - distances[near])
        assert J.shape == (int(near.sum()), gen.model.nv)
        rows += errors.shape[0]
    assert rows > 40  # the postures do come near the boxes


def test_a_posture_generation_depends_on_its_inputs_only(chair):
    """The QPs' warm starts do not carry over from one generation to the next: the same request after
    another one gives the same witness, bit for bit (plans are reproducible)."""
    robot, env, gen, q0, start = chair
    T = RoughTrajectory(gen.model, chair_egress.key_postures(robot, env, q0))
    rest = start[1:]
    first = gen.generate(start, rest, q0, PotentialTask(T))
    gen.generate(start, start[:2], q0, PotentialTask(T))
    again = gen.generate(start, rest, q0, PotentialTask(T))
    assert first.ok and again.ok
    np.testing.assert_array_equal(first.q, again.q)


def test_the_search_stops_at_its_cpu_budget(chair):
    robot, env, gen, q0, start = chair
    T = RoughTrajectory(gen.model, chair_egress.key_postures(robot, env, q0))
    planner = ContactPlanner(
        gen,
        T,
        Goal("y", 0.6, chair_egress.FINAL_PAIRS),
        chair_egress.PAIRS,
        SearchConfig(time_budget_s=120.0, cpu_budget_s=0.5),
    )
    result = planner.plan(start, q0)
    assert result.status == "timeout" and "CPU budget" in result.message
    assert 0.5 <= result.plan_cpu_s < 30.0 and result.nodes_generated >= 1


def test_a_search_stopped_before_its_first_expansion_reports_the_start(chair):
    """max_nodes 1 (a valid request: 1..100000) stopped the search before the root was expanded: a
    ValueError (min of no node) came out of contacts/plan as ``internal``; the start is the best set."""
    robot, env, gen, q0, start = chair
    T = RoughTrajectory(gen.model, chair_egress.key_postures(robot, env, q0))
    planner = ContactPlanner(
        gen, T, Goal("y", 0.6, chair_egress.FINAL_PAIRS), chair_egress.PAIRS, SearchConfig(max_nodes=1)
    )
    result = planner.plan(start, q0)
    assert result.status == "max_nodes" and result.nodes_expanded == 0
    assert [n.change for n in result.path] == ["start"]


def test_the_chair_scenario_refuses_bad_options_before_planning(capsys: pytest.CaptureFixture[str]):
    from services.cli import main

    for options, said in (
        (["--budget", "-5"], "--budget -5"),
        (["--max-nodes", "0"], "--max-nodes 0"),
        (["--n", "0"], "--n 0"),
        (["--plan", "no/such/plan.npz"], "no such file"),
    ):
        assert main(["scenario", "chair-egress", *options]) == 2
        assert said in capsys.readouterr().err


# ------------------------------------------------------------------------------------------ f_T
def test_potential_is_smooth_descends_along_t_and_rounds_corners(chair):
    robot, _env, gen, q0, _ = chair
    keys = [q0, robot.half_sitting_at(0.3, 0.0, 0.0), robot.half_sitting_at(0.3, 0.6, 0.0)]
    T = RoughTrajectory(gen.model, keys, k=30.0, corner_deviation=0.05)
    assert [p.kind for p in T.pieces] == ["line", "arc", "line"]
    # the arc stays within the deviation of the corner
    corner = base_point(keys[1])
    arc = T.pieces[1]
    mid = arc.a + arc.radius * (arc.b * math.cos(arc.angle / 2) + arc.c * math.sin(arc.angle / 2))
    assert np.linalg.norm(mid - corner) == pytest.approx(0.05, abs=1e-6)
    # on T, f_T = -k s' and it decreases toward the end
    values = [T.value(q) for q in keys]
    assert values[0] == pytest.approx(0.0, abs=1e-9)
    assert values[0] > values[1] > values[2]
    assert values[2] == pytest.approx(-30.0 * T.length, rel=1e-6)
    # continuity of s' across the arc: nearby points have nearby abscissas
    for u in np.linspace(0.0, 1.0, 50):
        p = T.configuration_at(T.project(base_point(pin.interpolate(gen.model, keys[1], keys[2], u))))
        assert np.isfinite(T.value(p))
    with pytest.raises(InvalidRequestError, match="bijective"):
        RoughTrajectory(gen.model, [keys[1], keys[1]])


def test_potential_task_moves_downhill(chair):
    robot, _env, gen, _q0, _ = chair
    keys = [robot.half_sitting_at(0.0, 0.0, 0.0), robot.half_sitting_at(0.0, 1.0, 0.0)]
    T = RoughTrajectory(gen.model, keys, k=4.0)
    task = PotentialTask(T)
    q = keys[0].copy()
    data = gen.model.createData()
    before = T.value(q)
    F = task.compute_error(q, data)
    q = pin.integrate(gen.model, q, -0.05 * F)
    assert T.value(q) < before


# ------------------------------------------------------------------------------------------ posture generator
def test_seated_start_is_a_witness_of_its_contacts(chair):
    _robot, _env, gen, q0, start = chair
    for contact in start:
        T = gen.spot_pose(q0, contact.spot)
        target = gen.contact_pose(contact)
        assert np.linalg.norm(T.translation - target.translation) < 1e-3
    com = pin.centerOfMass(gen.model, gen.data, q0)
    assert gen.stable_at(start, com)


def test_removed_contact_stays_as_geometry_and_leaves_the_stability(chair):
    _robot, _env, gen, q0, start = chair
    thighs_removed = tuple(c for c in start if "thigh" not in c.spot)
    result = gen.generate(start, thighs_removed, q0)
    assert result.ok, result.reason
    for contact in start:  # every contact still matched (§2.3)
        assert (
            np.linalg.norm(
                gen.spot_pose(result.q, contact.spot).translation - gen.contact_pose(contact).translation
            )
            < 3e-3
        )
    assert gen.stable_at(thighs_removed, pin.centerOfMass(gen.model, gen.data, result.q))
    # one foot alone cannot hold the seated robot
    assert not gen.generate(start, (start[0],), q0).ok


def test_floating_contact_is_found_inside_its_volume(chair):
    _robot, env, gen, q0, start = chair
    volume = SearchVolume((-0.28, -0.3, -0.5), (-0.1, -0.1, 0.5))
    result = gen.generate(start, start, q0, None, Floating("right_hand", "table.top", volume))
    assert result.ok, result.reason
    c = result.contact
    assert c is not None and volume.contains((c.x, c.y, c.theta), tol=2e-3)
    T = gen.spot_pose(result.q, "right_hand")
    assert abs(T.translation[2] - env.surface("table.top").T_world_surface.translation[2]) < 2e-3
    # a volume off the table's reach fails
    far = SearchVolume((0.25, 0.3, -0.1), (0.3, 0.35, 0.1))
    assert not gen.generate(start, start, q0, None, Floating("right_hand", "table.top", far)).ok


# ------------------------------------------------------------------------------------------ search
def test_first_expansion_one_leaf_per_pair_and_removals(chair):
    robot, env, gen, q0, start = chair
    T = RoughTrajectory(gen.model, chair_egress.key_postures(robot, env, q0))
    goal = Goal("y", 0.6, chair_egress.FINAL_PAIRS)
    counts = {}
    for best_first in (True, False):
        planner = ContactPlanner(
            gen,
            T,
            goal,
            chair_egress.PAIRS,
            SearchConfig(best_first_sons=best_first, max_nodes=60, time_budget_s=120),
        )
        root = planner._add(None, start, q0, "start")
        planner._removal_sons(root)
        planner._addition_sons(root)
        sons = planner.nodes[1:]
        for son in sons:  # a son differs from its father by exactly one contact (§2.2)
            assert len(set(son.contacts) ^ set(start)) == 1
        added = [s for s in sons if s.change.startswith("+")]
        pairs = [next(iter(set(s.contacts) - set(start))).pair for s in added]
        counts[best_first] = len(added)
        if best_first:  # §2.8: one leaf per pair
            assert len(pairs) == len(set(pairs))
        assert sum(s.change.startswith("-") for s in sons) >= 2
    assert counts[False] > counts[True]


def test_a_small_patch_turned_is_the_same_contact_with_patch_turns(chair):
    """SearchConfig.patch_turns: V's angle and the "too close" angle of a spot are at least the turn
    that moves its patch's corners by half of V's / close_m's length: a hand (6 x 6 cm) turned by 0.9
    rad is too close to itself, a sole (22 x 12 cm) keeps close_rad."""
    _robot, _env, gen, q0, _start = chair
    hand, sole = gen.spots["right_hand"], gen.spots["right_sole"]
    assert turn_moving_corners_by(hand, 0.04) == pytest.approx(
        2.0 * math.asin(0.04 / (2.0 * math.hypot(0.03, 0.03)))
    )
    assert turn_moving_corners_by(hand, 0.2) == math.pi  # no turn moves its corners that far
    assert turn_moving_corners_by(sole, 0.04) < 0.4
    a = (Contact("right_hand", "table.top", 0.1, 0.2, 0.0), Contact("right_sole", "floor", 0.3, 0.2, 0.0))
    turned_hand = (Contact("right_hand", "table.top", 0.12, 0.2, 0.9), a[1])
    turned_sole = (a[0], Contact("right_sole", "floor", 0.3, 0.2, 0.5))
    tols = {s.name: max(0.4, turn_moving_corners_by(s, 0.04)) for s in (hand, sole)}
    assert not sets_close(a, turned_hand, 0.08, 0.4)
    assert sets_close(a, turned_hand, 0.08, 0.4, tols)
    assert not sets_close(a, turned_sole, 0.08, 0.4, tols)
    ahead = q0.copy()
    ahead[0] += 0.3
    planner = ContactPlanner(
        gen, RoughTrajectory(gen.model, [q0, ahead]), Goal("y", 0.6), (), SearchConfig(patch_turns=True)
    )
    assert planner._v_rad["right_hand"] > 2.0 and planner._v_rad["right_sole"] == 0.8


def test_goal_needs_the_coordinate_and_the_final_contacts():
    goal = Goal("y", 0.5, (("left_sole", "floor"),))
    q = np.zeros(7)
    q[1] = 0.6
    assert goal.reached((Contact("left_sole", "floor", 0, 0, 0),), q)
    assert not goal.reached((Contact("left_hand", "floor", 0, 0, 0),), q)
    q[1] = 0.4
    assert not goal.reached((Contact("left_sole", "floor", 0, 0, 0),), q)
    with pytest.raises(InvalidRequestError, match="axis"):
        Goal("w", 0.0)


# ------------------------------------------------------------------------------------------ geometry
def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    t = float(np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * (b - a))))


def test_planner_capsules_reach_the_faces_of_the_urdf_foot_box(chair):
    robot, _env, gen, _q0, _start = chair
    geometry = robot.build_geometry_model("collision")
    box = next(o for o in geometry.geometryObjects if robot.model.frames[o.parentFrame].name == "LLEG_LINK5")
    half, centre = np.array(box.geometry.halfSide), box.placement.translation
    capsules = [c for c in gen.capsules if c.frame == "LLEG_LINK5"]
    assert len(capsules) > 1  # the model's foot capsule and the box's
    # points on the box's faces (lateral faces where the heels met the chair's legs, sole, toe, heel)
    for axis, sign in [(1, 1), (1, -1), (0, 1), (0, -1), (2, -1)]:
        for along in (-0.8, 0.0, 0.8):
            p = centre.copy()
            p[axis] += sign * half[axis]
            other = 1 if axis == 0 else 0
            p[other] += along * (half[other] - half[2])
            inside = min(
                _segment_distance(p, np.array(c.p0_local), np.array(c.p1_local)) - c.radius_m
                for c in capsules
            )
            # toe and heel: the capsules' end caps round the box's vertical edges (< 4 mm, under the
            # planner's 1.5 cm collision margin)
            assert inside <= (4e-3 if axis == 0 else 1e-4), (axis, sign, along, inside)
    # the foot's own contact (sole on the floor) excludes every foot capsule from the floor
    floor = next(j for j, b in enumerate(gen.boxes) if b.name == "floor")
    foot = {i for i, c in enumerate(gen.capsules) if c.frame == "LLEG_LINK5"}
    pairs = gen.box_pairs([("left_sole", "floor")])
    assert not any((i, floor) in pairs for i in foot)


def test_the_space_under_the_table_is_an_obstacle(chair):
    _robot, env, _gen, _q0, _start = chair
    under = next(b for b in env.boxes if b.name == "table[under]")
    top = env.surface("table.top")
    lowest = under.T_world_box.translation[2] - under.half_extents_m[2]
    highest = under.T_world_box.translation[2] + under.half_extents_m[2]
    assert lowest == pytest.approx(0.0, abs=1e-9)
    assert highest < top.T_world_surface.translation[2]
    assert under.half_extents_m[:2] == pytest.approx(top.half_size_m)


# ----------------------------------------------------------------------------------- interpolation, execution
def test_a_sample_into_a_box_is_found_and_named(chair):
    _robot, _env, gen, q0, start = chair
    touching = [c.pair for c in start]
    assert deepest_collision(gen, np.array([q0, q0]), touching) is None
    moved = q0.copy()
    moved[0] += 0.45  # the seated robot moved 0.45 m forward: its legs under the table
    depth, capsule, box, index = deepest_collision(gen, np.array([q0, moved, q0]), touching)
    assert depth > 0.01 and box.startswith("table") and index == 1, (depth, capsule, box)


def test_a_witness_regenerated_from_the_measured_state_keeps_the_supports_where_they_are(chair):
    _robot, _env, gen, q0, start = chair
    volume = SearchVolume((-0.28, -0.3, -0.5), (-0.1, -0.1, 0.5))
    planned = gen.generate(start, start, q0, None, Floating("right_hand", "table.top", volume))
    assert planned.ok and planned.contact is not None, planned.reason
    s2 = (*start, planned.contact)
    measured_q = q0.copy()
    measured_q[0] += 0.02  # the robot slid 2 cm forward on the seat (more than REREAD_M)
    s1, s2_measured, q2, reason = regenerate_witness(gen, start, s2, planned.q, measured_q)
    assert q2 is not None, reason
    for c in s1:  # the held contacts are where the measured spots are, 2 cm from the plan
        assert abs(c.x - next(p for p in start if p.pair == c.pair).x) == pytest.approx(0.02, abs=1e-6)
    for c in s2_measured:  # the new witness matches them, and the new contact where it was planned
        T = gen.spot_pose(q2, c.spot)
        assert np.linalg.norm(T.translation - gen.contact_pose(c).translation) < 3e-3
    assert planned.contact in s2_measured


def test_a_patch_bears_only_on_its_surface(chair):
    _robot, env, gen, _q0, _start = chair
    seat = env.surface("chair.seat")
    hx = seat.half_size_m[0]
    on_edge = Contact("left_thigh", "chair.seat", hx - 0.02, 0.06, 0.0)  # 2 cm from the front edge
    corners = patch_of(on_edge, gen.spots["left_thigh"], env).corners_world
    local = np.array([seat.T_world_surface.actInv(c) for c in corners])
    assert local[:, 0].max() == pytest.approx(hx) and local[:, 0].min() == pytest.approx(hx - 0.02 - 0.10)
    off = Contact("left_thigh", "chair.seat", hx + 0.2, 0.06, 0.0)
    with pytest.raises(InfeasibleError, match="off the surface"):
        patch_of(off, gen.spots["left_thigh"], env)


def test_a_new_sole_lands_on_its_own_side_of_the_other(chair):
    robot, env, gen, q0, start = chair
    planner = ContactPlanner(
        gen,
        RoughTrajectory(gen.model, [q0, robot.half_sitting_at(0.3, 0.0, 0.0)]),
        Goal("y", 0.6, chair_egress.FINAL_PAIRS),
        chair_egress.PAIRS,
        SearchConfig(stance_width_m=0.1),
    )
    left = next(c for c in start if c.spot == "left_sole")
    right = next(c for c in start if c.spot == "right_sole")
    standing_on_left = planner._add(None, (left,), q0, "start")
    volume = planner._volume(standing_on_left, "right_sole", "floor")
    assert volume is not None and volume.upper[1] == pytest.approx(left.y - 0.1)  # never crossing
    standing_on_right = planner._add(None, (right,), q0, "start")
    volume = planner._volume(standing_on_right, "left_sole", "floor")
    assert volume is not None and volume.lower[1] == pytest.approx(right.y + 0.1)
    hand = planner._volume(standing_on_right, "left_hand", "table.top")  # hands: any side
    hx, hy = env.surface("table.top").half_size_m  # but never at the very edge of a surface
    assert hand is not None and hand.lower[0] >= -hx + 0.05 - 1e-9 and hand.upper[0] <= hx - 0.05 + 1e-9
    assert hand.lower[1] >= -hy + 0.05 - 1e-9 and hand.upper[1] <= hy - 0.05 + 1e-9
