"""A bar carried in both hands: its size (:class:`CarriedBar`) and how the robot holds it (:class:`BarGrip`).

The bar of the paper's bar-carrying experiment ("Manipulating While Walking", `001_771c0ce3779b0683.txt`).
Navigation builds the grip from a configuration (``services.navigation.carry.grip_from_configuration``)
and plans with it; :class:`services.collision.motion.MotionChecker` adds the held bar to the robot's
collision shapes. Frames: the ``bar`` frame has its origin at the bar's centre and x along its axis
(from the right hand to the left hand).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError


@dataclass(frozen=True)
class CarriedBar:
    """A bar held horizontally in both hands, across the walking direction, in the ``base`` frame.

    ``length_m``, ``radius_m`` [m] and ``mass_kg`` of the paper's bar (1.8 m, 2.4 cm diameter, 0.5 kg);
    its centre is ``forward_m`` [m] ahead of the base origin at height ``height_m`` [m] above the floor;
    ``yaw_in_base_rad`` [rad] is the bar's axis direction in the base frame (pi/2: along base y).
    """

    length_m: float = 1.8
    radius_m: float = 0.012
    mass_kg: float = 0.5
    forward_m: float = 0.35
    height_m: float = 0.9
    yaw_in_base_rad: float = math.pi / 2

    def __post_init__(self) -> None:
        if not (self.length_m > 0.0 and self.radius_m > 0.0 and self.mass_kg > 0.0):
            raise InvalidRequestError("bar length, radius and mass must be > 0")
        if not all(math.isfinite(v) for v in (self.forward_m, self.height_m, self.yaw_in_base_rad)):
            raise InvalidRequestError("bar forward offset, height and yaw must be finite")


@dataclass(frozen=True, eq=False)
class BarGrip:
    """The bar held in both hands, as found in a configuration.

    ``held_point_in_grasp_m[side]`` is where the bar's axis crosses the grasp frame of ``side`` (3,) [m]
    (``RobotModel.held_object_offset``); ``along_m[side]`` the signed position of that point along the
    bar's x axis from its centre [m]; ``T_left_grasp_bar`` the bar frame in the left grasp frame (the bar
    is rigid with the left hand, as in the sim, where the left gripper's constraint holds it);
    ``centre_world_m`` / ``axis_world`` the bar at the configuration; ``grip_error_m`` how far the right
    held point is from the bar's axis there (0 when the bar is centred between the hands' held points).
    """

    bar: CarriedBar
    grasp_frames: dict[str, str]
    held_point_in_grasp_m: dict[str, np.ndarray]
    along_m: dict[str, float]
    T_left_grasp_bar: pin.SE3
    centre_world_m: np.ndarray
    axis_world: np.ndarray
    grip_error_m: float
