"""One call from a stereo pair to object positions in the world: detection, matching, stereo.

The pipeline of "Object Recognition and Localization" in Yoshida et al. (``001_771c0ce3779b0683.txt``):
per learned model, back projection of its Hue-Saturation histogram onto both images (vision.backproject),
CamShift from every blob of the back projection (vision.camshift), the left detection matched to a
right one on the same rows (rectified pair), then the 3D position by stereo inside the CamShift window
(vision.stereo) and into the world frame through the left camera's pose (from the robot's kinematics;
the caller computes T_world_left_camera).

Failures raise NotFoundError whose message says why and whose ``details["reason"]`` is one of
``not_in_view``, ``ambiguous``, ``not_in_right_view``, ``no_disparity``, ``stereo_mismatch``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from services import budget
from services.bus.schemas.perception import (
    REASON_AMBIGUOUS,
    REASON_HIDDEN_BY_OWN_BODY,
    REASON_NO_DISPARITY,
    REASON_NOT_IN_RIGHT_VIEW,
    REASON_STEREO_MISMATCH,
)
from services.errors import InvalidRequestError, NotFoundError
from vision.backproject import back_project
from vision.camera import StereoRig
from vision.camshift import Detection, DetectionConfig, RotatedBox, Window, check_unambiguous, detect_all
from vision.footprint import Footprint, footprint, outline_points
from vision.hidden_ball import Circle, free_circle, touches
from vision.histogram import ObjectModel, colour_mask, to_hsv
from vision.parts import PARTS_SLACK_M, joined_through
from vision.stereo import (
    StereoConfig,
    dense_disparity_median,
    dense_point,
    disparity_range,
    edge_disparity_median,
    point_from_pixel_disparity,
    sphere_centre_pixel,
    to_world,
    triangulate_centroids,
)


@dataclass(frozen=True)
class LocalizeConfig:
    """Detection and stereo parameters of :func:`localize`."""

    detection: DetectionConfig = field(default_factory=DetectionConfig)
    stereo: StereoConfig = field(default_factory=StereoConfig)
    max_size_ratio: float = 2.0  # left/right blob sizes of one object differ by less than this factor
    # No footprint nearer than this [m] (depth of the located point): a table 0.8 m away fills the wide
    # pair's view, the robot's own arm and what it holds hide parts of its outline in one image only.
    footprint_min_depth_m: float = 1.0
    # A ball nearer than this [m] is checked against the robot's own body in the images (the own-body
    # masks are drawn for it): the hand backed off a ball after a failed grasp hides part of it
    # (vision.hidden_ball). Farther, the hands are not between the cameras and a ball.
    hidden_ball_max_depth_m: float = 1.5


@dataclass(frozen=True)
class ObjectLocation:
    """A localized object.

    position_world, position_camera: centre [m] in the world frame and in the left optical frame.
    size_m: (width, height) of the CamShift box at the object's depth [m] (a ball: its diameter twice).
    confidence: min of the left and right detection confidences, in [0, 1].
    disparity_px: disparity used [px]; method: "centroid", "bm", "sgbm" or "edges" (see vision.stereo).
    left, right: the detections in each image (pixel boxes, windows, centroids).
    footprint: the floor rectangle of a non-spherical object from its outline's stereo points
      (vision.footprint); None for a ball, for an object cut by the left, right or top border in
      either image (part of its top's outline unseen: the rectangle would be too small) or when too few
      outline points match, or nearer than ``LocalizeConfig.footprint_min_depth_m``. A cut by the
      bottom border (the legs of a table close by, the near bottom corner of a box) leaves the top's
      outline whole: the footprint stays.
    """

    name: str
    position_world: tuple[float, float, float]
    position_camera: tuple[float, float, float]
    size_m: tuple[float, float]
    confidence: float
    disparity_px: float
    method: str
    left: Detection
    right: Detection
    footprint: Footprint | None = None

    @property
    def box_left(self) -> RotatedBox:
        return self.left.box

    @property
    def box_right(self) -> RotatedBox:
        return self.right.box

    @property
    def window_left(self) -> Window:
        return self.left.window


#: The robot's own body in a stereo pair: boolean (H, W) masks of the left and right images, or what
#: draws them when first needed (services/perception/own_body.py: ~20 ms a pair).
OwnBodyMasks = tuple[np.ndarray, np.ndarray] | Callable[[], tuple[np.ndarray, np.ndarray]]


@dataclass
class StereoFrame:
    """A stereo pair with the per-image work shared by every model (HSV, grey, the own-body masks)."""

    left_bgr: np.ndarray
    right_bgr: np.ndarray
    rig: StereoRig
    T_world_left_camera: np.ndarray
    #: Boolean (H, W) masks of the robot's own body in the left and right images, or a function drawing
    #: them, called once when a footprint or a partly hidden ball first needs them (None: not known): it
    #: hides what is behind it like another object (services/perception/own_body.py draws them).
    own_body: OwnBodyMasks | None = None
    hsv_left: np.ndarray = field(init=False)
    hsv_right: np.ndarray = field(init=False)
    _gray: tuple[np.ndarray, np.ndarray] | None = field(init=False, default=None)
    #: back projections by (model name, "left"/"right"): a look that reports every object seen uses
    #: each model's up to three times (detection, another object's outline, one object per region)
    _back_projections: dict[tuple[str, str], np.ndarray] = field(init=False, default_factory=dict)
    _colour_masks: dict[tuple[str, str], np.ndarray] = field(init=False, default_factory=dict)

    def __post_init__(self) -> None:
        k = self.rig.intrinsics
        k.check_image(self.left_bgr, "left image")
        k.check_image(self.right_bgr, "right image")
        T = np.asarray(self.T_world_left_camera, float)
        if T.shape != (4, 4) or not np.allclose(T[3], [0, 0, 0, 1]):
            raise InvalidRequestError(
                f"T_world_left_camera must be a 4x4 homogeneous transform, got {T.shape}"
            )
        self.T_world_left_camera = T
        if self.own_body is not None and not callable(self.own_body):
            self._check_own_body(self.own_body)
        self.hsv_left = to_hsv(self.left_bgr)
        self.hsv_right = to_hsv(self.right_bgr)

    def _check_own_body(self, masks: tuple[np.ndarray, np.ndarray]) -> None:
        shape = self.left_bgr.shape[:2]
        if len(masks) != 2 or any(np.shape(m) != shape for m in masks):
            raise InvalidRequestError(
                f"own_body masks must be two {shape[1]}x{shape[0]} masks like the images, got "
                f"{[np.shape(m) for m in masks]}"
            )

    def back_projection(self, model: ObjectModel, side: str) -> np.ndarray:
        """``model``'s back projection onto the ``side`` ("left" or "right") image (computed once)."""
        key = (model.name, side)
        bp = self._back_projections.get(key)
        if bp is None:
            hsv = self.hsv_left if side == "left" else self.hsv_right
            mask_key = (repr(model.config), side)  # the pixels coloured enough, shared by the models
            coloured = self._colour_masks.get(mask_key)
            if coloured is None:
                coloured = self._colour_masks[mask_key] = colour_mask(hsv, model.config)
            bp = self._back_projections[key] = back_project(hsv, model, coloured)
        return bp

    @property
    def own_masks(self) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
        """The own-body masks of the left and right images ((None, None): not known), drawn at the
        first use when the frame was given a function drawing them."""
        if self.own_body is None:
            return None, None
        if callable(self.own_body):
            masks = self.own_body()
            self._check_own_body(masks)
            self.own_body = (np.asarray(masks[0], dtype=bool), np.asarray(masks[1], dtype=bool))
        return self.own_body

    @property
    def gray(self) -> tuple[np.ndarray, np.ndarray]:
        if self._gray is None:
            self._gray = (
                cv2.cvtColor(self.left_bgr, cv2.COLOR_BGR2GRAY),
                cv2.cvtColor(self.right_bgr, cv2.COLOR_BGR2GRAY),
            )
        return self._gray


def _match_right(
    left: Detection,
    candidates: list[Detection],
    frame: StereoFrame,
    config: LocalizeConfig,
    bp_left: np.ndarray,
    bp_right: np.ndarray,
    ends: bool = False,
) -> Detection:
    """The right-image candidate on the same rows as ``left``, in the disparity range, of similar size.
    With ``ends`` (a big object: a box, a table, a chair), the silhouettes' first or last rows agreeing
    stand for the centroids' rows (:func:`_an_end_row_agrees`).

    The disparity tested is that of the centroids, or, when either silhouette is cut by a side border,
    that of the silhouettes' edges (the cut moves each centroid by a different amount: a table close
    by, cut by the right border in both images and with the held ball and the gripper in front of it,
    had centroids 8.5 px apart for edges 80 px apart, below the 10 px of the farthest depth: fetch
    seed 63's goto stopped with ``not_in_right_view``)."""
    d_lo, d_hi = disparity_range(frame.rig, config.stereo)
    size_l = float(np.mean(left.box[1]))
    row_tol = _row_tolerance(left, config)
    best, best_cost = None, np.inf
    for c in candidates:
        disparity = left.centre_px[0] - c.centre_px[0]
        if {"left", "right"} & {*left.border_sides, *c.border_sides}:
            try:
                disparity, _ = edge_disparity_median(
                    _silhouette(bp_left, left.window, config.detection),
                    left.window,
                    _silhouette(bp_right, c.window, config.detection),
                    c.window,
                    frame.rig.intrinsics.width,
                )
            except NotFoundError:
                continue  # no edge off the borders on common rows
        size_ratio = float(np.mean(c.box[1])) / size_l
        if not (0.9 * d_lo <= disparity <= 1.1 * d_hi):
            continue
        if abs(left.centre_px[1] - c.centre_px[1]) > row_tol and not (
            ends and _an_end_row_agrees(left, c, bp_left, bp_right, config)
        ):
            continue
        if not (1 / config.max_size_ratio <= size_ratio <= config.max_size_ratio):
            continue
        cost = abs(np.log(size_ratio)) + abs(np.log(max(c.score, 1e-9) / max(left.score, 1e-9)))
        if cost < best_cost:
            best, best_cost = c, cost
    if best is None:
        raise NotFoundError(
            f"'{left.name}' is seen in the left image at pixel "
            f"({left.centre_px[0]:.0f}, {left.centre_px[1]:.0f}) "
            f"but nowhere on the same rows of the right image within disparities [{d_lo:.0f}, {d_hi:.0f}] px "
            "(occluded or out of the right camera's view)",
            {"reason": REASON_NOT_IN_RIGHT_VIEW},
        )
    return best


def _row_tolerance(left: Detection, config: LocalizeConfig) -> float:
    """How far [px] the centroids of one object's two silhouettes may lie apart in rows (rectified)."""
    return config.stereo.max_row_difference_px + 0.05 * float(np.mean(left.box[1]))


def _an_end_row_agrees(
    left: Detection, right: Detection, bp_left: np.ndarray, bp_right: np.ndarray, config: LocalizeConfig
) -> bool:
    """Whether the first or the last rows of the two silhouettes lie within ``max_row_difference_px``
    (+ 1 px) of each other: one object seen over the same rows (rectified) except where something in
    front hides a different part of it in each image (a table behind a chair: its leg hidden lower down
    in one image; the centroids' rows 12 px apart, and the table was `not_in_right_view` from every
    viewpoint of layout box_near). Its centroids then do not correspond (:func:`locate_in_frame` uses
    the edges)."""
    ends = []
    for det, bp in ((left, bp_left), (right, bp_right)):
        rows = np.flatnonzero(_silhouette(bp, det.window, config.detection).any(axis=1))
        if len(rows) == 0:
            return False
        ends.append((det.window[1] + rows[0], det.window[1] + rows[-1]))
    slack = config.stereo.max_row_difference_px + 1.0
    return abs(ends[0][0] - ends[1][0]) <= slack or abs(ends[0][1] - ends[1][1]) <= slack


def _centroid_point(
    model: ObjectModel, left: Detection, right: Detection, rig: StereoRig
) -> tuple[np.ndarray, float]:
    """Left-optical-frame point [m] and disparity [px] from the two silhouette centroids."""
    if model.shape == "sphere":
        radius_px = 0.25 * (left.box[1][0] + left.box[1][1])  # the box's sides are the diameter
        return _sphere_point(left.centre_px, right.centre_px, radius_px, rig)
    p_camera = triangulate_centroids(rig, left.centre_px, right.centre_px)
    return p_camera, float(left.centre_px[0] - right.centre_px[0])


def _sphere_point(
    uv_left: tuple[float, float], uv_right: tuple[float, float], radius_px: float, rig: StereoRig
) -> tuple[np.ndarray, float]:
    """Left-optical-frame centre [m] and disparity [px] of a ball whose silhouettes are centred at
    ``uv_left``, ``uv_right`` [px] with the radius ``radius_px`` in the left image (the silhouette's
    centre moved to the image of the ball's centre: :func:`vision.stereo.sphere_centre_pixel`)."""
    p_camera = triangulate_centroids(rig, uv_left, uv_right)
    radius = radius_px * p_camera[2] / rig.intrinsics.fx
    p_right = p_camera - rig.T_left_right[:3, 3]
    uv_left = sphere_centre_pixel(rig, uv_left, radius, float(np.linalg.norm(p_camera)))
    uv_right = sphere_centre_pixel(rig, uv_right, radius, float(np.linalg.norm(p_right)))
    p_camera = triangulate_centroids(rig, uv_left, uv_right)
    return p_camera, float(uv_left[0] - uv_right[0])


#: A ball's silhouette whose outline runs along the robot's own pixels is taken as hidden when it covers
#: less than this fraction of its fitted circle in one image (:func:`_free_circles`).
HIDDEN_AREA_FRACTION = 0.9


def _free_circles(
    left: Detection,
    right: Detection,
    frame: StereoFrame,
    config: DetectionConfig,
    bp_left: np.ndarray,
    bp_right: np.ndarray,
    whether_hidden: bool = True,
) -> tuple[Circle, Circle] | None:
    """The circles of a ball's two silhouettes fitted to their outlines off the robot's own pixels
    (vision.hidden_ball), or None when the robot hides neither silhouette (``whether_hidden``: checked
    first; an outline along the robot's pixels with each silhouette covering more than
    ``HIDDEN_AREA_FRACTION`` of its circle is not hidden) or either fit fails (too little of the
    outline free)."""
    own_left, own_right = frame.own_masks
    if own_left is None or own_right is None:
        return None
    sil_left = _silhouette(bp_left, left.window, config)
    sil_right = _silhouette(bp_right, right.window, config)
    if whether_hidden and not (
        touches(sil_left, left.window, own_left) or touches(sil_right, right.window, own_right)
    ):
        return None
    circle_left = free_circle(sil_left, left.window, own_left)
    circle_right = free_circle(sil_right, right.window, own_right)
    if circle_left is None or circle_right is None:
        return None
    if whether_hidden:  # touching is not hiding: a whole silhouette's centroid is the better estimate
        seen = min(
            np.count_nonzero(sil) / (np.pi * circle.radius_px**2)
            for sil, circle in ((sil_left, circle_left), (sil_right, circle_right))
        )
        if seen > HIDDEN_AREA_FRACTION:
            return None
    return circle_left, circle_right


def _raise_if_own_body_hides(
    left: Detection,
    frame: StereoFrame,
    bp_left: np.ndarray,
    config: DetectionConfig,
    unmatched: NotFoundError,
) -> None:
    """NotFoundError ``hidden_by_own_body`` when the left silhouette ``left``, not matched in the right
    image (``unmatched``), runs along the robot's own pixels: its arm hides it there (after a failed
    grasp the hand rests on the ball, in front of it in one image, 7 px of it left in the other:
    fetch seed 77). Nothing when the frame has no own-body masks or the silhouette does not touch them."""
    own_left, _ = frame.own_masks
    if own_left is None or not touches(_silhouette(bp_left, left.window, config), left.window, own_left):
        return
    raise NotFoundError(
        f"'{left.name}' is seen in the left image at pixel ({left.centre_px[0]:.0f}, "
        f"{left.centre_px[1]:.0f}) next to the robot's own arm and not in the right image: the arm hides "
        "it; move the arm out of the view and look again",
        {"reason": REASON_HIDDEN_BY_OWN_BODY},
    ) from unmatched


def _match_hidden_ball(
    left: Detection,
    candidates: list[Detection],
    frame: StereoFrame,
    config: LocalizeConfig,
    bp_left: np.ndarray,
    bp_right: np.ndarray,
) -> tuple[Detection, tuple[Circle, Circle]] | None:
    """The right-image candidate of a ball refused by :func:`_match_right` (the robot's own arm cuts its
    silhouette in one image: the sizes differ, the centroids are not on the same rows), matched by the
    circles fitted to the free parts of the outlines: the same rows, a disparity in range, radii
    within ``max_size_ratio`` ** 0.5 of each other. (detection, its circles), or None."""
    d_lo, d_hi = disparity_range(frame.rig, config.stereo)
    best, best_cost = None, np.inf
    for c in candidates:
        circles = _free_circles(left, c, frame, config.detection, bp_left, bp_right, whether_hidden=False)
        if circles is None:
            continue
        cl, cr = circles
        ratio = cr.radius_px / cl.radius_px
        if not (0.9 * d_lo <= cl.u_px - cr.u_px <= 1.1 * d_hi):
            continue
        if abs(cl.v_px - cr.v_px) > config.stereo.max_row_difference_px + 0.05 * cl.radius_px:
            continue
        if abs(np.log(ratio)) > 0.5 * np.log(config.max_size_ratio):
            continue
        if abs(np.log(ratio)) < best_cost:
            best, best_cost = (c, circles), abs(np.log(ratio))
    return best


def _dense_point(
    model: ObjectModel,
    left: Detection,
    bp_left: np.ndarray,
    frame: StereoFrame,
    config: LocalizeConfig,
    method: str,
) -> tuple[np.ndarray, float]:
    """Point [m] and disparity [px] from the median dense disparity (bm/sgbm) of the object's pixels."""
    rig = frame.rig
    x, y, w, h = left.window
    mask = bp_left[y : y + h, x : x + w] >= config.detection.threshold
    gray_l, gray_r = frame.gray
    disparity, _ = dense_disparity_median(rig, gray_l, gray_r, left.window, mask, config.stereo, method)
    z = rig.depth_of_disparity(disparity)
    radius = (
        0.25 * (left.box[1][0] + left.box[1][1]) * z / rig.intrinsics.fx if model.shape == "sphere" else None
    )
    return dense_point(rig, left.centre_px, disparity, radius), float(disparity)


def _silhouette(bp: np.ndarray, window: Window, config: DetectionConfig) -> np.ndarray:
    """Boolean object mask of a window: back projection >= threshold, closed morphologically."""
    x, y, w, h = window
    support = (bp[y : y + h, x : x + w] >= config.threshold).astype(np.uint8)
    if config.close_kernel_px > 1:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (config.close_kernel_px,) * 2)
        support = cv2.morphologyEx(support, cv2.MORPH_CLOSE, kernel)
    return support > 0


