"""A ball partly hidden by the robot's own hand (vision.hidden_ball), and every object seen in a look
with identities kept apart (vision.localize.others_in_frame), on ray-cast stereo pairs with exact
ground truth (vision.synthetic): the robot's own pixels are the hand's labels, as
services/perception/own_body.py draws them from the robot model."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from services.errors import NotFoundError
from vision import synthetic as syn
from vision.camera import CameraIntrinsics, StereoRig, look_at
from vision.hidden_ball import fit_circle, free_circle
from vision.histogram import learn_model
from vision.localize import LocalizeConfig, StereoFrame, locate, locate_in_frame, others_in_frame

RIG = StereoRig(CameraIntrinsics.from_hfov(640, 480, math.radians(60.0)), 0.144)
BALL = (0.9, 0.0, 0.75)
BLUE: syn.BGR = (235.0, 60.0, 15.0)
DARK: syn.BGR = (50.0, 52.0, 55.0)  # the gripper's dark grey: no hue, no colour model
CAMERA = look_at([0.0, 0.0, 1.35], list(BALL))


#: A gripper-like bar between the cameras and the ball: it hides the ball's right rim in the left image
#: and its left part in the right one (the hand backed off above the ball after a failed grasp).
BAR = syn.Box("hand", (0.55, -0.036, 0.983), (0.03, 0.012, 0.05), DARK)
#: A hand resting on the ball (closed on nothing beside it): the whole ball hidden in the right image.
ON_IT = syn.Box("hand", (0.55, -0.045, 0.995), (0.04, 0.04, 0.04), DARK)


def scene(hand: bool, box: syn.Box = BAR) -> syn.Scene:
    """The orange ball on a grey stand, a blue ball beside it; with ``hand``, a dark box (the gripper)
    between the cameras and the ball."""
    hand_box = (box,) if hand else ()
    return syn.Scene(
        (
            *syn.room(),
            syn.Sphere("orange_ball", BALL, syn.BALL_RADIUS_M, syn.ORANGE),
            syn.Sphere("blue_ball", (BALL[0] + 0.08, BALL[1] + 0.2, BALL[2]), syn.BALL_RADIUS_M, BLUE),
            syn.Box("stand", (BALL[0], BALL[1] + 0.1, 0.35), (0.15, 0.25, 0.35), (140.0, 140.0, 140.0)),
            *hand_box,
        )
    )


@pytest.fixture(scope="module")
def models():
    s = scene(hand=False)
    render = syn.render(
        s, RIG.intrinsics, look_at([0.1, 0.4, 1.3], list(BALL)), 2, 2.0, np.random.default_rng(1)
    )
    return {
        n: learn_model(n, [render.image_bgr], [s.mask_of(render.labels, n)], shape="sphere")
        for n in ("orange_ball", "blue_ball")
    }


@pytest.fixture(scope="module")
def hidden_pair():
    """(left, right renders, own-body masks) of the ball with the hand in front."""
    s = scene(hand=True)
    left, right = syn.render_stereo(s, RIG, CAMERA, 2, 2.0, np.random.default_rng(3))
    grow = np.ones((5, 5), np.uint8)
    own = tuple(cv2.dilate(s.mask_of(r.labels, "hand").astype(np.uint8), grow) > 0 for r in (left, right))
    return left, right, own


def test_a_circle_is_fitted_to_the_free_part_of_a_cut_disc():
    yy, xx = np.mgrid[0:120, 0:160]
    disc = (xx - 80.3) ** 2 + (yy - 60.7) ** 2 <= 30.0**2
    hidden = np.zeros_like(disc)
    hidden[:, 95:] = True  # the right part hidden
    seen = disc & ~hidden
    circle = free_circle(seen, (0, 0, 160, 120), hidden)
    assert circle is not None
    assert circle.u_px == pytest.approx(80.3, abs=0.5) and circle.v_px == pytest.approx(60.7, abs=0.5)
    assert circle.radius_px == pytest.approx(30.0, abs=0.7)
    hidden[:, 70:] = True  # most of it hidden: too little arc left to say where the circle is
    assert free_circle(disc & ~hidden, (0, 0, 160, 120), hidden) is None
    assert fit_circle(np.array([[0, 0], [1, 1], [2, 2]])) is None  # collinear


def test_a_ball_partly_hidden_by_the_robots_hand_is_localized_from_its_free_outline(models, hidden_pair):
    left, right, own = hidden_pair
    ball = models["orange_ball"]
    # Without the robot's own pixels: the cut silhouettes' centroids give a wrong centre (or no match).
    try:
        plain = locate(ball, left.image_bgr, right.image_bgr, RIG, CAMERA)
        plain_error = float(np.linalg.norm(np.asarray(plain.position_world) - BALL))
    except NotFoundError:
        plain_error = math.inf
    assert plain_error > 0.02
    seen = locate(ball, left.image_bgr, right.image_bgr, RIG, CAMERA, own_body=own)
    assert seen.method == "free_outline"
    assert np.linalg.norm(np.asarray(seen.position_world) - BALL) < 0.01
    assert seen.size_m[0] == pytest.approx(0.1, abs=0.015)


def test_own_body_masks_are_drawn_only_when_a_ball_is_near_or_a_footprint_needs_them(models, hidden_pair):
    left, right, own = hidden_pair
    calls = []

    def draw():
        calls.append(1)
        return own

    near = StereoFrame(left.image_bgr, right.image_bgr, RIG, CAMERA, draw)
    locate_in_frame(models["orange_ball"], near, LocalizeConfig())
    locate_in_frame(models["blue_ball"], near, LocalizeConfig())
    assert calls == [1]  # drawn once, for the first ball near the cameras
    far = StereoFrame(left.image_bgr, right.image_bgr, RIG, CAMERA, draw)
    locate_in_frame(models["orange_ball"], far, LocalizeConfig(hidden_ball_max_depth_m=0.5))
    assert calls == [1]  # not needed: not drawn


def test_a_look_reports_the_other_objects_seen_and_one_object_per_region(models):
    s = scene(hand=False)
    left, right = syn.render_stereo(s, RIG, CAMERA, 1, 2.0, np.random.default_rng(4))
    frame = StereoFrame(left.image_bgr, right.image_bgr, RIG, CAMERA)
    found = locate_in_frame(models["orange_ball"], frame)
    others = others_in_frame(found, list(models.values()), frame)
    assert [o.name for o in others] == ["blue_ball"]
    assert (
        np.linalg.norm(np.asarray(others[0].position_world) - (BALL[0] + 0.08, BALL[1] + 0.2, BALL[2])) < 0.01
    )
    assert others[0].footprint is None and 0.0 < others[0].confidence <= 1.0
    # Another name for the orange colour (a second model learned from the orange ball's pixels): it
    # claims the orange ball's region, so it is the orange ball, not a second object there.
    twin = learn_model(
        "orange_twin", [left.image_bgr], [s.mask_of(left.labels, "orange_ball")], shape="sphere"
    )
    others = others_in_frame(found, [*models.values(), twin], frame)
    assert [o.name for o in others] == ["blue_ball"]


def test_a_ball_the_hand_hides_in_one_image_is_reported_hidden_by_the_robots_own_body(models):
    s = scene(hand=True, box=ON_IT)
    left, right = syn.render_stereo(s, RIG, CAMERA, 1, 2.0, np.random.default_rng(5))
    own = tuple(s.mask_of(r.labels, "hand") for r in (left, right))
    ball = models["orange_ball"]
    with pytest.raises(NotFoundError) as plain:
        locate(ball, left.image_bgr, right.image_bgr, RIG, CAMERA)
    assert plain.value.details["reason"] == "not_in_right_view"
    with pytest.raises(NotFoundError, match="the arm hides it") as hidden:
        locate(ball, left.image_bgr, right.image_bgr, RIG, CAMERA, own_body=own)
    assert hidden.value.details["reason"] == "hidden_by_own_body"
