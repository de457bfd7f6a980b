"""Self-collision avoidance between capsules (eqs. 12-13 of the footstep paper)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.capsule import CapsuleLike
from services.ik.geometry import closest_parameters, closest_points_segments, unit_clip
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
        self._axis_local = self.p1_local - self.p0_local
        self._ends_local = np.stack((self.p0_local, self.p1_local), 1)  # (k, p0/p1, xyz)
        self._pairs = pair_array
        # per pair: the clearance r_a + r_b + margin of eq. (12) [m], and the gap below which it has rows
        self._clearance = self.radii[self.pair_a] + self.radii[self.pair_b] + self.margin_m
        self._activation_gap = self._clearance + self.activation_m

    def _pairs_by_name(self, pairs: Sequence[tuple[str, str]]) -> list[tuple[int, int]]:
        index = {c.name: i for i, c in enumerate(self.capsules)}
        unknown = sorted({n for pair in pairs for n in pair if n not in index})
        if unknown:
            raise InvalidRequestError(
                f"task {self.name!r}: unknown capsules {unknown}; capsules are {sorted(index)}"
            )
        return [(index[a], index[b]) for a, b in pairs]

    def _capsule_placements(self, data: pin.Data) -> np.ndarray:
        """(k, 4, 4) homogeneous world placement of each capsule's frame (the distinct frames read
        once, in one pass)."""
        oMf = data.oMf
        return np.array([oMf[fid].homogeneous for fid in self._frames])[self._frame_of]

    def segments_world(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """World endpoints (k x 3 each) of every capsule segment."""
        ends = self._ends(self._capsule_placements(data))
        return ends[:, 0], ends[:, 1]

    def _ends(self, H: np.ndarray) -> np.ndarray:
        """(k, 2, 3) world endpoints p0, p1 of every capsule segment, from its frame's placement."""
        return np.einsum("kij,kcj->kci", H[:, :3, :3], self._ends_local) + H[:, None, :3, 3]

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
        H = self._capsule_placements(data)
        # ends[pair, 0 or 1 (capsule a or b), 0 or 1 (p0 or p1)], world frame [m]
        ends = self._ends(H)[self._pairs]
        p0a, p0b = ends[:, 0, 0], ends[:, 1, 0]
        dirs = ends[:, :, 1] - ends[:, :, 0]  # d = p1 - p0 of a and b
        d1, d2 = dirs[:, 0], dirs[:, 1]
        s, t = closest_parameters(d1, d2, p0a - p0b)
        AB = (p0b + t[:, None] * d2) - (p0a + s[:, None] * d1)
        gap = np.sqrt(np.einsum("ij,ij->i", AB, AB))
        active = np.flatnonzero(gap < self._activation_gap)
        if not active.shape[0]:
            return np.zeros(0), np.zeros((0, self.model.nv))
        capsules, params, clearance = self._point_pairs(active, ends, dirs, s, t)
        # rows: G = clearance - |AB|, dG = -n^T (J_B - J_A) with the points fixed in their frames;
        # the row's two points in one array, those of the a sides first: A = [:r], B = [r:]
        r = clearance.shape[0]
        H_rows = H[capsules]
        local = self.p0_local[capsules] + params[:, None] * self._axis_local[capsules]
        offsets = np.einsum("rij,rj->ri", H_rows[:, :3, :3], local)
        A_off, B_off = offsets[:r], offsets[r:]
        points = H_rows[:, :3, 3]
        AB = (points[r:] + B_off) - (points[:r] + A_off)
        distance = np.sqrt(np.einsum("ij,ij->i", AB, AB))
        far = distance > 1e-9
        n = np.where(far[:, None], AB / np.where(far, distance, 1.0)[:, None], _UP)
        # the frame Jacobians of the points (a frame once)
        frames = self._frame_of[capsules].tolist()
        J_of: dict[int, np.ndarray] = {}
        for k in frames:
            if k not in J_of:
                J_of[k] = pin.getFrameJacobian(self.model, data, self._frames[k], LWA)
        J = np.array([J_of[k] for k in frames])
        J_angular = np.ascontiguousarray(J[:, 3:])
        r_x_n = _cross(offsets, np.concatenate((n, n)))
        # point velocity v + w x r: n^T (v + w x r) = n^T v + (r x n)^T w
        rows = np.einsum("ri,riv->rv", n, J[r:, :3] - J[:r, :3])
        rows += np.einsum("ri,riv->rv", r_x_n[r:], J_angular[r:])
        rows -= np.einsum("ri,riv->rv", r_x_n[:r], J_angular[:r])
        return clearance - distance, -rows

    def _point_pairs(
        self, active: np.ndarray, ends: np.ndarray, dirs: np.ndarray, s: np.ndarray, t: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows of the ``active`` pairs (indices into the checked pairs, with their segments'
        ``ends`` (pair, a/b, p0/p1, xyz) and ``dirs`` (pair, a/b, xyz) [m], closest points at (s, t)):
        the closest points, then up to ``max_rows_per_pair - 1`` endpoint-to-segment pairs within
        the activation distance, closest first, each more than 1 cm (along either segment) from the
        pairs already chosen.

        Returns (capsules, params, clearance): for r rows, the capsules of sides a then of sides b
        (2r), their segment parameters (2r, s then t) and the rows' clearances [m] (r).
        """
        if self.max_rows_per_pair == 1:
            capsules = self._pairs[active].T.ravel()
            return capsules, np.concatenate((s[active], t[active])), self._clearance[active]
        k = active.shape[0]
        seg = ends[active].reshape(k, 4, 3)  # p0_i, p1_i, p0_j, p1_j
        d = dirs[active]  # d_i, d_j
        # Endpoint-to-segment candidates, the closest point of the other segment to each endpoint
        # (parameter <p - q0 | d> / |d|^2 clamped to [0, 1]): i's endpoints on j, j's on i.
        to_other = seg - seg[:, _OTHER_P0]
        other_d = d[:, _OTHER_D]
        len2 = np.einsum("kci,kci->kc", other_d, other_d)  # |d_j|^2, |d_j|^2, |d_i|^2, |d_i|^2
        along = np.einsum("kci,kci->kc", to_other, other_d)
        if np.count_nonzero(len2 > _EPS) == 4 * k:
            params = unit_clip(along / len2)
        else:  # a point segment: parameter 0 on it
            long = len2 > _EPS
            params = unit_clip(np.where(long, along / np.where(long, len2, 1.0), 0.0))
        # (s, t) of the four candidates: (0, t(p0_i)), (1, t(p1_i)), (s(p0_j), 0), (s(p1_j), 1)
        cand = np.empty((k, 2, 4))
        cand[:, 0, :2] = _ZERO_ONE
        cand[:, 0, 2:] = params[:, 2:]
        cand[:, 1, :2] = params[:, :2]
        cand[:, 1, 2:] = _ZERO_ONE
        pts = seg[:, 0::2, None] + cand[..., None] * d[:, :, None]  # (k, a/b, candidate, xyz)
        diff = pts[:, 1] - pts[:, 0]
        cand_d = np.sqrt(np.einsum("kci,kci->kc", diff, diff)).tolist()
        lengths = np.sqrt(len2).tolist()  # |d_j|, |d_j|, |d_i|, |d_i|
        within = (cand_d < self._activation_gap[active][:, None]).tolist()
        cand = cand.tolist()
        out_r, out_s, out_t = [], [], []
        for r, (s_r, t_r) in enumerate(zip(s[active].tolist(), t[active].tolist(), strict=True)):
            pairs = [(s_r, t_r)]
            len_i, len_j = lengths[r][2], lengths[r][0]
            cand_s, cand_t = cand[r]
            scored = sorted((cand_d[r][c], cand_s[c], cand_t[c]) for c in range(4) if within[r][c])
            for _, s_c, t_c in scored:
                if len(pairs) == self.max_rows_per_pair:
                    break
                # A candidate within 1 cm of a chosen pair on both segments adds no information.
                if all(abs(s_c - s_p) * len_i > 0.01 or abs(t_c - t_p) * len_j > 0.01 for s_p, t_p in pairs):
                    pairs.append((s_c, t_c))
            for s_p, t_p in pairs:
                out_r.append(r)
                out_s.append(s_p)
                out_t.append(t_p)
        rows = active[out_r]
        return self._pairs[rows].T.ravel(), np.array(out_s + out_t), self._clearance[rows]


_EPS = 1e-12  # a squared segment length [m^2] below which the segment is a point
_UP = np.array([0.0, 0.0, 1.0])
_ZERO_ONE = np.array([0.0, 1.0])
# for the endpoints p0_i, p1_i, p0_j, p1_j of a pair: the other segment's p0 and direction
_OTHER_P0 = np.array([2, 2, 0, 0])
_OTHER_D = np.array([1, 1, 0, 0])
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