def _edges_point(
    left: Detection,
    right: Detection,
    bp_left: np.ndarray,
    bp_right: np.ndarray,
    rig: StereoRig,
    config: DetectionConfig,
) -> tuple[np.ndarray, float]:
    """Point [m] (at the left centroid's ray) and disparity [px] from the silhouettes' edges."""
    disparity, _ = edge_disparity_median(
        _silhouette(bp_left, left.window, config),
        left.window,
        _silhouette(bp_right, right.window, config),
        right.window,
        rig.intrinsics.width,
    )
    if not disparity > 0:
        raise NotFoundError(
            f"stereo mismatch: the silhouette edges give a disparity of {disparity:.1f} px",
            {"reason": REASON_STEREO_MISMATCH},
        )
    return point_from_pixel_disparity(rig, left.centre_px[0], left.centre_px[1], disparity), disparity


def _one_object_in_parts(
    model: ObjectModel,
    left_candidates: list[Detection],
    bp_left: np.ndarray,
    bp_right: np.ndarray,
    frame: StereoFrame,
    config: LocalizeConfig,
    occluders: Sequence[ObjectModel],
) -> tuple[Detection, Detection] | None:
    """The left and right detections of ``model``'s object when its two best left candidates (called
    ambiguous) are parts of it that an occluder in front separates (vision.parts): in each image the
    pixels of its colour connected to a candidate through the other objects' or the robot's own pixels
    (:func:`vision.parts.joined_through`), the left one holding both parts, matched as usual
    (:func:`_match_right`), the parts' centres at the joined outline's depth (:func:`_edges_point`: the
    centroids of parts hidden differently in each image do not correspond) within the catalogued floor
    diagonal plus ``PARTS_SLACK_M``. None otherwise (ambiguous it stays: two objects of one colour, or a third
    blob as strong)."""
    det_cfg = config.detection
    a, b = left_candidates[0], left_candidates[1]
    others = [other for other in occluders if other.name != model.name]
    own_left, own_right = frame.own_masks
    left = joined_through(a, bp_left, _occluder_mask(frame, "left", others, det_cfg, own_left), det_cfg)
    if left is None or not _inside(b.centre_px, left.window):
        return None
    occluder_right = _occluder_mask(frame, "right", others, det_cfg, own_right)
    rights = [
        joined_through(c, bp_right, occluder_right, det_cfg)
        for c in detect_all(bp_right, model.name, det_cfg)
    ]
    try:
        right = _match_right(
            left, [r for r in rights if r is not None], frame, config, bp_left, bp_right, ends=True
        )
        depth = float(_edges_point(left, right, bp_left, bp_right, frame.rig, det_cfg)[0][2])
    except NotFoundError:
        return None
    k = frame.rig.intrinsics
    spread = depth * float(
        np.hypot((a.centre_px[0] - b.centre_px[0]) / k.fx, (a.centre_px[1] - b.centre_px[1]) / k.fy)
    )
    if spread > float(np.hypot(*model.floor_size_m)) + PARTS_SLACK_M:
        return None
    rest = [c for c in left_candidates[2:] if c.score >= det_cfg.ambiguity_ratio * left.score]
    return None if rest else (left, right)


