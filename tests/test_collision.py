"""services/collision: an obstacle read from its bus message keeps the message's floor rectangle, and a
bad message is a typed error naming the field (the 3D motion checker is tested through navigation's
stage 2 and walking's legs sweep: tests/test_navigation_stage2.py, tests/test_walking_service.py)."""

from __future__ import annotations

import numpy as np
import pytest

from services.bus.schemas.navigation import ObstacleMsg
from services.collision import BoxObstacle, CylinderObstacle, obstacle_from_msg, obstacle_geometry
from services.errors import InvalidRequestError

BOX = ObstacleMsg(name="crate", kind="box", center=[1.0, -0.5, 0.3], size=[0.4, 0.2, 0.6], yaw=0.7)
CYLINDER = ObstacleMsg(name="pole", kind="cylinder", center=[2.0, 1.0, 0.5], radius=0.15, height=1.0)


@pytest.mark.parametrize("message", [BOX, CYLINDER], ids=["box", "cylinder"])
def test_an_obstacle_keeps_its_messages_floor_rectangle(message):
    """The map's boxes on the floor (walking/goal, navigation's straight walks) are the same rectangle
    whether taken from the message or from the obstacle: a cylinder's bounding square, a box turned."""
    obstacle = obstacle_from_msg(message)
    assert isinstance(obstacle, BoxObstacle if message.kind == "box" else CylinderObstacle)
    ours, theirs = obstacle.footprint, message.footprint
    assert np.allclose(ours.corners(), theirs.corners(), atol=1e-12)
    _shape, placement, radius = obstacle_geometry(obstacle)
    assert np.allclose(placement.getTranslation(), message.center)
    assert radius == pytest.approx(obstacle.bounding_radius_xy_m)


@pytest.mark.parametrize(
    ("fields", "field"),
    [
        ({"center": [1.0, 0.0, 0.3], "size": [0.4, 0.2]}, "size"),
        ({"kind": "cone", "center": [1.0, 0.0, 0.3]}, "kind"),
    ],
)
def test_a_bad_obstacle_message_names_its_field(fields, field):
    with pytest.raises(InvalidRequestError, match=field) as info:
        obstacle_from_msg(ObstacleMsg(name="x", **fields))
    assert info.value.details["field"] == field


def test_a_bad_obstacle_in_a_request_is_named_by_its_place():
    """walking/goal and navigation/goto pass each message's index: the error points into the request."""
    bad = ObstacleMsg(name="crate", center=[1.0, 0.0, 0.3], size=[0.4])
    with pytest.raises(InvalidRequestError, match=r"obstacles\[3\]\.size \('crate'\)") as info:
        obstacle_from_msg(bad, 3)
    assert info.value.details == {"field": "size", "index": 3}
