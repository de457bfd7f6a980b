"""Pinhole camera math for rendering with pybullet: view/projection matrices from a camera pose and its
intrinsics, projection of world points to pixels, and linear depth from the depth buffer.

Conventions (those of ``services.model.specs.Intrinsics``, the type used here): the optical frame has z
forward along the optical axis, x right and y down in the image. Pixel coordinates (u, v) [px] have (0, 0)
at the top-left corner of the top-left pixel, u to the right and v down; the centre of the pixel in
row i, column j is (j + 0.5, i + 0.5). A world point at ``p_optical = (X, Y, Z)`` projects to
``u = fx X / Z + cx``, ``v = fy Y / Z + cy``.
"""

from __future__ import annotations

import numpy as np

from services.errors import InvalidRequestError
from services.model.specs import Intrinsics

# OpenGL cameras look along -z with y up: R_optical_gl = diag(1, -1, -1).
_OPTICAL_TO_GL = np.diag([1.0, -1.0, -1.0])


def view_matrix(T_world_optical: np.ndarray) -> list[float]:
    """pybullet/OpenGL view matrix (16 floats, column-major) of a camera whose optical frame has world
    pose ``T_world_optical`` (4x4 homogeneous)."""
    T = np.asarray(T_world_optical, dtype=float)
    R_world_gl = T[:3, :3] @ _OPTICAL_TO_GL
    view = np.eye(4)
    view[:3, :3] = R_world_gl.T
    view[:3, 3] = -R_world_gl.T @ T[:3, 3]
    return view.T.reshape(-1).tolist()  # column-major


def projection_matrix(intr: Intrinsics, near_m: float, far_m: float) -> list[float]:
    """OpenGL projection matrix (16 floats, column-major) reproducing the pinhole ``intr`` exactly,
    including an off-centre principal point; clipping planes ``near_m`` < ``far_m`` [m]."""
    if not 0.0 < near_m < far_m:
        raise InvalidRequestError(f"clipping planes must satisfy 0 < near < far, got {near_m}, {far_m}")
    W, H = float(intr.width_px), float(intr.height_px)
    P = np.zeros((4, 4))
    P[0, 0] = 2.0 * intr.fx / W
    P[0, 2] = 1.0 - 2.0 * intr.cx / W
    P[1, 1] = 2.0 * intr.fy / H
    P[1, 2] = 2.0 * intr.cy / H - 1.0
    P[2, 2] = -(far_m + near_m) / (far_m - near_m)
    P[2, 3] = -2.0 * far_m * near_m / (far_m - near_m)
    P[3, 2] = -1.0
    return P.T.reshape(-1).tolist()


def project(points_world: np.ndarray, T_world_optical: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixel coordinates (N, 2) [px] of world points (N, 3) [m]; NaN for points behind the camera."""
    pts = np.atleast_2d(np.asarray(points_world, dtype=float))
    T = np.asarray(T_world_optical, dtype=float)
    p_optical = (pts - T[:3, 3]) @ T[:3, :3]  # R^T (p - t), row-wise
    z = p_optical[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack(
            [K[0, 0] * p_optical[:, 0] / z + K[0, 2], K[1, 1] * p_optical[:, 1] / z + K[1, 2]], axis=1
        )
    uv[z <= 0.0] = np.nan
    return uv


def linear_depth(depth_buffer: np.ndarray, near_m: float, far_m: float) -> np.ndarray:
    """Depth along the optical axis [m] (float32) from an OpenGL depth buffer in [0, 1]; ``far_m`` where
    nothing was drawn."""
    d = np.asarray(depth_buffer, dtype=np.float64)
    z = far_m * near_m / (far_m - (far_m - near_m) * d)
    return z.astype(np.float32)


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """World pose (4x4) of an optical frame at ``eye`` looking at ``target`` [m], image up along ``up``
    (default world z)."""
    eye = np.asarray(eye, dtype=float)
    forward = np.asarray(target, dtype=float) - eye
    if np.linalg.norm(forward) < 1e-9:
        raise InvalidRequestError("camera eye and target coincide; give two different points")
    z = forward / np.linalg.norm(forward)
    up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=float)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:  # looking straight along `up`: pick any right direction
        x = np.cross(z, np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T
