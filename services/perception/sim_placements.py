"""Seeded placements of the orange ball in front of the robot's head stereo pair, rendered by the sim.

For the perception benchmark (scripts/bench.d/perception.py) and tests: the robot stands in a small
scene (the ball, static, plus the green box and the yellow table in the background); for each sample
the head gets a random pan/tilt, the ball is put at the nominal distance from the middle of the stereo
pair in a random direction inside the central part of the field of view (above the floor), and the pair
is rendered with pybullet exactly as ``sim/render`` does. Each sample carries the camera pose computed
from the robot's kinematics at its measured configuration (what ``perception/locate`` uses) and the
ball's ground-truth centre (to score the localization; never given to perception).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from typing import NamedTuple

import cv2
import numpy as np

from services.perception.locate import head_stereo
from services.perception.look_around import head_joints
from vision.camera import CameraIntrinsics

BALL = "orange_ball"
BALL_RADIUS_M = 0.05
#: The benchmark scene (sim.scene format): a static ball (moved to every placement), distractors far away.
SCENE = {
    "name": "perception_bench",
    "description": "the orange ball (static, moved to each placement), the green box and yellow table behind",
    "robot": {"x": 0.0, "y": 0.0, "yaw": 0.0},
    "floor": {"colour": "light_grey", "friction": 1.0},
    "objects": [
        {
            "name": BALL,
            "kind": "ball",
            "radius": BALL_RADIUS_M,
            "colour": "orange",
            "mass": 0.0,
            "xy": [1.5, 0.0],
        },
        {"name": "green_box", "kind": "box", "size": [0.5, 0.6, 0.7], "colour": "green", "xy": [4.5, 1.2]},
        {
            "name": "yellow_table",
            "kind": "table",
            "size": [1.0, 0.6, 0.72],
            "colour": "yellow",
            "xy": [4.0, -2.0],
            "yaw": 0.3,
        },
    ],
}


class StereoSample(NamedTuple):
    """One rectified stereo pair with ground truth: images BGR uint8, intrinsics (vision convention),
    baseline [m], the left camera pose in the world (4x4, optical frame), the ball centre in the world
    [m], nominal distance [m]."""

    left_bgr: np.ndarray
    right_bgr: np.ndarray
    intrinsics: CameraIntrinsics
    baseline_m: float
    T_world_left_camera: np.ndarray
    ball_world: np.ndarray
    distance_m: float


def sim_source(
    n_per_distance: int = 30,
    distances_m: Iterable[float] = (1.0, 1.5, 2.5),
    seed: int = 0,
    robot: str = "hrp2_like",
    camera: str = "wide",
    width_px: int = 640,
    height_px: int = 480,
    pan_range_rad: float = 0.6,
    tilt_down_range_rad: tuple[float, float] = (0.0, 0.6),
    bearing_range_rad: tuple[float, float] = (0.35, 0.25),
) -> Iterator[StereoSample]:
    """Seeded sim-rendered stereo pairs of the ball at each distance (see the module doc).

    pan_range_rad: head pan drawn in [-range, range]; tilt_down_range_rad: gaze depression drawn in this
    range [rad]; bearing_range_rad: (horizontal, vertical) half-ranges of the ball's direction from the
    optical axis [rad]. Distances are from the middle of the pair to the ball's centre [m].
    """
    from sim.scene import parse_scene
    from sim.world import World

    with World(robot, parse_scene(SCENE, "perception_bench")) as world:
        model = world.robot
        head = head_joints(model, camera)
        ip, it = model.joint_index(head.pan).idx_q, model.joint_index(head.tilt).idx_q
        q_stand = world.state().q.copy()
        for distance in distances_m:
            rng = np.random.default_rng([seed, round(distance * 1000)])
            for _ in range(n_per_distance):
                while True:
                    q = q_stand.copy()
                    q[ip] = rng.uniform(-pan_range_rad, pan_range_rad)
                    q[it] = float(
                        np.clip(head.tilt_sign * rng.uniform(*tilt_down_range_rad), *head.tilt_limits)
                    )
                    world.pyrobot.reset(q)
                    q_measured = world.state().q
                    stereo = head_stereo(model, q_measured, camera, width_px, height_px)
                    T_left = stereo.T_world_left_camera
                    middle = T_left[:3, 3] + T_left[:3, 0] * (0.5 * stereo.pair.baseline_m)
                    az = rng.uniform(-bearing_range_rad[0], bearing_range_rad[0])
                    el = rng.uniform(-bearing_range_rad[1], bearing_range_rad[1])
                    ray = np.array([math.tan(az), math.tan(el), 1.0])
                    ball = middle + T_left[:3, :3] @ (ray / np.linalg.norm(ray)) * distance
                    if ball[2] > BALL_RADIUS_M + 0.05:  # above the floor, not touching it
                        break
                world.set_object_pose(BALL, ball)
                left, right = world.render(camera, width_px, height_px)
                yield StereoSample(
                    cv2.cvtColor(left.rgb, cv2.COLOR_RGB2BGR),
                    cv2.cvtColor(right.rgb, cv2.COLOR_RGB2BGR),
                    stereo.rig.intrinsics,
                    stereo.rig.baseline_m,
                    T_left,
                    np.asarray(world.ground_truth()[BALL].position, dtype=float),
                    float(distance),
                )
