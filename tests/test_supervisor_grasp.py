"""The grasp's choices of where to aim, pure: memory and config only, no bus.

``ManipulationActions._where_it_was_aimed`` (fetch seed 37: a relocalization from the backed-off hand
put the ball 0.13 m off and 0.12 m low, less confidently, and the jaws were turned for the wrong
neighbour) and ``_grasp_point`` (fetch seed 46: aimed with the ball against the fixed finger, the hand
came down on the ball's side, rolled it away and closed on nothing)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from supervisor.config import SupervisorConfig
from supervisor.manipulation import (
    ManipulationActions,
    choose_hand,
    hand_in_the_way,
    raise_parts,
    refused_for_spheres,
)
from supervisor.memory import Memory, Sighting
from supervisor.scene_map import BoxEstimate

AIMED = np.array([3.33, 1.13, 0.75])  # where the last lowering aimed (seen from near) [m]


def _ball(position, confidence: float) -> Sighting:
    return Sighting(
        name="orange_ball",
        position_m=np.asarray(position, dtype=float),
        size_m=(0.08, 0.08),
        distance_m=0.9,
        confidence=confidence,
        sim_time_s=1.0,
        camera_m=np.array([2.6, 1.1, 1.4]),
    )


@pytest.fixture
def actions() -> ManipulationActions:
    actions = ManipulationActions()
    actions.memory = Memory()
    actions.config = SupervisorConfig()
    actions.said = []
    actions.progress = actions.said.append
    actions.memory.aimed["orange_ball"] = _ball(AIMED, 0.97)
    return actions


def test_a_jump_seen_less_confidently_keeps_where_it_was_aimed(actions):
    actions.memory.remember(_ball(AIMED + np.array([0.05, 0.0, -0.12]), 0.78))
    actions._where_it_was_aimed("orange_ball")
    assert np.allclose(actions.memory.get("orange_ball").position_m, AIMED)
    assert len(actions.said) == 1 and "keeping that one" in actions.said[0]


@pytest.mark.parametrize(
    ("offset", "confidence"),
    [
        ((0.05, 0.0, -0.12), 0.99),  # a jump, but seen more confidently: it moved (pushed by the hand)
        ((0.03, 0.02, 0.0), 0.5),  # within relocalized_jump_m: the new sighting is as good
    ],
)
def test_otherwise_the_new_sighting_is_kept(actions, offset, confidence):
    latest = AIMED + np.array(offset)
    actions.memory.remember(_ball(latest, confidence))
    actions._where_it_was_aimed("orange_ball")
    assert np.allclose(actions.memory.get("orange_ball").position_m, latest)
    assert actions.said == []


def test_without_an_earlier_lowering_the_sighting_is_kept(actions):
    actions.memory.aimed.clear()
    latest = AIMED + np.array([0.2, 0.0, 0.0])
    actions.memory.remember(_ball(latest, 0.3))
    actions._where_it_was_aimed("orange_ball")
    assert np.allclose(actions.memory.get("orange_ball").position_m, latest)


@pytest.mark.parametrize("yaw_deg", [-14.0, 0.0, 120.0])
def test_the_ball_goes_down_between_the_jaws_clear_of_the_fixed_finger(yaw_deg):
    """Fetch seed 46: the ball (radius 0.05 m) seen 0.097 m wide, aimed against the fixed finger, had
    its side under that finger; now its surface is ``grasp_clearance_m`` less the 1.5 mm it was seen
    too small off the fixed finger, and off the open moving finger too (the hand's own gap, 0.13 m)."""
    from services.model.robot_model import load_robot
    from sim.robot_info import robot_info_reply
    from supervisor.body import Body

    actions = ManipulationActions()
    actions.config = SupervisorConfig()
    actions.memory = Memory()
    actions.body = Body(bus=None)
    actions.body.robot._info = robot_info_reply(load_robot("hrp2_like"))  # the sim's reply, no bus
    actions.memory.remember(dataclasses.replace(_ball(AIMED, 0.97), size_m=(0.097, 0.097)))
    yaw = np.radians(yaw_deg)
    point = actions._grasp_point("right", "orange_ball", yaw)
    # The ball's centre in the grasp frame (turned by yaw about the vertical), the fixed finger at +y.
    c, s = np.cos(yaw), np.sin(yaw)
    in_hand = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ (AIMED - point)
    fixed_y = actions.body.robot.info.fixed_finger_y_m["right"]
    radius = 0.05  # the ball's own
    clearance = actions.config.grasp_clearance_m
    assert fixed_y - (in_hand[1] + radius) == pytest.approx(clearance - 0.0015, abs=1e-6)
    assert (in_hand[1] - radius) - (-fixed_y) > clearance  # the moving finger, open, farther still
    assert abs(in_hand[0]) < 1e-9 and abs(in_hand[2]) < 1e-9


def _hand_actions() -> ManipulationActions:
    """Manipulation actions on the sim's real ``robot_info`` reply of hrp2_like (no bus)."""
    from services.model.robot_model import load_robot
    from sim.robot_info import robot_info_reply
    from supervisor.body import Body

    actions = ManipulationActions()
    actions.config = SupervisorConfig()
    actions.memory = Memory()
    actions.body = Body(bus=None)
    actions.body.robot._info = robot_info_reply(load_robot("hrp2_like"))
    return actions


@pytest.mark.parametrize(("yaw_deg", "tilt_deg"), [(-32.0, 0.0), (57.0, 8.0), (148.0, -6.0)])
def test_the_grasp_point_follows_the_hand_as_it_is_turned(yaw_deg, tilt_deg):
    """The lowering keeps the orientation the reach above executed (the wrist turned clear of a
    neighbour, slightly tilted): the ball then lies where a held one would, ``grasp_clearance_m`` off
    the fixed finger, in the grasp frame turned so, not in the one the supervisor asked for."""
    from scipy.spatial.transform import Rotation

    from supervisor.manipulation import yaw_of

    actions = _hand_actions()
    actions.memory.remember(_ball(AIMED, 0.97))  # seen 0.08 m wide
    R = Rotation.from_euler("ZX", [yaw_deg, tilt_deg], degrees=True).as_matrix()
    point = actions._grasp_point("right", "orange_ball", 0.0, R_world_hand=R)
    # Where the ball is for the hand at ``point`` turned by R: against the model's fixed finger (the
    # sim's robot_info), its surface grasp_clearance_m off it, under the palm (the jaws close on it).
    in_hand = R.T @ (AIMED - point)
    fixed_y = actions.body.robot.info.fixed_finger_y_m["right"]
    radius = 0.04
    assert fixed_y - (in_hand[1] + radius) == pytest.approx(actions.config.grasp_clearance_m, abs=1e-9)
    assert (in_hand[1] - radius) - (-fixed_y) > actions.config.grasp_clearance_m  # the open moving finger
    assert abs(in_hand[0]) < 1e-9 and abs(in_hand[2]) < 1e-9
    assert math.degrees(yaw_of(R)) == pytest.approx(yaw_deg, abs=1e-6)
    # the hand turned by its yaw only: as ``_grasp_point`` for that yaw
    upright = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    by_yaw = actions._grasp_point("right", "orange_ball", math.radians(yaw_deg))
    assert np.allclose(actions._grasp_point("right", "orange_ball", 0.0, R_world_hand=upright), by_yaw)


@pytest.mark.parametrize(("tilt_deg", "refused"), [(4.0, False), (25.0, True)])
def test_a_free_yaw_posture_is_kept_with_the_fingers_down_only(tilt_deg, refused):
    """footsteps/plan's orientation task is below the reach: with the yaw free its final posture may
    leave the fingers off down; the stance is then not taken (``jaws_tilt_deg``)."""
    from scipy.spatial.transform import Rotation

    from supervisor.planners import LastSteps

    actions = _hand_actions()
    quat = Rotation.from_euler("zy", [-20.0, tilt_deg], degrees=True).as_quat().tolist()
    planned = LastSteps(None, "footsteps/plan", np.zeros(3), quat)
    reason = actions._fingers_not_down("right", planned)
    assert (reason is not None) == refused
    if refused:
        assert "25 deg off down" in reason


# ------------------------------------------------------------------------------------------ the hand's way
ORANGE = np.array([3.332, 1.133, 0.75])  # fetch seed 6's orange ball [m]; the robot at (2.44, 1.12)
STANCE = (2.44, 1.12)
R_BALL = 0.05


def _way(beside):
    c = SupervisorConfig()
    return hand_in_the_way(ORANGE, R_BALL, STANCE, beside, c.hand_way_deg, c.hand_way_gap_m)


def test_a_ball_close_on_the_right_hands_side_takes_the_left_hand():
    purple = np.array([3.441, 1.061, 0.75])  # seed 6: 3.1 cm away, 34 deg right of the approach
    blue = np.array([3.431, 1.328, 0.75])  # 11.9 cm away on the left: not in the way
    way = _way([(purple, R_BALL), (blue, R_BALL)])
    assert list(way) == ["right"] and way["right"][0][0] == pytest.approx(0.031, abs=1e-3)
    hand, why = choose_hand(way)
    assert hand == "left" and "right hand's side" in why


@pytest.mark.parametrize(
    ("offset", "hand"),
    [
        ((0.15, -0.08), "right"),  # 7 cm away: wide enough for the default hand
        ((0.145, 0.0), "right"),  # straight ahead (0 deg): on neither hand's side
        ((-0.13, -0.02), "right"),  # behind it, toward the robot (171 deg): neither side's way
    ],
)
def test_otherwise_the_default_hand(offset, hand):
    assert choose_hand(_way([(ORANGE + np.array([*offset, 0.0]), R_BALL)]))[0] == hand


def test_something_on_both_sides_keeps_the_default_hand_and_both_are_reported():
    right = ORANGE + np.array([0.04, -0.115, 0.0])  # layout balls_tight: 2.2 cm gaps, 71 deg either side
    left = ORANGE + np.array([0.04, 0.115, 0.0])
    way = _way([(right, R_BALL), (left, R_BALL)])
    assert sorted(way) == ["left", "right"]
    assert choose_hand(way) == ("right", "")


def test_only_refusals_because_of_the_spheres_are_planned_again_without_them():
    assert refused_for_spheres({"reason": "hand_obstacle", "criterion": "ee_error"})
    assert refused_for_spheres({"reason": "stepping_not_allowed", "criterion": "hand_obstacle"})
    assert not refused_for_spheres({"reason": "stepping_not_allowed", "criterion": "ee_error"})


BOX = BoxEstimate("green_box", (3.4, 1.19, 0.35), (0.53, 0.67, 0.7), 0.0)  # near face at x = 3.135


@pytest.mark.parametrize(
    ("hand_x", "hand_z", "parts"),
    [
        (3.0, 0.55, 2),  # over the box's edge at 0.77 m, 7 cm above its top (layout ball_far_side): up first
        (2.9, 0.55, 1),  # the line ends 3.5 cm before the box: one straight motion (seed 37)
        (3.0, 0.82, 1),  # over the edge at 0.85 m, 15 cm above its top: one straight motion
    ],
)
def test_a_raise_over_the_support_goes_up_first(hand_x, hand_z, parts):
    here = np.array([hand_x, 1.0, hand_z])
    point = np.array([hand_x + 0.2, 1.0, 0.87])
    got = raise_parts(here, point, BOX, SupervisorConfig().raise_box_margin_m)
    assert len(got) == parts and np.allclose(got[-1], point)
    if parts == 2:
        assert np.allclose(got[0], [hand_x, 1.0, 0.87])  # straight up where the hand is
    assert len(raise_parts(here, point, None, 0.1)) == 1  # no support known: as before


def test_only_an_object_on_the_floor_is_out_of_reach_for_good(actions):
    """A ball whose bottom is on the floor is refused for good from near (a standing robot does not
    squat); one higher up on a support the map does not hold yet (a table not seen) is not: the
    retry's fresh look may map that support."""
    actions.memory.remember(_ball([4.3, -0.7, 0.04], 0.9))  # radius 0.04 as seen: bottom at 0
    assert actions._on_floor("orange_ball")
    actions.memory.remember(_ball([2.4, -1.8, 0.76], 0.9))  # on a table top at 0.72 m
    assert not actions._on_floor("orange_ball")
    assert not actions._on_floor("blue_ball")  # never seen


def test_opening_either_hand_needs_a_hand_that_holds_or_reached(actions):
    """The console's "release it" naming no hand opens the hand that holds something (else the one that
    reached last); with neither, it asks for the hand instead of guessing."""
    from services.errors import InvalidRequestError
    from supervisor.script import EITHER_HAND, Step

    actions.last_reach = None
    with pytest.raises(InvalidRequestError, match="name the hand"):
        actions.do_open(Step(line=1, action="open", args=(EITHER_HAND,)))
    actions.memory.holding.update({"left": "orange_ball", "right": "blue_ball"})
    with pytest.raises(InvalidRequestError, match="both hands hold"):
        actions.do_open(Step(line=1, action="open", args=(EITHER_HAND,)))
