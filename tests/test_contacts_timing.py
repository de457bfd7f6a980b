"""Executing a contact plan (services/contacts): which body moves in a transition, the quasi-static timing
of a transition's path (knots by the intervals' times, the ZMP the motion needs kept near the CoM's
projection) and a plan saved to disk and read back."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from services.contacts.environment import environment_of
from services.contacts.interpolate import InterpolationConfig, moving_candidates, timed_segment
from services.contacts.plan_file import load_plan, save_plan
from services.contacts.posture import PostureGenerator
from services.contacts.sets import Contact, contact_at
from services.contacts.spots import robot_spots
from services.contacts.timing import interval_times, knots, time_segment, zmp_shift
from services.errors import InvalidRequestError
from services.ik import PostureTask
from services.model import load_robot
from sim.scene import layout, load_scene


@pytest.fixture(scope="module")
def gen():
    robot = load_robot("hrp2_like")
    return PostureGenerator(robot, environment_of(layout(load_scene("chair_egress"))), robot_spots(robot))


LEFT = Contact("left_sole", "floor", 0.15, 0.10, 0.0)
RIGHT = Contact("right_sole", "floor", 0.39, 0.11, -0.26)
HAND = Contact("right_hand", "chair.seat", 0.25, -0.18, -0.5)


def test_only_a_contact_made_now_or_released_before_moves():
    # a removal (the weight onto the right sole): nothing moves, the left sole stays until q2 (§2.3)
    assert moving_candidates((LEFT, RIGHT), (RIGHT,), ()) == []
    # the next addition: the hand comes, and the left sole released at the previous transition leaves
    assert moving_candidates((RIGHT,), (RIGHT, HAND), (LEFT,)) == ["left_sole", "right_hand"]


def test_knots_follow_the_intervals_times(gen):
    q0 = gen.robot.half_sitting_at(0.0, 0.0, 0.0)
    far, near = q0.copy(), q0.copy()
    far[0] += 0.08  # the base moves 8 cm, then 0.8 cm
    near[0] += 0.088
    times = interval_times(gen.model, np.array([q0, far, near]), 0.08, np.full(gen.model.nv - 6, 1.0))
    assert times == pytest.approx([1.0, 0.1])
    assert knots(times) == pytest.approx([0.0, 1.0 / 1.1, 1.0])
    assert knots(np.zeros(2)) == pytest.approx([0.0, 0.5, 1.0])


def test_the_zmp_of_a_still_posture_is_the_com_and_a_faster_motion_shifts_it(gen):
    q0 = gen.robot.half_sitting_at(0.0, 0.0, 0.0)
    assert zmp_shift(gen.model, np.array([q0] * 30), 0.005).max() < 1e-9
    q1 = q0.copy()
    q1[0] += 0.1
    slow = zmp_shift(gen.model, time_segment(gen.model, np.array([q0, q1]), 2.0, 0.005), 0.005).max()
    fast = zmp_shift(gen.model, time_segment(gen.model, np.array([q0, q1]), 1.0, 0.005), 0.005).max()
    assert slow > 1e-3 and fast == pytest.approx(4.0 * slow, rel=0.15)  # 1 / T^2


def test_a_timed_segment_stays_quasi_static(gen):
    q0 = gen.robot.half_sitting_at(0.0, 0.0, 0.0)
    waypoints = [q0]
    for dx in (0.09, 0.005, 0.005, 0.0):  # uneven postures: the CoM moves 9 cm in the first step
        q = waypoints[-1].copy()
        q[0] += dx
        waypoints.append(q)
    config = InterpolationConfig(min_segment_s=0.1)
    q = timed_segment(gen, np.array(waypoints), config, np.asarray(gen.robot.v_max, float))
    assert zmp_shift(gen.model, q, config.dt_s).max() <= config.zmp_shift_m * 1.05
    assert np.allclose(q[0], q0) and np.allclose(q[-1], waypoints[-1])
    com = np.array([pin.centerOfMass(gen.model, gen.data, s)[0] for s in q])
    assert np.all(np.diff(com) > -1e-6)  # no overshoot back and forth


def test_held_soles_stay_in_place_between_the_postures(gen):
    """A crouch on both soles: the postures match the soles, the spline between them does not; with
    the held frames (hold.py) every sample keeps them in place."""
    q0 = gen.robot.half_sitting_at(0.0, 0.0, 0.0)
    soles = tuple(
        contact_at(gen.spots[s], "floor", gen.env, gen.spot_pose(q0, s)) for s in ("left_sole", "right_sole")
    )
    waypoints = [q0]
    for dz, dx in ((-0.06, 0.03), (-0.12, -0.02)):
        q_ref = q0.copy()
        q_ref[0] += dx
        q_ref[2] += dz
        result = gen.generate(soles, soles, waypoints[-1], PostureTask(gen.model, q_ref))
        assert result.ok, result.reason
        waypoints.append(result.q)
    frames = [gen.spots[c.spot].frame_name for c in soles]
    v_max = np.asarray(gen.robot.v_max, float)

    def drift(samples: np.ndarray) -> float:
        return max(
            float(np.linalg.norm(gen.spot_pose(q, c.spot).translation - gen.contact_pose(c).translation))
            for q in samples[::5]
            for c in soles
        )

    free = timed_segment(gen, np.array(waypoints), InterpolationConfig(hold_contacts=False), v_max, frames)
    held = timed_segment(gen, np.array(waypoints), InterpolationConfig(), v_max, frames)
    assert drift(free) > 5e-4  # the spline alone leaves the floor between the postures
    assert drift(held) < max(2e-4, gen.config.tol)  # within the postures' own match
    assert np.allclose(held[0], waypoints[0]) and np.allclose(held[-1], waypoints[-1])


def test_a_saved_plan_reads_back(tmp_path):
    sets = [(LEFT, RIGHT), (RIGHT,), (RIGHT, HAND)]
    witnesses = np.arange(3 * 4, dtype=float).reshape(3, 4)
    path = save_plan(tmp_path / "p.npz", sets, witnesses, ["start", "- a", "+ b"], {"nodes": 3})
    plan = load_plan(path)
    assert plan.sets == sets and plan.changes == ["start", "- a", "+ b"] and plan.meta == {"nodes": 3}
    assert np.array_equal(plan.witnesses, witnesses)
    np.savez(tmp_path / "other.npz", witnesses=witnesses)
    with pytest.raises(InvalidRequestError, match="not a saved contact plan"):
        load_plan(tmp_path / "other.npz")


def test_an_execution_regenerates_a_witness_bitwise_the_same_whatever_came_before():
    # closed_loop.execution_generator: the dual active-set QPs, no warm start across generations; with
    # proxsuite (warm-started QP objects, 1e-15 noise) two replays of one plan parted at transition 2
    from services.contacts import chair_egress
    from services.contacts.closed_loop import execution_generator, regenerate_witness
    from services.contacts.posture import Floating
    from services.contacts.volumes import SearchVolume
    from sim.world import start_configuration

    robot = load_robot("hrp2_like")
    lay = layout(load_scene("chair_egress"))
    ex = execution_generator(robot, environment_of(lay))
    q0 = start_configuration(robot, lay)
    start = tuple(
        contact_at(ex.spots[s], e, ex.env, ex.spot_pose(q0, s)) for s, e in chair_egress.START_PAIRS
    )
    volume = SearchVolume((-0.28, -0.3, -0.5), (-0.1, -0.1, 0.5))
    planned = ex.generate(start, start, q0, None, Floating("right_hand", "table.top", volume))
    assert planned.ok, planned.reason
    s2 = (*start, planned.contact)
    measured = q0.copy()
    measured[0] += 0.02  # slid 2 cm on the seat
    first = regenerate_witness(ex, start, s2, planned.q, measured)[2]
    ex.generate(start[:3], start[:3], q0, PostureTask(ex.model, q0))  # something else in between
    again = regenerate_witness(ex, start, s2, planned.q, measured)[2]
    assert first is not None and np.array_equal(first, again)


def _seated_with_a_hand_on_the_table():
    """The chair egress's seated start and a witness with the right hand added on the table's top: the
    posture generator, q0, the start contacts and the leaning posture generation's result."""
    from services.contacts import chair_egress
    from services.contacts.posture import Floating
    from services.contacts.volumes import SearchVolume
    from sim.world import start_configuration

    robot = load_robot("hrp2_like")
    lay = layout(load_scene("chair_egress"))
    g = PostureGenerator(robot, environment_of(lay), robot_spots(robot))
    q0 = start_configuration(robot, lay)
    start = tuple(contact_at(g.spots[s], e, g.env, g.spot_pose(q0, s)) for s, e in chair_egress.START_PAIRS)
    volume = SearchVolume((-0.28, -0.3, -0.5), (-0.1, -0.1, 0.5))
    leaning = g.generate(start, start, q0, None, Floating("right_hand", "table.top", volume))
    assert leaning.ok, leaning.reason
    return g, q0, start, leaning


