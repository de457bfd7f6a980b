"""Robot models shared by every planner: ``load_robot("hrp2_like" | "talos") -> RobotModel``.

Pinocchio model (free-flyer root) and named frames, half-sitting, limits, sole rectangles, capsules,
cameras and per-robot parameters; ``services.model.pybullet_robot`` loads the same URDF in pybullet.
See services/model/README.md.
"""

from services.model.ground import FootstepBounds
from services.model.robot_model import RobotModel, load_robot, robot_names
from services.model.specs import (
    CameraSpec,
    Capsule,
    GripperSpec,
    JointIndex,
    RobotFrames,
    RobotParams,
    StereoPair,
)

__all__ = [
    "CameraSpec",
    "Capsule",
    "FootstepBounds",
    "GripperSpec",
    "JointIndex",
    "RobotFrames",
    "RobotModel",
    "RobotParams",
    "StereoPair",
    "load_robot",
    "robot_names",
]
