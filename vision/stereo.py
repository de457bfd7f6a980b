"""3D position of a detected object from a rectified stereo pair.

Yoshida et al. (``001_771c0ce3779b0683.txt``, "Object Recognition and Localization"): "A stereo-vision
algorithm by pixel correlation is applied on the stereo image pairs, and produces a dense 3D image of
the current scene. [...] the objects to localize are sufficiently textured so that precise enough 3D
points can be obtained in the vicinity of the objects."

Three estimators, all restricted to the object's CamShift windows:

- ``"centroid"``: sub-pixel triangulation of the back-projection mass centroids found independently in
  the left and right images: disparity = u_left - u_right, z = fx * baseline / disparity. The centroid of
  a silhouette is the image of (nearly) the object's centre; for a "sphere" model the small perspective
  offset of the silhouette's centre is removed (:func:`sphere_centre_pixel`).
- ``"bm"`` / ``"sgbm"``: the pixel-correlation stereo of the paper (OpenCV StereoBM / StereoSGBM) run on
  a crop around the window only, and the median disparity of the object's pixels. Correlation sees the
  front surface, so for a ``"sphere"`` model the centre is placed r / sqrt(2) further along the ray (the
  median depth of a sphere's visible cap lies r / sqrt(2) in front of its centre).
- ``"edges"``: the median, over the image rows both silhouettes cover, of the disparity of their leftmost
  and of their rightmost pixels (edges lying on an image border are skipped). Needs no texture and no
  complete silhouette: the last fallback for a uniformly coloured object cut by the left or right border
  (rendered scenes: correlation then finds nothing to match).

Which is the default is decided by measurement (``scripts/bench.d/perception.py``, vision/README.md):
on 30 placements per distance, centroid triangulation has median errors of 0.04 / 0.09 / 0.29 cm at
1.0 / 1.5 / 2.5 m against 0.44 / 0.51 / 0.44 cm for StereoBM and 0.56 / 0.57 / 0.96 cm for StereoSGBM
(synthetic textured images), and 0.10 / 0.12 / 0.28 cm against 1.9 / 2.3 / 2.6 cm for StereoBM on the
simulator's untextured renders (0.71 against 2.6 cm at 3.5 m; StereoBM on the whole image, the
paper's "dense 3D image", gives the crop's disparities at 4x its time); it is also the cheapest, so it
is the default. When the object touches
the left or right image border in either image (a silhouette cut there moves the centroid differently in
the two images) the dense median takes over, then the edges if correlation finds nothing. A cut by the
top or bottom border removes the same rows (epipolar lines) from both rectified images, so the
centroids still correspond: the centroid stays.

Frames: positions are in the left camera optical frame (x right, y down, z forward) [m];
:func:`to_world` maps them through ``T_world_camera``.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from services import budget
from services.bus.schemas.perception import REASON_NO_DISPARITY, REASON_STEREO_MISMATCH
from services.errors import InvalidRequestError, NotFoundError, RequestTimeoutError
from vision.camera import StereoRig, transform_points
from vision.camshift import Window

METHODS = ("centroid", "bm", "sgbm", "edges")
#: Held by the dense stereo computation that runs while a request's budget is open (one at a time; an
#: abandoned one keeps it until it ends: :func:`_compute_within_budget`).
_STEREO_SLOT = threading.Semaphore(1)


@dataclass(frozen=True)
class StereoConfig:
    """Stereo parameters.

    method: "centroid" (default, see module doc), "bm", "sgbm" or "edges".
    min_depth_m, max_depth_m: depth range searched [m] (sets the disparity range of bm/sgbm and bounds
      the centroid disparity).
    max_row_difference_px: largest |v_left - v_right| of matched centroids [px] plus 5 % of the object's
      size (rectified images: the same point is on the same row).
    bm_block_px, sgbm_block_px: correlation window sizes [px] (odd).
    min_valid_fraction: bm/sgbm need valid disparities on at least this fraction of the object pixels.
    dense_full_frame: bm/sgbm correlate the whole image (the paper's "dense 3D image of the current
      scene") instead of a crop around the object's window (same disparities there, measured by
      ``scripts/bench perception``; the crop is what the service uses).
    """

    method: str = "centroid"
    min_depth_m: float = 0.3
    max_depth_m: float = 8.0
    max_row_difference_px: float = 2.0
    bm_block_px: int = 11
    sgbm_block_px: int = 5
    min_valid_fraction: float = 0.2
    dense_full_frame: bool = False

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise InvalidRequestError(f"stereo method must be one of {METHODS}, got {self.method!r}")
        if not 0 < self.min_depth_m < self.max_depth_m:
            raise InvalidRequestError(
                f"need 0 < min_depth_m < max_depth_m, got {self.min_depth_m}, {self.max_depth_m}"
            )


def disparity_range(rig: StereoRig, config: StereoConfig) -> tuple[float, float]:
    """(smallest, largest) disparity [px] of the depth range [min_depth_m, max_depth_m]."""
    return float(rig.disparity_of_depth(config.max_depth_m)), float(
        rig.disparity_of_depth(config.min_depth_m)
    )


def point_from_pixel_disparity(rig: StereoRig, u_px: float, v_px: float, disparity_px: float) -> np.ndarray:
    """Point (3,) [m] in the left optical frame seen at left pixel (u, v) with the given disparity."""
    if not disparity_px > 0:
        raise InvalidRequestError(f"disparity must be > 0 px, got {disparity_px}")
    k = rig.intrinsics
    z = k.fx * rig.baseline_m / disparity_px
    return np.array([(u_px - k.cx) * z / k.fx, (v_px - k.cy) * z / k.fy, z])


def triangulate_centroids(
    rig: StereoRig, uv_left: tuple[float, float], uv_right: tuple[float, float]
) -> np.ndarray:
    """Left-optical-frame point (3,) [m] of matched sub-pixel centroids (rectified: rows averaged)."""
    disparity = uv_left[0] - uv_right[0]
    if not disparity > 0:
        raise NotFoundError(
            "stereo mismatch: the right-image blob is not left of the left-image one "
            f"(disparity {disparity:.2f} px)",
            {"reason": REASON_STEREO_MISMATCH},
        )
    return point_from_pixel_disparity(rig, uv_left[0], 0.5 * (uv_left[1] + uv_right[1]), disparity)


def sphere_centre_pixel(
    rig: StereoRig, centre_px: tuple[float, float], radius_m: float, distance_m: float
) -> tuple[float, float]:
    """Pixel of a sphere's centre from the centroid of its silhouette [px].

    Under perspective a sphere's silhouette is an ellipse whose centre lies further from the principal
    point than the image of the sphere's centre. With the cone of half-angle alpha (tan alpha = r /
    sqrt(D^2 - r^2)) around the direction at angle theta, the silhouette's ends along the radial line are
    at tan(theta -+ alpha), so its centre is c = t (1 + tau^2) / (1 - t^2 tau^2) (t = tan theta,
    tau = tan alpha, normalized image coordinates). Solving for t gives the centre's image. The shift is
    about 0.5 px near the image border at 1 m for a 5 cm ball (a 2-3 mm bias in depth), less further away.
    """
    k = rig.intrinsics
    xn, yn = (centre_px[0] - k.cx) / k.fx, (centre_px[1] - k.cy) / k.fy
    c = float(np.hypot(xn, yn))
    if c < 1e-12 or not 0 < radius_m < distance_m:
        return centre_px
    tau2 = radius_m**2 / (distance_m**2 - radius_m**2)
    a = 1.0 + tau2
    t = 2.0 * c / (a + math.sqrt(a * a + 4.0 * c * c * tau2))  # stable root of c tau^2 t^2 + a t - c = 0
    scale = t / c
    return (k.cx + xn * scale * k.fx, k.cy + yn * scale * k.fy)


def _matcher(method: str, min_disp: int, num_disp: int, config: StereoConfig):
    if method == "bm":
        bm = cv2.StereoBM_create(numDisparities=num_disp, blockSize=config.bm_block_px)
        bm.setMinDisparity(min_disp)
        bm.setTextureThreshold(5)
        bm.setUniquenessRatio(10)
        bm.setSpeckleWindowSize(0)
        return bm
    b = config.sgbm_block_px
    return cv2.StereoSGBM_create(
        minDisparity=min_disp,
        numDisparities=num_disp,
        blockSize=b,
        P1=8 * b * b,
        P2=32 * b * b,
        uniquenessRatio=10,
        disp12MaxDiff=1,
        mode=cv2.StereoSGBM_MODE_SGBM,
    )


def dense_disparity_median(
    rig: StereoRig,
    left_gray: np.ndarray,
    right_gray: np.ndarray,
    window_left: Window,
    object_mask: np.ndarray,
    config: StereoConfig,
    method: str = "bm",
) -> tuple[float, int]:
    """Median disparity [px] (and count of valid pixels) of the object pixels of a left-image window.

    Runs StereoBM ("bm") or StereoSGBM ("sgbm") on a crop holding the window plus the disparity search
    range, so the cost scales with the object's size. ``object_mask``: boolean, window-sized (h, w),
    True on the object's pixels. NotFoundError when too few pixels get a valid disparity.
    """
    if method not in ("bm", "sgbm"):
        raise InvalidRequestError(f"dense stereo method must be 'bm' or 'sgbm', got {method!r}")
    x, y, w, h = window_left
    d_lo, d_hi = disparity_range(rig, config)
    min_disp = max(0, math.floor(d_lo))
    num_disp = max(16, math.ceil((d_hi - min_disp) / 16.0) * 16)
    block = config.bm_block_px if method == "bm" else config.sgbm_block_px
    half = block // 2 + 1
    H, W = left_gray.shape[:2]
    r0, r1 = max(0, y - half), min(H, y + h + half)
    # The crop must reach min_disp + num_disp columns left of the window; pad with black past the border
    # (matchers also require that many columns).
    c0 = x - min_disp - num_disp - half
    c1 = min(W, x + w + half)
    if config.dense_full_frame:  # the whole scene's disparity image, as the paper computes it
        r0, r1, c0, c1 = 0, H, min(c0, 0), W
    pad = max(0, -c0)
    c0 = max(0, c0)
    crop_l = cv2.copyMakeBorder(left_gray[r0:r1, c0:c1], 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
    crop_r = cv2.copyMakeBorder(right_gray[r0:r1, c0:c1], 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
    c0 -= pad
    disp16 = _compute_within_budget(_matcher(method, min_disp, num_disp, config), crop_l, crop_r, method)
    disp = disp16[y - r0 : y - r0 + h, x - c0 : x - c0 + w].astype(np.float32) / 16.0
    valid = object_mask & (disp >= min_disp) & (disp > 0)
    n_valid = int(np.count_nonzero(valid))
    n_obj = int(np.count_nonzero(object_mask))
    if n_obj == 0 or n_valid < max(5, config.min_valid_fraction * n_obj):
        raise NotFoundError(
            f"dense stereo ({method}) found valid disparities on only {n_valid} of {n_obj} object pixels "
            "(too little texture, or the object is outside the right image)",
            {"reason": REASON_NO_DISPARITY},
        )
    return float(np.median(disp[valid])), n_valid


def _compute_within_budget(
    matcher: cv2.StereoMatcher, crop_l: np.ndarray, crop_r: np.ndarray, method: str
) -> np.ndarray:
    """The matcher's 16x fixed-point disparities of the crop, abandoned when the request's time budget
    (:mod:`services.budget`) runs out first (issue 16: a 2048 px SGBM takes seconds in one OpenCV call,
    which cannot be interrupted).

    Without an open budget (scripts, tests of this package) the matcher runs here. With one, it runs on
    a daemon thread (OpenCV releases the GIL) while this one waits at most what is left of the budget;
    past it, RequestTimeoutError: the reply goes out at once, and the computation, whose result nobody
    wants any more, ends on its own (its length is bounded by the largest image). One computation at a
    time (:data:`_STEREO_SLOT`): a request finding an abandoned one still running waits for it within
    its own budget, so abandoned work never piles up.
    """
    deadline = budget.current()
    if deadline is None:
        return matcher.compute(crop_l, crop_r)
    what = f"the dense stereo ({method}, a {crop_l.shape[1]} x {crop_l.shape[0]} px crop)"
    if not _STEREO_SLOT.acquire(timeout=max(deadline.remaining(), 0.0)):
        raise _abandoned(deadline, f"{what}, waiting for an abandoned one to end")
    result: dict[str, Any] = {}
    done = threading.Event()

    def run() -> None:
        try:
            result["disparity"] = matcher.compute(crop_l, crop_r)
        except Exception as exc:  # raised again by the waiting thread
            result["error"] = exc
        finally:
            _STEREO_SLOT.release()
            done.set()

    threading.Thread(target=run, name="stereo", daemon=True).start()
    if not done.wait(timeout=max(deadline.remaining(), 0.0)):
        raise _abandoned(deadline, f"{what}, abandoned")
    if "error" in result:
        raise result["error"]
    return result["disparity"]


def _abandoned(deadline: budget.Deadline, where: str) -> RequestTimeoutError:
    return RequestTimeoutError(
        f"the time budget of {deadline.budget_s:.3g} s ran out after {deadline.elapsed():.2f} s, at {where}: "
        "give a larger time_budget_s or smaller images",
        {"budget_s": deadline.budget_s, "elapsed_s": deadline.elapsed(), "stage": where},
    )


def silhouette_rows(silhouette: np.ndarray, window: Window) -> dict[int, tuple[int, int]]:
    """Image row [px] -> (first, last) object column [px] of a boolean window mask ``(x, y, w, h)``."""
    x, y = window[0], window[1]
    rows = np.flatnonzero(silhouette.any(axis=1))
    first = silhouette[rows].argmax(axis=1)
    last = silhouette.shape[1] - 1 - silhouette[rows][:, ::-1].argmax(axis=1)
    return {int(y + r): (int(x + a), int(x + b)) for r, a, b in zip(rows, first, last, strict=True)}


@dataclass(frozen=True)
class EdgeRows:
    """The silhouettes' edges on the image rows both cover, row by row (n rows, sorted).

    rows: (n,) image rows [px]; left_px, right_px: (n, 2) the (first, last) object column [px] of the
    left and of the right image's silhouette on each row; disparity_px: (n, 2) the disparity [px] of
    the left edges (column 0) and of the right edges (column 1), 0 where either image's edge lies on
    its window's first or last column: the image's border, or where the measurement window (CamShift's
    box of a big object close by) cut the silhouette; there the edge is not the object's contour."""

    rows: np.ndarray
    left_px: np.ndarray
    right_px: np.ndarray
    disparity_px: np.ndarray