def _inside(point_px: tuple[float, float], window: Window) -> bool:
    return (
        window[0] <= point_px[0] < window[0] + window[2] and window[1] <= point_px[1] < window[1] + window[3]
    )


def _occluder_mask(
    frame: StereoFrame,
    side: str,
    occluders: Sequence[ObjectModel],
    config: DetectionConfig,
    own: np.ndarray | None,
) -> np.ndarray | None:
    """Boolean (H, W) mask of the ``side`` image's pixels of the ``occluders``' colours (back projection
    >= threshold) and of the robot's ``own`` body (its mask, or None), None without either."""
    mask = None if own is None else np.asarray(own, dtype=bool)
    for other in occluders:
        seen = frame.back_projection(other, side) >= config.threshold
        mask = seen if mask is None else mask | seen
    return mask


def locate_in_frame(
    model: ObjectModel,
    frame: StereoFrame,
    config: LocalizeConfig | None = None,
    occluders: Sequence[ObjectModel] = (),
    with_footprint: bool = True,
) -> ObjectLocation:
    """Localize ``model``'s object in a prepared :class:`StereoFrame` (NotFoundError when not found).
    ``occluders``: the other objects' models, whose pixels next to its outline hide it there (its
    footprint leaves those edges out: vision.footprint), as do the robot's own (``frame.own_body``).
    ``with_footprint`` False: no footprint (an object seen in passing: :func:`others_in_frame`)."""
    config = config or LocalizeConfig()
    det_cfg = config.detection
    bp_left = frame.back_projection(model, "left")
    left_candidates = detect_all(bp_left, model.name, det_cfg)
    bp_right, joined_right = None, None
    try:
        left = check_unambiguous(left_candidates, det_cfg, f"'{model.name}'")
    except NotFoundError as e:
        e.details.setdefault("object", model.name)
        if e.details.get("reason") != REASON_AMBIGUOUS or model.shape == "sphere" or not model.floor_size_m:
            raise
        bp_right = frame.back_projection(model, "right")
        parts = _one_object_in_parts(model, left_candidates, bp_left, bp_right, frame, config, occluders)
        if parts is None:
            raise
        left, joined_right = parts
    if bp_right is None:
        bp_right = frame.back_projection(model, "right")
    candidates = [joined_right] if joined_right is not None else detect_all(bp_right, model.name, det_cfg)
    circles = None  # a ball's circles fitted off the robot's own pixels (vision.hidden_ball)
    try:
        right = _match_right(left, candidates, frame, config, bp_left, bp_right, ends=model.shape != "sphere")
    except NotFoundError as unmatched:
        hidden = (
            None
            if model.shape != "sphere"
            else _match_hidden_ball(left, candidates, frame, config, bp_left, bp_right)
        )
        if hidden is None:
            _raise_if_own_body_hides(left, frame, bp_left, det_cfg, unmatched)
            raise
        right, circles = hidden

    rig = frame.rig
    method = config.stereo.method
    side_cut = bool({"left", "right"} & {*left.border_sides, *right.border_sides})
    hidden_apart = model.shape != "sphere" and abs(left.centre_px[1] - right.centre_px[1]) > _row_tolerance(
        left, config
    )
    if method == "centroid" and (joined_right is not None or hidden_apart):
        # Parts joined around an occluder, or matched by their end rows: something in front hides
        # different parts in each image, so the centroids do not correspond (a table behind a chair's
        # back: 4.5 m for 3.0); the outer edges do.
        method = "edges"
    if method == "centroid" and side_cut:
        # A silhouette cut by a side border moves the centroid differently in each image; a cut by the
        # top or bottom border removes the same rows from both (rectified), which the centroid tolerates.
        method = "bm"
    if method == "centroid" and model.shape == "sphere":
        if circles is None:
            p_camera, disparity = _centroid_point(model, left, right, rig)
            if p_camera[2] < config.hidden_ball_max_depth_m:  # the robot's hand may hide part of it
                circles = _free_circles(left, right, frame, det_cfg, bp_left, bp_right)
        if circles is not None:  # its centre and radius from the outline's free part
            method = "free_outline"
            circle_left, circle_right = circles
            p_camera, disparity = _sphere_point(
                (circle_left.u_px, circle_left.v_px),
                (circle_right.u_px, circle_right.v_px),
                circle_left.radius_px,
                rig,
            )
    elif method == "centroid":
        p_camera, disparity = _centroid_point(model, left, right, rig)
    elif method == "edges":
        p_camera, disparity = _edges_point(left, right, bp_left, bp_right, rig, det_cfg)
    else:
        try:
            p_camera, disparity = _dense_point(model, left, bp_left, frame, config, method)
        except NotFoundError as dense_failed:
            if config.stereo.method != "centroid":
                raise  # the dense method was asked for: say it failed
            try:  # no texture to correlate (uniform colour): the silhouettes' edges still match
                method = "edges"
                p_camera, disparity = _edges_point(left, right, bp_left, bp_right, rig, det_cfg)
            except NotFoundError as edges_failed:
                raise NotFoundError(
                    f"'{model.name}' is cut by the image border and neither correlation nor its edges give "
                    f"a disparity: {dense_failed.message}; {edges_failed.message}",
                    {"reason": REASON_NO_DISPARITY},
                ) from edges_failed
    z = float(p_camera[2])
    size_m = (float(left.box[1][0] * z / rig.intrinsics.fx), float(left.box[1][1] * z / rig.intrinsics.fy))
    if method == "free_outline":  # the box is the seen part's: the whole ball's diameter instead
        size_m = (2.0 * circles[0].radius_px * z / rig.intrinsics.fx,) * 2
    p_world = to_world(p_camera, frame.T_world_left_camera)
    floor_rectangle = None
    cut = {"left", "right", "top"} & {*left.border_sides, *right.border_sides}
    if with_footprint and model.shape != "sphere" and not cut and z >= config.footprint_min_depth_m:
        others = [other for other in occluders if other.name != model.name]
        own_left, own_right = frame.own_masks
        outline = outline_points(
            _silhouette(bp_left, left.window, det_cfg),
            left.window,
            _silhouette(bp_right, right.window, det_cfg),
            right.window,
            rig,
            frame.T_world_left_camera,
            _occluder_mask(frame, "left", others, det_cfg, own_left),
            _occluder_mask(frame, "right", others, det_cfg, own_right),
        )
        floor_rectangle = footprint(
            outline.points,
            p_world,
            n_hidden=outline.n_hidden,
            runs=outline.runs,
            known_size_m=model.floor_size_m,
            camera_xy=frame.T_world_left_camera[:2, 3],
        )
    return ObjectLocation(
        model.name,
        tuple(float(v) for v in p_world),
        tuple(float(v) for v in p_camera),
        size_m,
        float(min(left.confidence, right.confidence)),
        float(disparity),
        method,
        left,
        right,
        floor_rectangle,
    )


