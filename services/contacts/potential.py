"""The rough trajectory T and its valley-like potential f_T (§2.7 of Escande et al., Fig. 2, eq. 1).

T is a piecewise linear curve through a few key postures. F is the 6-dimensional subspace of the free
flyer (base translation and rotation, the rotation as its log3 vector); T' is T projected onto F, with
its corners replaced by arcs of circles of the largest radius whose distance to the corner stays under
``corner_deviation`` (and whose tangent points stay within half of each adjacent segment), so that
f_T is twice continuously differentiable near the curve (§2.7). For a configuration P with projection
P', Q' is the closest point of T' to P', s' its curvilinear abscissa along T', Q = p^-1(Q') the
configuration of T there (free flyer = Q', joints linearly interpolated between the key postures), and

    f_T(P) = ||P - Q||^2 - k s'                                                        (eq. 1)

with ||.|| the Euclidean norm of the tangent difference P (-) Q (pinocchio's difference).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik import Task
from services.model.ground import yaw_of


def base_point(q: np.ndarray, R_ref: np.ndarray | None = None) -> np.ndarray:
    """The projection P' of a configuration onto F: (x, y, z [m], log3 of the base rotation [rad]),
    both expressed in a frame turned by ``R_ref`` (3x3; None: the world's)."""
    R = pin.Quaternion(np.asarray(q[3:7], dtype=float)).normalized().toRotationMatrix()
    p = np.asarray(q[:3], dtype=float)
    if R_ref is not None:
        p, R = R_ref.T @ p, R_ref.T @ R
    return np.concatenate((p, pin.log3(R)))


def heading_rotation(q: np.ndarray) -> np.ndarray:
    """The rotation about the vertical by the heading (yaw) of the base of ``q`` (3x3)."""
    R = pin.Quaternion(np.asarray(q[3:7], dtype=float)).normalized().toRotationMatrix()
    return pin.rpy.rpyToMatrix(0.0, 0.0, yaw_of(R))


@dataclass(frozen=True)
class _Piece:
    kind: str  # "line" or "arc"
    s0: float  # curvilinear abscissa at the piece's start
    length: float
    u0: float  # polyline parameter (segment index + fraction) at the piece's start
    u1: float
    a: np.ndarray  # line: start; arc: centre
    b: np.ndarray  # line: unit direction; arc: -n (from the centre to the start point)
    c: np.ndarray | None = None  # arc: u_in (the second in-plane axis)
    radius: float = 0.0
    angle: float = 0.0


@dataclass(frozen=True)
class Projection:
    """Closest point of T' to P': Q' (6), its abscissa s' [m-rad], unit tangent (6) and polyline
    parameter u (segment index + fraction along the key postures)."""

    point: np.ndarray
    s: float
    tangent: np.ndarray
    u: float
    distance: float


class RoughTrajectory:
    """T through ``key_postures`` (k x nq, pinocchio layout) of ``model``, with f_T's slope ``k``."""

    def __init__(
        self,
        model: pin.Model,
        key_postures: Sequence[np.ndarray],
        k: float = 30.0,
        corner_deviation: float = 0.05,
    ) -> None:
        keys = np.array([np.asarray(q, dtype=float) for q in key_postures])
        if keys.ndim != 2 or keys.shape[0] < 2 or keys.shape[1] != model.nq:
            raise InvalidRequestError(
                f"give at least 2 key postures of nq={model.nq} values each, got shape {keys.shape}"
            )
        if not np.all(np.isfinite(keys)):
            raise InvalidRequestError("key postures must be finite")
        if not k > 0.0:
            raise InvalidRequestError(f"the slope k of f_T must be positive, got {k}")
        self.model = model
        self.keys = keys
        self.k = float(k)
        # F's coordinates in the frame of the start's heading (§2.7 leaves F's frame open): log3 is not
        # invariant when the whole layout turns (the chair facing +y gave other f_T values, hence another
        # search, than the same scene facing +x); in the start's frame they do not depend on the layout's
        # heading (the identity, bit for bit, for a start facing +x)
        self.R_ref = heading_rotation(keys[0])
        vertices = np.array([base_point(q, self.R_ref) for q in keys])
        lengths = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
        if np.any(lengths < 1e-6):
            raise InvalidRequestError(
                "two consecutive key postures have the same base pose: p from T to F must be bijective (§2.7)"
            )
        self.pieces = _round_corners(vertices, lengths, corner_deviation)
        self.length = self.pieces[-1].s0 + self.pieces[-1].length
        self._last_closest: tuple[bytes, tuple[np.ndarray, Projection]] | None = None

    def project(self, P_prime: np.ndarray) -> Projection:
        """Q', s', the tangent and u for P' (6)."""
        best: Projection | None = None
        for piece in self.pieces:
            if piece.kind == "line":
                t = float(np.clip((P_prime - piece.a).dot(piece.b), 0.0, piece.length))
                point, tangent = piece.a + t * piece.b, piece.b
                frac = t / piece.length if piece.length > 0 else 0.0
                s = piece.s0 + t
            else:
                w = P_prime - piece.a
                alpha = float(np.clip(math.atan2(w.dot(piece.c), w.dot(piece.b)), 0.0, piece.angle))
                point = piece.a + piece.radius * (piece.b * math.cos(alpha) + piece.c * math.sin(alpha))
                tangent = -piece.b * math.sin(alpha) + piece.c * math.cos(alpha)
                frac = alpha / piece.angle
                s = piece.s0 + piece.radius * alpha
            d = float(np.linalg.norm(P_prime - point))
            if best is None or d < best.distance - 1e-12:
                best = Projection(point, s, tangent, piece.u0 + frac * (piece.u1 - piece.u0), d)
        assert best is not None
        return best

    def configuration_at(self, projection: Projection) -> np.ndarray:
        """Q = p^-1(Q'): the base from Q', the joints interpolated between the key postures at u."""
        u = min(max(projection.u, 0.0), self.keys.shape[0] - 1.0)
        i = min(int(u), self.keys.shape[0] - 2)
        f = u - i
        q = (1.0 - f) * self.keys[i] + f * self.keys[i + 1]
        q[:3] = self.R_ref @ projection.point[:3]
        q[3:7] = pin.Quaternion(self.R_ref @ pin.exp3(projection.point[3:])).coeffs()
        return q

    def closest(self, q: np.ndarray) -> tuple[np.ndarray, Projection]:
        """(Q, the projection of P') for q. The last answer is kept: the posture generator asks it
        twice per iteration for the same q (the criterion's error and f_T's value)."""
        key = np.asarray(q, dtype=float).tobytes()
        if self._last_closest is not None and self._last_closest[0] == key:
            Q, projection = self._last_closest[1]
            return Q.copy(), projection
        projection = self.project(base_point(q, self.R_ref))
        Q = self.configuration_at(projection)
        self._last_closest = (key, (Q, projection))
        return Q.copy(), projection

    def value(self, q: np.ndarray) -> float:
        """f_T(q) = ||q (-) Q||^2 - k s' (eq. 1)."""
        Q, projection = self.closest(q)
        d = pin.difference(self.model, Q, q)
        return float(d.dot(d)) - self.k * projection.s

    def progress(self, q: np.ndarray) -> float:
        """s' of q: how far along T' its base is (0 at the first key posture, ``length`` at the last)."""
        return self.project(base_point(q, self.R_ref)).s


def _round_corners(vertices: np.ndarray, lengths: np.ndarray, deviation: float) -> list[_Piece]:
    """Lines and arcs of T' (§2.7, Fig. 2 upper right)."""
    m = vertices.shape[0]
    dirs = np.diff(vertices, axis=0) / lengths[:, None]
    cut = np.zeros(m)  # distance from each vertex to its arc's tangent points
    arcs: dict[int, tuple[float, float, np.ndarray, np.ndarray]] = {}
    for i in range(1, m - 1):
        u_in, u_out = dirs[i - 1], dirs[i]
        phi = math.acos(float(np.clip(u_in.dot(u_out), -1.0, 1.0)))
        if phi < 1e-6 or phi > math.pi - 1e-6:
            continue
        half = 0.5 * phi
        r = deviation / (1.0 / math.cos(half) - 1.0)
        t = min(r * math.tan(half), 0.5 * lengths[i - 1], 0.5 * lengths[i])
        r = t / math.tan(half)
        normal = u_out - u_out.dot(u_in) * u_in
        normal /= np.linalg.norm(normal)
        cut[i] = t
        arcs[i] = (r, phi, normal, u_in)
    pieces: list[_Piece] = []
    s = 0.0
    for i in range(m - 1):
        start = vertices[i] + cut[i] * dirs[i]
        length = lengths[i] - cut[i] - cut[i + 1]
        pieces.append(
            _Piece(
                "line", s, length, i + cut[i] / lengths[i], i + 1 - cut[i + 1] / lengths[i], start, dirs[i]
            )
        )
        s += length
        if i + 1 in arcs:
            r, phi, normal, u_in = arcs[i + 1]
            a_point = vertices[i + 1] - cut[i + 1] * u_in
            centre = a_point + r * normal
            pieces.append(
                _Piece(
                    "arc",
                    s,
                    r * phi,
                    i + 1 - cut[i + 1] / lengths[i],
                    i + 1 + cut[i + 1] / lengths[i + 1],
                    centre,
                    -normal,
                    u_in,
                    r,
                    phi,
                )
            )
            s += r * phi
    return pieces


class PotentialTask(Task):
    """f_T as the posture generator's criterion (§2.8): a Gauss-Newton step on eq. (1). Its gradient is
    2 (P (-) Q) - k ds'/dP with ds'/dP the unit tangent t' of T' at Q' (P' near the curve), so the task
    F = P (-) Q - (k / 2) t (t: t' on the free-flyer coordinates, in Q's base frame as pinocchio's
    difference expresses them) has 1/2 ||F||^2 with the same gradient; J = identity (Q held during the
    step, recomputed at every iteration)."""

    def __init__(
        self, trajectory: RoughTrajectory, gain: float = 1.0, max_step: float | None = 0.6, name: str = "f_T"
    ) -> None:
        super().__init__(name, gain, max_step=max_step)
        self.trajectory = trajectory
        self._eye = np.eye(trajectory.model.nv)

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        Q, projection = self.trajectory.closest(q)
        F = pin.difference(self.trajectory.model, Q, q)
        R_Q = pin.Quaternion(Q[3:7]).toRotationMatrix()
        slope = 0.5 * self.trajectory.k
        R_ref = self.trajectory.R_ref  # t' is in F's frame (the start's heading)
        F[:3] -= slope * R_Q.T.dot(R_ref @ projection.tangent[:3])
        F[3:6] -= slope * R_Q.T.dot(R_ref @ projection.tangent[3:])
        return F

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self._eye
