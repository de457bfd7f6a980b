"""Integration: the sim (ball_fetch, nominal layout) and perception services over a real zenoh hub.

The perception service renders through ``sim/render`` or takes images in the request; the camera pose
comes from the q in the request (here the robot's own state, ``sim/state``). Ground truth only scores.
"""

from __future__ import annotations

import numpy as np
import pytest

from services.bus.schemas import perception as msg
from services.bus.schemas import sim
from services.errors import InvalidRequestError, NotFoundError

pytestmark = pytest.mark.integration

DEMO_OBJECTS = ["green_box", "orange_ball", "yellow_table"]
TIMEOUT_S = 20.0


@pytest.fixture(scope="module")
def bus(module_bus_harness):
    module_bus_harness.spawn_service("sim.service", "--scene", "ball_fetch", name="sim", timeout_s=60)
    module_bus_harness.spawn_service("services.perception.service", name="perception", timeout_s=60)
    return module_bus_harness


@pytest.fixture(scope="module")
def state(bus):
    return bus.client.call(sim.STATE, sim.StateRequest(), timeout_s=TIMEOUT_S)


@pytest.fixture(scope="module")
def truth(bus):
    reply = bus.client.call(sim.GROUND_TRUTH, sim.GroundTruthRequest(), timeout_s=TIMEOUT_S)
    return {o.name: o for o in reply.objects}


def locate(bus, **fields) -> msg.LocateReply:
    return bus.client.call(msg.LOCATE, msg.LocateRequest(**fields), timeout_s=TIMEOUT_S)


def test_models_lists_the_learned_objects(bus):
    reply = bus.client.call(msg.MODELS, msg.ModelsRequest(), timeout_s=TIMEOUT_S)
    assert set(DEMO_OBJECTS) <= set(reply.names)
    shapes = {o.name: o.shape for o in reply.objects}
    assert shapes["orange_ball"] == "sphere" and shapes["yellow_table"] == "blob"


def test_locate_the_ball_from_the_robot_configuration(bus, state, truth):
    reply = locate(bus, object="orange_ball", model=state.model, q=state.q, others=True)
    error_m = np.linalg.norm(np.subtract(reply.position, truth["orange_ball"].position))
    assert error_m < 0.03  # 3.4 m away
    assert reply.rendered and reply.camera == "wide" and reply.method == "centroid"
    assert reply.distance_m == pytest.approx(3.3, abs=0.2)
    assert 0.07 < reply.size_m[0] < 0.13 and reply.confidence > 0.5
    assert reply.box_left.u_px - reply.box_right.u_px == pytest.approx(reply.disparity_px, abs=1.0)
    # The other learned objects in the same images: the balls beside it, the box they are on.
    others = {o.object: o for o in reply.others}
    assert {"blue_ball", "purple_ball", "green_box"} <= set(others) and "orange_ball" not in others
    for name in ("blue_ball", "purple_ball"):
        assert np.linalg.norm(np.subtract(others[name].position, truth[name].position)) < 0.05
        assert 0.0 < others[name].confidence <= 1.0 and 0.07 < others[name].size_m[0] < 0.13
    assert locate(bus, object="orange_ball", model=state.model, q=state.q).others == []  # the default


def test_locate_without_q_uses_the_robots_current_state(bus, state, truth):
    reply = locate(bus, object="green_box")
    with_q = locate(bus, object="green_box", q=state.q)
    np.testing.assert_allclose(reply.position, with_q.position, atol=1e-9)
    box = truth["green_box"]
    assert np.all(np.abs(np.subtract(reply.position, box.position)) <= np.asarray(box.size_m) / 2 + 0.1)


def test_images_in_the_request_give_the_same_answer(bus, state):
    render = bus.client.call(sim.RENDER, sim.RenderRequest(camera="wide"), timeout_s=TIMEOUT_S)
    left, right = render.images
    images = msg.StereoImages(left_rgb=left.rgb, right_rgb=right.rgb, K=left.K)
    given = locate(bus, object="orange_ball", q=state.q, images=images)
    rendered = locate(bus, object="orange_ball", q=state.q)
    assert not given.rendered and given.sim_time_s == 0.0
    np.testing.assert_allclose(given.position, rendered.position, atol=1e-9)


def test_unknown_object_is_an_invalid_request_listing_the_known_names(bus):
    with pytest.raises(InvalidRequestError, match="unknown object 'purple_cube'") as e:
        locate(bus, object="purple_cube")
    assert all(name in e.value.message for name in DEMO_OBJECTS)
    assert set(DEMO_OBJECTS) <= set(e.value.details["valid"])


def test_unknown_stereo_pair_is_an_invalid_request(bus, state):
    with pytest.raises(InvalidRequestError, match="stereo pairs are"):
        locate(bus, object="orange_ball", q=state.q, camera="front")


def test_a_black_image_is_not_found(bus, state):
    black = np.zeros((480, 640, 3), np.uint8)
    with pytest.raises(NotFoundError, match="not in view") as e:
        locate(bus, object="orange_ball", q=state.q, images=msg.StereoImages(left_rgb=black, right_rgb=black))
    assert e.value.details["reason"] == "not_in_view"
    assert e.value.details["object"] == "orange_ball"


def test_the_table_out_of_view_is_not_found_saying_so(bus, state):
    """The yellow table is 50 deg to the right: the supervisor looks around (look_around.py)."""
    with pytest.raises(NotFoundError, match="yellow_table in the wide stereo pair: not in view") as e:
        locate(bus, object="yellow_table", q=state.q)
    assert e.value.details["reason"] == "not_in_view"
