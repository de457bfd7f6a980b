"""Histogram back projection.

Yoshida et al. (``001_771c0ce3779b0683.txt``, "Object Recognition and Localization"): "The object
detection is performed by back projecting the object histogram onto a video image. The back projection
image is obtained by replacing each pixel value by the corresponding value in the model histogram".
Pixels too grey, dark or bright for a reliable hue (the model's s_min / v_min / v_max) get 0.
"""

from __future__ import annotations

import cv2
import numpy as np

from vision.histogram import ObjectModel, colour_mask


def back_project(hsv: np.ndarray, model: ObjectModel, coloured: np.ndarray | None = None) -> np.ndarray:
    """Back projection of ``model`` onto an 8-bit HSV image: uint8 H x W, 255 = most typical colour.
    ``coloured``: the image's :func:`~vision.histogram.colour_mask` for ``model.config`` if already
    computed (None: computed here)."""
    bp = cv2.calcBackProject([hsv], [0, 1], model.lut, [0, 180, 0, 256], 1.0)
    return cv2.bitwise_and(bp, colour_mask(hsv, model.config) if coloured is None else coloured)
