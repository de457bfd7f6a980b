"""Tests of the walking pattern generator (services/walking): footsteps, ZMP reference, preview control,
swing trajectories, the pattern, the multibody ZMP and the support polygons."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg

from services.errors import InfeasibleError, InvalidRequestError
from services.model import load_robot
from services.model.ground import convex_hull_ccw as convex_hull
from services.model.ground import signed_distance
from services.walking.footsteps import (
    SIDES,
    Footstep,
    FootstepBounds,
    FootstepSequence,
    SolePose,
    arc_walk,
    side_steps,
    straight_walk,
    turn_in_place,
    validate_footsteps,
)
from services.walking.multibody_zmp import multibody_zmp
from services.walking.pattern import PatternOptions, plan_pattern
from services.walking.preview_control import (
    preview_gains,
    second_stage_correction,
    settle_at_end,
    simulate,
    simulate_loop,
)
from services.walking.support_polygon import distances_to_support, sole_polygon
from services.walking.swing import swing_trajectory
from services.walking.timing import DOUBLE, LEFT, RIGHT, WalkTiming, build_schedule

DT = 0.005


@pytest.fixture(scope="module", params=["hrp2_like", "talos"])
def robot(request):
    return load_robot(request.param)


def _walks(robot) -> dict[str, FootstepSequence]:
    """The walks of issue 5 from the robot's half-sitting stance."""
    q0 = robot.q_half_sitting
    left = robot.sole_pose(q0, "left").translation
    right = robot.sole_pose(q0, "right").translation
    kw = {
        "left_start": SolePose(left[0], left[1], 0.0),
        "right_start": SolePose(right[0], right[1], 0.0),
        "limits": FootstepBounds.from_robot(robot),
    }
    return {
        "straight": straight_walk(10, 0.2, **kw),
        "turn_left": turn_in_place(math.pi / 2, 4, sole_size_m=robot.sole_size_m, **kw),
        "turn_right": turn_in_place(-math.pi / 2, 4, sole_size_m=robot.sole_size_m, **kw),
        "side_left": side_steps(6, 0.05, **kw),
        "side_right": side_steps(6, -0.05, **kw),
        "arc": arc_walk(1.0, math.pi / 2, 18, **kw),
        "backwards": straight_walk(6, -0.15, **kw),
    }


# ------------------------------------------------------------------------------------ preview control


def test_preview_gains_solve_the_riccati_equation_and_are_stable():
    g = preview_gains(DT, 0.8, 1.6)
    assert g.Gd[0] == pytest.approx(-g.Gi)
    assert np.all(np.abs(g.eigvals) < 1.0)
    assert preview_gains(DT, 0.8, 1.6) is g  # cached
    # The closed-loop matrix really is the plant under u = -Gi sum e - Gx x - f.
    A, B, C = g.A, g.B, g.C
    np.testing.assert_allclose(g.M[:3, :3], A - np.outer(B, g.Gx))
    np.testing.assert_allclose(g.M[3, :3], C @ (A - np.outer(B, g.Gx)))
    # Gains against a direct DARE solution of the augmented system.
    At = np.zeros((4, 4))
    At[0, 0], At[0, 1:], At[1:, 1:] = 1.0, C @ A, A
    Bt = np.concatenate([[C @ B], B])[:, None]
    P = scipy.linalg.solve_discrete_are(At, Bt, np.diag([1.0, 0, 0, 0]), np.array([[1e-6]]))
    K = np.linalg.solve(1e-6 + Bt.T @ P @ Bt, Bt.T @ P @ At)[0]
    np.testing.assert_allclose([g.Gi, *g.Gx], K, rtol=1e-9)


def test_preview_control_tracks_a_constant_zmp_with_zero_steady_state_error():
    g = preview_gains(DT, 0.75, 1.6)
    n = 1600
    ref = np.zeros((n, 2))
    ref[200:] = [0.1, -0.05]
    res = simulate(g, ref)
    np.testing.assert_allclose(res.zmp_m[-1], [0.1, -0.05], atol=1e-6)
    np.testing.assert_allclose(res.com_m[-1], [0.1, -0.05], atol=1e-6)
    np.testing.assert_allclose(res.com_vel_m_s[-1], 0.0, atol=1e-6)
    # Started away from equilibrium, the integral action still removes the error.
    res2 = simulate(g, np.full(n, 0.02), x0=np.array([0.0, 0.1, 0.0]))
    assert abs(res2.zmp_m[-1] - 0.02) < 1e-6
    assert abs(res2.com_m[-1] - 0.02) < 1e-6


