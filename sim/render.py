"""Images of the world with pybullet's software renderer (ER_TINY_RENDERER: no GPU, no display).

Head cameras render with the robot's own intrinsics (scaled to the requested size); snapshots for people
come from named external viewpoints around the robot and the scene.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import TYPE_CHECKING

import cv2
import numpy as np
import pybullet as p

from services import budget
from services.bus.limits import MAX_IMAGE_PX
from services.errors import InvalidRequestError
from services.model.specs import CameraSpec, Intrinsics
from sim.cameras import linear_depth, look_at, projection_matrix, view_matrix
from sim.results import CameraImage

if TYPE_CHECKING:
    from sim.world import World

# Soft, mostly ambient light keeps object colours saturated (perception learns hue-saturation).
_LIGHT = {
    "lightDirection": [0.4, 0.3, 1.0],
    "lightColor": [1.0, 1.0, 1.0],
    "lightAmbientCoeff": 0.6,
    "lightDiffuseCoeff": 0.45,
    "lightSpecularCoeff": 0.05,
    "shadow": 0,
}
# TinyRenderer samples the pixel in row i, column j at u = j, v = i + 1 of the pinhole model; the
# camera convention (sim/cameras.py) puts that pixel's centre at (j + 0.5, i + 0.5). Shifting the
# principal point given to the renderer by this much makes the images follow the convention
# (measured: sphere centroids in rendered masks against projected centres, tests/test_sim.py).
_RENDER_PRINCIPAL_SHIFT_PX = (-0.5, 0.5)
VIEWPOINTS = ("overview", "front", "side", "back", "top")
_SNAPSHOT_HFOV_DEG = 60.0


def check_size(width_px: int, height_px: int) -> None:
    if not (0 < width_px <= MAX_IMAGE_PX and 0 < height_px <= MAX_IMAGE_PX):
        raise InvalidRequestError(
            f"image size {width_px}x{height_px} px is outside 1..{MAX_IMAGE_PX} px per side"
        )


class DrawCost:
    """The wall time of a TinyRenderer draw, estimated from the draws of this process: a draw is one
    pybullet call that cannot be stopped, so a request with a time budget (:mod:`services.budget`) is
    refused *before* a draw that would end past it (issue 16: the sim never keeps rendering for a
    caller that stopped waiting).

    The estimate is pixels x the largest wall time per pixel of the last ``window`` draws of at least
    ``min_pixels`` (smaller draws are dominated by their fixed cost), or ``prior_s_per_px`` before any.
    """

    def __init__(self, prior_s_per_px: float, min_pixels: int = 300_000, window: int = 8) -> None:
        self.min_pixels = min_pixels
        self._rates: deque[float] = deque([prior_s_per_px], maxlen=window)
        self._lock = threading.Lock()

    def estimate_s(self, pixels: int) -> float:
        """Estimated wall time [s] of a draw of ``pixels`` pixels."""
        with self._lock:
            return pixels * max(self._rates)

    def record(self, pixels: int, seconds: float) -> None:
        """A draw of ``pixels`` pixels took ``seconds`` [s] of wall time."""
        if pixels >= self.min_pixels:
            with self._lock:
                self._rates.append(seconds / pixels)


#: TinyRenderer's cost per pixel before any draw was timed [s/px]: measured 0.18-0.36 us/px on a quiet
#: 2-core machine (640 x 480 to 2048 x 2048 head cameras, with and without depth and segmentation).
PRIOR_S_PER_PX = 4.0e-7
DRAW_COST = DrawCost(PRIOR_S_PER_PX)


def _draw(
    world: World, intr: Intrinsics, T_world_camera: np.ndarray, *, want_depth: bool, want_segmentation: bool
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """One TinyRenderer draw: RGB (H, W, 3) uint8, and depth [m] and segmentation if asked. Refused
    with RequestTimeoutError before it starts when it would end past the request's budget."""
    cfg = world.config
    pixels = intr.width_px * intr.height_px
    budget.check_fits(
        DRAW_COST.estimate_s(pixels), f"the render of a {intr.width_px} x {intr.height_px} px image"
    )
    started = time.perf_counter()
    flags = 0 if want_segmentation else p.ER_NO_SEGMENTATION_MASK
    du, dv = _RENDER_PRINCIPAL_SHIFT_PX
    drawn = Intrinsics(intr.width_px, intr.height_px, intr.fx, intr.fy, intr.cx + du, intr.cy + dv)
    _, _, rgba, depth_buffer, seg = p.getCameraImage(
        intr.width_px,
        intr.height_px,
        viewMatrix=view_matrix(T_world_camera),
        projectionMatrix=projection_matrix(drawn, cfg.render_near_m, cfg.render_far_m),
        renderer=p.ER_TINY_RENDERER,
        flags=flags,
        physicsClientId=world.client,
        **_LIGHT,
    )
    rgb = np.ascontiguousarray(np.reshape(rgba, (intr.height_px, intr.width_px, 4))[:, :, :3], dtype=np.uint8)
    depth = None
    if want_depth:
        depth = linear_depth(
            np.reshape(depth_buffer, (intr.height_px, intr.width_px)), cfg.render_near_m, cfg.render_far_m
        )
    mask = np.reshape(seg, (intr.height_px, intr.width_px)).astype(np.int32) if want_segmentation else None
    DRAW_COST.record(pixels, time.perf_counter() - started)
    return rgb, depth, mask


