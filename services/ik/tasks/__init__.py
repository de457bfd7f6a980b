"""The task library of the prioritized IK, one class per file."""

from services.ik.tasks.com_position import ComPositionTask
from services.ik.tasks.com_support_polygon import ComSupportPolygonTask
from services.ik.tasks.feet_flat import FeetFlatTask
from services.ik.tasks.foot_outside_disk import FootOutsideDiskTask
from services.ik.tasks.frame_orientation import FrameOrientationTask
from services.ik.tasks.frame_pose import FramePoseTask
from services.ik.tasks.frame_position import FramePositionTask
from services.ik.tasks.gaze import GazeTask
from services.ik.tasks.joint_limits import JointLimitsTask
from services.ik.tasks.posture import PostureTask
from services.ik.tasks.self_collision import SelfCollisionTask

__all__ = [
    "ComPositionTask",
    "ComSupportPolygonTask",
    "FeetFlatTask",
    "FootOutsideDiskTask",
    "FrameOrientationTask",
    "FramePoseTask",
    "FramePositionTask",
    "GazeTask",
    "JointLimitsTask",
    "PostureTask",
    "SelfCollisionTask",
]
