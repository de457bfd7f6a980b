"""Upper-body tasks while walking: keep a hand at its pose, move it along a path, look at a point.

The pattern generator's whole-body stage (:class:`services.walking.wholebody.WholeBodyPlanner`) takes
caller levels below the feet, the CoM and the waist/chest orientation and above the rest posture
(the issue's "keep holding the bar; the hand follows this path; keep looking at this point"). This
module builds those levels from plain descriptions and moves their targets at every IK knot.

Frames: ``world`` (z up, fixed) or ``walk``, the horizontal frame that moves with the walk: origin on
the ground below the planned CoM (the pattern CoM plus the second-stage corrections), x axis turned by
the pattern's waist yaw (the same ``walk`` frame as ``services.navigation.carry``). A hand held in the
``walk`` frame is carried along (a bar in the hands); one held in the ``world`` frame stays where it
is (a hand on a fixed handle, for motions that do not go far).

- :class:`HandTarget`: with no waypoints the hand keeps its starting pose in its frame; with waypoints
  (times [s] and positions [m] in the frame) its position follows a C2 spline from its starting
  position at t = 0 through the waypoints (zero velocity at both ends) and stays at the last one. The
  orientation stays the starting one (in the frame) unless ``keep_orientation`` is False.
- :class:`GazeTarget`: the gaze axis (x of the model's ``gaze`` frame) passes through a point (the
  footstep paper's gaze task, section 4.3); the point the robot looks at moves from straight ahead of
  its starting gaze to the target over ``blend_s`` so that the head does not snap at t = 0.

Levels: the hands (both in one level), then the gaze, in that order of priority.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicSpline

from services.errors import InvalidRequestError
from services.ik import FramePoseTask, FramePositionTask, GazeTask, Level
from services.walking.footsteps import SIDES
from services.walking.zmp_reference import smoothstep5

FRAMES = ("walk", "world")
"""Frames in which upper-body targets are given."""


@dataclass(frozen=True)
class HandTarget:
    """A hand task: hold the starting pose of the ``side`` grasp frame in ``frame``, or follow waypoints.

    Attributes:
        side: "left" or "right".
        frame: "walk" (carried along with the walk) or "world".
        times_s: waypoint times [s] from the start of the walk, strictly increasing, > 0.
        positions_m: waypoint positions (x, y, z) [m] of the grasp frame in ``frame``.
        keep_orientation: also hold the starting orientation of the hand (in ``frame``).
    """

    side: str
    frame: str = "walk"
    times_s: tuple[float, ...] = ()
    positions_m: tuple[tuple[float, float, float], ...] = ()
    keep_orientation: bool = True

    def validate(self) -> None:
        """InvalidRequestError naming the field at fault."""
        if self.side not in SIDES:
            raise InvalidRequestError(f"hand task: side must be one of {list(SIDES)}, got {self.side!r}")
        if self.frame not in FRAMES:
            raise InvalidRequestError(
                f"{self.side} hand task: frame must be one of {list(FRAMES)}, got {self.frame!r}"
            )
        times = np.asarray(self.times_s, dtype=float)
        positions = np.asarray(self.positions_m, dtype=float)
        if times.shape[0] != positions.shape[0]:
            raise InvalidRequestError(
                f"{self.side} hand task: {times.shape[0]} waypoint times but {positions.shape[0]} positions"
            )
        if times.size and (positions.ndim != 2 or positions.shape[1] != 3):
            raise InvalidRequestError(
                f"{self.side} hand task: positions_m must be a list of [x, y, z] [m], got shape "
                f"{positions.shape}"
            )
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(positions))):
            raise InvalidRequestError(f"{self.side} hand task: waypoints must be finite numbers")
        if times.size and (times[0] <= 0 or np.any(np.diff(times) <= 0)):
            raise InvalidRequestError(
                f"{self.side} hand task: times_s must be strictly increasing and > 0 s (the hand starts "
                f"where it is at t = 0), got {times.tolist()}"
            )


@dataclass(frozen=True)
class GazeTarget:
    """Look at ``point_m`` (x, y, z) [m] in ``frame``; the target is blended in over ``blend_s`` [s]."""

    point_m: tuple[float, float, float]
    frame: str = "world"
    blend_s: float = 1.0

    def validate(self) -> None:
        """InvalidRequestError naming the field at fault."""
        point = np.asarray(self.point_m, dtype=float)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise InvalidRequestError(f"gaze task: point_m must be [x, y, z] [m], got {list(self.point_m)}")
        if self.frame not in FRAMES:
            raise InvalidRequestError(f"gaze task: frame must be one of {list(FRAMES)}, got {self.frame!r}")
        if not (math.isfinite(self.blend_s) and self.blend_s > 0):
            raise InvalidRequestError(f"gaze task: blend_s must be > 0 s, got {self.blend_s}")


@dataclass(frozen=True)
class TaskError:
    """Largest error of an upper-body task over a trajectory: ``max_error`` [m or rad] at ``time_s``."""

    max_error: float
    time_s: float
    unit: str


def walk_frame(com_xy_m: np.ndarray, yaw_rad: float) -> pin.SE3:
    """T_world_walk: origin on the ground (z = 0) below the CoM, x axis at ``yaw_rad``."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return pin.SE3(R, np.array([com_xy_m[0], com_xy_m[1], 0.0]))


