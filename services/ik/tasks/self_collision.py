"""Self-collision avoidance between capsules (eqs. 12-13 of the footstep paper)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.capsule import CapsuleLike
from services.ik.geometry import closest_point_on_segment, closest_points_segments
from services.ik.kinematics import LWA, frame_id
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
        # distinct frames: their placements and Jacobians are read once per evaluation
        self._frames, self._frame_of = np.unique(self.frame_ids, return_inverse=True)
        self._frames = [int(f) for f in self._frames]
        self._n_frames = len(self._frames)
        self._axis_local = self.p1_local - self.p0_local

    def _pairs_by_name(self, pairs: Sequence[tuple[str, str]]) -> list[tuple[int, int]]:
        index = {c.name: i for i, c in enumerate(self.capsules)}
        unknown = sorted({n for pair in pairs for n in pair if n not in index})
        if unknown:
            raise InvalidRequestError(
                f"task {self.name!r}: unknown capsules {unknown}; capsules are {sorted(index)}"
            )
        return [(index[a], index[b]) for a, b in pairs]

    def _frame_placements(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (f, 3, 3) and translations (f, 3) of the capsules' distinct frames."""
        rotations = np.empty((self._n_frames, 3, 3))
        translations = np.empty((self._n_frames, 3))
        for k, fid in enumerate(self._frames):
            T = data.oMf[fid]
            rotations[k] = T.rotation
            translations[k] = T.translation
        return rotations, translations

    def segments_world(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """World endpoints (k x 3 each) of every capsule segment."""
        return self._segments(*self._frame_placements(data))

    def _segments(self, rotations: np.ndarray, translations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, t = rotations[self._frame_of], translations[self._frame_of]
        return np.einsum("kij,kj->ki", R, self.p0_local) + t, np.einsum("kij,kj->ki", R, self.p1_local) + t

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
        rotations, translations = self._frame_placements(data)
        p0, p1 = self._segments(rotations, translations)
        a, b = self.pair_a, self.pair_b
        s, t = closest_points_segments(p0[a], p1[a], p0[b], p1[b])
        A = p0[a] + s[:, None] * (p1[a] - p0[a])
        B = p0[b] + t[:, None] * (p1[b] - p0[b])
        clearance = self.radii[a] + self.radii[b] + self.margin_m
        gap = np.sqrt(np.einsum("ij,ij->i", B - A, B - A))
        active = np.flatnonzero(gap < clearance + self.activation_m)
        if not active.shape[0]:
            return np.zeros(0), np.zeros((0, self.model.nv))
        rows_i, rows_j, rows_s, rows_t, rows_clear = self._point_pairs(
            p0, p1, a[active], b[active], s[active], t[active], clearance[active]
        )
        # rows: G = clearance - |AB|, dG = -n^T (J_B - J_A) with the points fixed in their frames
        fa, fb = self._frame_of[rows_i], self._frame_of[rows_j]
        A_off = np.einsum(
            "rij,rj->ri", rotations[fa], self.p0_local[rows_i] + rows_s[:, None] * self._axis_local[rows_i]
        )
        B_off = np.einsum(
            "rij,rj->ri", rotations[fb], self.p0_local[rows_j] + rows_t[:, None] * self._axis_local[rows_j]
        )
        AB = (translations[fb] + B_off) - (translations[fa] + A_off)
        distance = np.sqrt(np.einsum("ij,ij->i", AB, AB))
        far = distance > 1e-9
        n = np.where(far[:, None], AB / np.where(far, distance, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
        used = np.zeros(self._n_frames, dtype=bool)
        used[fa] = True
        used[fb] = True
        J = np.empty((self._n_frames, 6, self.model.nv))
        for k in np.flatnonzero(used).tolist():
            J[k] = pin.getFrameJacobian(self.model, data, self._frames[k], LWA)
        # point velocity v + w x r: n^T (v + w x r) = n^T v + (r x n)^T w
        rows = np.einsum("ri,riv->rv", n, J[fb, :3] - J[fa, :3])
        rows += np.einsum("ri,riv->rv", _cross(B_off, n), J[fb, 3:])
        rows -= np.einsum("ri,riv->rv", _cross(A_off, n), J[fa, 3:])
        return rows_clear - distance, -rows

    def _point_pairs(
        self,
        p0: np.ndarray,
        p1: np.ndarray,
        ai: np.ndarray,
        bj: np.ndarray,
        s: np.ndarray,
        t: np.ndarray,
        clearance: np.ndarray,
    ) -> tuple[np.ndarray, ...]:
        """Segment parameters of the rows of the active pairs (i, j): the closest points, then up to
        ``max_rows_per_pair - 1`` endpoint-to-segment pairs within the activation distance, closest
        first, each more than 1 cm (along either segment) from the pairs already chosen."""
        if self.max_rows_per_pair == 1:
            return ai, bj, s, t, clearance
        # Endpoint-to-segment candidates: each endpoint of one segment against the other segment.
        k = ai.shape[0]
        ends_i = np.stack((p0[ai], p1[ai]), 1).reshape(2 * k, 3)
        ends_j = np.stack((p0[bj], p1[bj]), 1).reshape(2 * k, 3)
        t_of_i = closest_point_on_segment(ends_i, np.repeat(p0[bj], 2, 0), np.repeat(p1[bj], 2, 0)).reshape(
            k, 2
        )
        s_of_j = closest_point_on_segment(ends_j, np.repeat(p0[ai], 2, 0), np.repeat(p1[ai], 2, 0)).reshape(
            k, 2
        )
        cand_s = np.concatenate((np.zeros((k, 1)), np.ones((k, 1)), s_of_j), 1)
        cand_t = np.concatenate((t_of_i, np.zeros((k, 1)), np.ones((k, 1))), 1)
        d_i, d_j = p1[ai] - p0[ai], p1[bj] - p0[bj]
        A = p0[ai][:, None] + cand_s[..., None] * d_i[:, None]
        B = p0[bj][:, None] + cand_t[..., None] * d_j[:, None]
        cand_d = np.sqrt(np.einsum("kci,kci->kc", B - A, B - A))
        len_i = np.sqrt(np.einsum("ij,ij->i", d_i, d_i)).tolist()
        len_j = np.sqrt(np.einsum("ij,ij->i", d_j, d_j)).tolist()
        within = (cand_d < (clearance + self.activation_m)[:, None]).tolist()
        cand_d, cand_s, cand_t = cand_d.tolist(), cand_s.tolist(), cand_t.tolist()
        out_i, out_j, out_s, out_t, out_c = [], [], [], [], []
        for r, (i, j, s_r, t_r) in enumerate(
            zip(ai.tolist(), bj.tolist(), s.tolist(), t.tolist(), strict=True)
        ):
            pairs = [(s_r, t_r)]
            scored = sorted((cand_d[r][c], cand_s[r][c], cand_t[r][c]) for c in range(4) if within[r][c])
            for _, s_c, t_c in scored:
                if len(pairs) == self.max_rows_per_pair:
                    break
                # A candidate within 1 cm of a chosen pair on both segments adds no information.
                if all(
                    abs(s_c - s_p) * len_i[r] > 0.01 or abs(t_c - t_p) * len_j[r] > 0.01 for s_p, t_p in pairs
                ):
                    pairs.append((s_c, t_c))
            for s_p, t_p in pairs:
                out_i.append(i)
                out_j.append(j)
                out_s.append(s_p)
                out_t.append(t_p)
                out_c.append(clearance[r])
        return (
            np.array(out_i, dtype=int),
            np.array(out_j, dtype=int),
            np.array(out_s),
            np.array(out_t),
            np.array(out_c),
        )


_NEXT, _PREV = np.array([1, 2, 0]), np.array([2, 0, 1])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products of (k, 3) arrays (np.cross without its axis handling)."""
    return a[:, _NEXT] * b[:, _PREV] - a[:, _PREV] * b[:, _NEXT]


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