def test_fast_preview_equals_the_plain_loop():
    rng = np.random.default_rng(3)
    g = preview_gains(DT, 0.8, 1.6)
    ref = np.cumsum(rng.normal(0, 0.002, (700, 2)), axis=0)
    x0 = rng.normal(0, 0.01, (3, 2))
    a, b = simulate(g, ref, x0), simulate_loop(g, ref, x0)
    for field in ("com_m", "com_vel_m_s", "com_acc_m_s2", "zmp_m"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), atol=1e-9)
    np.testing.assert_allclose(a.jerk_m_s3, b.jerk_m_s3, atol=1e-6)
    # The cart-table relations hold on the output.
    np.testing.assert_allclose(a.zmp_m, a.com_m - 0.8 / 9.81 * a.com_acc_m_s2, atol=1e-12)
    np.testing.assert_allclose(np.diff(a.com_acc_m_s2, axis=0), DT * a.jerk_m_s3[:-1], atol=1e-9)


@pytest.mark.parametrize("loop", [False, True])
def test_preview_control_is_the_same_anywhere_on_the_floor(loop):
    """A walk 2.9 m from the origin is the walk at the origin, translated (the finite-horizon gains alone
    would kick the CoM: the ZMP swung 0.36 m there)."""
    run = simulate_loop if loop else simulate
    g = preview_gains(DT, 0.8, 1.6)
    ref = np.zeros((400, 2))
    ref[200:] = (0.05, -0.09)
    x0 = np.array([[0.01, 0.0], [0.0, 0.0], [0.0, 0.0]])
    offset = np.array([2.9, -1.7])
    shifted_x0 = x0.copy()
    shifted_x0[0] += offset
    here, there = run(g, ref, x0), run(g, ref + offset, shifted_x0)
    np.testing.assert_allclose(there.zmp_m - offset, here.zmp_m, atol=1e-9)
    np.testing.assert_allclose(there.com_m - offset, here.com_m, atol=1e-9)
    np.testing.assert_allclose(there.jerk_m_s3, here.jerk_m_s3, atol=1e-6)


def test_second_stage_moves_the_cart_table_zmp_by_the_multibody_error():
    g = preview_gains(DT, 0.75, 1.6)
    t = np.arange(1200) * DT
    target = np.zeros(1200)
    multibody = 0.015 * np.exp(-(((t - 3.0) / 0.3) ** 2))  # a 15 mm bump of multibody ZMP error
    corr = second_stage_correction(g, target, multibody)
    assert corr.com_m.shape == (1200,)
    assert abs(corr.com_m[0]) < 1e-12 and abs(corr.com_vel_m_s[0]) < 1e-12
    # The correction's own cart-table ZMP cancels the error: p_mb + dp_cart ~ target.
    residual = multibody + corr.zmp_m - target
    assert np.abs(residual).max() < 0.1 * np.abs(multibody).max()
    assert abs(corr.com_m[-1]) < 1e-5


def test_settle_at_end_stops_exactly_and_joins_smoothly():
    g = preview_gains(DT, 0.75, 1.6)
    ref = np.zeros(600)
    ref[100:] = 0.05
    raw = simulate(g, ref)
    res = settle_at_end(raw, 200, DT, 0.75, np.array([0.05]))
    assert res.com_m[-1] == pytest.approx(0.05, abs=1e-12)
    assert res.com_vel_m_s[-1] == pytest.approx(0.0, abs=1e-12)
    assert res.com_acc_m_s2[-1] == pytest.approx(0.0, abs=1e-12)
    k = 600 - 200  # first blended sample: unchanged value, velocity and acceleration
    for a, b in (
        (res.com_m, raw.com_m),
        (res.com_vel_m_s, raw.com_vel_m_s),
        (res.com_acc_m_s2, raw.com_acc_m_s2),
    ):
        np.testing.assert_allclose(a[: k + 1], b[: k + 1], atol=1e-15)
    np.testing.assert_allclose(res.zmp_m, res.com_m - 0.75 / 9.81 * res.com_acc_m_s2, atol=1e-12)
    # Velocity is the integral of acceleration inside the blend (consistent derivatives).
    np.testing.assert_allclose(
        np.diff(res.com_m[k:]) / DT, 0.5 * (res.com_vel_m_s[k:-1] + res.com_vel_m_s[k + 1 :]), atol=1e-6
    )


def test_preview_rejects_bad_parameters():
    with pytest.raises(InvalidRequestError, match="com_height_m"):
        preview_gains(DT, 0.0, 1.6)
    with pytest.raises(InvalidRequestError, match="horizon_s"):
        preview_gains(DT, 0.8, -1.0)


