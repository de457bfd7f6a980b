"""Results returned by :class:`sim.world.World` (frozen dataclasses; arrays are numpy)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from services.model.specs import Intrinsics
from sim.contacts import Contact

OUTCOMES = ("completed", "fell", "collision")


@dataclass(frozen=True)
class RobotState:
    """Robot state at ``sim_time_s`` [s]: ``q`` (nq, pinocchio layout: base position [m] and quaternion
    xyzw in world, then joints [rad or m]), ``v`` (nv: base velocity in the base frame, joints)."""

    q: np.ndarray
    v: np.ndarray
    sim_time_s: float


@dataclass(frozen=True)
class ExecutionResult:
    """How a trajectory execution ended.

    Attributes:
        outcome: ``completed``, ``fell`` or ``collision``.
        message: a sentence saying what happened (which links collided, the tilt at the fall...).
        state: the final robot state.
        samples_executed: trajectory samples played (the first one is the start state).
        duration_s: sim time spent executing [s].
        tracking_error_rad: largest |commanded - measured| joint position over the motion [rad] (grippers
            excluded; prismatic joints in [m]).
        tracking_rms_rad: root mean square of the joint tracking errors [rad].
        worst_joint: the joint where the largest error occurred.
        base_error_m: largest distance between the measured base position and the planned one [m].
        foot_slip_m: largest horizontal drift of a loaded sole from where it landed [m].
        collisions: the unplanned contacts (first time each pair touched), empty unless ``collision``.
        fall_base_height_m, fall_tilt_rad: base height [m] and tilt [rad] when the fall was detected.
    """

    outcome: str
    message: str
    state: RobotState
    samples_executed: int
    duration_s: float
    tracking_error_rad: float
    tracking_rms_rad: float
    worst_joint: str
    base_error_m: float
    foot_slip_m: float
    collisions: tuple[Contact, ...] = ()
    fall_base_height_m: float = 0.0
    fall_tilt_rad: float = 0.0


@dataclass(frozen=True)
class GripperResult:
    """Outcome of a gripper command: ``grasped``, ``not_grasped``, ``released`` or ``opened``;
    ``held`` is the object now held by that hand ("" if none), ``released`` the object just let go
    ("" if none); ``finger_q`` the gripper joint after the motion [m or rad]."""

    side: str
    action: str
    outcome: str
    held: str
    released: str
    finger_q: float
    sim_time_s: float


@dataclass(frozen=True)
class CameraImage:
    """One rendered camera image.

    ``rgb`` (H, W, 3) uint8; ``depth_m`` (H, W) float32 depth along the optical axis [m] or None;
    ``segmentation`` (H, W) int32 body ids (-1 background; see ``labels``) or None; ``T_world_camera``
    (4x4) pose of the optical frame (z forward, x right, y down) at render time.
    """

    name: str
    intrinsics: Intrinsics
    T_world_camera: np.ndarray
    rgb: np.ndarray
    depth_m: np.ndarray | None = None
    segmentation: np.ndarray | None = None
    labels: dict[int, str] = field(default_factory=dict)


@dataclass(frozen=True)
class ObjectState:
    """Ground truth of one scene object: pose of its reference point (``position`` [m], ``quaternion``
    xyzw) in the world, its description and which hand holds it (``held_by``: "", "left", "right")."""

    name: str
    kind: str
    position: np.ndarray
    quaternion: np.ndarray
    colour: tuple[float, float, float, float]
    size_m: tuple[float, float, float]
    radius_m: float
    length_m: float
    mass_kg: float
    held_by: str
