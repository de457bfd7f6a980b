"""The ``perception`` service: learned objects localized by a head stereo pair (vision/ on the bus).

Run: ``python -m services.perception.service [--models-dir DIR] [--method centroid|bm|sgbm]`` (plus the
common service options: ``--config``, ``--robot``, ``--hub``, ``--log-level``); the same options can be
given in the ``perception:`` section of the config file (:class:`PerceptionConfig`).

Endpoints (services/bus/schemas/perception.py; README.md has the details and failure codes):

* ``perception/locate``: object name + robot configuration -> world position, size, confidence, pixel
  boxes. The images come with the request or from ``sim/render``; the camera pose always comes from the
  robot's kinematics at ``q`` (never from the simulator's ground truth).
* ``perception/models``: the objects it knows.
* ``perception/look_around``: the head joints and the views to visit to look all around for an object
  (the plan of services/perception/look_around.py for the request's robot model).

Stateless: models are loaded once at start-up (restart to pick up newly learned ones). Looking around
for an object that is not in view is the supervisor's job (services/perception/look_around.py).
``perception/locate``'s ``time_budget_s`` bounds the whole request (the sim's state and render get what
is left of it): past it the reply is ``timeout`` with ``details.stage``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from services import budget
from services.bus.schemas import perception as msg
from services.bus.schemas import sim
from services.bus.service import Service, config_with, handles, run_service
from services.errors import InvalidRequestError, NotFoundError
from services.model import RobotModel, load_robot
from services.perception.config import PerceptionConfig
from services.perception.locate import (
    HeadStereo,
    default_localize_config,
    head_stereo,
    localize_config,
    locate_with_others,
    object_model,
    stereo_pair,
)
from services.perception.look_around import head_joints, scan_angles, turn_offsets
from services.perception.own_body import OwnBody
from vision.footprint import Footprint
from vision.histogram import DEFAULT_MODELS_DIR, load_models
from vision.localize import LocalizeConfig, ObjectLocation
from vision.stereo import METHODS


def rgb_to_bgr(image: Any, what: str) -> np.ndarray:
    """A (H, W, 3) uint8 RGB array as BGR (OpenCV order); InvalidRequestError naming ``what`` otherwise."""
    if not isinstance(image, np.ndarray) or image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise InvalidRequestError(
            f"{what} must be an (H, W, 3) uint8 RGB image, got "
            f"{getattr(image, 'shape', type(image).__name__)} {getattr(image, 'dtype', '')}".rstrip(),
            {"field": what},
        )
    return cv2.cvtColor(image, cv2.COLOR_RGB2BGR)


def _box(box: tuple[tuple[float, float], tuple[float, float], float]) -> msg.PixelBox:
    """A vision RotatedBox (pixel centres at integers) as a PixelBox (pixel centres at +0.5)."""
    (u, v), (w, h), angle = box
    return msg.PixelBox(u_px=u + 0.5, v_px=v + 0.5, width_px=w, height_px=h, angle_deg=angle)


def seen_object(loc: ObjectLocation) -> msg.SeenObject:
    """An object seen in passing, for the bus."""
    return msg.SeenObject(
        object=loc.name,
        position=list(loc.position_world),
        distance_m=float(np.linalg.norm(loc.position_camera)),
        size_m=list(loc.size_m),
        confidence=loc.confidence,
        method=loc.method,
        box_left=_box(loc.left.box),
    )


def to_reply(
    loc: ObjectLocation,
    head: HeadStereo,
    rendered: bool,
    sim_time_s: float,
    others: list[ObjectLocation] | None = None,
) -> msg.LocateReply:
    """The bus reply of a localization (``others``: the other objects seen in the same images)."""
    return msg.LocateReply(
        object=loc.name,
        position=list(loc.position_world),
        position_camera=list(loc.position_camera),
        distance_m=float(np.linalg.norm(loc.position_camera)),
        size_m=list(loc.size_m),
        confidence=loc.confidence,
        method=loc.method,
        disparity_px=loc.disparity_px,
        box_left=_box(loc.left.box),
        box_right=_box(loc.right.box),
        window_left=[int(v) for v in loc.left.window],
        camera=head.name,
        T_world_camera=head.T_world_left_camera.tolist(),
        rendered=rendered,
        sim_time_s=sim_time_s,
        footprint=None if loc.footprint is None else _footprint(loc.footprint),
        others=[seen_object(o) for o in others or []],
    )


def _footprint(fp: Footprint) -> msg.FootprintMsg:
    return msg.FootprintMsg(
        center=list(fp.center_m),
        size=list(fp.size_m),
        yaw=fp.yaw_rad,
        top_z=fp.top_z_m,
        n_points=fp.n_points,
        n_hidden=fp.n_hidden,
    )


class PerceptionService(Service):
    """Object localization: Hue-Saturation histograms, back projection, CamShift and stereo (vision/)."""

    name = "perception"
    Config = PerceptionConfig

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--models-dir", help=f"object models directory (default {DEFAULT_MODELS_DIR})")
        parser.add_argument("--method", choices=METHODS, help="default stereo estimator (default centroid)")

    @classmethod
    def configure(cls, config: PerceptionConfig, args: argparse.Namespace) -> PerceptionConfig:
        changes: dict[str, Any] = {}
        if args.models_dir:
            changes["models_dir"] = args.models_dir
        if args.method:
            changes["stereo_method"] = args.method
        config = config_with(config, **changes)
        load_robot(config.robot_model)  # fail at start-up with a message, not in the first request
        return config

    def start(self) -> None:
        cfg: PerceptionConfig = self.config
        self.models_dir = Path(cfg.models_dir) if cfg.models_dir else DEFAULT_MODELS_DIR
        self.models = load_models(self.models_dir)
        self.localize_config = default_localize_config(cfg.stereo_method, cfg.max_depth_m)
        self._own_bodies: dict[str, OwnBody] = {}  # robot model name -> its visual shapes
        if self.models:
            self.log.info("models from %s: %s", self.models_dir, ", ".join(sorted(self.models)))
        else:
            self.log.warning(
                "no object models in %s: learn them with `humanoid perception learn-sim`", self.models_dir
            )

    # ------------------------------------------------------------------------------ endpoints
    @handles(msg.MODELS, blocking=False)
    def list_models(self, request: msg.ModelsRequest) -> msg.ModelsReply:
        names = sorted(self.models)
        return msg.ModelsReply(
            names=names,
            objects=[
                msg.ObjectModelInfo(
                    name=n,
                    shape=self.models[n].shape,
                    n_pixels=self.models[n].n_pixels,
                    source=self.models[n].source,
                )
                for n in names
            ],
            models_dir=str(self.models_dir),
        )

    @handles(msg.LOOK_AROUND)
    def look_around(self, request: msg.LookAroundRequest) -> msg.LookAroundReply:
        robot = load_robot(request.model or self.config.robot_model)
        head = head_joints(robot, request.camera)
        left = robot.cameras[stereo_pair(robot, request.camera).left]
        return msg.LookAroundReply(
            head_pan_joint=head.pan,
            head_tilt_joint=head.tilt,
            pan_limits_rad=list(head.pan_limits),
            tilt_limits_rad=list(head.tilt_limits),
            tilt_sign=head.tilt_sign,
            views=[[pan, tilt] for pan, tilt in scan_angles(robot, request.camera)],
            turns_rad=turn_offsets(robot, request.camera),
            image_size_px=[left.width_px, left.height_px],
        )

    @handles(msg.LOCATE)
    def locate(self, request: msg.LocateRequest) -> msg.LocateReply:
        cfg: PerceptionConfig = self.config
        object_model(self.models, request.object)  # an unknown name fails before anything is rendered
        config = localize_config(self.localize_config, request.method)
        with budget.within(request.time_budget_s or cfg.time_budget_s):
            return self._locate(request, config)

    def _locate(self, request: msg.LocateRequest, config: LocalizeConfig) -> msg.LocateReply:
        """perception/locate within the budget opened by :meth:`locate`."""
        cfg: PerceptionConfig = self.config
        robot, q = self._robot_and_q(request)
        if request.images is not None:
            left = rgb_to_bgr(request.images.left_rgb, "images.left_rgb")
            right = rgb_to_bgr(request.images.right_rgb, "images.right_rgb")
            if left.shape != right.shape:
                raise InvalidRequestError(
                    f"images.left_rgb is {left.shape[1]}x{left.shape[0]} px but images.right_rgb is "
                    f"{right.shape[1]}x{right.shape[0]} px; a stereo pair has two images of one size",
                    {"field": "images"},
                )
            height, width = left.shape[:2]
            head = head_stereo(robot, q, request.camera, width, height, request.images.K)
            rendered, sim_time_s = False, 0.0
        else:
            stereo_pair(robot, request.camera)  # an unknown pair is this request's fault, not the sim's
            budget.check("the render of the stereo pair (sim/render)")
            wait_s = budget.remaining(cfg.render_timeout_s)
            render = self.client.call(
                sim.RENDER,
                sim.RenderRequest(
                    camera=request.camera,
                    width_px=request.width_px,
                    height_px=request.height_px,
                    time_budget_s=wait_s,  # the sim gives up when this call does (no draw left running)
                ),
                timeout_s=wait_s,
            )
            image_left, image_right = render.images
            left = cv2.cvtColor(image_left.rgb, cv2.COLOR_RGB2BGR)
            right = cv2.cvtColor(image_right.rgb, cv2.COLOR_RGB2BGR)
            head = head_stereo(robot, q, request.camera, image_left.width_px, image_left.height_px)
            self._check_render_pose(head, np.asarray(image_left.T_world_camera, dtype=float))
            rendered, sim_time_s = True, render.sim_time_s
        budget.check("the stereo localization", {"rendered": rendered})
        try:
            own = self._own_body(robot)
            loc, others = locate_with_others(
                self.models, request.object, head, left, right, config, own, q, request.others
            )
        except NotFoundError as e:
            details = {**e.details, "object": request.object, "camera": request.camera}
            raise NotFoundError(
                f"{request.object} in the {request.camera} stereo pair: {e.message}", details
            ) from e
        return to_reply(loc, head, rendered, sim_time_s, others)

    # ------------------------------------------------------------------------------ helpers
    def _own_body(self, robot: RobotModel) -> OwnBody:
        """The robot's visual shapes (built once per robot model): its own pixels in the images."""
        own = self._own_bodies.get(robot.name)
        if own is None:
            own = self._own_bodies[robot.name] = OwnBody(robot)
        return own

    def _robot_and_q(self, request: msg.LocateRequest) -> tuple[RobotModel, np.ndarray]:
        """The robot model and configuration of the request; q = the sim's current state when omitted."""
        if request.q is not None:
            return load_robot(request.model or self.config.robot_model), np.asarray(request.q, dtype=float)
        state = self.client.call(
            sim.STATE, sim.StateRequest(), timeout_s=budget.remaining(self.config.render_timeout_s)
        )
        if request.model and request.model != state.model:
            raise InvalidRequestError(
                f"model {request.model!r} was asked without q, but the sim runs {state.model!r}: "
                "give q for that model, or leave model empty",
                {"field": "model"},
            )
        return load_robot(state.model), np.asarray(state.q, dtype=float)

    def _check_render_pose(self, head: HeadStereo, T_world_rendered: np.ndarray) -> None:
        """Warn when the sim rendered from elsewhere than q says (the caller's q is stale)."""
        gap = float(np.linalg.norm(T_world_rendered[:3, 3] - head.T_world_left_camera[:3, 3]))
        if gap > self.config.check_render_pose_m:
            self.log.warning(
                "the images were rendered %.3f m away from the camera pose of the request's q: "
                "pass the robot's current q (sim/state), or positions will be off by about as much",
                gap,
            )


if __name__ == "__main__":
    raise SystemExit(run_service(PerceptionService))