#: Two models' silhouettes sharing more than this fraction of the smaller one's pixels are one object
#: (:func:`others_in_frame`).
SAME_PIXELS_FRACTION = 0.5


def _left_silhouette(
    loc: ObjectLocation, model: ObjectModel, frame: StereoFrame, config: DetectionConfig
) -> np.ndarray:
    """Boolean (H, W) mask of ``loc``'s silhouette in the left image (its window only)."""
    mask = np.zeros(frame.hsv_left.shape[:2], dtype=bool)
    x, y, w, h = loc.left.window
    mask[y : y + h, x : x + w] = _silhouette(frame.back_projection(model, "left"), loc.left.window, config)
    return mask


def others_in_frame(
    found: ObjectLocation,
    models: Sequence[ObjectModel],
    frame: StereoFrame,
    config: LocalizeConfig | None = None,
) -> list[ObjectLocation]:
    """The objects of ``models`` other than ``found`` (localized in ``frame``) seen in the same stereo
    pair, most confident first, without footprints (seen in passing: each position, size and
    confidence as :func:`locate_in_frame` gives them; ask for one to get its footprint); the others
    are not seen there (any NotFoundError reason).

    Identity: a model is one named object of the catalogue, learned from that object's pixels only
    (services/perception/learn_from_sim.py checks that no model's detection falls on another object),
    and a model seeing two similar regions is ``ambiguous`` (vision.camshift), never two objects. When
    two models still claim one region (more than ``SAME_PIXELS_FRACTION`` of the smaller silhouette's
    pixels in the left image are the other's), it is one object: ``found`` (asked for) or else the
    more confident detection; the other is left out."""
    config = config or LocalizeConfig()
    by_name = {m.name: m for m in models}
    seen: list[ObjectLocation] = []
    for model in models:
        if model.name == found.name:
            continue
        if budget.expired():  # optional work: the asked object is found, report what was seen so far
            break
        try:
            seen.append(locate_in_frame(model, frame, config, with_footprint=False))
        except NotFoundError:
            continue
    if not seen:
        return []
    kept: list[tuple[ObjectLocation, np.ndarray]] = []
    if found.name in by_name:
        kept.append((found, _left_silhouette(found, by_name[found.name], frame, config.detection)))
    others: list[ObjectLocation] = []
    for loc in sorted(seen, key=lambda o: -o.confidence):
        mask = _left_silhouette(loc, by_name[loc.name], frame, config.detection)
        area = int(mask.sum())
        if any(
            np.count_nonzero(mask & other) > SAME_PIXELS_FRACTION * max(1, min(area, int(other.sum())))
            for _, other in kept
        ):
            continue
        kept.append((loc, mask))
        others.append(loc)
    return others


