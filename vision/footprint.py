"""An object's footprint on the floor from the 3D points of its silhouette's outline (stereo).

Yoshida et al. (``001_771c0ce3779b0683.txt``, "Object Recognition and Localization"): stereo "produces a
dense 3D image of the current scene [...] precise enough 3D points can be obtained in the vicinity of
the objects", and navigation avoids the objects so located ("Coupling the Motion Planner with
Perception"). Our renders are uniformly coloured (correlation finds nothing to match inside a face), so
the 3D points are those of the silhouette's outline: on each image row both silhouettes cover, the
leftmost object pixel of the left image and that of the right image see the same point of the object's
occluding contour (as in vision.stereo's ``"edges"`` estimator), and so do the rightmost ones. Each
matched edge is triangulated. For a box-like object (a box, a table, a chair) these contour points lie
on its outline: the far edges of its top, its vertical edges or legs, the bottom edges in front. Their
horizontal projection, wrapped in the minimum-area rectangle, gives the object's yaw, which the
silhouette's width alone cannot give; each side of that rectangle then moves to the median of the points
nearest to it (the rectangle wraps the outermost points, which whole-pixel disparities scatter in
depth: 20 cm per pixel at 4 m), which gives the footprint's centre and size.

Edges on the image's left or right border, or on its measurement window's, are skipped (the object is
cut there); points farther than ``max_extent_m`` from the object's located centre are outliers (a
mismatched row) and are dropped.
An edge next to another object's silhouette (``occluder_left`` / ``occluder_right``: the pixels of the
other learned objects) is not this object's contour but where that object hides it: its disparity is
the occluder's, and its point lies on the occluder, nearer the camera (a table half behind a chair was
mapped 0.2-0.8 m toward the robot, and the put missed it: fetch seeds 13, 21, 23). Such edges are
dropped too; the hidden side then rests on the edges that are seen.

Frames: world (z up) [m]; pixels in vision's convention (pixel centres at integer coordinates).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from services.model.ground import Rectangle
from vision.camera import StereoRig
from vision.camshift import Window
from vision.stereo import edge_rows, to_world

#: Fewer matched outline points than this give no footprint.
MIN_POINTS = 8
#: Running-median window [rows] and tolerance (the larger of [px] and a fraction of the disparity) of
#: the edge disparities along one side of the silhouette.
CONSISTENCY_WINDOW_ROWS = 31
CONSISTENCY_TOLERANCE_PX = 1.0
CONSISTENCY_FRACTION = 0.04
#: How far [fraction of the disparity] the rows within half a window of either end of a side may be
#: from the median of the window of rows nearest that end (:func:`_consistent`): a corner's other
#: contour there (the far edge of a top on the first rows, a box's near bottom edge on the last) or a
#: slanted edge was up to 12.5 % off a line through them in 80 sides of the table, box and chair seen
#: from 0.7-4 m in fetch looks (seeds 0, 18, 40, 63, 64); an edge paired with another leg's contour,
#: 400 % (seed 40's put look).
CONSISTENCY_END_FRACTION = 0.25
#: A side of the rectangle moves to the median of the points nearest to it when it has this many.
MIN_SIDE_POINTS = 5
#: Rectangles within this fraction of the least area compete on how well the points fit their boundary.
AREA_SLACK = 0.1
#: The top is the highest height [m] with at least ``TOP_SUPPORT_FRACTION`` of the points (and
#: ``MIN_POINTS``) within ``TOP_BAND_M`` below it: edges mismatched behind an occluder (an arm in front
#: of the table in one image) triangulate nearer, hence higher, but few of them at any one height. A
#: thin tall part has no such height (a chair's back seen from its side: its edge's points spread over
#: 0.45 m, and the seat's rows gave the top, 0.5 m instead of 0.9 m; the arms, above 0.53 m, were not
#: kept clear of it and the walk brushed it, fetch seed 64): the top is also at least the highest point
#: of every unbroken run of ``CONSISTENCY_WINDOW_ROWS`` rows on one side (a contour seen whole; a
#: mismatched run that long is not kept by :func:`_consistent`).
TOP_BAND_M = 0.03
TOP_SUPPORT_FRACTION = 0.03
#: Outline points higher than the top by more than this [m] are not the object's and are left out of
#: its rectangle: an edge paired with another contour in the other image (an occluder's, another
#: part's) triangulates off along the ray, and nearer the camera, which looks down, is higher (fetch
#: seed 40's put look: 4 points at 1.05 m above a 0.73 m top stretched the table to 1.46 m). The
#: top itself holds 3 % of the points within ``TOP_BAND_M`` (or a whole outline run): a few such
#: points do not raise it.
ABOVE_TOP_M = 0.1
#: A rectangle shorter than the object's known floor size by more than this [m] is grown to it
#: (:func:`_to_known_size`), from the side with ``ANCHOR_RATIO`` times the points of the other.
KNOWN_SIZE_TOLERANCE_M = 0.08
ANCHOR_RATIO = 2.0
#: A rectangle longer or wider than the object's known floor size by more than this [m] is not a
#: measurement of it and gives no footprint (refused: the caller keeps what it knew, or looks again).
#: Whole-pixel disparities legitimately stretch a side by up to 20 cm at 4 m (``scripts/bench
#: perception``: +17.9 cm long side, +20.4 cm short side at most; 87 dumped fetch looks of the table at
#: 1-3.6 m: +18 cm at most); an edge paired with another contour on a run of rows in the middle of a
#: side, which neither :func:`_consistent` nor ``ABOVE_TOP_M`` catches, made a 1.0 m table 1.70 m long
#: (fetch seed 47's approach look, the robot then stepped back 0.34 m "to make room" from the phantom).
OVERSIZE_TOLERANCE_M = 0.3
#: An edge whose outside neighbour within this many pixels belongs to an occluder is dropped (the
#: silhouettes are closed morphologically and anti-aliased: a pixel or two lies between them).
OCCLUDER_GAP_PX = 2


@dataclass(frozen=True)
class Footprint:
    """A horizontal rectangle on the floor: centre (x, y) [m], size (along its yaw, across) [m], yaw [rad]
    in (-pi/2, pi/2], its top ``top_z_m`` [m] (world; see ``TOP_BAND_M``), ``n_points`` used,
    ``n_hidden`` outline edges left out next to an occluder (:class:`Outline`): how much of its outline
    was not seen."""

    center_m: tuple[float, float]
    size_m: tuple[float, float]
    yaw_rad: float
    top_z_m: float
    n_points: int
    n_hidden: int = 0


@dataclass(frozen=True)
class Outline:
    """The world points (n, 3) [m] of an object's matched outline edges, and ``n_hidden``: the edges
    matched in both images but left out next to an occluder (another object, the robot's own body);
    ``runs``: the indices into ``points`` of each unbroken run of at least ``CONSISTENCY_WINDOW_ROWS``
    consecutive rows kept on one side (a contour seen whole: a leg, a vertical edge, a chair's back)."""

    points: np.ndarray
    n_hidden: int = 0
    runs: tuple[np.ndarray, ...] = ()


def outline_points(
    silhouette_left: np.ndarray,
    window_left: Window,
    silhouette_right: np.ndarray,
    window_right: Window,
    rig: StereoRig,
    T_world_left_camera: np.ndarray,
    occluder_left: np.ndarray | None = None,
    occluder_right: np.ndarray | None = None,
) -> Outline:
    """World points (n, 3) [m] of the silhouettes' matched left and right edges, row by row.

    An edge lies between its object pixel and the background pixel next to it (half a pixel outward);
    the disparity is the same in both images, so only the column used for the ray moves.
    ``occluder_left``, ``occluder_right``: boolean (H, W) masks of the whole images where other objects
    are seen (None: none); an edge within :data:`OCCLUDER_GAP_PX` of one in either image is dropped
    (module docstring).
    """
    # Edges on a window's first or last column (the image's border or where the measurement window
    # cut the silhouette: CamShift's box of a big object close by) are not the object's contour: 0.
    edges = edge_rows(silhouette_left, window_left, silhouette_right, window_right, rig.intrinsics.width)
    rows = [int(r) for r in edges.rows]
    hidden = 0

    def free(i: int, side: int) -> bool:  # no occluder just outside either image's edge on row i
        nonlocal hidden
        r = rows[i]
        if _beside(occluder_left, r, int(edges.left_px[i, side]), side) or _beside(
            occluder_right, r, int(edges.right_px[i, side]), side
        ):
            hidden += 1
            return False
        return True

    sides = (  # (columns, disparities) of the left edges, then of the right edges
        (
            edges.left_px[:, side] + (0.5 if side else -0.5),
            [
                int(edges.disparity_px[i, side]) if edges.disparity_px[i, side] and free(i, side) else 0
                for i in range(len(rows))
            ],
        )
        for side in (0, 1)
    )
    u, v, d = [], [], []
    runs = []
    for columns, disparities in sides:
        keep = _consistent(np.asarray(disparities, dtype=float))
        runs += [len(u) + run for run in _runs(np.asarray(rows)[keep], CONSISTENCY_WINDOW_ROWS)]
        u.extend(np.asarray(columns)[keep])
        v.extend(np.asarray(rows)[keep])
        d.extend(np.asarray(disparities, dtype=float)[keep])
    if not u:
        return Outline(np.zeros((0, 3)), hidden)
    k = rig.intrinsics
    u_px, v_px, d_px = (np.asarray(a, dtype=float) for a in (u, v, d))
    z = k.fx * rig.baseline_m / d_px
    p_camera = np.stack([(u_px - k.cx) * z / k.fx, (v_px - k.cy) * z / k.fy, z], axis=1)
    return Outline(to_world(p_camera, T_world_left_camera), hidden, tuple(runs))


def _runs(rows: np.ndarray, min_rows: int) -> list[np.ndarray]:
    """Index arrays of the runs of consecutive values in the sorted ``rows`` [px] at least ``min_rows``
    long."""
    if len(rows) == 0:
        return []
    breaks = np.flatnonzero(np.diff(rows) != 1) + 1
    return [run for run in np.split(np.arange(len(rows)), breaks) if len(run) >= min_rows]


def _beside(occluder: np.ndarray | None, row: int, col: int, side: int) -> bool:
    """Whether ``occluder`` (H, W) has a pixel within :data:`OCCLUDER_GAP_PX` outside the edge at
    (``row``, ``col``) [px]: to its left for a left edge (``side`` 0), to its right for a right one."""
    if occluder is None:
        return False
    if side == 0:
        return bool(occluder[row, max(0, col - OCCLUDER_GAP_PX) : col].any())
    return bool(occluder[row, col + 1 : col + 1 + OCCLUDER_GAP_PX].any())


def _consistent(disparity_px: np.ndarray) -> np.ndarray:
    """Mask of the edges (one side, row by row) whose disparity agrees with the running median of the
    rows around it: an edge occluded in one image only (an object in front of it) gives a run of wrong
    disparities shorter than the window; a disparity <= 0 (edge on the border) is never kept.

    The window is padded at either end with the end row's own value (a slanted edge's disparity,
    changing linearly along the rows, is then met exactly there too); so the end row is always the
    median of its own window, and a short run there as well. The rows within half a window of either
    end must therefore also lie within ``CONSISTENCY_END_FRACTION`` of the median of the
    ``CONSISTENCY_WINDOW_ROWS`` edges kept nearest that end (all of them when fewer; rows left out
    next to an occluder do not count): an end may be another contour of the object (a corner: the far
    edge of a top on its first rows), not another object's or another part's. Without it: a table
    running out of the image's bottom, its near right leg behind the robot's hand in one image and seen
    below it in the other, got that leg's edge paired with the other leg's on its bottom 4 rows, 342 px
    of disparity where the rows above had 68, a point 0.47 m in front of the table; the table was
    mapped 1.46 m long instead of 1.0 and the put lowered the ball onto nothing (fetch seed 40, and
    seeds 14, 29, 44, 45 alike; seed 47's approach look had 8 such rows, 305 px, after 6 left out next
    to the hand)."""
    n = len(disparity_px)
    if n == 0:
        return np.zeros(0, dtype=bool)
    d = np.asarray(disparity_px, dtype=float)
    half = CONSISTENCY_WINDOW_ROWS // 2
    padded = np.pad(d, half, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)
    valid = windows > 0
    median = np.array([np.median(w[m]) if m.any() else 0.0 for w, m in zip(windows, valid, strict=True)])
    tolerance = np.maximum(CONSISTENCY_TOLERANCE_PX, CONSISTENCY_FRACTION * median)
    keep = (d > 0) & (np.abs(d - median) <= tolerance)
    seen = d[d > 0]
    for nearest, ends in (
        (seen[:CONSISTENCY_WINDOW_ROWS], slice(0, half)),
        (seen[-CONSISTENCY_WINDOW_ROWS:], slice(max(0, n - half), n)),
    ):
        if len(nearest):
            near_end = float(np.median(nearest))
            slack = max(CONSISTENCY_TOLERANCE_PX, CONSISTENCY_END_FRACTION * near_end)
            keep[ends] &= np.abs(d[ends] - near_end) <= slack
    return keep


def _rectangle(xy: np.ndarray) -> tuple[tuple[float, float], tuple[float, float], float]:
    """The rectangle of the points: among the minimum-area ones (rotating calipers over the convex
    hull's edges, within ``AREA_SLACK`` of the least area), the one its points lie closest to the
    boundary of. Three corners of a rectangle and the edges between them (the fourth corner hidden
    behind the object) fit equally well in the rectangle along the hypotenuse: the outline points lie
    on the true rectangle's boundary, not across it. Returns (centre, (length along yaw, width), yaw)."""
    hull = cv2.convexHull(xy.astype(np.float32)).reshape(-1, 2).astype(float)
    if len(hull) < 3:
        raise ValueError("degenerate outline")
    edges = np.roll(hull, -1, axis=0) - hull
    angles = np.unique(np.round(np.arctan2(edges[:, 1], edges[:, 0]) % (math.pi / 2.0), 9))
    candidates = []
    for angle in angles:
        axes = Rectangle((0.0, 0.0), (0.0, 0.0), float(angle))  # the candidate's axes through the origin
        local = axes.to_local(xy)  # coordinates along (c, s) and (-s, c)
        lo, hi = local.min(axis=0), local.max(axis=0)
        area = float(np.prod(hi - lo))
        to_boundary = np.minimum(np.abs(local - lo), np.abs(hi - local)).min(axis=1)
        cx, cy = axes.to_world(0.5 * (lo + hi))[0]
        candidates.append(
            (area, float(np.mean(to_boundary)), (float(cx), float(cy)), tuple(hi - lo), float(angle))
        )
    least = min(candidate[0] for candidate in candidates)
    _area, _fit, centre, size, yaw = min(
        (candidate for candidate in candidates if candidate[0] <= least * (1.0 + AREA_SLACK)),
        key=lambda candidate: candidate[1],
    )
    return centre, size, yaw


def _median_sides(
    xy: np.ndarray, centre: tuple[float, float], size: tuple[float, float], yaw: float
) -> tuple[tuple[float, float], tuple[float, float], tuple[int, int, int, int]]:
    """The rectangle (centre, size along yaw and across) with each side moved to the median of the
    points nearest to it (at least :data:`MIN_SIDE_POINTS` of them, else the side stays), and the
    number of points nearest to each side (low and high along the yaw, low and high across).

    The outline points of a side scatter about it in depth: each matched edge has a whole-pixel
    disparity, off by up to a pixel (20 cm at 4 m with the wide pair). The minimum-area rectangle wraps
    the outermost of them, so it grows with the noise; the median of a side's points does not."""
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    local = (xy - np.asarray(centre)) @ R  # coordinates along the yaw and across
    half = 0.5 * np.asarray(size, dtype=float)
    lo, hi = -half.copy(), half.copy()
    to_side = np.abs(
        np.stack(
            [local[:, 0] + half[0], half[0] - local[:, 0], local[:, 1] + half[1], half[1] - local[:, 1]],
            axis=1,
        )
    )
    nearest = np.argmin(to_side, axis=1)
    n = [int(np.count_nonzero(nearest == side)) for side in range(4)]
    counts = (n[0], n[1], n[2], n[3])
    for side, (axis, bound) in enumerate(((0, lo), (0, hi), (1, lo), (1, hi))):
        on_side = nearest == side
        if counts[side] >= MIN_SIDE_POINTS:
            bound[axis] = np.median(local[on_side, axis])
    middle = R @ (0.5 * (lo + hi)) + np.asarray(centre)
    return (float(middle[0]), float(middle[1])), (float(hi[0] - lo[0]), float(hi[1] - lo[1])), counts


def _to_known_size(
    centre: tuple[float, float],
    size: tuple[float, float],
    yaw: float,
    counts: tuple[int, int, int, int],
    known: tuple[float, float],
    camera_xy: np.ndarray | None,
) -> tuple[tuple[float, float], tuple[float, float]]:
    """The rectangle grown to the object's ``known`` floor size [m] where it came out shorter by more
    than :data:`KNOWN_SIZE_TOLERANCE_M` (part of its outline hidden: by another object in front of
    one end, by itself behind what is seen; which fitted side is the known long one: below): the
    better-seen side of that axis stays (the one with
    :data:`ANCHOR_RATIO` times the points of the other, else the one nearer ``camera_xy``, else both
    move apart evenly) and the other moves out. A side longer than known is left as fitted (the
    extra points may be the object's as well as another's: nothing says which side to cut)."""
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    big, small = max(known), min(known)
    target = (big, small) if size[0] >= size[1] else (small, big)
    # Which fitted side is which known one: the longer to the longer, unless the other way round more
    # sides already match (within the tolerance). A 1.0 x 0.6 m table with all but 0.45 m of its length
    # hidden fits as 0.45 x 0.6: its 0.6 m side is the known short one, not the long.
    swapped = (target[1], target[0])

    def matching(t: tuple[float, float]) -> int:
        return sum(abs(t[i] - size[i]) <= KNOWN_SIZE_TOLERANCE_M for i in (0, 1))

    if matching(swapped) > matching(target):
        target = swapped
    lo, hi = -0.5 * np.asarray(size, dtype=float), 0.5 * np.asarray(size, dtype=float)
    camera = None if camera_xy is None else (np.asarray(camera_xy, dtype=float) - np.asarray(centre)) @ R
    for axis in (0, 1):
        grow = target[axis] - (hi[axis] - lo[axis])
        if grow <= KNOWN_SIZE_TOLERANCE_M:
            continue
        n_lo, n_hi = counts[2 * axis], counts[2 * axis + 1]
        if n_lo >= ANCHOR_RATIO * max(n_hi, 1):
            hi[axis] += grow
        elif n_hi >= ANCHOR_RATIO * max(n_lo, 1):
            lo[axis] -= grow
        elif camera is not None and abs(camera[axis]) > 1e-6:
            if camera[axis] < 0.0:  # the low side faces the camera: the high side was hidden
                hi[axis] += grow
            else:
                lo[axis] -= grow
        else:
            lo[axis] -= 0.5 * grow
            hi[axis] += 0.5 * grow
    middle = R @ (0.5 * (lo + hi)) + np.asarray(centre)
    return (float(middle[0]), float(middle[1])), (float(hi[0] - lo[0]), float(hi[1] - lo[1]))


def _oversized(size: tuple[float, float], known: tuple[float, float]) -> bool:
    """Whether the rectangle's longer or shorter side [m] exceeds the ``known`` one's by more than
    :data:`OVERSIZE_TOLERANCE_M`."""
    return bool(np.any(np.sort(size) - np.sort(known) > OVERSIZE_TOLERANCE_M))


def _top(z_m: np.ndarray) -> float:
    """The highest well-supported height of the points [m] (see ``TOP_BAND_M``)."""
    z = np.sort(z_m)[::-1]
    support = max(MIN_POINTS, math.ceil(TOP_SUPPORT_FRACTION * len(z)))
    # points in [z_i - band, z_i]: those at or above z_i - band, less the i ones above z_i
    below = np.searchsorted(-z, -(z - TOP_BAND_M), side="right") - np.arange(len(z))
    supported = np.flatnonzero(below >= support)
    return float(z[supported[0]] if len(supported) else np.median(z))


def _near(xy: np.ndarray, centre_xy: np.ndarray, max_extent_m: float) -> np.ndarray:
    """Mask of the points within ``max_extent_m`` [m] of the located centre, or, when that holds fewer
    than half of them, of the points' own median: the located centre (the triangulated centroids of the
    two silhouettes) is off when an occluder hides different parts of the object in each image (the
    chair in front of the table hid its left legs in one image and its right leg in the other: the
    centre came out 1 m away and a 1.0 x 0.6 m table was fitted to the 20 points left, fetch seed 21)."""
    near = np.linalg.norm(xy - centre_xy, axis=1) <= max_extent_m
    if len(xy) == 0 or 2 * np.count_nonzero(near) >= len(xy):
        return near
    return np.linalg.norm(xy - np.median(xy, axis=0), axis=1) <= max_extent_m


def footprint(
    points_world: np.ndarray,
    centre_world: np.ndarray,
    max_extent_m: float = 1.0,
    n_hidden: int = 0,
    runs: tuple[np.ndarray, ...] = (),
    known_size_m: tuple[float, float] | None = None,
    camera_xy: np.ndarray | None = None,
) -> Footprint | None:
    """The minimum-area rectangle of the points' horizontal projection (see the module docstring).

    points_world: (n, 3) [m]; centre_world: the object's located centre [m] (points farther than
    ``max_extent_m`` from it horizontally are dropped, see :func:`_near`); ``n_hidden``: the outline's
    edges left out next to an occluder (:class:`Outline`), reported; ``runs``: the outline's unbroken
    runs (:class:`Outline`), whose highest points bound the top from below (:func:`_top`);
    ``known_size_m``: the object's floor rectangle [m] when known (its model's catalogue): a rectangle
    shorter is grown to it (:func:`_to_known_size`, ``camera_xy`` [m] the camera that saw it), one
    longer by more than :data:`OVERSIZE_TOLERANCE_M` is refused (None). None with fewer than
    :data:`MIN_POINTS` points.
    """
    p = np.asarray(points_world, dtype=float).reshape(-1, 3)
    kept = _near(p[:, :2], np.asarray(centre_world, dtype=float)[:2], max_extent_m) & (p[:, 2] > -0.05)
    run_top = max((float(p[run, 2].max()) for run in runs if kept[run].all()), default=-np.inf)
    p = p[kept]
    if len(p) < MIN_POINTS:
        return None
    top = max(_top(p[:, 2]), run_top)
    p = p[p[:, 2] <= top + ABOVE_TOP_M]
    if len(p) < MIN_POINTS:
        return None
    try:
        centre, size, yaw = _rectangle(p[:, :2])
    except ValueError:
        return None
    (cx, cy), (w, h), counts = _median_sides(p[:, :2], centre, size, yaw)
    if known_size_m is not None:
        (cx, cy), (w, h) = _to_known_size((cx, cy), (w, h), yaw, counts, known_size_m, camera_xy)
        if _oversized((w, h), known_size_m):
            return None
    if w < h:  # the first side along the yaw is the longer one
        w, h, yaw = h, w, yaw + math.pi / 2.0
    yaw = (yaw + math.pi / 2.0) % math.pi - math.pi / 2.0  # a rectangle's yaw is defined modulo pi
    return Footprint(
        (float(cx), float(cy)),
        (float(w), float(h)),
        float(yaw),
        top,
        len(p),
        int(n_hidden),
    )
