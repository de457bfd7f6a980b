"""Degree-of-freedom bookkeeping: which configuration entries map one-to-one onto velocity entries,
joint-name selections, and the masks used by the level options of the reaching paper."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.ik.kinematics import joint_id

# Limits at or beyond this magnitude are "no limit" (URDF continuous joints, free flyers).
UNBOUNDED = 1e10


def vector_space_dofs(
    model: pin.Model, joint_ids: Sequence[int] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(q indices, v indices) of the coordinates of joints whose configuration is a vector space
    (nq == nv: revolute, prismatic, ...), so that q[q_idx] changes exactly by dq[v_idx] in
    ``pin.integrate``. Free flyers, planar joints and unbounded revolute joints are left out."""
    ids = range(1, model.njoints) if joint_ids is None else joint_ids
    q_idx: list[int] = []
    v_idx: list[int] = []
    for j in ids:
        joint = model.joints[j]
        if joint.nq == joint.nv:
            q_idx.extend(range(joint.idx_q, joint.idx_q + joint.nq))
            v_idx.extend(range(joint.idx_v, joint.idx_v + joint.nv))
    return np.array(q_idx, dtype=int), np.array(v_idx, dtype=int)


def bounded_dofs(model: pin.Model, q_lower: np.ndarray, q_upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q indices, v indices) of the vector-space coordinates with at least one finite limit."""
    q_idx, v_idx = vector_space_dofs(model)
    finite = (np.abs(q_lower[q_idx]) < UNBOUNDED) | (np.abs(q_upper[q_idx]) < UNBOUNDED)
    return q_idx[finite], v_idx[finite]


def joint_dofs(model: pin.Model, joint_names: Sequence[str]) -> np.ndarray:
    """Velocity indices of the named joints (InvalidRequestError for an unknown name)."""
    v_idx: list[int] = []
    for name in joint_names:
        joint = model.joints[joint_id(model, name)]
        v_idx.extend(range(joint.idx_v, joint.idx_v + joint.nv))
    return np.array(v_idx, dtype=int)


def dof_mask(model: pin.Model, joint_names: Sequence[str]) -> np.ndarray:
    """Boolean mask over the nv velocity coordinates, True on the named joints: the selection
    matrix S = diag{S_i} of the reaching paper (section on the weighted pseudo-inverse)."""
    mask = np.zeros(model.nv, dtype=bool)
    mask[joint_dofs(model, joint_names)] = True
    return mask


def near_limit_mask(
    model: pin.Model, q: np.ndarray, margin_rad: float, q_lower: np.ndarray, q_upper: np.ndarray
) -> np.ndarray:
    """Boolean mask over nv, False on the bounded coordinates within ``margin_rad`` of a limit: the
    selection matrix S_l of the reaching paper that forbids joints approaching their range limit."""
    mask = np.ones(model.nv, dtype=bool)
    q_idx, v_idx = bounded_dofs(model, q_lower, q_upper)
    near = (q[q_idx] - q_lower[q_idx] < margin_rad) | (q_upper[q_idx] - q[q_idx] < margin_rad)
    mask[v_idx[near]] = False
    return mask


def link_mass_weights(model: pin.Model, floor_ratio: float = 1e-3) -> np.ndarray:
    """Per-velocity-coordinate weights W_i = m_i / M of eq. (4) of the reaching paper: the mass of
    the link moved by the joint over the total mass (every coordinate of a multi-dof joint gets its
    link's ratio). Massless links (virtual footprint joints) get ``floor_ratio`` times the smallest
    positive ratio so that the metric stays positive definite."""
    total = sum(model.inertias[j].mass for j in range(1, model.njoints))
    ratios = np.zeros(model.nv)
    for j in range(1, model.njoints):
        joint = model.joints[j]
        ratios[joint.idx_v : joint.idx_v + joint.nv] = model.inertias[j].mass / total
    positive = ratios[ratios > 0.0]
    floor = floor_ratio * (positive.min() if positive.size else 1.0)
    return np.maximum(ratios, floor)
