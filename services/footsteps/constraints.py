"""Footstep-specific constraints of sections 3.2-3.3 of the footstep paper, as IK tasks
(:class:`services.ik.task.Task`) on the virtual chain model (:mod:`services.footsteps.chain`).

- :class:`RootSoleOnFootprintTask`: the robot's root sole rigidly on the last footprint F_{p-1}
  (the attachment of the humanoid to the virtual structure, Fig. 2), an equality.
- :class:`FrontStepBoundsTask`: the relative step bounds in the last support polygon (front foot
  relative to F_{p-1}); in the other support polygons they are the chain's joint limits, since
  Q_i is exactly the pose of F_i in F_{i-1}.
- :class:`NonOverlapTask`: no overlap of the footprints of every support polygon (Fig. 5), the
  inner corners of each foot kept outside the other foot's half-plane, following eqs. (12)-(13).

Disk obstacles (section 4.1), the front foot flat on the ground, the CoM over the final support
polygon (eq. 11), self-collision (eq. 13) and joint limits are generic tasks of ``services.ik``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from services.footsteps.chain import VirtualChain
from services.footsteps.geometry import non_overlap_rows
from services.ik.task import Task

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
    d_x = np.array([[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])
    J_p = R_At @ (J_B[:3] - J_A[:3] + d_x @ J_A[3:])
    # (w_B - w_A) x x_B = -[x_B]x (w_B - w_A)
    xb_x = np.array([[0.0, -x_B[2], x_B[1]], [x_B[2], 0.0, -x_B[0]], [-x_B[1], x_B[0], 0.0]])
    J_x = -R_At @ xb_x @ (J_B[3:] - J_A[3:])
    n2 = x_rel[0] ** 2 + x_rel[1] ** 2
    J_yaw = (x_rel[0] * J_x[1] - x_rel[1] * J_x[0]) / n2
    r = np.array([p_rel[0], p_rel[1], np.arctan2(x_rel[1], x_rel[0])])
    return r, np.vstack([J_p[:2], J_yaw[None, :]])


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
    ) -> None:
        limits = chain.bounds.for_swing(chain.front_side)
        inset = np.array([margin[0], margin[0], margin[1]])
        lower = np.array([lim[0] for lim in limits]) + inset
        upper = np.array([lim[1] for lim in limits]) - inset
        super().__init__(name, gain, lower=lower, upper=upper)
        self.model = chain.model
        self.parent_fid = chain.footprint_frame_ids[-1]
        self.child_fid = int(chain.model.getFrameId(chain.front_sole_frame))

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        return relative_planar_pose(self.model, data, self.parent_fid, self.child_fid)


class FrontFootHoldTask(Task):
    """The front foot at a given pose relative to F_{p-1}: r - r_target = 0 with r the front sole's
    (dx, dy, dtheta) in F_{p-1} (:func:`relative_planar_pose`), an equality [m, rad].

    With r_target the folded value (the initial stance) and the lowest priority, this is section
    5.1's "forcing the footprints to remain at their initial position" applied to the implicit last
    step Q_p: a front foot that no task needs stays next to the root foot, and a step that is not
    needed keeps its initial pose and is discarded.
    """

    def __init__(
        self, chain: VirtualChain, r_target: np.ndarray, gain: float = 1.0, name: str = "hold:front"
    ) -> None:
        super().__init__(name, gain)
        self.model = chain.model
        self.parent_fid = chain.footprint_frame_ids[-1]
        self.child_fid = int(chain.model.getFrameId(chain.front_sole_frame))
        self.r_target = np.asarray(r_target, dtype=float).reshape(3)

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        r, J = relative_planar_pose(self.model, data, self.parent_fid, self.child_fid)
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
    ) -> None:
        super().__init__(name, gain, lower=-np.inf, upper=0.0)
        self.model = chain.model
        self.length_m, self.width_m = float(sole_size_m[0]), float(sole_size_m[1])
        self.margin_m = float(margin_m)
        self.child_is_left = [side == "left" for side in chain.sides[1:]]
        self.front_is_left = chain.front_side == "left"
        self.parent_fid = chain.footprint_frame_ids[-1]
        self.front_fid = int(chain.model.getFrameId(chain.front_sole_frame))

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        n_pairs = len(self.child_is_left) + 1
        G = np.empty(4 * n_pairs)
        J = np.zeros((4 * n_pairs, self.model.nv))
        for i, is_left in enumerate(self.child_is_left):
            # Q_i: q and v indices coincide for the chain (vector-space joints at the start of q~).
            g, dg = non_overlap_rows(
                q[3 * i : 3 * i + 3], is_left, self.length_m, self.width_m, self.margin_m
            )
            G[4 * i : 4 * i + 4] = g
            J[4 * i : 4 * i + 4, 3 * i : 3 * i + 3] = dg
        r, J_r = relative_planar_pose(self.model, data, self.parent_fid, self.front_fid)
        g, dg = non_overlap_rows(r, self.front_is_left, self.length_m, self.width_m, self.margin_m)
        G[-4:] = g
        J[-4:] = dg @ J_r
        return G, J
