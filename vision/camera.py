"""Pinhole cameras and rectified stereo rigs.

Conventions used by the whole ``vision`` package:

- Camera optical frame: x right, y down, z forward (along the optical axis), in metres.
- Pixel ``(u, v)`` = (column, row). Integer coordinates are pixel *centres* (OpenCV convention), so a
  pixel centre ``(u, v)`` sees the ray ``((u - cx) / fx, (v - cy) / fy, 1)`` in the optical frame. For a
  symmetric W x H camera ``cx = (W - 1) / 2``.
- A rectified stereo pair: both cameras have the same intrinsics and parallel optical axes; the right
  camera is at ``+baseline_m`` along the left camera's x axis, so a point at depth ``z`` has disparity
  ``u_left - u_right = fx * baseline_m / z`` [px] (positive).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.errors import InvalidRequestError


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of an undistorted (rectified) camera.

    fx, fy: focal lengths [px]; cx, cy: principal point [px] (pixel-centre convention, see module doc);
    width, height: image size [px].
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        if not (self.fx > 0 and self.fy > 0):
            raise InvalidRequestError(f"focal lengths must be > 0 px, got fx={self.fx}, fy={self.fy}")
        if self.width <= 0 or self.height <= 0:
            raise InvalidRequestError(f"image size must be positive, got {self.width}x{self.height}")

    @staticmethod
    def from_hfov(width: int, height: int, hfov_rad: float) -> CameraIntrinsics:
        """Square-pixel camera of horizontal field of view ``hfov_rad`` [rad], principal point centred."""
        if not 0.0 < hfov_rad < math.pi:
            raise InvalidRequestError(f"hfov_rad must be in (0, pi), got {hfov_rad}")
        f = (width / 2.0) / math.tan(hfov_rad / 2.0)
        return CameraIntrinsics(f, f, (width - 1) / 2.0, (height - 1) / 2.0, int(width), int(height))

    @staticmethod
    def from_matrix(
        K: np.ndarray, width: int, height: int, pixel_centre_offset_px: float = 0.5
    ) -> CameraIntrinsics:
        """Intrinsics from a 3x3 camera matrix ``K`` [px] of a ``width`` x ``height`` image.

        ``pixel_centre_offset_px``: where ``K`` puts the centre of pixel (row i, column j), at
        (j + offset, i + offset). The default 0.5 is the convention of ``sim/render`` and of the robot
        models' cameras (services.model: (0, 0) is the top-left *corner* of the image, cx = W / 2); 0 is
        OpenCV's (and this package's); the principal point is shifted accordingly (getting it wrong turns
        every bearing by half a pixel; depth from disparity is unaffected).
        """
        k = np.asarray(K, dtype=float)
        if k.shape != (3, 3) or not np.all(np.isfinite(k)):
            raise InvalidRequestError(f"K must be a finite 3x3 camera matrix, got shape {k.shape}")
        if abs(k[0, 1]) > 1e-9 or np.any(np.abs(k[2] - (0.0, 0.0, 1.0)) > 1e-9):
            raise InvalidRequestError(f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {k.tolist()}")
        off = float(pixel_centre_offset_px)
        return CameraIntrinsics(k[0, 0], k[1, 1], k[0, 2] - off, k[1, 2] - off, int(width), int(height))

    @property
    def matrix(self) -> np.ndarray:
        """3x3 camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, p_camera: np.ndarray) -> np.ndarray:
        """Pixel coordinates (u, v) [px] of points ``p_camera`` (..., 3) in the optical frame [m]."""
        p = np.asarray(p_camera, dtype=float)
        return np.stack(
            [self.fx * p[..., 0] / p[..., 2] + self.cx, self.fy * p[..., 1] / p[..., 2] + self.cy], axis=-1
        )

    def check_image(self, image: np.ndarray, what: str) -> None:
        """Raise InvalidRequestError unless ``image`` is an H x W (x C) array matching these intrinsics."""
        if not isinstance(image, np.ndarray) or image.ndim not in (2, 3):
            raise InvalidRequestError(f"{what}: expected an HxW or HxWx3 image array, got {type(image)}")
        h, w = image.shape[:2]
        if (w, h) != (self.width, self.height):
            raise InvalidRequestError(
                f"{what}: image is {w}x{h} px but the intrinsics are for {self.width}x{self.height} px"
            )


@dataclass(frozen=True)
class StereoRig:
    """A rectified stereo pair: common intrinsics and the baseline [m] (right camera at +x of the left)."""

    intrinsics: CameraIntrinsics
    baseline_m: float

    def __post_init__(self) -> None:
        if not self.baseline_m > 0:
            raise InvalidRequestError(f"baseline_m must be > 0 m, got {self.baseline_m}")

    @property
    def T_left_right(self) -> np.ndarray:  # noqa: N802 (frame names, as T_world_camera)
        """4x4 pose of the right camera optical frame in the left camera optical frame."""
        T = np.eye(4)
        T[0, 3] = self.baseline_m
        return T

    def disparity_of_depth(self, z_m: float | np.ndarray) -> float | np.ndarray:
        """Disparity [px] of a point at depth ``z_m`` [m]."""
        return self.intrinsics.fx * self.baseline_m / np.asarray(z_m)

    def depth_of_disparity(self, disparity_px: float | np.ndarray) -> float | np.ndarray:
        """Depth [m] of a disparity ``disparity_px`` [px] (> 0)."""
        return self.intrinsics.fx * self.baseline_m / np.asarray(disparity_px)


def transform_points(T_a_b: np.ndarray, p_b: np.ndarray) -> np.ndarray:
    """Express points ``p_b`` (..., 3) given in frame b in frame a, with the 4x4 pose ``T_a_b``."""
    T = np.asarray(T_a_b, dtype=float)
    if T.shape != (4, 4):
        raise InvalidRequestError(f"expected a 4x4 homogeneous transform, got shape {T.shape}")
    p = np.asarray(p_b, dtype=float)
    return p @ T[:3, :3].T + T[:3, 3]


def look_at(eye_world: np.ndarray, target_world: np.ndarray, up_world=(0.0, 0.0, 1.0)) -> np.ndarray:
    """4x4 pose ``T_world_camera`` of an optical frame at ``eye_world`` looking at ``target_world`` [m].

    The optical z axis points at the target, x is to the right and y down (``up_world`` appears up).
    """
    eye = np.asarray(eye_world, dtype=float)
    z = np.asarray(target_world, dtype=float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up_world, dtype=float))
    if np.linalg.norm(x) < 1e-9:
        raise InvalidRequestError("look_at: the viewing direction is parallel to up_world")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T