class UpperBody:
    """The caller levels of a walk and the callback that moves their targets (see the module docstring).

    Build it with the planner's IK ``model`` (:attr:`WholeBodyPlanner.model`), the robot and the walk's
    start, pass :attr:`levels` and :meth:`update` to :meth:`WholeBodyPlanner.solve`, then measure how
    well the tasks were met with :meth:`errors`.
    """

    def __init__(
        self,
        model: pin.Model,
        robot: Any,
        q_start: np.ndarray,
        com_start_m: np.ndarray,
        waist_yaw_rad: np.ndarray,
        times_s: np.ndarray,
        hands: Sequence[HandTarget] = (),
        gaze: GazeTarget | None = None,
    ) -> None:
        """``com_start_m`` is the CoM at t = 0 [m]; ``waist_yaw_rad`` and ``times_s`` are the pattern's."""
        sides = [h.side for h in hands]
        for h in hands:
            h.validate()
        if len(set(sides)) != len(sides):
            raise InvalidRequestError(f"one hand task per side, got sides {sides}")
        if gaze is not None:
            gaze.validate()
        self.robot = robot
        self.hands = tuple(hands)
        self.gaze = gaze
        self.waist_yaw_rad = np.asarray(waist_yaw_rad, dtype=float)
        self.times_s = np.asarray(times_s, dtype=float)
        data = robot.new_data()
        robot.forward(q_start, data)
        W0_inv = walk_frame(com_start_m[:2], float(self.waist_yaw_rad[0])).inverse()
        self._hand_tasks: list[FramePoseTask | FramePositionTask] = []
        self._hand_start: list[pin.SE3] = []  # pose of the grasp frame at t = 0, in the task's frame
        self._hand_paths: list[CubicSpline | None] = []
        self._hand_end_s: list[float] = []
        for h in self.hands:
            frame = robot.frames.grasp(h.side)
            T0_world = pin.SE3(data.oMf[robot.frame_id(frame)])
            T0 = W0_inv * T0_world if h.frame == "walk" else T0_world
            self._hand_start.append(T0)
            if h.keep_orientation:
                task: FramePoseTask | FramePositionTask = FramePoseTask(
                    model, frame, T0_world, name=f"{h.side}_hand"
                )
            else:
                task = FramePositionTask(model, frame, T0_world.translation, name=f"{h.side}_hand")
            self._hand_tasks.append(task)
            if h.times_s:
                t = np.concatenate([[0.0], np.asarray(h.times_s, dtype=float)])
                p = np.vstack([T0.translation, np.asarray(h.positions_m, dtype=float)])
                self._hand_paths.append(CubicSpline(t, p, bc_type="clamped"))
                self._hand_end_s.append(float(t[-1]))
            else:
                self._hand_paths.append(None)
                self._hand_end_s.append(0.0)
        self._gaze_task: GazeTask | None = None
        if gaze is not None:
            T = pin.SE3(data.oMf[robot.frame_id(robot.frames.gaze)])
            target_world = self._point_world(gaze, np.asarray(com_start_m)[:2], 0)
            axis = T.rotation[:, 0]
            ahead = float(axis @ (target_world - T.translation))
            if ahead <= 0.0:
                raise InvalidRequestError(
                    f"gaze task: the point {list(gaze.point_m)} ({gaze.frame} frame) is behind the robot's "
                    "head at the start; the gaze task needs a point in front of it (turn first)"
                )
            # Blend from the point straight ahead at the target's distance (gaze error 0 at t = 0).
            distance = float(np.linalg.norm(target_world - T.translation))
            self._gaze_start_world = T.translation + distance * axis
            self._gaze_task = GazeTask(
                model, robot.frames.gaze, self._gaze_start_world, axis_in_camera=(1.0, 0.0, 0.0), name="gaze"
            )
        self.levels: list[Level] = []
        if self._hand_tasks:
            self.levels.append(Level(tuple(self._hand_tasks), name="hands"))
        if self._gaze_task is not None:
            self.levels.append(Level((self._gaze_task,), name="gaze"))

    # ------------------------------------------------------------------------------------ targets
    def _point_world(self, gaze: GazeTarget, com_xy_m: np.ndarray, k: int) -> np.ndarray:
        point = np.asarray(gaze.point_m, dtype=float)
        if gaze.frame == "world":
            return point
        return walk_frame(com_xy_m, float(self.waist_yaw_rad[k])).act(point)

    def hand_target(self, i: int, k: int, com_xy_m: np.ndarray) -> pin.SE3:
        """World target of hand task ``i`` at sample ``k`` with the planned CoM ``com_xy_m`` [m]."""
        h, T0 = self.hands[i], self._hand_start[i]
        path = self._hand_paths[i]
        t = float(self.times_s[k])
        position = T0.translation if path is None else path(min(t, self._hand_end_s[i]))
        T = pin.SE3(T0.rotation, np.asarray(position, dtype=float))
        if h.frame == "walk":
            T = walk_frame(com_xy_m, float(self.waist_yaw_rad[k])) * T
        return T

    def gaze_point(self, k: int, com_xy_m: np.ndarray) -> np.ndarray:
        """World point looked at at sample ``k`` [m] (blended in from straight ahead)."""
        if self.gaze is None:
            raise InvalidRequestError("this walk has no gaze task")
        target = self._point_world(self.gaze, com_xy_m, k)
        s = float(smoothstep5(np.array([self.times_s[k] / self.gaze.blend_s]))[0])
        return self._gaze_start_world + s * (target - self._gaze_start_world)

    def update(self, k: int, t_s: float, com_ref_m: np.ndarray) -> None:
        """Knot callback of :meth:`WholeBodyPlanner.solve`: set every target for sample ``k``."""
        for i, task in enumerate(self._hand_tasks):
            T = self.hand_target(i, k, com_ref_m[:2])
            if isinstance(task, FramePoseTask):
                task.set_target(T)
            else:
                task.set_target(T.translation)
        if self._gaze_task is not None:
            self._gaze_task.set_target(self.gaze_point(k, com_ref_m[:2]))

    # ------------------------------------------------------------------------------------ figures
    def errors(self, qs: np.ndarray, com_ref_m: np.ndarray) -> dict[str, TaskError]:
        """Largest error of each task over the trajectory ``qs`` (full model, every sample), and when:
        ``<side>_hand`` position error [m] (and ``<side>_hand_rotation`` [rad] if the orientation is
        held), ``gaze``: distance [m] of the target point from the gaze axis."""
        robot = self.robot
        data = robot.new_data()
        n = qs.shape[0]
        series: dict[str, np.ndarray] = {}
        for h in self.hands:
            series[f"{h.side}_hand"] = np.zeros(n)
            if h.keep_orientation:
                series[f"{h.side}_hand_rotation"] = np.zeros(n)
        if self.gaze is not None:
            series["gaze"] = np.zeros(n)
        hand_fids = [robot.frame_id(robot.frames.grasp(h.side)) for h in self.hands]
        gaze_fid = robot.frame_id(robot.frames.gaze)
        for k in range(n):
            pin.framesForwardKinematics(robot.model, data, qs[k])
            for i, h in enumerate(self.hands):
                T = data.oMf[hand_fids[i]]
                target = self.hand_target(i, k, com_ref_m[k, :2])
                series[f"{h.side}_hand"][k] = np.linalg.norm(T.translation - target.translation)
                if h.keep_orientation:
                    rotation = np.linalg.norm(pin.log3(target.rotation.T @ T.rotation))
                    series[f"{h.side}_hand_rotation"][k] = rotation
            if self.gaze is not None:
                T = data.oMf[gaze_fid]
                v = self.gaze_point(k, com_ref_m[k, :2]) - T.translation
                axis = T.rotation[:, 0]
                series["gaze"][k] = np.linalg.norm(v - (axis @ v) * axis)
        out = {}
        for name, values in series.items():
            k = int(np.argmax(values))
            unit = "rad" if name.endswith("_rotation") else "m"
            out[name] = TaskError(float(values[k]), float(self.times_s[k]), unit)
        return out