def edge_rows(
    silhouette_left: np.ndarray,
    window_left: Window,
    silhouette_right: np.ndarray,
    window_right: Window,
    image_width_px: int,
) -> EdgeRows:
    """The silhouettes' matched edges row by row (:class:`EdgeRows`): on a row both cover, the leftmost
    object pixel of the left image and that of the right image see (nearly) the same point of the
    object's occluding contour; so do the rightmost ones. silhouette_*: boolean (h, w) masks of the
    object in each image's window (x, y, w, h) [px]. The one rule of which edges are the contour, for
    the edge stereo (:func:`edge_disparity_median`) and the footprint's outline (vision.footprint)."""
    left = silhouette_rows(silhouette_left, window_left)
    right = silhouette_rows(silhouette_right, window_right)
    rows = np.array(sorted(left.keys() & right.keys()), dtype=int)
    left_px = np.array([left[r] for r in rows], dtype=int).reshape(-1, 2)
    right_px = np.array([right[r] for r in rows], dtype=int).reshape(-1, 2)
    firsts = np.array([window_left[0], window_right[0]])
    lasts = (
        np.minimum([window_left[0] + window_left[2], window_right[0] + window_right[2]], image_width_px) - 1
    )
    inside_first = (left_px[:, 0] > firsts[0]) & (right_px[:, 0] > firsts[1])
    inside_last = (left_px[:, 1] < lasts[0]) & (right_px[:, 1] < lasts[1])
    disparity = (left_px - right_px) * np.stack([inside_first, inside_last], axis=1)
    return EdgeRows(rows, left_px, right_px, disparity)


