"""One object seen in parts: two blobs of its colour that an occluder in front of it separates.

A table behind a chair (the chair's back in front of the middle of the table's top) shows its colour as
two blobs of similar mass, left and right of the chair's back: CamShift's detection (vision.camshift)
calls that ``ambiguous`` (two candidates of similar score), which is right for two objects of one
colour and wrong here (fetch layout ``table_to_box``: the re-look at the table from 3.2 m failed so,
and the robot kept an earlier glimpse of one leg at the image's corner, 55 cm off the table's centre,
walked along it and brushed the table). Yoshida et al. (``001_771c0ce3779b0683.txt``, "Object
Recognition and Localization") localize each learned object by its colour's back projection; what is
decided here is only whether two of its blobs are one object. They are when:

- their pixels are connected through the pixels of something else seen in front (the other learned
  objects' colours, the robot's own body: the occluder masks of vision.footprint), in each image of
  the pair (:func:`joined_through`): nothing but an occluder separates them;
- the two parts' centres, at the joined object's depth, lie within the object's catalogued floor
  diagonal of each other, with :data:`PARTS_SLACK_M` for the stereo noise: both fit on one object of
  its size (checked by the caller, vision.localize, which has the stereo).

The joined detection's window bounds the pixels of the object's colour connected to a part so; its
silhouette, centroid and score are measured there again (vision.camshift.measure). The footprint's
outline then runs from the leftmost part's left edges to the rightmost part's right edges, and the
edges next to the occluder are left out there (vision.footprint).

Frames: pixels of one image (vision's convention).
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from vision.camshift import Detection, DetectionConfig, measure

#: Two parts' centres may lie this much [m] farther apart than the object's floor diagonal (stereo noise
#: of the parts' centroids: about 10 cm at 4 m).
PARTS_SLACK_M = 0.15
#: Pixels [px] between a part and its occluder that still connect them (the silhouettes are closed
#: morphologically and anti-aliased: vision.footprint's ``OCCLUDER_GAP_PX``).
CONNECT_GAP_PX = 2


def joined_through(
    seed: Detection, bp: np.ndarray, occluder: np.ndarray | None, config: DetectionConfig
) -> Detection | None:
    """The detection of the pixels of the object's colour (back projection ``bp`` >= threshold)
    connected to ``seed``'s silhouette directly or through the ``occluder`` pixels (boolean (H, W),
    None: none), gaps up to :data:`CONNECT_GAP_PX` bridged: measured (vision.camshift.measure) in their
    bounding window, with the seed's confidence (the joined box is not the CamShift ellipse a whole
    silhouette fills). None without an occluder, or when nothing is measured there."""
    if occluder is None:
        return None
    own = bp >= config.threshold
    size = 2 * CONNECT_GAP_PX + 1
    region = cv2.dilate(
        (own | occluder).astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_RECT, (size, size))
    )
    _n, labels = cv2.connectedComponents(region)
    x, y, w, h = seed.window
    seed_labels = np.unique(labels[y : y + h, x : x + w][own[y : y + h, x : x + w]])
    seed_labels = seed_labels[seed_labels > 0]
    if len(seed_labels) == 0:
        return None
    x0, y0, w0, h0 = cv2.boundingRect((own & np.isin(labels, seed_labels)).astype(np.uint8))
    box = ((x0 + 0.5 * w0, y0 + 0.5 * h0), (float(w0), float(h0)), 0.0)
    det = measure(bp, seed.name, box, replace(config, window_margin=0.0), redetected=True)
    return None if det is None else replace(det, confidence=seed.confidence)