def render_camera(
    world: World,
    name: str,
    spec: CameraSpec,
    T_world_camera: np.ndarray,
    width_px: int,
    height_px: int,
    *,
    depth: bool = False,
    segmentation: bool = False,
) -> CameraImage:
    """Render one head camera at ``width_px`` x ``height_px`` (same field of view as ``spec``)."""
    check_size(width_px, height_px)
    intr = spec.scaled(width_px, height_px)
    rgb, depth_m, mask = _draw(world, intr, T_world_camera, want_depth=depth, want_segmentation=segmentation)
    labels = {}
    if segmentation:
        labels = {world.robot_id: "robot", world.floor_id: "floor", **world.body_names}
    return CameraImage(name, intr, T_world_camera, rgb, depth_m, mask, labels)


def viewpoint_pose(
    world: World,
    viewpoint: str,
    eye: tuple[float, float, float] | None = None,
    target: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """World pose (4x4) of the optical frame of a snapshot camera.

    ``overview``: high, behind and to the right of the robot, looking at the middle of robot and scene;
    ``front``/``side``/``back``: 3 m from the robot at chest height; ``top``: 8 m above the scene centre;
    ``eye`` and ``target`` [m] (both given) override the viewpoint.
    """
    if eye is not None or target is not None:
        if eye is None or target is None:
            raise InvalidRequestError("a custom snapshot viewpoint needs both eye and target [m]")
        return look_at(np.array(eye), np.array(target))
    T_base = world.base_pose()
    base = T_base.translation
    yaw = math.atan2(T_base.rotation[1, 0], T_base.rotation[0, 0])
    forward = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    left = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    chest = np.array([base[0], base[1], 0.9])
    points = [base[:2]] + [np.array(o.position[:2]) for o in world.layout.objects]
    centre_xy = np.mean(points, axis=0)
    extent = max(1.5, max(float(np.linalg.norm(pt - centre_xy)) for pt in points))
    if viewpoint == "overview":  # from behind-right and above, far enough for robot + objects to fit
        target_pt = np.array([centre_xy[0], centre_xy[1], 0.3])
        heading = forward + 0.6 * left
        heading /= np.linalg.norm(heading)
        distance = 1.25 * extent / math.tan(math.radians(_SNAPSHOT_HFOV_DEG) / 2.0)
        elevation = math.radians(40.0)
        offset = distance * (-math.cos(elevation) * heading + np.array([0.0, 0.0, math.sin(elevation)]))
        return look_at(target_pt + offset, target_pt)
    if viewpoint == "front":
        return look_at(chest + 3.0 * forward + np.array([0.0, 0.0, 0.3]), chest)
    if viewpoint == "back":
        return look_at(chest - 3.0 * forward + np.array([0.0, 0.0, 0.5]), chest + forward)
    if viewpoint == "side":
        return look_at(chest + 3.0 * left + np.array([0.0, 0.0, 0.2]), chest)
    if viewpoint == "top":
        return look_at(
            np.array([centre_xy[0], centre_xy[1], 2.5 + 2.0 * extent]),
            np.array([centre_xy[0], centre_xy[1], 0.0]),
            up=forward,
        )
    raise InvalidRequestError(f"unknown viewpoint {viewpoint!r}; valid viewpoints: {list(VIEWPOINTS)}")


def snapshot_png(
    world: World,
    viewpoint: str,
    width_px: int,
    height_px: int,
    eye: tuple[float, float, float] | None = None,
    target: tuple[float, float, float] | None = None,
) -> bytes:
    """A PNG image of the world from ``viewpoint`` (see :func:`viewpoint_pose`)."""
    check_size(width_px, height_px)
    f = (width_px / 2.0) / math.tan(math.radians(_SNAPSHOT_HFOV_DEG) / 2.0)
    intr = Intrinsics(width_px, height_px, f, f, width_px / 2.0, height_px / 2.0)
    rgb, _, _ = _draw(
        world, intr, viewpoint_pose(world, viewpoint, eye, target), want_depth=False, want_segmentation=False
    )
    ok, png = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return png.tobytes()