def localize(
    models: Sequence[ObjectModel],
    left_bgr: np.ndarray,
    right_bgr: np.ndarray,
    rig: StereoRig,
    T_world_left_camera: np.ndarray,
    config: LocalizeConfig | None = None,
    require_all: bool = True,
    occluders: Sequence[ObjectModel] = (),
    own_body: OwnBodyMasks | None = None,
) -> list[ObjectLocation]:
    """Localize every model's object in a rectified stereo pair.

    left_bgr, right_bgr: BGR uint8 images matching ``rig.intrinsics``; T_world_left_camera: 4x4 pose of
    the left camera optical frame (x right, y down, z forward) in the world frame.
    Returns one ObjectLocation per object found, in the order of ``models``. With ``require_all`` a
    missing object raises NotFoundError (``details["missing"]`` maps each missing name to its reason,
    ``details["found"]`` lists the names found); otherwise missing objects are left out.
    ``occluders``: models of objects that may hide parts of them (:func:`locate_in_frame`);
    ``own_body``: the robot's own pixels in the left and right images (:class:`StereoFrame`).
    """
    config = config or LocalizeConfig()
    frame = StereoFrame(left_bgr, right_bgr, rig, T_world_left_camera, own_body)
    found: list[ObjectLocation] = []
    missing: dict[str, str] = {}
    messages: list[str] = []
    for model in models:
        budget.check(f"the localization of {model.name}", {"found": [f.name for f in found]})
        try:
            found.append(locate_in_frame(model, frame, config, occluders))
        except NotFoundError as e:
            missing[model.name] = str(e.details.get("reason", "not_found"))
            messages.append(e.message)
    if missing and require_all:
        if len(models) == 1:
            raise NotFoundError(messages[0], {"object": models[0].name, "reason": missing[models[0].name]})
        raise NotFoundError(
            "; ".join(messages),
            {"missing": missing, "found": [f.name for f in found], "reason": next(iter(missing.values()))},
        )
    return found


def locate(
    model: ObjectModel,
    left_bgr: np.ndarray,
    right_bgr: np.ndarray,
    rig: StereoRig,
    T_world_left_camera: np.ndarray,
    config: LocalizeConfig | None = None,
    occluders: Sequence[ObjectModel] = (),
    own_body: OwnBodyMasks | None = None,
) -> ObjectLocation:
    """Localize one object (see :func:`localize`); NotFoundError saying why when it is not found."""
    return localize(
        [model], left_bgr, right_bgr, rig, T_world_left_camera, config, occluders=occluders, own_body=own_body
    )[0]
