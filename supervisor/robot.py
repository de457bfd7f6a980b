"""The robot as the supervisor knows it, from the services' replies (it loads no robot model).

Static facts come once from ``sim/robot_info`` (joints, limits, half-sitting, role frames, grippers,
cameras) and ``perception/look_around`` (the head's pan and tilt joints and the views of a search);
kinematics at a configuration (mid-feet pose, sole heights, frame poses, a configuration placed on the
ground) from ``sim/kinematics``. Configurations are in the pinocchio layout of ``StateReply.q``: 7 base
coordinates, then one value per joint of ``joint_names``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from services.bus.schemas import perception as perception_msg
from services.bus.schemas import sim as sim_msg
from services.errors import InvalidRequestError
from supervisor.calls import ServiceCaller

INFO_TIMEOUT_S = 20.0
#: Base coordinates before the joints in q (free flyer: x, y, z, qx, qy, qz, qw).
BASE_NQ = 7


class Pose(NamedTuple):
    """A world pose: ``translation`` (3,) [m] and ``rotation`` (3, 3)."""

    translation: np.ndarray
    rotation: np.ndarray


class Robot:
    """Facts and kinematics of the simulated robot, asked of ``sim`` and ``perception`` over the bus."""

    def __init__(self, bus: ServiceCaller) -> None:
        self.bus = bus
        self._info: sim_msg.RobotInfoReply | None = None
        self._head: perception_msg.LookAroundReply | None = None

    # Static facts ----------------------------------------------------------------------------------
    @property
    def info(self) -> sim_msg.RobotInfoReply:
        """``sim/robot_info`` (asked once)."""
        if self._info is None:
            info = self.bus.call(sim_msg.ROBOT_INFO, sim_msg.RobotInfoRequest(), INFO_TIMEOUT_S)
            if info.nq != BASE_NQ + len(info.joint_names):
                raise InvalidRequestError(
                    f"robot {info.model}: nq = {info.nq} is not 7 + one value per joint "
                    f"({len(info.joint_names)} joints): the supervisor handles one-dof joints only"
                )
            self._info = info
        return self._info

    @property
    def head(self) -> perception_msg.LookAroundReply:
        """``perception/look_around`` for this robot's wide pair (asked once): head joints, views, turns."""
        if self._head is None:
            request = perception_msg.LookAroundRequest(model=self.name, camera="wide")
            self._head = self.bus.call(perception_msg.LOOK_AROUND, request, INFO_TIMEOUT_S)
        return self._head

    @property
    def name(self) -> str:
        return self.info.model

    @property
    def nq(self) -> int:
        return self.info.nq

    @property
    def joint_names(self) -> list[str]:
        return self.info.joint_names

    @property
    def q_half_sitting(self) -> np.ndarray:
        return np.asarray(self.info.q_half_sitting, dtype=float)

    @property
    def q_lower(self) -> np.ndarray:
        return np.asarray(self.info.q_lower, dtype=float)

    @property
    def q_upper(self) -> np.ndarray:
        return np.asarray(self.info.q_upper, dtype=float)

    def index(self, joint: str) -> int:
        """Index of ``joint`` in q."""
        try:
            return BASE_NQ + self.info.joint_names.index(joint)
        except ValueError:
            raise InvalidRequestError(f"{self.name} has no joint {joint!r}") from None

    def gripper_index(self, side: str) -> int:
        return self.index(self.info.gripper_joints[side])

    def grasp_frame(self, side: str) -> str:
        return self.info.frames[f"{side}_grasp"]

    def held_object_offset(self, side: str, radius_m: float) -> np.ndarray:
        """Where the centre of a held object of radius ``radius_m`` ends up in the grasp frame [m] (3,):
        against the fixed finger (``fixed_finger_y_m``), or at the origin for a symmetric gripper."""
        y = float(self.info.fixed_finger_y_m.get(side, 0.0))
        offset = np.zeros(3)
        if y != 0.0:
            offset[1] = y - np.sign(y) * radius_m
        return offset

    # Kinematics ------------------------------------------------------------------------------------
    def kinematics(
        self, q: np.ndarray, frames: Sequence[str] = (), place_at: Sequence[float] = ()
    ) -> sim_msg.KinematicsReply:
        """``sim/kinematics`` at ``q`` ((nq,) or (k, nq))."""
        request = sim_msg.KinematicsRequest(
            q=np.ascontiguousarray(q, dtype=float), frames=list(frames), place_at=[float(v) for v in place_at]
        )
        return self.bus.call(sim_msg.KINEMATICS, request, INFO_TIMEOUT_S)

    def mid_feet_pose(self, q: np.ndarray) -> tuple[float, float, float]:
        """(x [m], y [m], yaw [rad]) of the mid-feet frame at ``q``."""
        x, y, yaw = (float(v) for v in np.asarray(self.kinematics(q).mid_feet)[0])
        return x, y, yaw

    def sole_heights(self, Q: np.ndarray) -> np.ndarray:
        """(k, 2) heights [m] of the left and right soles at each configuration of ``Q``."""
        return np.asarray(self.kinematics(Q).sole_z_m)

    def frame_pose(self, q: np.ndarray, frame: str) -> Pose:
        """World pose of ``frame`` at ``q``."""
        T = np.asarray(self.kinematics(q, frames=[frame]).poses)[0, 0]
        return Pose(T[:3, 3].copy(), T[:3, :3].copy())

    def grasp_position(self, q: np.ndarray, side: str) -> np.ndarray:
        """World position [m] of the ``side`` hand's grasp frame at ``q``."""
        return self.frame_pose(q, self.grasp_frame(side)).translation

    def place_on_ground(self, q: np.ndarray, x_m: float, y_m: float, yaw_rad: float) -> np.ndarray:
        """``q`` moved so that its mid-feet frame is at (x, y, yaw) with the soles at z = 0."""
        return np.array(self.kinematics(q, place_at=(x_m, y_m, yaw_rad)).q_placed, dtype=float)
