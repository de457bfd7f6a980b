"""Self-collision avoidance between capsules (eqs. 12-13 of the footstep paper)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.capsule import CapsuleLike
from services.ik.geometry import closest_point_on_segment, closest_points_segments
from services.ik.kinematics import frame_id, point_jacobian
from services.ik.task import Task


class SelfCollisionTask(Task):
    """Keep every pair of capsules at least ``margin_m`` apart (surface to surface).

    For a pair of points A, B (one on each segment) at distance |AB| with n = AB/|AB|, eq. (12) with
    d = r_A + r_B + margin is G = d - <AB | n> <= 0 and eq. (13) its differential form with
    dG = -n^T (J_B - J_A) dq (A, B held fixed in their bodies). Rows are produced only for pairs
    closer than ``activation_m`` beyond the margin, and at most three per pair (eq. 13's "maximum of
    three constraints"): the closest points of the two segments, then the closest endpoint-to-segment
    pairs, which take over when the segments are near parallel and the closest points jump.

    ``capsules``: any objects with ``name``, ``frame``, ``p0_local``, ``p1_local``, ``radius_m``
    (``services.ik.Capsule``, or a robot's ``services.model`` capsules as they are).
    ``pairs``: pairs to check, as capsule indices or names (a robot's ``collision_pairs``); default
    every pair on two different joints that are not parent and child (adjacent links always touch).
    """

    def __init__(
        self,
        model: pin.Model,
        capsules: Sequence[CapsuleLike],
        pairs: Sequence[tuple[int, int]] | Sequence[tuple[str, str]] | None = None,
        margin_m: float = 0.01,
        activation_m: float = 0.05,
        max_rows_per_pair: int = 3,
        gain: float = 1.0,
        name: str = "self_collision",
    ) -> None:
        super().__init__(name, gain, lower=-np.inf, upper=0.0)
        if len(capsules) < 2:
            raise InvalidRequestError(f"task {name!r}: needs at least two capsules")
        if not 1 <= max_rows_per_pair <= 3:
            raise InvalidRequestError(f"task {name!r}: max_rows_per_pair must be 1, 2 or 3")
        self.model = model
        self.capsules = tuple(capsules)
        self.frame_ids = np.array([frame_id(model, c.frame) for c in capsules])
        self.p0_local = np.array([c.p0_local for c in capsules], dtype=float)
        self.p1_local = np.array([c.p1_local for c in capsules], dtype=float)
        self.radii = np.array([c.radius_m for c in capsules], dtype=float)
        if pairs is None:
            pairs = default_pairs(model, self.frame_ids)
        elif len(pairs) and isinstance(pairs[0][0], str):
            pairs = self._pairs_by_name(pairs)
        pair_array = np.array(pairs, dtype=int).reshape(-1, 2)
        if pair_array.size and (pair_array.min() < 0 or pair_array.max() >= len(capsules)):
            raise InvalidRequestError(f"task {name!r}: pair index out of range 0..{len(capsules) - 1}")
        self.pair_a, self.pair_b = pair_array[:, 0], pair_array[:, 1]
        self.margin_m = float(margin_m)
        self.activation_m = float(activation_m)
        self.max_rows_per_pair = max_rows_per_pair

    def _pairs_by_name(self, pairs: Sequence[tuple[str, str]]) -> list[tuple[int, int]]:
        index = {c.name: i for i, c in enumerate(self.capsules)}
        unknown = sorted({n for pair in pairs for n in pair if n not in index})
        if unknown:
            raise InvalidRequestError(
                f"task {self.name!r}: unknown capsules {unknown}; capsules are {sorted(index)}"
            )
        return [(index[a], index[b]) for a, b in pairs]

    def segments_world(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """World endpoints (k x 3 each) of every capsule segment."""
        p0 = np.empty_like(self.p0_local)
        p1 = np.empty_like(self.p1_local)
        for i, fid in enumerate(self.frame_ids):
            T = data.oMf[int(fid)]
            p0[i] = T.rotation @ self.p0_local[i] + T.translation
            p1[i] = T.rotation @ self.p1_local[i] + T.translation
        return p0, p1

    def distances(self, data: pin.Data) -> np.ndarray:
        """Surface distance [m] of every checked pair (negative when the capsules overlap)."""
        p0, p1 = self.segments_world(data)
        a, b = self.pair_a, self.pair_b
        s, t = closest_points_segments(p0[a], p1[a], p0[b], p1[b])
        A = p0[a] + s[:, None] * (p1[a] - p0[a])
        B = p0[b] + t[:, None] * (p1[b] - p0[b])
        return np.linalg.norm(B - A, axis=1) - self.radii[a] - self.radii[b]

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        p0, p1 = self.segments_world(data)
        a, b = self.pair_a, self.pair_b
        s, t = closest_points_segments(p0[a], p1[a], p0[b], p1[b])
        A = p0[a] + s[:, None] * (p1[a] - p0[a])
        B = p0[b] + t[:, None] * (p1[b] - p0[b])
        clearance = self.radii[a] + self.radii[b] + self.margin_m
        active = np.flatnonzero(np.linalg.norm(B - A, axis=1) < clearance + self.activation_m)
        values: list[float] = []
        rows: list[np.ndarray] = []
        for k in active:
            i, j = int(a[k]), int(b[k])
            for s_i, t_j in self._point_pairs(p0, p1, i, j, float(s[k]), float(t[k]), clearance[k]):
                value, row = self._row(data, i, j, s_i, t_j, clearance[k])
                values.append(value)
                rows.append(row)
        if not rows:
            return np.zeros(0), np.zeros((0, self.model.nv))
        return np.array(values), np.vstack(rows)

    def _point_pairs(
        self, p0: np.ndarray, p1: np.ndarray, i: int, j: int, s: float, t: float, clearance: float
    ) -> list[tuple[float, float]]:
        pairs = [(s, t)]
        if self.max_rows_per_pair == 1:
            return pairs
        # Endpoint-to-segment candidates: each endpoint of one segment against the other segment.
        ends_i = np.array([p0[i], p1[i]])
        ends_j = np.array([p0[j], p1[j]])
        t_of_i = closest_point_on_segment(ends_i, np.repeat(p0[j][None], 2, 0), np.repeat(p1[j][None], 2, 0))
        s_of_j = closest_point_on_segment(ends_j, np.repeat(p0[i][None], 2, 0), np.repeat(p1[i][None], 2, 0))
        candidates = [(0.0, t_of_i[0]), (1.0, t_of_i[1]), (s_of_j[0], 0.0), (s_of_j[1], 1.0)]
        scored = []
        for s_c, t_c in candidates:
            A = p0[i] + s_c * (p1[i] - p0[i])
            B = p0[j] + t_c * (p1[j] - p0[j])
            distance = float(np.linalg.norm(B - A))
            if distance < clearance + self.activation_m:
                scored.append((distance, s_c, t_c))
        scored.sort()
        len_i = float(np.linalg.norm(p1[i] - p0[i]))
        len_j = float(np.linalg.norm(p1[j] - p0[j]))
        for _, s_c, t_c in scored:
            if len(pairs) == self.max_rows_per_pair:
                break
            # A candidate within 1 cm of a chosen pair on both segments adds no information.
            if all(abs(s_c - s_p) * len_i > 0.01 or abs(t_c - t_p) * len_j > 0.01 for s_p, t_p in pairs):
                pairs.append((s_c, t_c))
        return pairs

    def _row(
        self, data: pin.Data, i: int, j: int, s: float, t: float, clearance: float
    ) -> tuple[float, np.ndarray]:
        A_local = self.p0_local[i] + s * (self.p1_local[i] - self.p0_local[i])
        B_local = self.p0_local[j] + t * (self.p1_local[j] - self.p0_local[j])
        A, J_A = point_jacobian(self.model, data, int(self.frame_ids[i]), A_local)
        B, J_B = point_jacobian(self.model, data, int(self.frame_ids[j]), B_local)
        AB = B - A
        distance = float(np.linalg.norm(AB))
        n = AB / distance if distance > 1e-9 else np.array([0.0, 0.0, 1.0])
        return clearance - distance, -(n @ (J_B - J_A))


def default_pairs(model: pin.Model, frame_ids: np.ndarray) -> list[tuple[int, int]]:
    """Capsule pairs on two different joints that are not parent and child."""
    joints = [int(model.frames[int(f)].parentJoint) for f in frame_ids]
    pairs = []
    for i in range(len(joints)):
        for j in range(i + 1, len(joints)):
            ji, jj = joints[i], joints[j]
            if ji == jj or model.parents[ji] == jj or model.parents[jj] == ji:
                continue
            pairs.append((i, j))
    return pairs
