"""From a robot configuration and a head stereo pair to a localized object (no bus).

The glue between the robot model (services.model: camera poses from the kinematics, intrinsics and
baselines of its stereo pairs) and vision.localize. The camera pose always comes from the robot's
kinematics at the given configuration (the robot knows where its head is); never from the simulator's
ground truth. The service (service.py) only adds the bus: images from ``sim/render`` or the request.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from services import budget
from services.errors import InvalidRequestError, NotFoundError
from services.model import RobotModel
from services.model.specs import StereoPair
from services.perception.own_body import OwnBody
from vision.camera import CameraIntrinsics, StereoRig
from vision.histogram import ObjectModel, select_models
from vision.localize import LocalizeConfig, ObjectLocation, StereoFrame, locate_in_frame, others_in_frame
from vision.stereo import METHODS, StereoConfig


@dataclass(frozen=True)
class HeadStereo:
    """A head stereo pair at a configuration: the rectified rig and the left optical frame's world pose.

    pair: names of the two cameras and the baseline; rig: intrinsics in vision's pixel convention (pixel
    centres at integer coordinates) and baseline [m]; T_world_left_camera: 4x4 pose [m].
    """

    name: str
    pair: StereoPair
    rig: StereoRig
    T_world_left_camera: np.ndarray = field(repr=False)


def stereo_pair(robot: RobotModel, camera: str) -> StereoPair:
    """The robot's stereo pair ``camera`` ("wide", "narrow"); InvalidRequestError listing the valid ones."""
    if camera not in robot.stereo_pairs:
        raise InvalidRequestError(
            f"{robot.name} has no stereo pair {camera!r}; stereo pairs are {sorted(robot.stereo_pairs)}",
            {"field": "camera", "valid": sorted(robot.stereo_pairs)},
        )
    return robot.stereo_pairs[camera]


def head_stereo(
    robot: RobotModel,
    q: np.ndarray,
    camera: str,
    width_px: int,
    height_px: int,
    K: np.ndarray | None = None,
) -> HeadStereo:
    """The stereo pair ``camera`` of ``robot`` at configuration ``q`` for images of the given size.

    K: 3x3 matrix [px] of both cameras (pixel (i, j) centred at (j + 0.5, i + 0.5)); None: the robot
    model's left camera scaled to ``width_px`` x ``height_px``.
    """
    pair = stereo_pair(robot, camera)
    q = robot.check_q(np.asarray(q, dtype=float))
    if K is None:
        K = robot.cameras[pair.left].scaled(int(width_px), int(height_px)).K
    intrinsics = CameraIntrinsics.from_matrix(K, width_px, height_px)
    T_world_left = robot.camera_pose(q, pair.left, robot.new_data()).homogeneous.copy()  # thread-safe
    return HeadStereo(camera, pair, StereoRig(intrinsics, pair.baseline_m), T_world_left)


def localize_config(base: LocalizeConfig, method: str = "") -> LocalizeConfig:
    """``base`` with the stereo estimator ``method`` ("" keeps the base's); InvalidRequestError if unknown."""
    if not method:
        return base
    if method not in METHODS:
        raise InvalidRequestError(
            f"stereo method {method!r} is not one of {list(METHODS)}",
            {"field": "method", "valid": list(METHODS)},
        )
    return replace(base, stereo=replace(base.stereo, method=method))


def object_model(models: dict[str, ObjectModel], name: str) -> ObjectModel:
    """The model of object ``name``; InvalidRequestError listing the known names (or saying how to learn
    models when there are none)."""
    if not models:
        raise InvalidRequestError(
            "no object models are loaded: learn them with `humanoid perception learn-sim` "
            "(writes vision/models/<name>.json) and restart the perception service",
            {"field": "object", "valid": []},
        )
    return select_models(models, [name])[0]


def locate_object(
    models: dict[str, ObjectModel],
    name: str,
    head: HeadStereo,
    left_bgr: np.ndarray,
    right_bgr: np.ndarray,
    config: LocalizeConfig | None = None,
    own_body: OwnBody | None = None,
    q: np.ndarray | None = None,
) -> ObjectLocation:
    """Localize object ``name`` in a head stereo pair (BGR uint8 images) taken at configuration ``q``;
    ``own_body``: the robot's links, whose pixels (drawn at ``q``) hide what is behind them
    (services/perception/own_body.py; None, or ``q`` None: not drawn).

    InvalidRequestError for an unknown name (listing the known ones) or images not matching the rig;
    NotFoundError with ``details["reason"]`` (not_in_view, ambiguous, not_in_right_view, no_disparity,
    stereo_mismatch) when it is not found.
    """
    return locate_with_others(models, name, head, left_bgr, right_bgr, config, own_body, q, others=False)[0]


def locate_with_others(
    models: dict[str, ObjectModel],
    name: str,
    head: HeadStereo,
    left_bgr: np.ndarray,
    right_bgr: np.ndarray,
    config: LocalizeConfig | None = None,
    own_body: OwnBody | None = None,
    q: np.ndarray | None = None,
    others: bool = True,
) -> tuple[ObjectLocation, list[ObjectLocation]]:
    """:func:`locate_object`, and with ``others`` every other known object seen in the same pair
    (vision.localize.others_in_frame: no footprints; [] without ``others``). The own-body masks are
    drawn only when used (a footprint's outline, a ball partly hidden by the robot's hand)."""
    model = object_model(models, name)
    occluders = [m for other, m in models.items() if other != name]  # what may hide parts of it
    config = config or LocalizeConfig()
    masks = None
    if own_body is not None and q is not None:

        def masks() -> tuple[np.ndarray, np.ndarray]:
            rig = head.rig
            return own_body.stereo_masks(q, rig.intrinsics, head.T_world_left_camera, rig.baseline_m)

    frame = StereoFrame(left_bgr, right_bgr, head.rig, head.T_world_left_camera, masks)
    budget.check(f"the localization of {name}")
    try:
        found = locate_in_frame(model, frame, config, occluders)
    except NotFoundError as e:
        e.details.setdefault("object", name)
        raise
    seen = others_in_frame(found, list(models.values()), frame, config) if others else []
    return found, seen


def default_localize_config(method: str = "centroid", max_depth_m: float = 8.0) -> LocalizeConfig:
    """The service's localization parameters: vision defaults with the given estimator and depth range."""
    return LocalizeConfig(stereo=StereoConfig(method=method, max_depth_m=max_depth_m))
