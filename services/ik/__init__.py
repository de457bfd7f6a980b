"""Prioritized equality/inequality inverse kinematics (hierarchical QP on proxsuite) and its tasks.

Section 2 of the footstep paper (Kanoun, Laumond, Yoshida): a strict hierarchy of linear equality
(eq. 2) and inequality (eq. 4) systems; see ``README.md`` in this package for the API and an example.
Pure algorithm package: no bus, no I/O.
"""

from services.ik.capsule import Capsule
from services.ik.dofs import dof_mask, link_mass_weights, near_limit_mask
from services.ik.kinematics import compute_kinematics
from services.ik.level import Level
from services.ik.monitors import ArmManipulability, manipulability, task_value
from services.ik.run import IKResult, run
from services.ik.solver import HierarchicalSolver, LevelReport, SolverConfig
from services.ik.task import Task
from services.ik.tasks import (
    ComPositionTask,
    ComSupportPolygonTask,
    FeetFlatTask,
    FootOutsideDiskTask,
    FrameOrientationTask,
    FramePoseTask,
    FramePositionTask,
    GazeTask,
    JointLimitsTask,
    PostureTask,
    SelfCollisionTask,
)

__all__ = [
    "ArmManipulability",
    "Capsule",
    "ComPositionTask",
    "ComSupportPolygonTask",
    "FeetFlatTask",
    "FootOutsideDiskTask",
    "FrameOrientationTask",
    "FramePoseTask",
    "FramePositionTask",
    "GazeTask",
    "HierarchicalSolver",
    "IKResult",
    "JointLimitsTask",
    "Level",
    "LevelReport",
    "PostureTask",
    "SelfCollisionTask",
    "SolverConfig",
    "Task",
    "compute_kinematics",
    "dof_mask",
    "link_mass_weights",
    "manipulability",
    "near_limit_mask",
    "run",
    "task_value",
]
