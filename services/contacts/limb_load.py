"""What a limb's joints can hold at a contact spot: a bound on the contact force from the joints' torque
limits (an extension of §2.2 of Escande et al., whose stability checks friction only).

The paper's static stability asks for contact forces inside friction cones that balance gravity. A
plan can then hang half the robot's weight on one hand; executed, the arm's shoulder and elbow reach
their torque limits and the arm gives way (measured in the sim: 300-330 N on a hand, LARM_JOINT0 and
LARM_JOINT3 at 100 % of their effort, services/contacts/README.md). This module bounds what a spot can
carry by what its limb can hold *in any posture*, so that the bound is a constant per spot and enters
the stability as one linear inequality per contact patch (the static-equilibrium region stays a fixed
polygon per contact set, as the posture generator needs):

    the limb of a spot is the unbranched chain of joints ending at the spot's body (walking up from the
    spot's joint while the parent joint carries no other limb: for a hand, the arm's seven joints up to
    the shoulder; the chest, carrying both arms and the head, is a branch point);

    for a joint j of the limb, a force f at a point of the patch has a moment about j's axis of at most
    |f| L_j, where L_j bounds the distance from j's axis to any patch corner whatever the posture: the
    part of the first link after j that lies off j's axis (that link is fixed in j's frame; an upper arm
    along its own yaw axis adds nothing), plus the lengths of the links after it, plus the corner's
    distance to its body's joint (the triangle inequality); exact for a patch on j's own body. The
    limb's own weight has a moment of at most G_j = sum_k m_k g d_jk (every body k carried by j, its
    centre of mass at the bounded distance d_jk from j's axis);

    so |f| <= (tau_max_j - G_j) / L_j keeps joint j within its effort limit tau_max_j, and the spot's
    bound is the smallest over the limb's joints.

The bound is on |f| (``ContactPatch.max_load``); the stability turns it into a bound on the patch's
normal force (``stability.py``).

It is conservative (the worst posture and the worst direction); it is meant for limbs that do not
carry the robot's weight along their joints' alignment: for a leg it would forbid standing on one
foot (a straight leg holds the whole weight with little torque), so the posture generator applies it
to the spots of ``PostureConfig.limb_load_spots`` only (the hands and forearms by default).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from services.contacts.spots import ContactSpot
from services.errors import InvalidRequestError

GRAVITY_M_S2 = 9.81


def limb_joints(model: pin.Model, joint_id: int) -> list[int]:
    """The joint ids of the limb ending at ``joint_id``, from that joint up to the limb's root (the
    first joint whose parent joint carries more than one child joint, or whose parent is the universe
    or the free flyer)."""
    children: dict[int, int] = {}
    for j in range(1, model.njoints):
        children[model.parents[j]] = children.get(model.parents[j], 0) + 1
    chain = [joint_id]
    while True:
        parent = model.parents[chain[-1]]
        if parent <= 1 or children.get(parent, 0) > 1:  # 0: universe, 1: the free flyer
            return chain
        chain.append(parent)


def _subtree(model: pin.Model, joint_id: int) -> list[int]:
    """``joint_id`` and every joint below it."""
    out = [joint_id]
    for j in range(joint_id + 1, model.njoints):
        if model.parents[j] in out:
            out.append(j)
    return out


def _axis(model: pin.Model, joint_id: int) -> np.ndarray | None:
    """The unit rotation axis of a revolute joint in its own frame (None for another joint type)."""
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    column = pin.getJointJacobian(model, data, joint_id, pin.LOCAL)[:, model.joints[joint_id].idx_v]
    norm = float(np.linalg.norm(column[3:]))
    return column[3:] / norm if norm > 1e-9 else None


def _distance_to_axis_m(
    model: pin.Model, top: int, axis: np.ndarray, joint_id: int, points: np.ndarray
) -> float:
    """Upper bound, in any posture, of the distance between joint ``top``'s axis (through its origin)
    and the ``points`` (k x 3) fixed in the frame of joint ``joint_id`` (``top`` or below it): exact for
    ``top``'s own body; below, the part of the first link (fixed in ``top``'s frame) off the axis plus
    the lengths of the links after it (the triangle inequality) plus the points' distance to their
    joint."""

    def off_axis(v: np.ndarray) -> float:
        return float(np.linalg.norm(v - axis * float(axis.dot(v))))

    points = np.atleast_2d(points)
    if joint_id == top:
        return max(off_axis(p) for p in points)
    length, j = 0.0, joint_id
    while model.parents[j] != top:
        length += float(np.linalg.norm(model.jointPlacements[j].translation))
        j = model.parents[j]
    first = off_axis(model.jointPlacements[j].translation)  # j: the child of top on the way
    return first + length + max(float(np.linalg.norm(p)) for p in points)


def force_cap_n(model: pin.Model, spot: ContactSpot) -> float:
    """The largest contact force |f| [N] at any point of ``spot``'s patch that every joint of the
    spot's limb holds within its effort limit together with the limb's own weight, in any posture
    (module docstring). ``model`` has the spot's frame (``spots.model_with_spots``)."""
    if not model.existFrame(spot.frame_name):
        raise InvalidRequestError(f"the model has no frame {spot.frame_name!r} (model_with_spots)")
    frame = model.frames[model.getFrameId(spot.frame_name)]
    spot_joint = frame.parentJoint
    corners = np.array([frame.placement.act(c) for c in spot.corners_local()])  # in the joint's frame
    cap = math.inf
    for j in limb_joints(model, spot_joint):
        effort = float(model.effortLimit[model.joints[j].idx_v])
        axis = _axis(model, j)
        if axis is None:  # a prismatic joint holds the force's component along its axis
            cap = min(cap, effort)
            continue
        lever = _distance_to_axis_m(model, j, axis, spot_joint, corners)
        weight_moment = sum(
            model.inertias[k].mass
            * GRAVITY_M_S2
            * _distance_to_axis_m(model, j, axis, k, model.inertias[k].lever[None, :])
            for k in _subtree(model, j)
        )
        if effort <= weight_moment:
            return 0.0
        cap = min(cap, (effort - weight_moment) / max(lever, 1e-9))
    return cap
