"""The grasp's choice of which sighting to aim at (``ManipulationActions._where_it_was_aimed``), pure:
memory and config only, no bus (fetch seed 37: a relocalization from the backed-off hand put the ball
0.13 m off and 0.12 m low, less confidently, and the jaws were turned for the wrong neighbour)."""

from __future__ import annotations

import numpy as np
import pytest

from supervisor.config import SupervisorConfig
from supervisor.manipulation import ManipulationActions
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