# ------------------------------------------------------------------------------------------- swing


def test_swing_has_zero_velocity_and_acceleration_at_liftoff_and_touchdown():
    T, h = 0.8, 0.05
    start, end = SolePose(0.1, -0.1, 3.0), SolePose(0.5, -0.05, -3.0)  # yaw goes the short way
    t = np.linspace(0.0, T, 8001)
    tr = swing_trajectory(start, end, T, t, step_height_m=h)
    np.testing.assert_allclose(tr.pose[0], [0.1, -0.1, 0.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(tr.pose[-1], [0.5, -0.05, 0.0, 3.0 + (2 * math.pi - 6.0)], atol=1e-12)
    for end_idx in (0, -1):
        np.testing.assert_allclose(tr.vel[end_idx], 0.0, atol=1e-12)
        np.testing.assert_allclose(tr.acc[end_idx], 0.0, atol=1e-12)
    assert tr.pose[:, 2].max() == pytest.approx(h, abs=1e-6)
    assert tr.pose[:, 2].min() >= 0.0
    # Analytic derivatives against finite differences (step 1e-4 s: errors O(1e-8 * jerk)).
    dt = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(tr.pose, dt, axis=0)[1:-1], tr.vel[1:-1], atol=1e-5)
    np.testing.assert_allclose(np.gradient(tr.vel, dt, axis=0)[1:-1], tr.acc[1:-1], atol=5e-3)
    # The foot lifts before moving horizontally.
    early = t < 0.1 * T
    np.testing.assert_allclose(tr.pose[early, 0], 0.1)


# ------------------------------------------------------------------------------------- footsteps


def test_generated_walks_are_within_the_robot_bounds(robot):
    bounds = FootstepBounds.from_robot(robot)
    for name, seq in _walks(robot).items():
        validate_footsteps(seq, bounds)  # raises on failure
        assert seq.steps, name
    left, right = _walks(robot)["turn_left"].final_stance()
    assert left.yaw_rad == pytest.approx(math.pi / 2) and right.yaw_rad == pytest.approx(math.pi / 2)


def test_step_beyond_the_bounds_is_infeasible_and_named():
    seq = straight_walk(4, 0.30, limits=None)  # 0.30 m > dx_max 0.22 m, as asked (unchecked)
    with pytest.raises(InfeasibleError) as err:
        validate_footsteps(seq, FootstepBounds())
    assert "step 0 (right foot): dx=0.3000 m relative to the left sole" in err.value.message
    assert "above the bound 0.2200 m by 0.0800 m" in err.value.message
    assert err.value.details["step_index"] == 0
    assert err.value.details["excess"] == pytest.approx(0.08)
    # A foot crossing under the other one: dy of the left sole below 0.07 m.
    steps = (Footstep("right", SolePose(0.2, -0.095, 0.0)), Footstep("left", SolePose(0.4, -0.35, 0.0)))
    with pytest.raises(InfeasibleError, match=r"step 1 \(left foot\): dy="):
        validate_footsteps(
            FootstepSequence(SolePose(0, 0.095, 0), SolePose(0, -0.095, 0), steps), FootstepBounds()
        )
    # Turning the left foot inwards beyond -0.1 rad.
    steps = (Footstep("left", SolePose(0.0, 0.095, -0.3)),)
    with pytest.raises(InfeasibleError, match=r"dyaw=-0\.3000 rad"):
        validate_footsteps(
            FootstepSequence(SolePose(0, 0.095, 0), SolePose(0, -0.095, 0), steps), FootstepBounds()
        )


def test_generators_split_a_walk_beyond_the_bounds_into_more_steps(robot):
    """arc_walk(1.0, pi/2, 10) turns 0.17 rad per step, beyond the 0.1 rad the outer foot may turn
    inwards (footstep paper §5): the generators now use the fewest steps that fit, for the same walk."""
    bounds = FootstepBounds.from_robot(robot)
    q0 = robot.q_half_sitting
    kw = {side + "_start": SolePose(*robot.sole_pose(q0, side).translation[:2], 0.0) for side in SIDES}
    with pytest.raises(InfeasibleError, match=r"step 1 \(right foot\): dyaw=0\.1745 rad"):
        validate_footsteps(arc_walk(1.0, math.pi / 2, 10, limits=None, **kw), bounds)
    arc = arc_walk(1.0, math.pi / 2, 10, limits=bounds, **kw)
    validate_footsteps(arc, bounds)
    # 16 advancing steps of pi/32 = 0.098 rad (15 would be 0.105 rad), and one to close the feet.
    assert len(arc.steps) == 17
    assert arc == arc_walk(1.0, math.pi / 2, 17, limits=None, **kw)  # the same arc, only split
    left, right = arc.final_stance()
    assert left.yaw_rad == pytest.approx(math.pi / 2) and right.yaw_rad == pytest.approx(math.pi / 2)
    mid = np.array([(left.x_m + right.x_m) / 2, (left.y_m + right.y_m) / 2])
    start = np.array([(kw["left_start"].x_m + kw["right_start"].x_m) / 2, 0.0])
    np.testing.assert_allclose(mid - start, [1.0, 1.0], atol=1e-9)  # quarter circle of radius 1 m
    # Straight: the same 0.9 m in the fewest steps within dx_max (0.22 m: 5 of 0.18 m, 0.25 m: 4 of
    # 0.225 m) instead of 3 of 0.30 m, and one to close the feet.
    walk = straight_walk(4, 0.30, limits=bounds, **kw)
    validate_footsteps(walk, bounds)
    n_advancing = math.ceil(0.9 / bounds.dx_max_m)
    expected = [0.9 * min(k, n_advancing) / n_advancing for k in range(1, n_advancing + 2)]
    assert [s.pose.x_m for s in walk.steps] == pytest.approx(expected)
    # Turning pi in 2 steps: pi/2 per opening step (bound pi/4), and the soles would collide: 2 more
    # steps at a time, so that the walk still ends with the feet parallel.
    turn = turn_in_place(math.pi, 2, sole_size_m=robot.sole_size_m, limits=bounds, **kw)
    validate_footsteps(turn, bounds)
    assert len(turn.steps) % 2 == 0
    assert [p.yaw_rad for p in turn.final_stance()] == pytest.approx([math.pi, math.pi])
    # Side steps wider than dy_max: the same 0.3 m sideways in narrower steps.
    side = side_steps(2, 0.3, limits=bounds, **kw)
    validate_footsteps(side, bounds)
    left, right = side.final_stance()
    assert (left.y_m + right.y_m) / 2 == pytest.approx(0.3)
    # Walks that fit are unchanged.
    assert straight_walk(10, 0.2, limits=bounds, **kw) == straight_walk(10, 0.2, limits=None, **kw)


def test_a_walk_that_no_split_can_fit_is_infeasible():
    with pytest.raises(
        InfeasibleError, match=r"an arc of 0\.010 m radius .* in 4 to 32 steps: with 32 steps"
    ):
        arc_walk(0.01, math.pi, 4)  # turning about a point between the feet: 0.1 rad per step at most
    with pytest.raises(InvalidRequestError, match="feet overlap at the start"):
        straight_walk(4, 0.3, left_start=SolePose(0, 0.05, 0), right_start=SolePose(0, -0.05, 0))


def test_overlapping_feet_and_empty_sequences_are_invalid():
    start = (SolePose(0, 0.095, 0), SolePose(0, -0.095, 0))
    steps = (Footstep("left", SolePose(0.1, -0.0, 0.0)),)  # dy = 0.095 within bounds but soles overlap
    with pytest.raises(InvalidRequestError, match=r"feet overlap after step 0 \(left foot\) by 45.0 mm"):
        validate_footsteps(FootstepSequence(*start, steps), FootstepBounds())
    with pytest.raises(InvalidRequestError, match="feet overlap at the start"):
        validate_footsteps(
            FootstepSequence(SolePose(0, 0.05, 0), SolePose(0, -0.05, 0), steps), FootstepBounds()
        )
    with pytest.raises(InvalidRequestError, match="no step"):
        validate_footsteps(FootstepSequence(*start, ()), FootstepBounds())
    with pytest.raises(InvalidRequestError, match="n_steps must be an integer >= 1"):
        straight_walk(0, 0.2)


def test_zero_or_negative_durations_are_invalid():
    seq = straight_walk(2, 0.1)
    with pytest.raises(InvalidRequestError, match="single_support_s must be > 0 s, got 0"):
        plan_pattern(seq, WalkTiming(single_support_s=0.0), PatternOptions(com_height_m=0.75))
    with pytest.raises(InvalidRequestError, match=r"double_support_s must be > 0 s, got -0\.1"):
        plan_pattern(seq, WalkTiming(double_support_s=-0.1), PatternOptions(com_height_m=0.75))
    with pytest.raises(InvalidRequestError, match="shorter than one sample"):
        plan_pattern(seq, WalkTiming(double_support_s=0.001), PatternOptions(com_height_m=0.75))
    with pytest.raises(InvalidRequestError, match="CoM height"):
        plan_pattern(seq, WalkTiming(), PatternOptions())


def test_footstep_sequence_round_trips_through_plain_data():
    seq = arc_walk(1.2, 0.6, 8)
    assert FootstepSequence.from_dict(seq.to_dict()) == seq
    with pytest.raises(InvalidRequestError, match="side 'middle'"):
        FootstepSequence.from_dict(
            {
                "left_start": [0, 0, 0],
                "right_start": [0, 0, 0],
                "steps": [{"side": "middle", "pose": [0, 0, 0]}],
            }
        )


# ------------------------------------------------------------------------------------------ pattern


def test_zmp_reference_and_planned_zmp_stay_inside_the_support_polygon(robot):
    bounds = FootstepBounds.from_robot(robot)
    c0 = robot.com(robot.q_half_sitting)
    for name, seq in _walks(robot).items():
        p = plan_pattern(seq, WalkTiming(), PatternOptions(), initial_com_m=c0, bounds=bounds)
        ref = distances_to_support(p.zmp_ref_m, p.phase, p.left_sole, p.right_sole, *robot.sole_size_m)
        planned = distances_to_support(
            p.zmp_planned_m, p.phase, p.left_sole, p.right_sole, *robot.sole_size_m
        )
        assert ref.max() <= -0.010, name
        assert planned.max() <= -0.010, (name, planned.max())


def test_the_start_transient_of_the_preview_control_shrinks_with_the_lead_in():
    """From rest, the preview controller pushes the ZMP away from the first support as soon as its
    window sees the first transfer (walking README, "Paper vs here"): the planned ZMP's largest deviation
    from its reference before the transfer falls with the standing lead-in (hrp2_like, measured 88, 14,
    0.8 mm for 0.6, 1.0, 1.6 s) and stays inside the double-support polygon."""
    robot = load_robot("hrp2_like")
    seq = _walks(robot)["straight"]
    c0 = robot.com(robot.q_half_sitting)
    # the double-support polygon's outer edge in y (the soles side by side)
    outer_y = abs(robot.sole_pose(robot.q_half_sitting, "left").translation[1]) + 0.5 * robot.sole_size_m[1]
    deviation = []
    for hold in (0.6, 1.0, 1.6):
        timing = WalkTiming(initial_hold_s=hold)
        p = plan_pattern(seq, timing, PatternOptions(), initial_com_m=c0)
        before = slice(0, round(hold / DT))
        deviation.append(float(np.abs(p.zmp_planned_m[before] - p.zmp_ref_m[before]).max()))
        assert np.abs(p.zmp_planned_m[before, 1]).max() < outer_y - 0.05
    assert deviation[0] > deviation[1] > deviation[2]
    assert deviation[2] < 0.002


def test_pattern_feet_and_com_end_where_planned(robot):
    bounds = FootstepBounds.from_robot(robot)
    c0 = robot.com(robot.q_half_sitting)
    seq = _walks(robot)["arc"]
    p = plan_pattern(seq, WalkTiming(), PatternOptions(), initial_com_m=c0, bounds=bounds)
    left, right = seq.final_stance()
    np.testing.assert_allclose(p.left_sole[-1], [left.x_m, left.y_m, 0.0, left.yaw_rad], atol=1e-9)
    np.testing.assert_allclose(p.right_sole[-1], [right.x_m, right.y_m, 0.0, right.yaw_rad], atol=1e-9)
    mid = 0.5 * (left.as_array()[:2] + right.as_array()[:2])
    np.testing.assert_allclose(p.com_m[-1, :2], mid, atol=2e-3)
    np.testing.assert_allclose(p.com_m[0], c0, atol=1e-12)
    np.testing.assert_allclose(p.com_vel_m_s[[0, -1]], 0.0, atol=2e-3)
    assert p.waist_yaw_rad[-1] == pytest.approx(math.pi / 2)
    # A support sole never moves; a swing sole is in the air only in single support.
    for side, support in (("left", LEFT), ("right", RIGHT)):
        sole = p.sole(side)
        moving = np.any(np.abs(np.diff(sole, axis=0)) > 1e-12, axis=1)
        assert not np.any(moving & (p.phase[:-1] == support))
        assert not np.any(moving & (p.phase[:-1] == DOUBLE))
        assert np.all(sole[p.phase == DOUBLE, 2] == 0.0)
    assert set(np.unique(p.phase)) == {DOUBLE, LEFT, RIGHT}
    assert p.n_samples == round(p.duration_s / DT) + 1


def test_straight_walk_timing_and_phases():
    seq = straight_walk(10, 0.2)
    timing = WalkTiming(single_support_s=0.8, double_support_s=0.1)
    p = plan_pattern(seq, timing, PatternOptions(com_height_m=0.75))
    t = timing  # start hold, first transfer, 10 single + 9 double supports, last transfer, final hold
    expected = t.initial_hold_s + t.initial_double_support_s + 10 * 0.8 + 9 * 0.1
    expected += t.final_double_support_s + t.final_hold_s
    assert p.duration_s == pytest.approx(expected)
    assert np.count_nonzero(p.phase != DOUBLE) == 10 * 160
    assert p.phase_names()[0] == "double"
    # First moving foot is the right one: the left sole supports first.
    assert p.phase[np.argmax(p.phase != DOUBLE)] == LEFT


def test_slow_steps_lengthen_only_their_single_supports_and_are_found_by_time():
    seq = straight_walk(4, 0.2)
    base = WalkTiming()
    slow = WalkTiming(slow_steps=(1, 2), slow_step_factor=1.5)
    fast = build_schedule([s.side for s in seq.steps], base)
    sched = build_schedule([s.side for s in seq.steps], slow)
    assert sched.duration_s == pytest.approx(fast.duration_s + 2 * 0.5 * base.single_support_s)
    swings = {seg.step_index: seg.n for seg in sched.segments if seg.role == "swing"}
    n_ss = base.samples(base.single_support_s)
    assert swings == {0: n_ss, 1: base.samples(1.5 * base.single_support_s), 2: swings[1], 3: n_ss}
    for seg in sched.segments:
        t_mid = (seg.start + seg.n // 2) * sched.dt_s
        expected = {
            "swing": (seg.step_index,),
            "transfer": (seg.step_index, seg.step_index + 1),
            "initial": (0,),
            "final": (3,),
        }.get(seg.role, ())
        assert sched.steps_at(t_mid) == expected, seg
    with pytest.raises(InvalidRequestError):
        build_schedule(["left"], WalkTiming(slow_step_factor=0.5))
    with pytest.raises(InvalidRequestError):
        build_schedule(["left"], WalkTiming(slow_steps=(-1,)))


# ------------------------------------------------------------------------------------ multibody ZMP


def test_multibody_zmp_of_a_rigid_body_in_horizontal_acceleration_is_the_cart_table_zmp():
    robot = load_robot("hrp2_like")
    q0 = robot.q_half_sitting
    n, a = 200, np.array([0.8, -0.4])
    t = np.arange(n) * DT
    qs = np.repeat(q0[None], n, axis=0)
    qs[:, :2] += 0.5 * a * t[:, None] ** 2
    mb = multibody_zmp(robot.model, qs, DT)
    c = robot.com(q0)
    inner = slice(2, n - 2)  # the ends see the rest assumed outside the trajectory
    np.testing.assert_allclose(mb.com_acc_m_s2[inner, :2], np.broadcast_to(a, (n - 4, 2)), atol=1e-6)
    expected = mb.com_m[inner, :2] - c[2] / 9.81 * a
    np.testing.assert_allclose(mb.zmp_m[inner], expected, atol=1e-6)
    np.testing.assert_allclose(mb.angular_momentum_rate_n_m[inner], 0.0, atol=1e-6)


def test_multibody_zmp_includes_the_angular_momentum_rate():
    """A robot rotating about its CoM with constant angular acceleration about the world x axis: the ZMP
    moves by dL_x / (m g) in y (sign of eq. for p_y)."""
    robot = load_robot("hrp2_like")
    q0 = robot.q_half_sitting.copy()
    data = robot.new_data()
    c = pin.centerOfMass(robot.model, data, q0).copy()
    n, alpha = 120, 0.5
    qs = np.empty((n, robot.nq))
    T0 = pin.XYZQUATToSE3(q0[:7])
    for k in range(n):
        angle = 0.5 * alpha * (k * DT) ** 2
        R = pin.rpy.rpyToMatrix(angle, 0.0, 0.0)
        T = pin.SE3(R, c) * pin.SE3(np.eye(3), -c) * T0  # rotate about the (world) CoM
        qs[k] = q0
        qs[k, :7] = pin.SE3ToXYZQUAT(T)
    mb = multibody_zmp(robot.model, qs, DT)
    k = n // 2
    pin.computeCentroidalMap(robot.model, data, qs[k])
    np.testing.assert_allclose(mb.com_m[k], c, atol=1e-9)
    dL = mb.angular_momentum_rate_n_m[k]
    assert dL[0] > 1.0  # rolling to the left needs a +x torque from the ground
    fz = robot.total_mass_kg * (9.81 + mb.com_acc_m_s2[k, 2])
    assert mb.zmp_m[k, 1] == pytest.approx(c[1] + dL[0] / fz, abs=1e-9)
    assert mb.zmp_m[k, 0] == pytest.approx(c[0] - dL[1] / fz, abs=1e-6)


# ---------------------------------------------------------------------------------- support polygon


def test_convex_hull_keeps_the_corners_of_rectangles_with_float_noise():
    """Sole corners computed twice differ by float noise; the former hull (cross product <= 1e-12 m^2)
    dropped a real corner next to such a pair in 15 % of the cases (even 2 of 4 corners)."""
    rng = np.random.default_rng(7)
    for _ in range(500):
        pose = np.array([*rng.uniform(-2.0, 2.0, 2), rng.choice([0.0, math.pi / 2, rng.uniform(-4, 4)])])
        for length, width in ((0.24, 0.14), (0.205, 0.122), (1e-5, 1e-5)):
            corners = sole_polygon(pose, length, width)
            noisy = corners + rng.normal(0.0, rng.choice([1e-16, 1e-15, 1e-12]), corners.shape)
            mid_edge = 0.5 * (corners[0] + corners[1])  # collinear: not a vertex
            hull = convex_hull(np.vstack([corners, noisy, mid_edge]))
            assert hull.shape == (4, 2)
            # each corner is a vertex (up to the noise), in counter-clockwise order
            assert np.abs(hull[:, None, :] - corners[None]).max(axis=2).min(axis=0).max() < 1e-11
            edges = np.roll(hull, -1, axis=0) - hull
            assert np.all(
                edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1]
                - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
                > 0
            )
    # Two soles side by side: their 8 corners, 4 of them on the hull; coincident inner edges drop out.
    both = np.vstack(
        [
            sole_polygon(np.array([0.0, 0.095, 0.0]), 0.24, 0.14),
            sole_polygon(np.array([0.0, -0.095, 0.0]), 0.24, 0.14),
        ]
    )
    assert convex_hull(both).shape == (4, 2)


def test_signed_distance_to_a_convex_polygon():
    hull = convex_hull(np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], dtype=float))
    assert hull.shape == (4, 2)
    d = signed_distance(np.array([[0.5, 0.5], [0.9, 0.5], [2.0, 0.5], [2.0, 2.0], [1.0, 0.3]]), hull)
    np.testing.assert_allclose(d, [-0.5, -0.1, 1.0, math.sqrt(2), 0.0], atol=1e-12)


