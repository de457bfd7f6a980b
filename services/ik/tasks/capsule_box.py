"""Capsules of the robot kept out of fixed boxes of the environment (environment collisions, §2.2 of
Escande et al.; the same inequality form as the self-collision task, eqs. (12)-(13) of the footstep
paper): for each checked (capsule, box) pair with closest points A on the capsule's segment and B on
the box,

    G = r + d - <BA | n> <= 0,   n = BA / |BA|,

where r is the capsule radius and d a safety margin; when the segment point is inside the box, the
signed distance is minus the depth to the nearest face and n that face's normal. The row's Jacobian
moves A with its link (B is fixed): dG = -n^T J_A.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.ik.capsule import CapsuleLike
from services.ik.kinematics import frame_id, point_jacobian
from services.ik.task import Task


@dataclass(frozen=True)
class ObstacleBox:
    """A fixed box: the world placement of its centre (rotation and translation) and half extents [m]."""

    name: str
    T_world_box: pin.SE3
    half_extents_m: np.ndarray


def segment_box_distances(
    p0: np.ndarray,
    p1: np.ndarray,
    R_box: np.ndarray,
    t_box: np.ndarray,
    half: np.ndarray,
    iterations: int = 12,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed distances [m] between k segments [p0, p1] (k x 3, world) and k boxes (rotations k x 3 x 3,
    centres k x 3, half extents k x 3), with the closest points A on the segments and the unit normals
    n pointing from the boxes to A (world, k x 3 each).

    Alternating projections between the (convex) segment and box converge to the closest pair when
    they are disjoint; a segment point inside its box gives minus the depth to the box's nearest face.
    """
    a = np.einsum("kji,kj->ki", R_box, p0 - t_box)
    b = np.einsum("kji,kj->ki", R_box, p1 - t_box)
    d = b - a
    dd = np.einsum("ki,ki->k", d, d)
    long = dd > 1e-12
    inv = np.where(long, 1.0 / np.where(long, dd, 1.0), 0.0)
    s = np.full(a.shape[0], 0.5)
    neg = -half
    # np.minimum(np.maximum(...)) is np.clip's arithmetic without its per-call overhead (hot loop)
    for _ in range(iterations):
        closest = np.minimum(np.maximum(a + s[:, None] * d, neg), half)
        s = np.minimum(np.maximum(np.einsum("ki,ki->k", closest - a, d) * inv, 0.0), 1.0)
    point = a + s[:, None] * d
    diff = point - np.minimum(np.maximum(point, neg), half)
    dist = np.sqrt(np.einsum("ki,ki->k", diff, diff))
    outside = dist > 1e-9
    n_local = np.where(outside[:, None], diff / np.where(outside, dist, 1.0)[:, None], 0.0)
    if not outside.all():  # inside: the nearest face
        inside = np.flatnonzero(~outside)
        depth = half[inside] - np.abs(point[inside])
        axis = np.argmin(depth, axis=1)
        n_local[inside, axis] = np.where(point[inside, axis] >= 0.0, 1.0, -1.0)
        dist[inside] = -depth[np.arange(inside.shape[0]), axis]
    return dist, np.einsum("kij,kj->ki", R_box, point) + t_box, np.einsum("kij,kj->ki", R_box, n_local)


