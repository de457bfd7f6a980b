"""Colour models of objects: 2D Hue-Saturation histograms learned from sample images.

Implements the learning step of "Object Recognition and Localization" in Yoshida et al.
(``001_771c0ce3779b0683.txt``): "the model of the objects to be detected are previously learned using two
dimensional histogram in the {Hue, Saturation} color space by taking a sample image". Value (brightness)
is left out so the model does not depend on shading; pixels too grey (low saturation) or too dark (low
value) are ignored, since their hue is noise (Bradski's CamShift paper, ref. 26 there, does the same).

Histogram layout: ``hist[h_bin, s_bin]`` over OpenCV's 8-bit HSV (hue 0..179, saturation 0..255),
Gaussian-smoothed (hue wraps around) so unseen shades next to the learned ones still count, and scaled
so its largest bin is 1: back projection then reads it as "how typical of the object is this colour".

Models are JSON files (readable, diffable, no pickle) named ``<name>.json`` in a models directory.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

from services.errors import InvalidRequestError, NotFoundError

MODEL_FORMAT = "humanoid-vision/hs-histogram"
MODEL_VERSION = 1
DEFAULT_MODELS_DIR = Path(__file__).resolve().parent / "models"
_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_\-]{0,63}$")
SHAPES = ("blob", "sphere")


@dataclass(frozen=True)
class HistogramConfig:
    """How a Hue-Saturation model is built (stored with the model, used again at back projection).

    h_bins, s_bins: histogram bins over hue 0..180 and saturation 0..256 (OpenCV 8-bit HSV).
    s_min, v_min, v_max: pixels with saturation < s_min, value < v_min or value > v_max are ignored, both
      when learning and when back projecting (grey, black and blown-out pixels have no reliable hue).
    smooth_sigma_bins: std of the Gaussian smoothing of the histogram [bins]; hue wraps around.
    """

    h_bins: int = 30
    s_bins: int = 32
    s_min: int = 60
    v_min: int = 40
    v_max: int = 255
    smooth_sigma_bins: float = 0.7

    def __post_init__(self) -> None:
        if not (2 <= self.h_bins <= 180 and 2 <= self.s_bins <= 256):
            raise InvalidRequestError(
                f"h_bins must be in [2, 180] and s_bins in [2, 256], got {self.h_bins}, {self.s_bins}"
            )
        if not (0 <= self.s_min <= 255 and 0 <= self.v_min <= self.v_max <= 255):
            raise InvalidRequestError(
                f"need 0 <= s_min <= 255 and 0 <= v_min <= v_max <= 255, got s_min={self.s_min}, "
                f"v_min={self.v_min}, v_max={self.v_max}"
            )
        if self.smooth_sigma_bins < 0:
            raise InvalidRequestError(f"smooth_sigma_bins must be >= 0, got {self.smooth_sigma_bins}")


@dataclass(frozen=True, eq=False)
class ObjectModel:
    """A named object's colour model.

    hist: (h_bins, s_bins) float32, max 1. n_pixels: coloured pixels it was learned from.
    shape: "blob" (any object) or "sphere" (lets stereo methods that see only the front surface report
    the centre; see vision.stereo). floor_size_m: the sides of its floor rectangle [m] as catalogued
    with the views it was learned from (the scene's object description; None: unknown): a footprint
    seen partly hidden is grown to it (vision.footprint).
    """

    name: str
    hist: np.ndarray
    config: HistogramConfig = field(default_factory=HistogramConfig)
    n_pixels: int = 0
    shape: str = "blob"
    source: str = ""
    floor_size_m: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        check_name(self.name)
        if self.floor_size_m is not None and not (
            len(self.floor_size_m) == 2 and all(0.0 < v < 100.0 for v in self.floor_size_m)
        ):
            raise InvalidRequestError(
                f"model {self.name!r}: floor_size_m must be two sides in (0, 100) m, got {self.floor_size_m}"
            )
        if self.shape not in SHAPES:
            raise InvalidRequestError(f"shape must be one of {SHAPES}, got {self.shape!r}")
        expected = (self.config.h_bins, self.config.s_bins)
        if self.hist.shape != expected:
            raise InvalidRequestError(f"model {self.name!r}: hist shape {self.hist.shape} != bins {expected}")

    @property
    def lut(self) -> np.ndarray:
        """The histogram as cv2.calcBackProject expects it: float32, values 0..255."""
        return (self.hist * 255.0).astype(np.float32)


def check_name(name: str) -> str:
    """Validate an object name (lower-case letters, digits, '_' and '-'; it names the model file)."""
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise InvalidRequestError(
            f"object name {name!r} is not valid: use 1-64 lower-case letters, digits, '_' or '-', "
            "starting with a letter or digit (e.g. 'orange_ball')"
        )
    return name


def to_hsv(image_bgr: np.ndarray) -> np.ndarray:
    """8-bit HSV (hue 0..179) of a BGR uint8 image, as OpenCV defines it."""
    if not isinstance(image_bgr, np.ndarray) or image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise InvalidRequestError(
            f"expected an HxWx3 BGR image, got {getattr(image_bgr, 'shape', image_bgr)}"
        )
    if image_bgr.dtype != np.uint8:
        raise InvalidRequestError(f"expected a uint8 image, got dtype {image_bgr.dtype}")
    return cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)


def colour_mask(hsv: np.ndarray, config: HistogramConfig) -> np.ndarray:
    """uint8 mask (255 = usable) of pixels saturated and bright enough to have a meaningful hue."""
    return cv2.inRange(hsv, (0, config.s_min, config.v_min), (180, 255, config.v_max))


def rect_mask(shape: tuple[int, ...], rect: tuple[int, int, int, int]) -> np.ndarray:
    """Boolean mask of an image of ``shape`` with the rectangle ``(x, y, w, h)`` [px] set."""
    x, y, w, h = (int(v) for v in rect)
    H, W = shape[:2]
    if w <= 0 or h <= 0 or x < 0 or y < 0 or x + w > W or y + h > H:
        raise InvalidRequestError(f"rectangle (x={x}, y={y}, w={w}, h={h}) is not inside the {W}x{H} image")
    m = np.zeros((H, W), bool)
    m[y : y + h, x : x + w] = True
    return m


def learn_model(
    name: str,
    images_bgr: Sequence[np.ndarray],
    masks: Sequence[np.ndarray],
    config: HistogramConfig | None = None,
    shape: str = "blob",
    source: str = "",
    min_pixels: int = 50,
) -> ObjectModel:
    """Learn the Hue-Saturation histogram of object ``name`` from sample images and object masks.

    images_bgr: BGR uint8 images; masks: same-size boolean/uint8 masks (non-zero = object pixel).
    Raises InvalidRequestError when the masks hold fewer than ``min_pixels`` coloured pixels.
    """
    check_name(name)
    config = config or HistogramConfig()
    if len(images_bgr) == 0 or len(images_bgr) != len(masks):
        raise InvalidRequestError(
            f"need as many masks as images (at least one), got {len(images_bgr)} images, {len(masks)} masks"
        )
    acc = np.zeros((config.h_bins, config.s_bins), np.float32)
    n_masked = n_used = 0
    for k, (image, mask) in enumerate(zip(images_bgr, masks, strict=True)):
        hsv = to_hsv(image)
        m = np.asarray(mask)
        if m.shape != hsv.shape[:2]:
            raise InvalidRequestError(
                f"mask {k} is {m.shape[::-1]} px but image {k} is {hsv.shape[1::-1]} px"
            )
        m = (m != 0).astype(np.uint8) * 255
        n_masked += int(np.count_nonzero(m))
        m = cv2.bitwise_and(m, colour_mask(hsv, config))
        n_used += int(np.count_nonzero(m))
        acc += cv2.calcHist([hsv], [0, 1], m, [config.h_bins, config.s_bins], [0, 180, 0, 256])
    if n_used < min_pixels:
        raise InvalidRequestError(
            f"model {name!r}: only {n_used} of the {n_masked} masked pixels are coloured enough "
            f"(saturation >= {config.s_min}, value in [{config.v_min}, {config.v_max}]); "
            f"need >= {min_pixels}. "
            "Check the mask, or the object is grey/black/white and a hue-saturation model cannot describe it."
        )
    if config.smooth_sigma_bins > 0:
        acc = gaussian_filter(acc, config.smooth_sigma_bins, mode=("wrap", "constant"))
    hist = (acc / acc.max()).astype(np.float32)
    return ObjectModel(name, hist, config, n_used, shape, source)


def save_model(model: ObjectModel, models_dir: str | Path = DEFAULT_MODELS_DIR) -> Path:
    """Write ``model`` to ``<models_dir>/<name>.json`` (creating the directory); returns the path."""
    directory = Path(models_dir)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{model.name}.json"
    doc = {
        "format": MODEL_FORMAT,
        "version": MODEL_VERSION,
        "name": model.name,
        "shape": model.shape,
        "n_pixels": model.n_pixels,
        "source": model.source,
        **({} if model.floor_size_m is None else {"floor_size_m": [float(v) for v in model.floor_size_m]}),
        "config": asdict(model.config),
        "hist": [[round(float(v), 5) for v in row] for row in model.hist],
    }
    path.write_text(json.dumps(doc, indent=1) + "\n")
    return path


def load_model(path: str | Path) -> ObjectModel:
    """Read a model file written by :func:`save_model`."""
    p = Path(path)
    if not p.is_file():
        raise NotFoundError(f"no model file {p}")
    try:
        doc = json.loads(p.read_text())
    except json.JSONDecodeError as e:
        raise InvalidRequestError(f"model file {p} is not valid JSON: {e}") from e
    if doc.get("format") != MODEL_FORMAT or doc.get("version") != MODEL_VERSION:
        raise InvalidRequestError(
            f"model file {p} has format {doc.get('format')!r} v{doc.get('version')}, "
            f"expected {MODEL_FORMAT!r} v{MODEL_VERSION}"
        )
    try:
        config = HistogramConfig(**doc["config"])
        hist = np.asarray(doc["hist"], np.float32)
        n_pixels, source = int(doc["n_pixels"]), doc.get("source", "")
        floor = doc.get("floor_size_m")
        floor_size = None if floor is None else (float(floor[0]), float(floor[1]))
        return ObjectModel(doc["name"], hist, config, n_pixels, doc["shape"], source, floor_size)
    except (KeyError, TypeError, ValueError) as e:
        raise InvalidRequestError(f"model file {p} is malformed ({type(e).__name__}: {e})") from e


def load_models(models_dir: str | Path = DEFAULT_MODELS_DIR) -> dict[str, ObjectModel]:
    """All models ``*.json`` of a directory, by name (empty dict when the directory does not exist)."""
    directory = Path(models_dir)
    if not directory.is_dir():
        return {}
    return {m.name: m for m in (load_model(p) for p in sorted(directory.glob("*.json")))}


def select_models(models: dict[str, ObjectModel], names: Sequence[str]) -> list[ObjectModel]:
    """The models called ``names``; InvalidRequestError listing the known names for an unknown one."""
    unknown = [n for n in names if n not in models]
    if unknown:
        raise InvalidRequestError(
            f"unknown object {unknown[0]!r}: known objects are {sorted(models)}",
            {"field": "object", "valid": sorted(models)},
        )
    return [models[n] for n in names]
