"""Footstep-specific constraints of sections 3.2-3.3 of the footstep paper, as IK tasks
(:class:`services.ik.task.Task`) on the virtual chain model (:mod:`services.footsteps.chain`).

- :class:`RootSoleOnFootprintTask`: the robot's root sole rigidly on the last footprint F_{p-1}
  (the attachment of the humanoid to the virtual structure, Fig. 2), an equality.
- :class:`FrontStepBoundsTask`: the relative step bounds in the last support polygon (front foot
  relative to F_{p-1}); in the other support polygons they are the chain's joint limits, since
  Q_i is exactly the pose of F_i in F_{i-1}.
- :class:`NonOverlapTask`: no overlap of the footprints of every support polygon (Fig. 5), the
  inner corners of each foot kept outside the other foot's half-plane, following eqs. (12)-(13).
- :class:`FootprintDisksTask`: every movable footprint and the front sole outside every disk
  obstacle (section 4.1): the relative velocity of the disk centre and the closest footprint point
  bounded as in eq. (13).

The front foot flat on the ground, the CoM over the final support polygon (eq. 11), self-collision
(eq. 13) and joint limits are generic tasks of ``services.ik``. Every task reads the chain model's
kinematics, in the frame of the root footprint F_0 (:mod:`services.footsteps.chain`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.footsteps.chain import VirtualChain
from services.footsteps.geometry import non_overlap_rows_many
from services.ik.task import Task
from services.model.ground import yaw_of

LOCAL = pin.ReferenceFrame.LOCAL
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def relative_planar_pose(
    model: pin.Model, data: pin.Data, parent_fid: int, child_fid: int
) -> tuple[np.ndarray, np.ndarray]:
    """r = (dx [m], dy [m], dtheta [rad]) of frame ``child_fid`` projected in the ground frame of
    ``parent_fid`` (a flat frame), and dr/dq~ (3 x nv).

    dx, dy are the first two coordinates of R_A^T (p_B - p_A); dtheta is the heading of R_A^T x_B
    (x_B the child's x axis). With world-axes velocities (v, w) of both frames:
    d(R_A^T d) = R_A^T (v_B - v_A - w_A x d) and d(R_A^T x_B) = R_A^T ((w_B - w_A) x x_B).
    """
    T_A, T_B = data.oMf[parent_fid], data.oMf[child_fid]
    R_At = T_A.rotation.T
    d = T_B.translation - T_A.translation
    J_A = pin.getFrameJacobian(model, data, parent_fid, LWA)
    J_B = pin.getFrameJacobian(model, data, child_fid, LWA)
    p_rel = R_At @ d
    x_B = T_B.rotation[:, 0]
    x_rel = R_At @ x_B
    # v_B - v_A - w_A x d = v_B - v_A + [d]x w_A
    J_p = R_At @ (J_B[:3] - J_A[:3] + _skew(d) @ J_A[3:])
    # (w_B - w_A) x x_B = -[x_B]x (w_B - w_A)
    J_x = -R_At @ _skew(x_B) @ (J_B[3:] - J_A[3:])
    n2 = x_rel[0] ** 2 + x_rel[1] ** 2
    J_yaw = (x_rel[0] * J_x[1] - x_rel[1] * J_x[0]) / n2
    r = np.array([p_rel[0], p_rel[1], np.arctan2(x_rel[1], x_rel[0])])
    J = np.empty((3, J_p.shape[1]))
    J[:2] = J_p[:2]
    J[2] = J_yaw
    return r, J


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v]x (3 x 3, C order) of a 3-vector: [v]x w = v x w."""
    x, y, z = v.tolist()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


class FrontRelativePose:
    """:func:`relative_planar_pose` of the front sole in F_{p-1}, computed once per configuration for
    the tasks that read it (step bounds, non-overlap, the front foot hold): the solver evaluates
    every task at the same q with ``data`` already filled, so the pose is recomputed only when q or
    ``data`` changes. The returned arrays are read-only."""

    def __init__(self, chain: VirtualChain) -> None:
        self.model = chain.model
        self.parent_fid = chain.footprint_frame_ids[-1]
        self.child_fid = chain.front_sole_fid
        self._data: pin.Data | None = None
        self._q = b""
        self._value: tuple[np.ndarray, np.ndarray] | None = None

    def get(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """(r, dr/dq~) at q (``data`` holding the kinematics of q)."""
        # q by its bytes: the same bytes are the same configuration (a cheaper test than the values')
        key = np.ascontiguousarray(q, dtype=float).tobytes()
        if self._value is None or data is not self._data or key != self._q:
            r, J = relative_planar_pose(self.model, data, self.parent_fid, self.child_fid)
            r.flags.writeable = False
            J.flags.writeable = False
            self._value, self._data, self._q = (r, J), data, key
        return self._value


class RootSoleOnFootprintTask(Task):
    """The robot's root sole frame equal to the last footprint frame F_{p-1}: F = log6(T_F^-1 T_sole)
    (6 rows, [m] and [rad]), an equality at the top priority (the robot "made" its root step there).

    J = Jlog6(T_rel) (J_sole^local - Ad(T_sole^-1 T_F) J_F^local): the chain's joints move both frames
    together and cancel.
    """

    def __init__(self, chain: VirtualChain, gain: float = 1.0, name: str = "root_sole_on_footprint") -> None:
        super().__init__(name, gain)
        self.model = chain.model
        self.sole_fid = int(chain.model.getFrameId(chain.root_sole_frame))
        self.footprint_fid = chain.footprint_frame_ids[-1]

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        T_rel = data.oMf[self.footprint_fid].actInv(data.oMf[self.sole_fid])
        return np.array(pin.log6(T_rel).vector)

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        T_F, T_S = data.oMf[self.footprint_fid], data.oMf[self.sole_fid]
        T_rel = T_F.actInv(T_S)
        J_S = pin.getFrameJacobian(self.model, data, self.sole_fid, LOCAL)
        J_F = pin.getFrameJacobian(self.model, data, self.footprint_fid, LOCAL)
        J_rel = J_S - T_rel.inverse().toActionMatrix() @ J_F
        return np.array(pin.log6(T_rel).vector), pin.Jlog6(T_rel) @ J_rel


class FrontStepBoundsTask(Task):
    """Relative step bounds of section 3.3 in the last support polygon: (dx, dy, dtheta) of the
    front sole in F_{p-1} within the chain's bounds for the front foot's side (mirrored for the right
    foot), lambda (lower - r) <= dr <= lambda (upper - r) (eq. 4).

    Unlike the chain's joints (hard limits), the front foot's pose results from the whole robot, and
    the linearized rows let it overshoot by a fraction of a millimetre: ``margin`` (m, rad) keeps the
    rows that far inside (the planner's bounds are already inset, ``planner.step_bounds``).
    """

    def __init__(
        self,
        chain: VirtualChain,
        gain: float = 1.0,
        margin: tuple[float, float] = (0.0, 0.0),
        name: str = "front_step_bounds",
        front: FrontRelativePose | None = None,
    ) -> None:
        limits = chain.bounds.for_swing(chain.front_side)
        inset = np.array([margin[0], margin[0], margin[1]])
        lower = np.array([lim[0] for lim in limits]) + inset
        upper = np.array([lim[1] for lim in limits]) - inset
        super().__init__(name, gain, lower=lower, upper=upper)
        self.front = front or FrontRelativePose(chain)

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        return self.front.get(q, data)


class FrontFootHoldTask(Task):
    """The front foot at a given pose relative to F_{p-1}: r - r_target = 0 with r the front sole's
    (dx, dy, dtheta) in F_{p-1} (:func:`relative_planar_pose`), an equality [m, rad].

    With r_target the folded value (the initial stance) and the lowest priority, this is section
    5.1's "forcing the footprints to remain at their initial position" applied to the implicit last
    step Q_p: a front foot that no task needs stays next to the root foot, and a step that is not
    needed keeps its initial pose and is discarded.
    """

    def __init__(
        self,
        chain: VirtualChain,
        r_target: np.ndarray,
        gain: float = 1.0,
        name: str = "hold:front",
        front: FrontRelativePose | None = None,
    ) -> None:
        super().__init__(name, gain)
        self.front = front or FrontRelativePose(chain)
        self.r_target = np.asarray(r_target, dtype=float).reshape(3)

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        r, J = self.front.get(q, data)
        error = r - self.r_target
        error[2] = (error[2] + np.pi) % (2.0 * np.pi) - np.pi
        return error, J


class NonOverlapTask(Task):
    """No overlap of the two footprints of every support polygon (Fig. 5): 4 rows G <= 0 per polygon,
    the inner corners of each footprint at least ``margin_m`` outside the half-plane of the other one
    (:func:`services.footsteps.geometry.non_overlap_rows`), bounded in velocity as in eq. (13).

    Support polygons: (F_{i-1}, F_i) for i = 1 .. p-1, where r = Q_i are joint values, and
    (F_{p-1}, front sole), where r is the front sole's relative pose (:func:`relative_planar_pose`).
    """

    def __init__(
        self,
        chain: VirtualChain,
        sole_size_m: tuple[float, float],
        margin_m: float = 0.01,
        gain: float = 1.0,
        name: str = "non_overlap",
        front: FrontRelativePose | None = None,
    ) -> None:
        super().__init__(name, gain, lower=-np.inf, upper=0.0)
        self.model = chain.model
        self.length_m, self.width_m = float(sole_size_m[0]), float(sole_size_m[1])
        self.margin_m = float(margin_m)
        self.child_is_left = np.array([side == "left" for side in chain.sides[1:]], dtype=bool)
        self.front_is_left = np.array([chain.front_side == "left"])
        self.n_chain = len(self.child_is_left)
        self._is_left = np.append(self.child_is_left, self.front_is_left)
        self.front = front or FrontRelativePose(chain)
        # Q_i: q and v indices coincide for the chain (vector-space joints at the start of q~); the
        # rows of support polygon i only involve Q_i.
        n = self.n_chain
        self._rows = np.repeat(np.arange(4 * n).reshape(n, 4), 3, axis=1).reshape(n, 4, 3)
        self._cols = np.broadcast_to((3 * np.arange(n))[:, None, None] + np.arange(3), (n, 4, 3))

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        n = self.n_chain
        # every support polygon's r in one array: Q_1 .. Q_{p-1}, then the front sole's pose
        r = np.empty((n + 1, 3))
        r[:n] = q[: 3 * n].reshape(n, 3)
        r_front, J_front = self.front.get(q, data)
        r[n] = r_front
        g, dg = non_overlap_rows_many(r, self._is_left, self.length_m, self.width_m, self.margin_m)
        J = np.zeros((4 * (n + 1), self.model.nv))
        if n:
            J[self._rows, self._cols] = dg[:n]
        J[-4:] = dg[n] @ J_front
        return g.ravel(), J


class FootprintDisksTask(Task):
    """Disk obstacles on the ground (section 4.1): the movable footprints F_1 .. F_{p-1} and the
    front sole each stay ``margin_m`` outside every disk; one row per (disk, footprint), disk-major.

    As for a pair of capsules (eqs. 12-13): B is the point of the footprint rectangle closest to the
    disk centre c (the closest edge point when c is under the sole), s the signed distance from c to
    the footprint (negative inside), G = radius + margin - s <= 0 and dG = n^T dB with n the
    footprint's outward normal at B and B held fixed in the footprint. The footprints of the chain
    are planar functions of Q_1 .. Q_i (F_i = F_{i-1} (+) Q_i, F_0 the model's origin), so their
    rows are computed for all footprints and disks at once: dB/d(dx_j, dy_j) are the x and y axes of
    F_{j-1} and dB/d(dtheta_j) = e_z x (B - O_j) for j <= i. The front sole's rows use its frame
    Jacobian, with the exact yaw rate of its x axis.

    ``centers_xy`` are in the model's frame (:meth:`VirtualChain.model_point`).
    """

    def __init__(
        self,
        chain: VirtualChain,
        sole_size_m: tuple[float, float],
        centers_xy: Sequence[Sequence[float]],
        radii_m: Sequence[float],
        margin_m: float = 0.0,
        gain: float = 1.0,
        name: str = "disks",
    ) -> None:
        super().__init__(name, gain, lower=-np.inf, upper=0.0)
        self.model = chain.model
        self.front_fid = chain.front_sole_fid
        self.n_chain = chain.n_footprints - 1
        self.half = 0.5 * np.array(sole_size_m, dtype=float)
        self.centers = np.array(centers_xy, dtype=float).reshape(-1, 2)
        self.clearance = np.asarray(radii_m, dtype=float).reshape(-1) + float(margin_m)
        self.lower_triangle = np.tril(np.ones((self.n_chain, self.n_chain)))

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        n, k = self.n_chain, self.centers.shape[0]
        # F_0 .. F_{p-1}: yaws and origins by composing the Q_i from the model's origin
        Q = q[: 3 * n].reshape(n, 3)
        yaw = np.empty(n + 1)
        yaw[0] = 0.0
        np.cumsum(Q[:, 2], out=yaw[1:])
        cos, sin = np.cos(yaw), np.sin(yaw)
        moves = _rotate(cos[:-1], sin[:-1], Q[:, :2])
        origins = np.empty((n + 1, 2))
        origins[0] = 0.0
        np.cumsum(moves, axis=0, out=origins[1:])
        T_front = data.oMf[self.front_fid]
        R_front = T_front.rotation
        yaw_front = yaw_of(R_front)
        # the movable footprints F_1 .. F_{p-1}, then the front sole
        fp_origin = np.empty((n + 1, 2))
        fp_origin[:n] = origins[1:]
        fp_origin[n] = T_front.translation[:2]
        fp_cos, fp_sin = np.empty(n + 1), np.empty(n + 1)
        fp_cos[:n], fp_sin[:n] = cos[1:], sin[1:]
        fp_cos[n], fp_sin[n] = math.cos(yaw_front), math.sin(yaw_front)
        d = self.centers[:, None, :] - fp_origin[None]  # (k, n + 1, 2)
        local = _rotate(fp_cos, -fp_sin, d)  # in each footprint's frame
        h = self.half
        # the outward normal and the closest point B in each footprint's frame, rotated together below
        normal_and_B = np.empty((2, *local.shape))
        B_local = np.minimum(np.maximum(local, -h), h, out=normal_and_B[1])  # (np.clip(local, -h, h))
        offset = local - B_local
        outside = np.sqrt(np.einsum("...i,...i->...", offset, offset))
        is_out = outside > 1e-9
        n_local = np.divide(offset, np.where(is_out, outside, 1.0)[..., None], out=normal_and_B[0])
        signed = outside
        if np.count_nonzero(is_out) != is_out.size:
            # the centre under a sole: the nearest edge, negative distance
            x, y = local[..., 0], local[..., 1]
            gaps = np.stack((h[0] - x, x + h[0], h[1] - y, y + h[1]), -1)
            edge = gaps.argmin(axis=-1)
            gap = np.take_along_axis(gaps, edge[..., None], -1)[..., 0]
            inner_n = _EDGE_NORMALS[edge]
            inside = ~is_out
            normal_and_B[0] = np.where(inside[..., None], inner_n, n_local)
            normal_and_B[1] = np.where(inside[..., None], local + gap[..., None] * inner_n, B_local)
            signed = np.where(inside, -gap, outside)
        G = self.clearance[:, None] - signed
        # outward normal and lever of B in the model frame
        normal, lever = _rotate(fp_cos, fp_sin, normal_and_B)
        J = np.zeros((k, n + 1, self.model.nv))
        if n:
            nx, ny = normal[:, :n, 0:1], normal[:, :n, 1:2]  # (k, n, 1): footprint i, joints j below
            B = fp_origin[None, :n] + lever[:, :n]
            tri = self.lower_triangle
            J[:, :n, 0 : 3 * n : 3] = (nx * cos[:-1] + ny * sin[:-1]) * tri
            J[:, :n, 1 : 3 * n : 3] = (ny * cos[:-1] - nx * sin[:-1]) * tri
            # n . (e_z x (B - O_j)) with O_j the origin of F_j (the joint axis of dtheta_j)
            J[:, :n, 2 : 3 * n : 3] = (
                ny * (B[..., 0:1] - origins[1:, 0]) - nx * (B[..., 1:2] - origins[1:, 1])
            ) * tri
        J_f = pin.getFrameJacobian(self.model, data, self.front_fid, LWA)
        x_axis = R_front[:, 0]
        # exact yaw rate of the sole x axis projected on the ground, d atan2(x_y, x_x), tilt included
        tilt = x_axis[2] / (x_axis[0] ** 2 + x_axis[1] ** 2)
        J_yaw = J_f[5] - tilt * (x_axis[0] * J_f[3] + x_axis[1] * J_f[4])
        n_f, lever_f = normal[:, n], lever[:, n]
        J[:, n] = n_f.dot(J_f[:2]) + (n_f[:, 1] * lever_f[:, 0] - n_f[:, 0] * lever_f[:, 1])[:, None] * J_yaw
        return G.ravel(), J.reshape(k * (n + 1), self.model.nv)


_EDGE_NORMALS = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])


def _rotate(cos: np.ndarray, sin: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Planar vectors ``v`` (..., 2) rotated by the angles of (cos, sin) (broadcast against v[..., 0])."""
    x, y = v[..., 0], v[..., 1]
    first = cos * x - sin * y
    out = np.empty((*first.shape, 2))
    out[..., 0] = first
    np.add(sin * x, cos * y, out=out[..., 1])
    return out
