"""Object detection on a back projection: CamShift, re-detection over the whole image, confidence.

Yoshida et al. (``001_771c0ce3779b0683.txt``, "Object Recognition and Localization"): "We use a method
called Continuously Adaptive Mean SHIFT (CAMSHIFT) algorithm [Bradski 1998] to locate the object center
and orientation in the back projection image."

CamShift climbs the back-projection mass from a starting window, so it needs a window that overlaps the
object. Measured: after the ball jumps 13 cm at 1.5 m (about 48 px, more than its 37 px diameter) the old
window sees nothing and CamShift returns an empty box. So every search starts from the connected blobs of
the thresholded back projection over the whole image (:func:`find_blobs`), and :class:`Tracker` falls back
to that re-detection whenever its CamShift window comes back empty or weak.

Per detection we report (all in pixels of that image):
- ``box``: CamShift's rotated rectangle ((u, v), (width, height), angle [deg]); its sides are 4 standard
  deviations of the back-projection mass (a uniform disc gives its diameter);
- ``centre_px``: the sub-pixel centroid of the object's silhouette in the window around the box (the
  supporting pixels, back projection >= threshold, closed morphologically), which is what stereo
  triangulation uses (CamShift's own centre is integer);
- ``confidence`` in [0, 1]: mean back projection of the supporting pixels / 255 times the fraction of the
  ellipse inscribed in the CamShift box that they fill (a uniform, fully typical disc scores about 1);
- ``score``: the supporting mass (sum of back projection / 255, i.e. "equivalent pixels"), used to rank
  candidates and to call two of them ambiguous.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import cv2
import numpy as np

from services.bus.schemas.perception import REASON_AMBIGUOUS, REASON_NOT_IN_VIEW
from services.errors import InvalidRequestError, NotFoundError

Window = tuple[int, int, int, int]  # x, y, width, height [px]
RotatedBox = tuple[tuple[float, float], tuple[float, float], float]  # (u, v), (w, h) [px], angle [deg]


@dataclass(frozen=True)
class DetectionConfig:
    """Detection parameters.

    threshold: back-projection value (0..255) from which a pixel supports the object.
    min_area_px: smallest blob (supporting pixels) taken as an object.
    close_kernel_px: morphological closing that joins a blob split by texture or thin occluders (0 = off).
    max_candidates: blobs tried, largest first.
    camshift_iterations, camshift_eps_px: stop criteria of the mean shift inside CamShift.
    window_margin: the measurement window is the CamShift box's bounding rectangle grown by this fraction.
    min_confidence: detections below it are rejected (tracker: re-detect).
    ambiguity_ratio: a second candidate with score >= ratio x the best one makes the detection ambiguous.
    """

    threshold: int = 40
    min_area_px: int = 15
    close_kernel_px: int = 5
    max_candidates: int = 6
    camshift_iterations: int = 10
    camshift_eps_px: float = 0.5
    window_margin: float = 0.3
    min_confidence: float = 0.2
    ambiguity_ratio: float = 0.6

    def __post_init__(self) -> None:
        if not 0 < self.threshold < 256:
            raise InvalidRequestError(f"threshold must be in 1..255, got {self.threshold}")
        if not 0.0 < self.ambiguity_ratio <= 1.0:
            raise InvalidRequestError(f"ambiguity_ratio must be in (0, 1], got {self.ambiguity_ratio}")


@dataclass(frozen=True)
class Detection:
    """One object found in one image (pixels of that image; see the module doc for the fields)."""

    name: str
    centre_px: tuple[float, float]
    box: RotatedBox
    window: Window
    score: float
    area_px: int
    confidence: float
    touches_border: bool
    redetected: bool = False
    border_sides: tuple[str, ...] = ()  # image borders the support touches: "left", "right", "top", "bottom"


@dataclass(frozen=True)
class Blob:
    """A connected region of the thresholded back projection: bounding window, pixel count, mass."""

    window: Window
    area_px: int
    score: float


@functools.lru_cache(maxsize=8)
def _kernel(size_px: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size_px, size_px))


def find_blobs(bp: np.ndarray, config: DetectionConfig) -> list[Blob]:
    """Connected blobs of ``bp >= threshold`` (after closing), by decreasing mass, at most max_candidates."""
    support = (bp >= config.threshold).astype(np.uint8)
    if config.close_kernel_px > 1:
        support = cv2.morphologyEx(support, cv2.MORPH_CLOSE, _kernel(config.close_kernel_px))
    # External contours are much cheaper than connectedComponentsWithStats on mostly empty images.
    contours, _ = cv2.findContours(support, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    rects = [cv2.boundingRect(c) for c in contours]
    order = [
        i
        for i in np.argsort([-r[2] * r[3] for r in rects])
        if rects[i][2] * rects[i][3] >= config.min_area_px
    ]
    blobs = []
    for i in order[: 2 * config.max_candidates]:
        x, y, w, h = rects[i]
        inside = np.zeros((h, w), np.uint8)
        cv2.drawContours(inside, contours, int(i), 1, -1, offset=(-x, -y))
        roi = bp[y : y + h, x : x + w]
        # Only truly supporting pixels count, not the ones the closing filled in.
        sel = (inside > 0) & (roi >= config.threshold)
        area = int(np.count_nonzero(sel))
        if area >= config.min_area_px:
            blobs.append(Blob((x, y, w, h), area, float(roi[sel].sum()) / 255.0))
    blobs.sort(key=lambda b: -b.score)
    return blobs[: config.max_candidates]


def camshift(bp: np.ndarray, window: Window, config: DetectionConfig) -> tuple[RotatedBox, Window] | None:
    """CamShift (Bradski 1998) from ``window``; None when the window holds no mass (object lost)."""
    x, y, w, h = window
    if w <= 0 or h <= 0:
        return None
    crit = (
        cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT,
        config.camshift_iterations,
        config.camshift_eps_px,
    )
    box, new_window = cv2.CamShift(bp, (int(x), int(y), int(w), int(h)), crit)
    (u, v), (bw, bh), angle = box
    if bw <= 0 or bh <= 0:
        return None
    return ((float(u), float(v)), (float(bw), float(bh)), float(angle)), tuple(int(c) for c in new_window)


def _grow(box: RotatedBox, margin: float, shape: tuple[int, int]) -> Window:
    """Bounding window of ``box`` grown by ``margin`` (fraction) + 2 px, clipped to the image."""
    x, y, w, h = cv2.boundingRect(cv2.boxPoints(box).astype(np.float32))
    dx, dy = int(np.ceil(w * margin / 2)) + 2, int(np.ceil(h * margin / 2)) + 2
    x0, y0 = max(0, x - dx), max(0, y - dy)
    x1, y1 = min(shape[1], x + w + dx), min(shape[0], y + h + dy)
    return x0, y0, max(0, x1 - x0), max(0, y1 - y0)


def measure(
    bp: np.ndarray, name: str, box: RotatedBox, config: DetectionConfig, redetected: bool = False
) -> Detection | None:
    """Sub-pixel centroid, score and confidence of the supporting mass around a CamShift ``box``."""
    x, y, w, h = _grow(box, config.window_margin, bp.shape)
    if w == 0 or h == 0:
        return None
    roi = bp[y : y + h, x : x + w]
    support = roi >= config.threshold
    weights = np.where(support, roi, 0).astype(np.float32)
    # Sub-pixel centre: centroid of the object's silhouette, the support closed morphologically so pixels
    # dropped by noise inside the object do not move it. Weighting by the raw back projection instead is
    # 1.7x (noise 2 grey levels) to 3x (noise 6) noisier: pixel noise moves pixels between neighbouring
    # histogram bins (measured disparity std at 2.5 m: 0.044 px silhouette, 0.059 px saturated weights,
    # 0.136 px raw weights).
    silhouette = support.astype(np.uint8)
    if config.close_kernel_px > 1:
        silhouette = cv2.morphologyEx(silhouette, cv2.MORPH_CLOSE, _kernel(config.close_kernel_px))
    m = cv2.moments(silhouette, binaryImage=True)
    if m["m00"] <= 0:
        return None
    u, v = x + m["m10"] / m["m00"], y + m["m01"] / m["m00"]
    area = int(np.count_nonzero(support))
    # Fill of the ellipse inscribed in the CamShift box (local coordinates of the roi).
    (bu, bv), (bw, bh), angle = box
    ellipse = np.zeros((h, w), np.uint8)
    cv2.ellipse(ellipse, ((bu - x, bv - y), (bw, bh), angle), 1, -1)
    n_ellipse = int(np.count_nonzero(ellipse))
    fill = np.count_nonzero(support & (ellipse > 0)) / n_ellipse if n_ellipse else 0.0
    strength = float(weights[support].mean()) / 255.0 if area else 0.0
    H, W = bp.shape
    ys, xs = np.nonzero(support)
    sides: tuple[str, ...] = ()
    if area:
        at = (x + xs.min() <= 0, x + xs.max() >= W - 1, y + ys.min() <= 0, y + ys.max() >= H - 1)
        sides = tuple(side for side, hit in zip(("left", "right", "top", "bottom"), at, strict=True) if hit)
    return Detection(
        name,
        (float(u), float(v)),
        box,
        (x, y, w, h),
        float(weights.sum()) / 255.0,
        area,
        strength * fill,
        bool(sides),
        redetected,
        sides,
    )


def _overlap(a: Window, b: Window) -> bool:
    return a[0] < b[0] + b[2] and b[0] < a[0] + a[2] and a[1] < b[1] + b[3] and b[1] < a[1] + a[3]


def detect_all(bp: np.ndarray, name: str, config: DetectionConfig | None = None) -> list[Detection]:
    """Every distinct candidate of object ``name`` over the whole back projection, best score first.

    Each blob seeds CamShift; candidates whose CamShift windows converge onto an already found one are
    merged; candidates under ``min_confidence`` are dropped.
    """
    config = config or DetectionConfig()
    found: list[Detection] = []
    for blob in find_blobs(bp, config):
        if any(_overlap(blob.window, d.window) for d in found):
            continue
        result = camshift(bp, blob.window, config)
        if result is None:
            continue
        det = measure(bp, name, result[0], config, redetected=True)
        if det is None or det.confidence < config.min_confidence or det.area_px < config.min_area_px:
            continue
        if any(
            np.hypot(det.centre_px[0] - d.centre_px[0], det.centre_px[1] - d.centre_px[1]) < 2 for d in found
        ):
            continue
        found.append(det)
    found.sort(key=lambda d: -d.score)
    return found


def check_unambiguous(candidates: list[Detection], config: DetectionConfig, where: str = "") -> Detection:
    """The best candidate; NotFoundError when there is none or a second one scores nearly as well."""
    if not candidates:
        raise NotFoundError(
            f"not in view: no region of the colour of {where or 'the object'}", {"reason": REASON_NOT_IN_VIEW}
        )
    best = candidates[0]
    if len(candidates) > 1 and candidates[1].score >= config.ambiguity_ratio * best.score:
        second = candidates[1]
        raise NotFoundError(
            f"ambiguous: two blobs of similar score for {where or best.name} at pixels "
            f"({best.centre_px[0]:.0f}, {best.centre_px[1]:.0f}) score {best.score:.0f} and "
            f"({second.centre_px[0]:.0f}, {second.centre_px[1]:.0f}) score {second.score:.0f} "
            f"(ratio {second.score / best.score:.2f} >= {config.ambiguity_ratio})",
            {"reason": REASON_AMBIGUOUS, "pixels": [list(best.centre_px), list(second.centre_px)]},
        )
    return best


class Tracker:
    """CamShift tracking of named objects across frames of one camera, with re-detection when lost.

    ``update(name, bp)`` runs CamShift from the object's previous window; when that returns an empty box
    or a detection under ``min_confidence``, it re-detects over the whole image (:func:`detect_all`) and
    restarts from the best candidate. Not thread-safe; one Tracker per camera stream.
    """

    def __init__(self, config: DetectionConfig | None = None) -> None:
        self.config = config or DetectionConfig()
        self._windows: dict[str, Window] = {}
        self.redetections: dict[str, int] = {}

    def window(self, name: str) -> Window | None:
        """The current search window of ``name`` (None before the first detection or after a loss)."""
        return self._windows.get(name)

    def forget(self, name: str) -> None:
        """Drop the track of ``name`` (the next update re-detects)."""
        self._windows.pop(name, None)

    def update(self, name: str, bp: np.ndarray) -> Detection | None:
        """Track ``name`` in the back projection ``bp`` of a new frame; None when it is nowhere to be seen."""
        cfg = self.config
        previous = self._windows.get(name)
        if previous is not None:
            result = camshift(bp, previous, cfg)
            if result is not None:
                det = measure(bp, name, result[0], cfg)
                if (
                    det is not None
                    and det.confidence >= cfg.min_confidence
                    and det.area_px >= cfg.min_area_px
                ):
                    self._windows[name] = result[1]
                    return det
        candidates = detect_all(bp, name, cfg)
        if not candidates:
            self._windows.pop(name, None)
            return None
        best = candidates[0]
        self.redetections[name] = self.redetections.get(name, 0) + 1
        # Restart CamShift from the re-detected box so the next frame continues as a track.
        self._windows[name] = _grow(best.box, 0.0, bp.shape)
        return replace(best, redetected=True)