# ------------------------------------------------------------------------------------- whole body


@pytest.fixture(scope="module")
def planners():
    from services.walking.wholebody import WholeBodyPlanner

    return {name: WholeBodyPlanner(load_robot(name)) for name in ("hrp2_like", "talos")}


@pytest.mark.parametrize("walk", ["straight", "turn_left", "side_right", "arc"])
def test_wholebody_multibody_zmp_stays_inside_the_polygon(planners, robot, walk):
    wb = planners[robot.name]
    q0 = robot.q_half_sitting
    seq = _walks(robot)[walk]
    p = plan_pattern(
        seq,
        WalkTiming(),
        PatternOptions(),
        initial_com_m=robot.com(q0),
        bounds=FootstepBounds.from_robot(robot),
    )
    res = wb.solve(p, q0)
    assert res.q.shape == (p.n_samples, robot.nq)
    assert res.zmp_distance_m.max() <= -0.010, res.figures()
    assert res.max_sole_error_m < 1e-3 and res.max_com_error_m < 1e-3
    # The robot ends where the footsteps say, at rest.
    left, right = seq.final_stance()
    for side, pose in (("left", left), ("right", right)):
        T = robot.sole_pose(res.q[-1], side)
        np.testing.assert_allclose(T.translation, [pose.x_m, pose.y_m, 0.0], atol=1e-3)
        yaw = math.atan2(T.rotation[1, 0], T.rotation[0, 0])
        assert abs(math.remainder(yaw - pose.yaw_rad, 2 * math.pi)) < 1e-3
    assert np.abs(res.q[-1] - res.q[-2]).max() < 1e-6


