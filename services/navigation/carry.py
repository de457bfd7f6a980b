"""Stage 2, the upper-body task: a bar held in both hands while walking.

"Manipulating While Walking" (`001_771c0ce3779b0683.txt`): the dynamic pattern generator turns the path
into a whole-body motion "by taking account of dynamic balance based on ZMP" while the hands hold the
carried object; the smooth reshaping then changes "the bar's configuration at key frames" (Figure 2 (b))
and "New constraints are enforced by using a whole-body IK solver" (Figure 2 (d)). This module holds:

- :class:`BarGrip` (:mod:`services.collision.carried`): how the robot holds the bar, read from its
  starting configuration by :func:`grip_from_configuration` (the held point of
  each hand on the bar's axis, the bar frame in the left grasp frame);
- :class:`HandOnBarTask`: the IK task of one hand on the bar: the hand's held point on a target point
  of the bar's axis and the grasp x axis along the bar; the roll of the hand about the bar is left free
  (a cylinder can be held at any roll), so the task has 5 rows;
- :class:`BarTrajectory`: the bar's task-space trajectory on the 5 ms grid (centre, axis) and
  :func:`nominal_bar_trajectory`: the bar carried along with the walking pattern (its CoM and waist
  yaw) at a height profile [m] the reshaping edits.

Frames: ``world`` z-up; the ``bar`` frame has its origin at the bar's centre and x along its axis (from
the right hand to the left hand); ``walk`` is the horizontal frame at the pattern's CoM with the waist
yaw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.collision.carried import BarGrip, CarriedBar
from services.errors import InvalidRequestError
from services.ik.kinematics import frame_id, frame_jacobian, point_jacobian
from services.ik.task import Task
from services.walking.pattern import WalkPattern

MAX_AXIS_ANGLE_RAD = math.radians(20.0)
"""A hand whose grasp x axis is farther than this from the line between the hands does not hold a bar."""


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors (np.cross costs ~10 us a call; this runs at every IK knot)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def bar_rotation(axis_world: np.ndarray) -> np.ndarray:
    """Rotation R_world_bar of a bar frame with x along ``axis_world`` and z as close to world z as
    possible (3, 3)."""
    x = np.asarray(axis_world, dtype=float)
    x = x / math.sqrt(x @ x)
    up = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.95 else np.array([1.0, 0.0, 0.0])
    y = _cross(up, x)
    y /= math.sqrt(y @ y)
    return np.column_stack([x, y, _cross(x, y)])


def grip_from_configuration(
    robot: object, q: np.ndarray, bar: CarriedBar, centre_offset_m: float = 0.0
) -> BarGrip:
    """The grip of ``bar`` held in both hands at configuration ``q``.

    The bar's axis is the line through the two held points (left minus right); its centre is their
    midpoint moved by ``centre_offset_m`` [m] along the axis (towards the left hand when > 0).
    InvalidRequestError when the hands cannot be holding this bar (held points too close or farther apart
    than the bar, a grasp x axis far from the bar's axis).
    """
    q = robot.check_q(q)  # type: ignore[attr-defined]
    data = robot.new_data()  # type: ignore[attr-defined]
    frames = {side: getattr(robot.frames, f"{side}_grasp") for side in ("left", "right")}  # type: ignore[attr-defined]
    offsets = {side: robot.held_object_offset(side, bar.radius_m) for side in ("left", "right")}  # type: ignore[attr-defined]
    poses = {side: robot.frame_pose(q, frames[side], data) for side in ("left", "right")}  # type: ignore[attr-defined]
    points = {side: poses[side].act(offsets[side]) for side in ("left", "right")}
    span = points["left"] - points["right"]
    spacing = float(np.linalg.norm(span))
    if not 0.1 <= spacing <= bar.length_m:
        raise InvalidRequestError(
            f"the hands' held points are {spacing:.3f} m apart at the starting configuration; a bar of "
            f"{bar.length_m} m held in both hands needs them 0.1 to {bar.length_m} m apart: start from a "
            f"configuration holding the bar",
            {"field": "q_start", "hand_spacing_m": spacing},
        )
    axis = span / spacing
    for side in ("left", "right"):
        x_grasp = poses[side].rotation[:, 0]
        angle = math.acos(min(1.0, abs(float(x_grasp @ axis))))
        if angle > MAX_AXIS_ANGLE_RAD:
            raise InvalidRequestError(
                f"the {side} hand's grasp x axis is {math.degrees(angle):.0f} deg from the line between the "
                f"hands (at most {math.degrees(MAX_AXIS_ANGLE_RAD):.0f} deg): the configuration does not "
                f"hold a bar across both hands",
                {"field": "q_start", "side": side, "axis_angle_rad": angle},
            )
    if abs(centre_offset_m) > 0.5 * bar.length_m:
        raise InvalidRequestError(
            f"centre_offset_m={centre_offset_m} m puts the bar's centre beyond its half length "
            f"{0.5 * bar.length_m} m"
        )
    centre = 0.5 * (points["left"] + points["right"]) + centre_offset_m * axis
    T_world_bar = pin.SE3(bar_rotation(axis), centre)
    along = {side: float((points[side] - centre) @ axis) for side in ("left", "right")}
    return BarGrip(
        bar=bar,
        grasp_frames=frames,
        held_point_in_grasp_m=offsets,
        along_m=along,
        T_left_grasp_bar=poses["left"].actInv(T_world_bar),
        centre_world_m=centre,
        axis_world=axis,
        grip_error_m=0.0,
    )


class HandOnBarTask(Task):
    """One hand on the bar: the hand's held point at ``target_world_m`` and its grasp x axis along
    ``axis_world`` (either direction); the roll about the bar is free.

    F = [p - p_target (3) [m]; x . u; x . v (2)] with (u, v) an orthonormal basis of the plane normal to
    the bar's axis and x the grasp x axis in world. J = [J_point; (x cross u)^T J_w; (x cross v)^T J_w]
    (d x = w cross x, so d(x . u) = w . (x cross u)), J_w the frame's angular velocity Jacobian.
    """

    def __init__(
        self,
        model: pin.Model,
        frame_name: str,
        held_point_in_frame_m: np.ndarray,
        target_world_m: np.ndarray,
        axis_world: np.ndarray,
        gain: float = 1.0,
        name: str | None = None,
    ) -> None:
        super().__init__(name or f"hand_on_bar:{frame_name}", gain)
        self.model = model
        self.frame_id = frame_id(model, frame_name)
        self.held_point_m = np.asarray(held_point_in_frame_m, dtype=float).reshape(3)
        self.set_target(target_world_m, axis_world)

    def set_target(self, target_world_m: np.ndarray, axis_world: np.ndarray) -> None:
        """New held-point target [m] (world) and bar axis direction (world, any length > 0)."""
        target = np.asarray(target_world_m, dtype=float).reshape(3)
        axis = np.asarray(axis_world, dtype=float).reshape(3)
        norm = float(np.linalg.norm(axis))
        if not (np.all(np.isfinite(target)) and math.isfinite(norm) and norm > 1e-9):
            raise InvalidRequestError(f"task {self.name!r}: target and axis must be finite, axis non-zero")
        R = bar_rotation(axis / norm)
        self.target_world_m = target
        self.axis_world = R[:, 0]
        self.u, self.v = R[:, 1], R[:, 2]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        p, J_point = point_jacobian(self.model, data, self.frame_id, self.held_point_m)
        x = data.oMf[self.frame_id].rotation[:, 0]
        J_w = frame_jacobian(self.model, data, self.frame_id)[3:]
        error = np.empty(5)
        error[:3] = p - self.target_world_m
        error[3] = x @ self.u
        error[4] = x @ self.v
        J = np.empty((5, J_w.shape[1]))
        J[:3] = J_point
        J[3] = _cross(x, self.u) @ J_w
        J[4] = _cross(x, self.v) @ J_w
        return error, J

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]


def hands_on_bar(model: pin.Model, grip: BarGrip) -> dict[str, HandOnBarTask]:
    """Both hands' :class:`HandOnBarTask` (``left``, ``right``), each held point on its place on the bar
    as ``grip`` holds it (the targets move with the bar: ``set_target``)."""
    return {
        side: HandOnBarTask(
            model,
            grip.grasp_frames[side],
            grip.held_point_in_grasp_m[side],
            grip.centre_world_m + grip.along_m[side] * grip.axis_world,
            grip.axis_world,
            name=f"{side}_hand_on_bar",
        )
        for side in ("left", "right")
    }


@dataclass(frozen=True, eq=False)
class BarTrajectory:
    """The bar's task-space motion on a time grid: ``times_s`` (n,) [s], ``centre_m`` (n, 3) [m] and unit
    ``axis`` (n, 3) in world. ``height_m`` is ``centre_m[:, 2]``."""

    times_s: np.ndarray
    centre_m: np.ndarray
    axis: np.ndarray

    @property
    def height_m(self) -> np.ndarray:
        return self.centre_m[:, 2]

    def held_point(self, grip: BarGrip, side: str, k: int) -> np.ndarray:
        """Target [m] of the ``side`` hand's held point at sample ``k``."""
        return self.centre_m[k] + grip.along_m[side] * self.axis[k]


def nominal_bar_trajectory(pattern: WalkPattern, grip: BarGrip, height_m: np.ndarray) -> BarTrajectory:
    """The bar carried with the walk: rigid in the ``walk`` frame (the pattern's CoM, horizontally, and
    its waist yaw) as at the start, at height ``height_m`` (n,) [m] of its centre.

    Following the CoM keeps the arms' posture while the body sways and turns, so the hands do not have to
    make up for the lateral sway of the walk.
    """
    n = pattern.n_samples
    heights = np.asarray(height_m, dtype=float)
    if heights.shape != (n,) or not np.all(np.isfinite(heights)):
        raise InvalidRequestError(f"height_m must be {n} finite numbers [m], got shape {heights.shape}")
    com_xy = pattern.com_m[:, :2]
    yaw = pattern.waist_yaw_rad - pattern.waist_yaw_rad[0]
    offset0 = grip.centre_world_m[:2] - com_xy[0]
    c, s = np.cos(yaw), np.sin(yaw)
    centre = np.empty((n, 3))
    centre[:, 0] = com_xy[:, 0] + c * offset0[0] - s * offset0[1]
    centre[:, 1] = com_xy[:, 1] + s * offset0[0] + c * offset0[1]
    centre[:, 2] = heights
    a0 = grip.axis_world
    axis = np.column_stack([c * a0[0] - s * a0[1], s * a0[0] + c * a0[1], np.full(n, a0[2])])
    return BarTrajectory(pattern.times_s, centre, axis)


def bar_poses(robot: object, grip: BarGrip, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bar as the robot actually carries it along ``qs`` (n, nq): rigid with the left hand.

    Returns ``centre_m`` (n, 3), ``axis`` (n, 3) and ``grip_error_m`` (n,), the distance [m] of the right
    hand's held point from where the rigid bar puts it (the IK's tracking error between the hands).
    """
    model = robot.model  # type: ignore[attr-defined]
    data = model.createData()
    fid_l = model.getFrameId(grip.grasp_frames["left"])
    fid_r = model.getFrameId(grip.grasp_frames["right"])
    n = qs.shape[0]
    centre, axis, err = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    T_lb = grip.T_left_grasp_bar
    p_r = grip.held_point_in_grasp_m["right"]
    for k in range(n):
        pin.forwardKinematics(model, data, qs[k])
        T_bar = pin.updateFramePlacement(model, data, fid_l) * T_lb
        centre[k] = T_bar.translation
        axis[k] = T_bar.rotation[:, 0]
        right = pin.updateFramePlacement(model, data, fid_r).act(p_r)
        err[k] = np.linalg.norm(right - (centre[k] + grip.along_m["right"] * axis[k]))
    return centre, axis, err


__all__ = [
    "BarGrip",
    "BarTrajectory",
    "HandOnBarTask",
    "bar_poses",
    "bar_rotation",
    "grip_from_configuration",
    "hands_on_bar",
    "nominal_bar_trajectory",
]