def edge_disparity_median(
    silhouette_left: np.ndarray,
    window_left: Window,
    silhouette_right: np.ndarray,
    window_right: Window,
    image_width_px: int,
    min_rows: int = 3,
) -> tuple[float, int]:
    """Median disparity [px] of the silhouettes' left and right edges, row by row, and the edges used.

    silhouette_*: boolean (h, w) masks of the object in each image's window (x, y, w, h) [px]; the
    edges are :func:`edge_rows`' (those on an image's border or its window's are skipped).
    NotFoundError (reason ``no_disparity``) when fewer than ``min_rows`` edges remain.
    """
    edges = edge_rows(silhouette_left, window_left, silhouette_right, window_right, image_width_px)
    disparities = edges.disparity_px[edges.disparity_px != 0]
    if len(disparities) < min_rows:
        raise NotFoundError(
            f"edge stereo found only {len(disparities)} silhouette edges off the image and window borders in "
            "both images (the object is cut by both side borders, or seen in too few common rows)",
            {"reason": REASON_NO_DISPARITY},
        )
    return float(np.median(disparities)), len(disparities)


def dense_point(
    rig: StereoRig,
    centre_px: tuple[float, float],
    disparity_px: float,
    sphere_radius_m: float | None = None,
) -> np.ndarray:
    """Left-optical-frame point [m] at the centroid ray and the median surface disparity.

    For a sphere (``sphere_radius_m`` given) the point moves r / sqrt(2) further along the ray, from the
    median depth of the visible cap to the centre.
    """
    p = point_from_pixel_disparity(rig, centre_px[0], centre_px[1], disparity_px)
    if sphere_radius_m:
        p = p + p / np.linalg.norm(p) * (sphere_radius_m / math.sqrt(2.0))
    return p


def to_world(p_camera: np.ndarray, T_world_camera: np.ndarray) -> np.ndarray:
    """Points (..., 3) from a camera optical frame to the world frame, with the 4x4 pose T_world_camera."""
    return transform_points(T_world_camera, p_camera)