def test_a_walk_far_from_the_origin_is_the_walk_at_the_origin_translated():
    """Planned from (2.9, 0.8) facing 0.6 rad, the whole-body walk keeps the same ZMP margin as at the
    origin (it was 70 mm outside the polygon before the preview control worked relative to its start)."""
    from services.walking.wholebody import plan_walk

    robot = load_robot("hrp2_like")
    results = []
    for x, y, yaw in ((0.0, 0.0, 0.0), (2.9, 0.8, 0.6)):
        q = robot.q_half_sitting.copy()
        R = pin.utils.rpyToMatrix(0.0, 0.0, yaw)
        q[:3] = R @ q[:3] + [x, y, 0.0]
        q[3:7] = pin.Quaternion(R @ pin.Quaternion(q[3:7]).toRotationMatrix()).coeffs()
        soles = {}
        for side in ("left", "right"):
            T = robot.sole_pose(q, side)
            soles[side] = SolePose(T.translation[0], T.translation[1], yaw)
        walk = straight_walk(2, 0.1, left_start=soles["left"], right_start=soles["right"])
        results.append(plan_walk(robot, walk, q))
    here, there = results
    assert here.min_zmp_margin_m >= 0.010
    assert there.min_zmp_margin_m == pytest.approx(here.min_zmp_margin_m, abs=1e-4)


