"""Plain data types of the robot model interface (frozen dataclasses, no pinocchio objects)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple, Self

import numpy as np

from services.errors import InvalidRequestError
from services.model.ground import FootstepBounds

SIDES = ("left", "right")


def check_side(side: str) -> str:
    """Return ``side`` if it is "left" or "right", else raise :class:`InvalidRequestError`."""
    if side not in SIDES:
        raise InvalidRequestError(f"side must be 'left' or 'right', got {side!r}", {"valid": list(SIDES)})
    return side


class JointIndex(NamedTuple):
    """Where one actuated (1-DoF) joint sits in q (``idx_q``) and in v (``idx_v``)."""

    idx_q: int
    idx_v: int


@dataclass(frozen=True)
class RobotFrames:
    """Names of the pinocchio frames with a role. All frames follow REP-103 body conventions (x forward,
    y left, z up in half-sitting) except camera optical frames (z forward along the optical axis,
    x right, y down in the image).

    - ``left_sole``/``right_sole``: centre of the sole rectangle, on the sole surface, z up (normal).
    - ``left_grasp``/``right_grasp``: between the fingertips (centre of the open gripper); z points
      from the grasp point back towards the wrist, y is the closing direction axis of the fingers.
    - ``gaze``: in the head, x is the gaze axis (middle of the wide stereo pair).
    - ``torso``: chest frame after the chest pitch joint; ``base``: the waist (free-flyer) frame.
    """

    left_sole: str
    right_sole: str
    left_grasp: str
    right_grasp: str
    gaze: str
    torso: str
    base: str

    def sole(self, side: str) -> str:
        """Sole frame name of ``side`` ("left" or "right")."""
        return self.left_sole if check_side(side) == "left" else self.right_sole

    def grasp(self, side: str) -> str:
        """Grasp frame name of ``side`` ("left" or "right")."""
        return self.left_grasp if check_side(side) == "left" else self.right_grasp


@dataclass(frozen=True)
class Capsule:
    """A segment swept by a sphere, fixed to a pinocchio frame: points in that frame [m]."""

    name: str
    frame: str
    p0_local: tuple[float, float, float]
    p1_local: tuple[float, float, float]
    radius_m: float


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics [px] of a ``width_px`` x ``height_px`` image (optical convention: z forward, x
    right, y down; pixel (0, 0)'s top-left *corner* at (0, 0), so the centre of row i, column j is at
    (j + 0.5, i + 0.5)). A point ``(X, Y, Z)`` of the optical frame projects to ``(fx X / Z + cx,
    fy Y / Z + cy)``. Use :meth:`scaled` for another resolution."""

    width_px: int
    height_px: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def K(self) -> np.ndarray:  # noqa: N802 (the usual name of the intrinsic matrix)
        """3x3 intrinsic matrix [px]."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def hfov_rad(self) -> float:
        """Horizontal field of view [rad]."""
        return 2.0 * math.atan2(self.width_px / 2.0, self.fx)

    @property
    def vfov_rad(self) -> float:
        """Vertical field of view [rad]."""
        return 2.0 * math.atan2(self.height_px / 2.0, self.fy)

    def scaled(self, width_px: int, height_px: int) -> Self:
        """The same field of view rendered at another resolution (same type, other fields kept)."""
        if width_px <= 0 or height_px <= 0:
            raise InvalidRequestError(f"image size must be positive, got {width_px}x{height_px}")
        sx, sy = width_px / self.width_px, height_px / self.height_px
        return replace(
            self,
            width_px=width_px,
            height_px=height_px,
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=self.cx * sx,
            cy=self.cy * sy,
        )


@dataclass(frozen=True)
class CameraSpec(Intrinsics):
    """A pinhole camera on a robot frame: its :class:`Intrinsics` and the ``frame`` of its optical axes."""

    frame: str


@dataclass(frozen=True)
class StereoPair:
    """Two camera names (keys of ``RobotModel.cameras``) and their baseline [m] (right is at -baseline
    along the left camera's optical x axis)."""

    left: str
    right: str
    baseline_m: float


@dataclass(frozen=True)
class GripperSpec:
    """Gripper joint values: ``open_q`` and ``closed_q`` (in the joint's unit, m or rad)."""

    open_q: float
    closed_q: float


@dataclass(frozen=True)
class RobotParams:
    """Per-robot parameters, one YAML file per robot (``services/model/data/<robot>.yaml``)."""

    footstep_bounds: FootstepBounds
    step_height_m: float
    com_height_m: float
    step_duration_s: float
    double_support_s: float
    manipulability_threshold: float
    ee_error_threshold_m: float
    fall_base_height_m: float
    fall_tilt_rad: float
    gripper: GripperSpec
    extra: dict[str, float] = field(default_factory=dict)
