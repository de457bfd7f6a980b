"""The supervisor's map (supervisor/scene_map.py): navigation boxes from perception's sightings."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from services.bus.schemas.perception import FootprintMsg
from supervisor.memory import Memory, Sighting
from supervisor.scene_map import box_estimate, distance_to_box, neighbours, ray_entry, viewpoints_past


def _fp(center, size, yaw, top_z, n_points) -> FootprintMsg:
    return FootprintMsg(center=list(center), size=list(size), yaw=yaw, top_z=top_z, n_points=n_points)


def _sighting(footprint: FootprintMsg | None, camera_xy=(0.0, 0.0), name: str = "yellow_table") -> Sighting:
    return Sighting(
        name=name,
        position_m=np.array([2.0, 0.0, 0.5]),
        size_m=(0.9, 0.5),
        distance_m=2.0,
        confidence=0.9,
        sim_time_s=0.0,
        camera_m=np.array([*camera_xy, 1.4]),
        footprint=footprint,
    )


def test_a_footprint_becomes_the_box_up_to_its_top():
    box = box_estimate(_sighting(_fp((2.1, 0.2), (1.0, 0.6), 0.3, 0.72, 500)))
    assert box.center_m == pytest.approx((2.1, 0.2, 0.36))
    assert box.size_m == pytest.approx((1.0, 0.6, 0.72))
    assert box.yaw_rad == pytest.approx(0.3)


def test_a_thin_footprint_hides_its_depth_behind_what_was_seen():
    """A chair seen from behind shows its back only: the box extends away from the camera to a square."""
    box = box_estimate(_sighting(_fp((2.0, 0.0), (0.46, 0.06), math.pi / 2, 0.9, 300), name="chair"))
    assert box.size_m[:2] == pytest.approx((0.46, 0.46))
    assert box.center_m[:2] == pytest.approx((2.2, 0.0))  # pushed back, away from the camera at x = 0
    assert distance_to_box(box, 1.96, 0.0) == pytest.approx(0.01)  # the seen back stays the near face


def test_without_a_footprint_the_box_faces_the_camera():
    box = box_estimate(_sighting(None))
    assert box.yaw_rad == pytest.approx(0.0)
    assert box.center_m[0] > 2.0  # pushed back from the seen middle of the silhouette


def test_the_viewpoints_past_an_occluder_see_beside_it_along_the_same_sight_line():
    """Layout chair_in_way: a chair 1.9 m ahead hides a box behind it. From each viewpoint (stepped
    aside, left first) the old sight line's parallel passes the chair's rectangle by the margin."""
    chair = box_estimate(_sighting(_fp((1.8, 0.5), (0.46, 0.46), 2.8, 0.9, 300), name="chair"))
    start = np.array([0.0, 0.0])
    views = viewpoints_past(chair, start, 0.5)
    sight = np.array([1.8, 0.5]) / np.hypot(1.8, 0.5)
    assert [v[2] for v in views] == pytest.approx([math.atan2(0.5, 1.8)] * 2)
    left, right = (np.array(v[:2]) for v in views)
    assert np.cross(sight, left) > 0 > np.cross(sight, right)  # left side first
    for view in (left, right):
        assert abs(float(np.dot(view - start, sight))) < 1e-9  # sideways from where it looked
        assert ray_entry(chair, view, sight) == math.inf  # the sight line passes beside the chair
        gap = min(abs(float(np.cross(sight, corner - view))) for corner in chair.footprint.corners())
        assert gap == pytest.approx(0.5)


def test_a_ray_enters_a_yawed_box_at_its_face():
    box = box_estimate(_sighting(_fp((2.0, 0.0), (1.0, 0.6), math.pi / 2, 0.72, 500)))
    # Yawed by 90 deg: 0.6 m deep along x, its near face at x = 1.7.
    assert ray_entry(box, np.array([0.0, 0.0]), np.array([1.0, 0.0])) == pytest.approx(1.7)
    assert ray_entry(box, np.array([2.0, 0.1]), np.array([1.0, 0.0])) == 0.0  # from inside
    assert ray_entry(box, np.array([0.0, 0.0]), np.array([0.0, 1.0])) == math.inf  # misses
    assert ray_entry(box, np.array([0.0, 0.0]), np.array([-1.0, 0.0])) == math.inf  # behind the origin


def _ball(name: str, xyz, seen_m: float = 0.1) -> Sighting:
    return Sighting(
        name=name,
        position_m=np.asarray(xyz, dtype=float),
        size_m=(seen_m, seen_m),
        distance_m=1.0,
        confidence=0.9,
        sim_time_s=0.0,
        camera_m=np.array([2.5, 0.0, 1.4]),
    )


def test_the_balls_seen_beside_one_to_grasp_are_spheres_the_arm_keeps_clear_of():
    memory = Memory()
    for s in (
        _ball("orange_ball", (3.4, 0.8, 0.75)),
        _ball("blue_ball", (3.58, 0.98, 0.75), 0.104),
        _ball("purple_ball", (3.56, 0.64, 0.75), 0.2),  # seen too large: the radius is bounded
        _ball("red_ball", (3.9, 0.8, 0.75)),  # 0.5 m away: not a neighbour
        replace(_sighting(None, name="green_box"), position_m=np.array([3.5, 0.8, 0.4])),  # on the map
    ):
        memory.remember(s)
    spheres = neighbours(memory, np.array([3.4, 0.8, 0.75]), 0.3, {"orange_ball"})
    assert [tuple(c) for c, _ in spheres] == [(3.56, 0.64, 0.75), (3.58, 0.98, 0.75)]  # nearest first
    assert [r for _, r in spheres] == pytest.approx([0.06, 0.052])
    memory.holding["right"] = "blue_ball"  # a held ball is not beside it
    spheres = neighbours(memory, np.array([3.4, 0.8, 0.75]), 0.3, {"orange_ball"})
    assert [tuple(c) for c, _ in spheres] == [(3.56, 0.64, 0.75)]


def test_making_room_steps_away_from_the_object_not_always_straight_back():
    """Straight back from an object ahead; sideways from one beside the robot (fetch seed 18: straight
    back, the left hand beside the chair touched it); straight back from inside one."""
    from supervisor.locomotion import away_from
    from supervisor.scene_map import BoxEstimate

    box = BoxEstimate("chair", (0.0, 0.0, 0.45), (0.45, 0.45, 0.9), 0.0)
    ahead = away_from(box, -0.6, 0.0, 0.0)  # facing +x, the box 0.6 m ahead
    assert ahead == pytest.approx((-1.0, 0.0), abs=0.05)
    beside = away_from(box, 0.0, -0.6, 0.0)  # the box on the robot's left
    assert beside == pytest.approx((0.0, -1.0), abs=0.05)
    turned = away_from(box, 0.0, -0.6, math.pi / 2)  # the same place, facing +y: the box ahead
    assert turned == pytest.approx((-1.0, 0.0), abs=0.05)
    assert away_from(box, 0.05, 0.0, 1.0) == (-1.0, 0.0)  # inside


def test_a_sighting_without_footprint_keeps_the_last_one_where_it_still_fits():
    from dataclasses import replace

    from supervisor.memory import Memory

    memory = Memory()
    table = _fp((2.0, 0.0), (1.0, 0.6), 0.0, 0.72, 500)
    memory.remember(_sighting(table))
    close_up = replace(_sighting(None), position_m=np.array([2.3, 0.2, 0.6]))  # cut by the image border
    memory.remember(close_up)
    assert memory.get("yellow_table").footprint == table
    assert memory.get("yellow_table").position_m[0] == pytest.approx(2.3)  # the rest is the new sighting
    moved = replace(_sighting(None), position_m=np.array([4.0, 1.0, 0.5]))  # seen elsewhere: moved
    memory.remember(moved)
    assert memory.get("yellow_table").footprint is None


def test_a_footprint_more_hidden_than_the_one_it_disagrees_with_does_not_replace_it():
    """At the put's start, from 1 m, the gripper and the ball hid part of the table's outline: the
    rectangle fitted to the rest (1.47 m long, 0.2 m off) replaced the whole-outline one seen from
    1.25 m, and the put missed (fetch seed 0, session 8). A disagreeing footprint is kept only if as
    much of its outline was seen; one that agrees, or was seen better, replaces it."""
    from msgspec import structs

    from supervisor.memory import Memory

    memory = Memory()
    seen = structs.replace(_fp((2.0, 0.0), (1.0, 0.6), 0.0, 0.72, 550), n_hidden=5)
    memory.remember(_sighting(seen))
    partly = structs.replace(_fp((2.2, 0.05), (1.47, 0.6), 0.0, 0.72, 650), n_hidden=130)
    assert memory.remember(_sighting(partly)).footprint == seen
    agreeing = structs.replace(_fp((2.03, 0.0), (1.05, 0.6), 0.0, 0.72, 600), n_hidden=130)
    assert memory.remember(_sighting(agreeing)).footprint == agreeing  # the same table, seen again
    elsewhere = _fp((3.0, 1.0), (1.0, 0.6), 0.0, 0.72, 400)  # moved, seen whole
    assert memory.remember(_sighting(elsewhere)).footprint == elsewhere


def test_a_footprint_proved_wrong_is_not_inherited_again():
    """A put lowered the object inside the table's rectangle onto nothing: the rectangle is dropped, and
    the next sighting without a footprint (close up, cut by the border) maps the table from its own
    silhouette instead of inheriting the wrong rectangle (fetch seed 13)."""
    from dataclasses import replace

    from supervisor.memory import Memory

    memory = Memory()
    wrong = _fp((2.0, 0.0), (1.4, 1.0), 0.0, 0.9, 200)
    memory.remember(_sighting(wrong))
    memory.drop_footprint("yellow_table")
    memory.drop_footprint("chair")  # never seen: nothing to drop
    close_up = replace(_sighting(None), position_m=np.array([2.3, 0.2, 0.6]))
    memory.remember(close_up)
    assert memory.get("yellow_table").footprint is None
    box = box_estimate(memory.get("yellow_table"))
    assert box.size_m[:2] != pytest.approx((1.4, 1.0))


def test_the_approach_turns_clear_of_what_the_hand_felt():
    """Fetch seed 6: the robot 0.6 m behind the ball, the fingers came down on a ball 0.12 m beyond it
    and to the right; the turns about the ball that put it 60 deg off the approach are 45 and 60 deg to
    the left (30 is not enough, and the right brings the approach toward it); none is needed when
    nothing was felt in the way."""
    from supervisor.manipulation import turns_clear_of

    ball = np.array([3.33, 1.12, 0.75])
    robot = (2.72, 1.18)
    felt = [np.array([3.43, 1.07, 0.78])]
    turns = [math.degrees(t) for t in turns_clear_of(ball, robot, felt, 60.0, (30.0, 45.0, 60.0))]
    assert turns == pytest.approx([45.0, 60.0])
    assert turns_clear_of(ball, robot, [np.array([3.0, 1.6, 0.75])], 60.0, (30.0,)) == []


def test_fingers_down_the_jaws_turn_clear_of_what_the_wrist_felt():
    """Fetch seed 37: the wrist touched the ball beside the target at points 80-140 deg to the right
    of the approach (no walk around the ball moves them out of the wrist's way): the fingers-down hand
    is turned by 75 deg, the touched points then near its x axis (beside the plates of its fingers,
    not between its jaws); nothing felt off the x axis: no turn."""
    from supervisor.manipulation import jaws_clear_of

    ball = np.array([3.635, 0.525, 0.75])
    felt = [
        ball + 0.06 * np.array([math.cos(a), math.sin(a), 0.0]) for a in np.radians([-80.0, -100.0, -140.0])
    ]
    turns = (15.0, 30.0, 45.0, 60.0, 75.0, 90.0)
    yaw = jaws_clear_of(ball, felt, 0.0, turns)
    assert math.degrees(yaw) == pytest.approx(75.0)  # the x axis line at -105 deg: 25, 5, 35 deg off
    assert jaws_clear_of(ball, [ball + np.array([0.1, 0.0, 0.0])], 0.0, turns) == pytest.approx(0.0)


def test_a_lowered_ball_touching_only_an_edge_is_moved_toward_it():
    """Fetch seed 5: the ball held 5 cm beyond the table's edge touched it on its side (70 deg off
    straight below its centre): the top lies toward the contact; a contact under the ball is a ball
    standing on the top (also with another contact on an edge beside it); no contact, no edge."""
    from supervisor.put import toward_edge

    centre = np.array([2.48, -2.28, 0.737])
    edge = np.array([2.467, -2.235, 0.72])  # 4.7 cm across, 1.7 cm below
    inward = toward_edge(centre, [edge], 45.0)
    assert inward is not None
    assert inward == pytest.approx((edge[:2] - centre[:2]) / np.linalg.norm(edge[:2] - centre[:2]))
    under = np.array([2.485, -2.28, 0.687])
    assert toward_edge(centre, [under], 45.0) is None
    assert toward_edge(centre, [edge, under], 45.0) is None
    assert toward_edge(centre, [], 45.0) is None


def test_a_lowering_stopped_by_the_wrist_alone_is_a_collision_not_a_put():
    """Fetch seed 52: the wrist (RARM_LINK5) came onto the table's edge with the ball 5 cm above the top
    and just inside it; released, the ball rolled off. Only a contact of the held object says it stands
    on the place."""
    from services.bus.schemas.sim import Contact
    from supervisor.put import arm_only

    wrist = Contact(
        robot_link="RARM_LINK5", other="yellow_table", position=[2.41, -2.44, 0.72], normal_force_n=5.0
    )
    ball = Contact(
        robot_link="held:orange_ball", other="yellow_table", position=[2.38, -2.50, 0.72], normal_force_n=5.0
    )
    assert arm_only([wrist], "orange_ball")
    assert not arm_only([ball], "orange_ball")
    assert not arm_only([wrist, ball], "orange_ball")
    assert not arm_only([], "orange_ball")


def test_requests_in_a_recorded_log_are_counted_per_window(tmp_path):
    """scripts/bench fetch counts footsteps/plan calls in the recorder's MCAP log, per fetch window:
    requests only (not replies, not other endpoints), by log time, also in a log still being written."""
    from services.bus.codec import encode
    from services.bus.mcaplog import LogWriter
    from services.bus.schemas import footsteps as fs_msg
    from supervisor.evaluate import requests_in_log

    path = tmp_path / "log.mcap"
    writer = LogWriter(path, chunk_size_bytes=1)
    request = encode(fs_msg.PlanRequest(tasks=[fs_msg.Task(kind="posture")]))
    for t_ns, key in [
        (100, "hrp/hrp2/footsteps/plan/request"),
        (150, "hrp/hrp2/footsteps/plan/reply"),
        (200, "hrp/hrp2/footsteps/plan/request"),
        (250, "hrp/hrp2/footsteps/heartbeat"),
        (900, "hrp/hrp2/footsteps/plan/request"),
    ]:
        writer.write(key, request, t_ns)
    assert requests_in_log(path, fs_msg.PLAN, [(0, 300), (300, 800), (800, 1000)]) == [2, 0, 1]  # open
    writer.close()
    assert requests_in_log(path, fs_msg.PLAN, [(0, 1000)]) == [3]


def test_a_release_point_beside_a_ball_or_behind_one_on_the_forearms_way_is_not_clear():
    """Layout table_to_box: the ball put on the box beside two others; the forearm (coming down from
    the robot's side) touched the one 10 cm from the release point."""
    from supervisor.put import clear_of

    robot = np.array([3.54, 0.14])
    balls = [np.array([3.58, 0.98]), np.array([3.58, 0.62])]
    assert not clear_of(np.array([3.50, 0.72]), robot, balls, 0.15, 0.2)  # 0.13 m from one
    assert not clear_of(np.array([3.58, 0.78]), robot, balls, 0.15, 0.2)  # that one on the forearm's way
    assert clear_of(np.array([3.36, 0.80]), robot, balls, 0.15, 0.2)


def test_only_the_balls_on_the_place_move_the_release_point():
    """A ball on the table 8 cm from the release point moves it; the same ball on the floor in front of
    the table (under the forearm's way, but not on the place) does not."""
    from supervisor.config import SupervisorConfig
    from supervisor.memory import Memory, Sighting
    from supervisor.put import PutActions
    from supervisor.scene_map import BoxEstimate

    table = BoxEstimate("yellow_table", (2.4, -1.8, 0.36), (1.0, 0.6, 0.72), 0.0)
    point, robot = np.array([2.05, -1.8]), np.array([1.4, -1.8])

    def released_with(ball_at) -> np.ndarray:
        actions = PutActions()
        actions.memory, actions.config, actions.progress = Memory(), SupervisorConfig(), lambda _: None
        actions.memory.remember(
            Sighting("blue_ball", np.asarray(ball_at, float), (0.1, 0.1), 1.0, 0.9, 1.0, np.zeros(3))
        )
        return actions._clear_of_balls(point, table, "yellow_table", robot)

    moved = released_with([2.05, -1.72, 0.77])  # on the top (bottom at 0.72 m)
    assert np.linalg.norm(moved - point) > 0.05
    assert np.allclose(released_with([1.95, -1.75, 0.05]), point)  # on the floor in front of the table