def test_second_stage_reduces_the_multibody_zmp_error(planners):
    """Asking for more margin than the first stage gives triggers the second preview stage, which
    brings the multibody ZMP closer to the reference where it acts."""
    from services.walking.wholebody import WholeBodyOptions, WholeBodyPlanner

    robot = load_robot("hrp2_like")
    q0 = robot.q_half_sitting
    p = plan_pattern(_walks(robot)["straight"], WalkTiming(), PatternOptions(), initial_com_m=robot.com(q0))
    res = WholeBodyPlanner(robot, WholeBodyOptions(zmp_margin_m=0.08, max_corrections=2)).solve(p, q0)
    assert res.corrections == 2
    first, last = res.history[0], res.history[-1]
    assert last["max_zmp_error_walking_mm"] < 0.7 * first["max_zmp_error_walking_mm"]
    assert last["min_margin_mm"] > first["min_margin_mm"]
    # The corrected CoM reference starts and ends on the pattern's.
    np.testing.assert_allclose(res.com_ref_m[[0, -1]], p.com_m[[0, -1]], atol=1e-9)


def test_wholebody_runs_caller_upper_body_tasks(planners):
    """A caller level moves the right hand with the CoM and raises it smoothly by 10 cm (carrying
    something); the targets at t = 0 hold at the starting configuration."""
    from services.ik import FramePositionTask, Level

    robot = load_robot("hrp2_like")
    wb = planners["hrp2_like"]
    q0 = robot.q_half_sitting
    seq = straight_walk(4, 0.15, left_start=SolePose(0, 0.095, 0), right_start=SolePose(0, -0.095, 0))
    p = plan_pattern(seq, WalkTiming(), PatternOptions(), initial_com_m=robot.com(q0))
    hand0 = robot.frame_pose(q0, robot.frames.right_grasp).translation
    offset = hand0 - p.com_m[0]
    hand = FramePositionTask(wb.model, robot.frames.right_grasp, hand0, name="hand")
    lift = np.array([0.0, 0.0, 0.10])

    def target(t_s, com_ref_m):
        return (
            com_ref_m
            + offset
            + lift * min(1.0, t_s / 3.0) ** 3 * (10 - 15 * min(1.0, t_s / 3.0) + 6 * min(1.0, t_s / 3.0) ** 2)
        )

    def update(k, t_s, com_ref_m):
        hand.set_target(target(t_s, com_ref_m))

    res = wb.solve(p, q0, extra_levels=[Level((hand,), name="hand")], update_extra=update)
    np.testing.assert_allclose(res.q[0], q0, atol=1e-12)
    errors = [
        np.abs(robot.frame_pose(q, robot.frames.right_grasp).translation - target(t, c)).max()
        for q, c, t in zip(res.q[::40], res.com_ref_m[::40], res.times_s[::40], strict=True)
    ]
    assert max(errors) < 2e-3
    assert res.zmp_distance_m.max() <= -0.010


def test_wholebody_rejects_a_start_away_from_the_footsteps(planners):
    robot = load_robot("hrp2_like")
    q0 = robot.half_sitting_at(0.3, 0.0, 0.0)
    p = plan_pattern(straight_walk(2, 0.1), WalkTiming(), PatternOptions(com_height_m=0.75))
    with pytest.raises(InvalidRequestError, match="left sole of q_start is at"):
        planners["hrp2_like"].solve(p, q0)
