"""The grasp's choices of where to aim, pure: memory and config only, no bus.

``ManipulationActions._where_it_was_aimed`` (fetch seed 37: a relocalization from the backed-off hand
put the ball 0.13 m off and 0.12 m low, less confidently, and the jaws were turned for the wrong
neighbour) and :func:`~supervisor.manipulation.aim_again` (with the hand above the ball, seen again:
the hand moves above where it is now, or not; fetch seed 46: the hand closed on nothing beside it)."""

from __future__ import annotations

import numpy as np
import pytest

from supervisor.config import SupervisorConfig
from supervisor.manipulation import AIM_FAR, AIM_HIDDEN, AIM_KEEP, AIM_MOVE, ManipulationActions, aim_again
from supervisor.memory import Memory, Sighting

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


@pytest.mark.parametrize(
    ("offset", "verdict"),
    [
        ((0.0, 0.0, 0.0), AIM_KEEP),
        ((0.01, -0.008, 0.0), AIM_KEEP),  # 1.3 cm aside: within reaim_m
        ((0.0, 0.0, -0.04), AIM_KEEP),  # only lower: the hand comes straight down anyway
        ((0.025, 0.01, 0.0), AIM_MOVE),  # fetch seed 46's kind: a few centimetres aside
        ((-0.06, 0.05, -0.02), AIM_MOVE),
        ((0.09, 0.0, -0.05), AIM_FAR),  # 10.3 cm off in all: not trusted with the hand above it
        ((0.2, 0.0, 0.0), AIM_FAR),
    ],
)
def test_seen_again_with_the_hand_above_it(offset, verdict):
    config = SupervisorConfig()
    assert aim_again(np.array(offset), config.reaim_m, config.reaim_max_m) == verdict


def test_seen_less_surely_with_the_hand_above_it_keeps_the_aim():
    """Fetch seed 46: the ball half hidden by the hand above it, seen 2.4 cm off at confidence 0.65
    (aimed at 0.97): not a reason to move the hand."""
    config = SupervisorConfig()
    offset = np.array([-0.019, 0.01, -0.014])
    assert aim_again(offset, config.reaim_m, config.reaim_max_m, (0.65, 0.97)) == AIM_HIDDEN
    assert aim_again(offset, config.reaim_m, config.reaim_max_m, (0.95, 0.97)) == AIM_MOVE
