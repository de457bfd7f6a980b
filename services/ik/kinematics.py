"""Kinematic helpers shared by the tasks: frame lookup, frame and point Jacobians, skew matrices.

Everything reads a ``pin.Data`` already filled by :func:`compute_kinematics` (once per iteration).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def frame_id(model: pin.Model, frame_name: str) -> int:
    """Index of ``frame_name`` in ``model``; raises InvalidRequestError listing close names."""
    if not model.existFrame(frame_name):
        names = [frame.name for frame in model.frames]
        close = [n for n in names if frame_name.split("_")[0] in n][:12] or names[:12]
        raise InvalidRequestError(
            f"unknown frame {frame_name!r} in model {model.name!r}; frames include: {', '.join(close)}"
        )
    return int(model.getFrameId(frame_name))


def joint_id(model: pin.Model, joint_name: str) -> int:
    """Index of ``joint_name`` in ``model``; raises InvalidRequestError listing the joints."""
    if not model.existJointName(joint_name):
        raise InvalidRequestError(
            f"unknown joint {joint_name!r} in model {model.name!r}; joints: {', '.join(model.names[1:])}"
        )
    return int(model.getJointId(joint_name))


def compute_kinematics(model: pin.Model, data: pin.Data, q: np.ndarray, with_com: bool) -> None:
    """Fill ``data`` for the tasks: joint placements and Jacobians, frame placements, and (when
    ``with_com``) the centre of mass ``data.com[0]`` [m] and its Jacobian ``data.Jcom`` (3 x nv)."""
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    if with_com:
        # Reuses the joint placements just computed: no second forward kinematics pass.
        pin.jacobianCenterOfMass(model, data, False)


def frame_jacobian(model: pin.Model, data: pin.Data, fid: int) -> np.ndarray:
    """6 x nv Jacobian of frame ``fid`` in LOCAL_WORLD_ALIGNED: rows 0-2 the velocity of the frame
    origin in world axes [m/unit], rows 3-5 its angular velocity in world axes [rad/unit]."""
    return pin.getFrameJacobian(model, data, fid, LWA)


def point_jacobian(
    model: pin.Model, data: pin.Data, fid: int, point_in_frame_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World position [m] of a point fixed in frame ``fid`` and its 3 x nv translation Jacobian."""
    T_world_frame = data.oMf[fid]
    offset_world = T_world_frame.rotation @ point_in_frame_m
    J = frame_jacobian(model, data, fid)
    # v_point = v_origin + omega x r = v_origin - [r]x omega
    J_point = J[:3] - skew(offset_world) @ J[3:]
    return T_world_frame.translation + offset_world, J_point


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v]x such that [v]x w = v x w."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
