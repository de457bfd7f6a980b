"""Facts of the simulated robot model for clients that do not load it (the supervisor): its joints,
role frames and cameras (``sim/robot_info``), and its forward kinematics at given configurations
(``sim/kinematics``). Pure functions of a ``services.model`` robot; ``sim/service.py`` is the adapter."""

from __future__ import annotations

import numpy as np

from services import budget
from services.bus.limits import MAX_CONFIGURATIONS, MAX_FRAME_POSES
from services.bus.schemas import sim as msg
from services.errors import InvalidRequestError
from services.model import RobotModel

#: ``sim/kinematics`` looks at the request's time budget every this many configurations.
BUDGET_CHECK_CONFIGURATIONS = 200
#: Joints whose name starts with one of these are the chest's (hrp2_like: CHEST_JOINT*; talos: torso_*).
CHEST_PREFIXES = ("CHEST", "TORSO")


def robot_info_reply(robot: RobotModel) -> msg.RobotInfoReply:
    """The ``sim/robot_info`` reply of ``robot``."""
    frames = {
        role: getattr(robot.frames, role)
        for role in ("left_sole", "right_sole", "left_grasp", "right_grasp", "gaze", "torso")
    }
    fixed = {}
    for side in ("left", "right"):
        # held_object_offset(side, r) = (0, y - sign(y) r, 0): y from a tiny radius.
        tiny = 1e-6
        y = float(robot.held_object_offset(side, tiny)[1])
        fixed[side] = y + float(np.sign(y)) * tiny if y != 0.0 else 0.0
    return msg.RobotInfoReply(
        model=robot.name,
        nq=robot.nq,
        joint_names=list(robot.joint_names),
        q_half_sitting=np.array(robot.q_half_sitting, dtype=float),
        q_lower=np.array(robot.q_lower, dtype=float),
        q_upper=np.array(robot.q_upper, dtype=float),
        chest_joints=[n for n in robot.joint_names if n.upper().startswith(CHEST_PREFIXES)],
        gripper_joints={side: robot.gripper_joint(side) for side in ("left", "right")},
        frames=frames,
        fixed_finger_y_m=fixed,
        cameras={name: [c.width_px, c.height_px] for name, c in robot.cameras.items()},
        stereo_pairs={name: [p.left, p.right] for name, p in robot.stereo_pairs.items()},
    )


def kinematics_reply(robot: RobotModel, request: msg.KinematicsRequest) -> msg.KinematicsReply:
    """The ``sim/kinematics`` reply: mid-feet poses, sole heights and frame poses at each configuration.

    Raises:
        InvalidRequestError: q not (nq,) or (k, nq), an unknown frame, ``place_at`` not [x, y, yaw].
        RequestTimeoutError: the request's time budget (:mod:`services.budget`, opened by the service)
            ran out (checked every ``BUDGET_CHECK_CONFIGURATIONS`` configurations).
    """
    Q = np.asarray(request.q, dtype=float)
    if Q.ndim == 1:
        Q = Q[None, :]
    if Q.ndim != 2 or Q.shape[0] < 1 or Q.shape[1] != robot.nq:
        raise InvalidRequestError(f"q must be (nq,) or (k, nq) with nq = {robot.nq}, got {Q.shape}")
    if not np.all(np.isfinite(Q)):
        raise InvalidRequestError("q has a non-finite value")
    if Q.shape[0] > MAX_CONFIGURATIONS or Q.shape[0] * len(request.frames) > MAX_FRAME_POSES:
        raise InvalidRequestError(
            f"{Q.shape[0]} configurations x {len(request.frames)} frames: at most {MAX_CONFIGURATIONS} "
            f"configurations and {MAX_FRAME_POSES} frame poses per sim/kinematics request; split it",
            {"field": "q", "limit": MAX_CONFIGURATIONS},
        )
    for name in request.frames:
        robot.frame_id(name)  # InvalidRequestError naming the role frames
    if request.place_at and len(request.place_at) != 3:
        raise InvalidRequestError(f"place_at must be [x, y, yaw] ([m], [m], [rad]), got {request.place_at!r}")
    data = robot.new_data()
    k = Q.shape[0]
    mid = np.zeros((k, 3))
    sole_z = np.zeros((k, 2))
    poses = np.zeros((k, len(request.frames), 4, 4))
    for i, q in enumerate(Q):
        if i % BUDGET_CHECK_CONFIGURATIONS == 0:
            budget.check(f"the forward kinematics, configuration {i} of {k}")
        mid[i] = robot.mid_feet_pose(q, data)  # runs the forward kinematics into data
        sole_z[i] = [robot.sole_pose(q, side, data).translation[2] for side in ("left", "right")]
        for j, name in enumerate(request.frames):
            poses[i, j] = robot.frame_pose(q, name, data).homogeneous
    placed = np.zeros(0)
    if request.place_at:
        x, y, yaw = (float(v) for v in request.place_at)
        placed = np.asarray(robot.place_on_ground(Q[-1], x, y, yaw), dtype=float)
    return msg.KinematicsReply(mid_feet=mid, sole_z_m=sole_z, poses=poses, q_placed=placed)