class CapsuleBoxTask(Task):
    """Keep every (capsule, box) pair of ``pairs`` at least ``margin_m`` apart (surface to surface).

    ``capsules``: capsule-like objects (``services.ik.Capsule`` or a robot's capsules); ``boxes``:
    :class:`ObstacleBox`; ``pairs``: (capsule index, box index). Rows are only written for pairs closer
    than ``margin_m + activation_m`` (a far pair constrains nothing).
    """

    def __init__(
        self,
        model: pin.Model,
        capsules: Sequence[CapsuleLike],
        boxes: Sequence[ObstacleBox],
        pairs: Sequence[tuple[int, int]],
        margin_m: float = 0.01,
        activation_m: float = 0.05,
        gain: float = 0.5,
        name: str = "capsules_out_of_boxes",
    ) -> None:
        super().__init__(name, gain, lower=-np.inf, upper=0.0)
        self.model = model
        self.capsules = tuple(capsules)
        self.boxes = tuple(boxes)
        self.pairs = [(int(i), int(j)) for i, j in pairs]
        self.margin_m = float(margin_m)
        self.activation_m = float(activation_m)
        self._fids = [frame_id(model, c.frame) for c in self.capsules]
        self._ends_local = np.array([(c.p0_local, c.p1_local) for c in self.capsules], dtype=float)
        self._radii = np.array([c.radius_m for c in self.capsules], dtype=float)
        self._R = np.array([b.T_world_box.rotation for b in self.boxes]).reshape(-1, 3, 3)
        self._t = np.array([b.T_world_box.translation for b in self.boxes]).reshape(-1, 3)
        self._half = np.array([b.half_extents_m for b in self.boxes], dtype=float).reshape(-1, 3)
        self._pair_capsule = np.array([i for i, _ in self.pairs], dtype=int)
        self._pair_box = np.array([j for _, j in self.pairs], dtype=int)
        # broad phase: each pair's capsule radius plus its box's circumradius (the box within that
        # distance of its centre)
        circumradius = np.linalg.norm(self._half, axis=1)
        self._pair_reach = self._radii[self._pair_capsule] + circumradius[self._pair_box]

    def _ends(self, data: pin.Data) -> np.ndarray:
        """The capsules' segment ends in the world (capsules x 2 x 3) [m]."""
        H = np.array([data.oMf[f].homogeneous for f in self._fids])
        return np.einsum("kij,kcj->kci", H[:, :3, :3], self._ends_local) + H[:, None, :3, 3]

    def _pairs_at(
        self, ends: np.ndarray, rows: np.ndarray | slice
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(surface distances [m], closest capsule points A, normals n) of the pairs ``rows``."""
        c, b = self._pair_capsule[rows], self._pair_box[rows]
        dist, A, n = segment_box_distances(ends[c, 0], ends[c, 1], self._R[b], self._t[b], self._half[b])
        return dist - self._radii[c], A, n

    def _all_pairs(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(surface distances [m], closest capsule points A, normals n) of every pair."""
        return self._pairs_at(self._ends(data), slice(None))

    def _near_pairs(self, ends: np.ndarray, within_m: float) -> np.ndarray:
        """Indices of the pairs that may be closer than ``within_m`` (surface to surface): the distance
        from the box's centre to the capsule's segment, less the capsule's radius and the box's
        circumradius, is a lower bound of the pair's distance, so every pair left out is farther."""
        c, b = self._pair_capsule, self._pair_box
        p0, d = ends[c, 0], ends[c, 1] - ends[c, 0]
        w = self._t[b] - p0
        dd = np.einsum("ki,ki->k", d, d)
        s = np.clip(np.einsum("ki,ki->k", w, d) / np.maximum(dd, 1e-12), 0.0, 1.0)
        gap = w - s[:, None] * d
        lower = np.sqrt(np.einsum("ki,ki->k", gap, gap)) - self._pair_reach
        return np.flatnonzero(lower <= within_m)

    def distances(self, data: pin.Data) -> np.ndarray:
        """Signed surface distance [m] of every pair (negative: penetration)."""
        if not self.pairs:
            return np.zeros(0)
        return self._all_pairs(data)[0]

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        if not self.pairs:
            return np.zeros(0), np.zeros((0, self.model.nv))
        # only the pairs the broad phase cannot rule out (the same rows as computing every pair)
        within = self.margin_m + self.activation_m
        ends = self._ends(data)
        near = self._near_pairs(ends, within)
        dist, A, n = self._pairs_at(ends, near)
        active = np.flatnonzero(dist <= within)
        if not active.shape[0]:
            return np.zeros(0), np.zeros((0, self.model.nv))
        rows = []
        for r in active.tolist():
            fid = self._fids[self._pair_capsule[near[r]]]
            local = data.oMf[fid].actInv(A[r])
            _, J_A = point_jacobian(self.model, data, fid, local)
            rows.append(-n[r].dot(J_A))
        return self.margin_m - dist[active], np.array(rows)