def test_a_released_hand_unloads_along_its_force_profile():
    # contact_forces.py: the hand held from S1 gets the force QP's normal force at the start; removed
    # at q2 (a removal), its planned force goes down to zero at the transition's end
    from services.contacts.contact_forces import force_targets, normal_forces

    g, _q0, start, leaning = _seated_with_a_hand_on_the_table()
    s1 = (*start, leaning.contact)
    q = np.array([leaning.q] * 30)
    (target,) = force_targets(g, s1, start, q, 0.005)
    assert target.joints[0] == "RARM_JOINT5" and target.other == "table"
    assert target.normal == pytest.approx((0.0, 0.0, 1.0))
    com = pin.centerOfMass(g.model, g.data, leaning.q)
    assert target.force_n[0] == pytest.approx(normal_forces(g, s1, com)[leaning.contact.pair])
    assert target.force_n[0] > 1.0 and target.force_n[-1] == pytest.approx(0.0, abs=1e-6)
    assert force_targets(g, start, start, q, 0.005) == ()  # no arm in contact: nothing to follow


def test_a_hand_goes_up_and_forward_over_a_tables_edge():
    # interpolate._over_the_edge: from beside the thigh to the table's top, the hand rises while it
    # moves forward (straight up from beside the thigh, the body was pulled 17 cm back), and it is
    # above the top's level before it is past the halfway point (the edge is near the target)
    from services.contacts.interpolate import EDGE_CLEARANCE_M, RISE_FORWARD, _over_the_edge

    T1 = pin.SE3(np.eye(3), np.array([0.13, 0.39, 0.495]))
    T2 = pin.SE3(np.eye(3), np.array([0.48, 0.30, 0.64]))
    up = np.array([0.0, 0.0, 1.0])
    frames = _over_the_edge(T1, T2, T1.translation, up, 40, (0.0, 0.0))
    points = np.array([f.translation for f in frames])
    across = np.linalg.norm(points[:, :2] - T1.translation[:2], axis=1) / np.linalg.norm(
        (T2.translation - T1.translation)[:2]
    )
    rising = points[:, 2] < 0.64 + EDGE_CLEARANCE_M - 1e-9
    first_above = int(np.argmin(rising))
    assert 0.05 < across[first_above // 2] < RISE_FORWARD  # forward while rising, not straight up
    assert np.all(across[:first_above] <= RISE_FORWARD + 1e-9)  # above the level before the halfway point
    assert np.allclose(points[-1], T2.translation)


def test_a_transition_counts_the_arms_as_supports_only_when_its_ends_need_them():
    # interpolate.stability_contacts: both ends stand on the soles and thighs (seated, a hand on the
    # table): the postures are first sought stable without the hand; on the left sole alone the seated
    # robot does not stand, so the hand stays a support; and without the option, always the paper's set
    from services.contacts.interpolate import stability_contacts, stands_on

    g, q0, start, leaning = _seated_with_a_hand_on_the_table()
    s1 = (*start, leaning.contact)
    helpers = InterpolationConfig(arms_as_helpers=True)
    assert stands_on(g, start, leaning.q, helpers.helpers_end_margin_m)
    assert stability_contacts(g, s1, q0, leaning.q, helpers) == [start, s1]
    assert stability_contacts(g, s1, q0, leaning.q, InterpolationConfig()) == [s1]
    left = next(c for c in start if c.spot == "left_sole")
    assert not stands_on(g, (left,), leaning.q, 0.0)
    assert stability_contacts(g, (left, leaning.contact), q0, leaning.q, helpers) == [(left, leaning.contact)]
    far = replace(helpers, helpers_end_margin_m=1.0)  # no CoM is a metre inside a chair's and feet's region
    assert not stands_on(g, start, leaning.q, far.helpers_end_margin_m)
    assert stability_contacts(g, s1, q0, leaning.q, far) == [s1]


def test_the_force_control_experiment_hands_the_arms_their_planned_forces():
    # closed_loop.replan_transition with InterpolationConfig.force_control (an experiment, off by
    # default: sim/README.md, services/contacts/README.md): the hand released on the way back to the
    # seated start gets its force profile for the sim's damping control, one value per sample played,
    # unloading to zero at the transition's end
    from services.contacts.closed_loop import replan_transition

    assert not InterpolationConfig().force_control
    g, q0, start, leaning = _seated_with_a_hand_on_the_table()
    s1 = (*start, leaning.contact)
    step = replan_transition(g, s1, start, q0, leaning.q, config=InterpolationConfig(n=4, force_control=True))
    (target,) = step.force_targets
    assert target.joints[0] == "RARM_JOINT5" and target.other == "table"
    assert target.force_n.shape == (len(step.q),)
    assert target.force_n[0] > 1.0 and target.force_n[-1] == pytest.approx(0.0, abs=1e-6)
