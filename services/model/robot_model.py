"""The robot model interface every planner uses: pinocchio model + named frames, postures, limits,
sole rectangles, capsules, cameras and per-robot parameters, for ``hrp2_like`` and ``talos``."""

from __future__ import annotations

import dataclasses
import functools
import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.model.ground import convex_hull_ccw, yaw_of
from services.model.params import load_params
from services.model.robots import DESCRIPTIONS, RobotDescription, collision_pairs_for
from services.model.specs import (
    CameraSpec,
    Capsule,
    JointIndex,
    RobotFrames,
    RobotParams,
    StereoPair,
    check_side,
)

FREE_FLYER_NQ = 7
FREE_FLYER_NV = 6


def robot_names() -> list[str]:
    """Names accepted by :func:`load_robot`."""
    return sorted(DESCRIPTIONS)


@functools.cache
def load_robot(name: str = "hrp2_like") -> RobotModel:
    """The robot model called ``name`` ("hrp2_like" or "talos"); cached, shared and read-only.

    Raises :class:`InvalidRequestError` listing the valid names for an unknown robot.
    """
    if name not in DESCRIPTIONS:
        raise InvalidRequestError(
            f"unknown robot {name!r}; valid robots are {robot_names()}", {"valid": robot_names()}
        )
    return RobotModel(DESCRIPTIONS[name]())


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


def _se3(xyz: Sequence[float], rpy: Sequence[float]) -> pin.SE3:
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.asarray(xyz, dtype=float))


def _link_masses(urdf_path: Path) -> dict[str, float]:
    """Mass [kg] of every URDF link (0 for links without an inertial)."""
    root = ET.parse(urdf_path).getroot()
    masses: dict[str, float] = {}
    for link in root.findall("link"):
        mass = link.find("inertial/mass")
        masses[link.get("name", "")] = float(mass.get("value", "0")) if mass is not None else 0.0
    return masses


class RobotModel:
    """One robot: an immutable pinocchio model with a free-flyer root, and everything planners need.

    Configuration ``q`` (nq) is ``[x, y, z, qx, qy, qz, qw, joints...]`` (pinocchio free-flyer: base
    position in world [m], base orientation quaternion), velocity ``v`` (nv) is ``[v_base (6, local
    frame), joint velocities]``. World frame: z up, ground at z = 0.

    Do not mutate ``model``; create per-thread data with :meth:`new_data`.
    """

    def __init__(self, desc: RobotDescription) -> None:
        self._desc = desc
        self.name: str = desc.name
        self.urdf_path: Path = desc.urdf_path
        self.package_dirs: tuple[Path, ...] = desc.package_dirs
        model = pin.buildModelFromUrdf(str(desc.urdf_path), pin.JointModelFreeFlyer())
        for extra in desc.extra_frames:
            if not model.existFrame(extra.parent_frame):
                raise ValueError(
                    f"{desc.name}: frame {extra.parent_frame!r} for {extra.name!r} not in the URDF"
                )
            parent = model.frames[model.getFrameId(extra.parent_frame)]
            placement = parent.placement * _se3(extra.xyz, extra.rpy)
            model.addFrame(
                pin.Frame(
                    extra.name,
                    parent.parentJoint,
                    model.getFrameId(extra.parent_frame),
                    placement,
                    pin.FrameType.OP_FRAME,
                )
            )
        self.model: pin.Model = model
        self._data = model.createData()
        self.nq: int = model.nq
        self.nv: int = model.nv
        self.frames: RobotFrames = desc.frames
        for role, frame in vars(desc.frames).items():
            if not model.existFrame(frame):
                raise ValueError(f"{desc.name}: frame {frame!r} ({role}) is not in the model")

        # Actuated joints (all 1-DoF) in model order.
        names: list[str] = []
        index: dict[str, JointIndex] = {}
        for jid in range(2, model.njoints):
            joint = model.joints[jid]
            if joint.nq != 1 or joint.nv != 1:
                raise ValueError(f"{desc.name}: joint {model.names[jid]} is not 1-DoF")
            names.append(model.names[jid])
            index[model.names[jid]] = JointIndex(joint.idx_q, joint.idx_v)
        self.joint_names: tuple[str, ...] = tuple(names)
        self._joint_index = index

        lower = np.array(model.lowerPositionLimit, dtype=float)
        upper = np.array(model.upperPositionLimit, dtype=float)
        lower[:FREE_FLYER_NQ] = -np.inf
        upper[:FREE_FLYER_NQ] = np.inf
        v_max = np.array(model.velocityLimit, dtype=float)
        v_max[:FREE_FLYER_NV] = np.inf
        self.q_lower: np.ndarray = _readonly(lower)
        self.q_upper: np.ndarray = _readonly(upper)
        self.v_max: np.ndarray = _readonly(v_max)
        self.effort_max: np.ndarray = _readonly(
            np.concatenate([np.full(FREE_FLYER_NV, np.inf), np.array(model.effortLimit)[FREE_FLYER_NV:]])
        )

        self.sole_size_m: tuple[float, float] = desc.sole_size_m
        params = load_params(desc.params_path)
        # The stepping bounds carry the sole rectangle that must not overlap the other one.
        length_m, width_m = (float(v) for v in desc.sole_size_m)
        bounds = dataclasses.replace(params.footstep_bounds, sole_length_m=length_m, sole_width_m=width_m)
        self.params: RobotParams = dataclasses.replace(params, footstep_bounds=bounds)
        # pybullet only: flat sole box thickness [m] replacing the foot collision shapes (None: keep the
        # URDF's), and the constraint-solver iterations the robot needs in pybullet.
        self.pybullet_sole_box_m: float | None = desc.pybullet_sole_box_m
        self.pybullet_solver_iterations: int = desc.pybullet_solver_iterations
        self.cameras: dict[str, CameraSpec] = dict(desc.cameras)
        self.stereo_pairs: dict[str, StereoPair] = dict(desc.stereo_pairs)
        for cam in self.cameras.values():
            if not model.existFrame(cam.frame):
                raise ValueError(f"{desc.name}: camera frame {cam.frame!r} is not in the model")

        self.link_masses_kg: dict[str, float] = _link_masses(desc.urdf_path)
        self.total_mass_kg: float = float(pin.computeTotalMass(model))

        self.capsules: tuple[Capsule, ...] = self._resolve_capsules()
        self.collision_pairs: tuple[tuple[str, str], ...] = collision_pairs_for(desc.capsules)

        q = pin.neutral(model)
        for joint, value in desc.half_sitting.items():
            q[self.joint_index(joint).idx_q] = value
        missing = set(self.joint_names) - set(desc.half_sitting)
        if missing:
            raise ValueError(f"{desc.name}: half-sitting misses joints {sorted(missing)}")
        self.q_half_sitting: np.ndarray = _readonly(self.place_on_ground(q, 0.0, 0.0, 0.0))

    # ----------------------------------------------------------------------------------------- joints
    def joint_index(self, name: str) -> JointIndex:
        """(idx_q, idx_v) of the actuated joint ``name``; InvalidRequestError listing the valid names."""
        try:
            return self._joint_index[name]
        except KeyError:
            raise InvalidRequestError(
                f"{self.name} has no joint {name!r}; valid joints are {list(self.joint_names)}",
                {"valid": list(self.joint_names)},
            ) from None

    def arm_joints(self, side: str) -> list[str]:
        """Arm joint names of ``side`` from shoulder to wrist, gripper excluded."""
        return list(self._desc.arm_joints[check_side(side)])

    def gripper_joint(self, side: str) -> str:
        """Gripper joint name of ``side``; open/closed values are ``params.gripper``."""
        return self._desc.gripper_joints[check_side(side)]

    def held_object_offset(self, side: str, radius_m: float) -> np.ndarray:
        """Where the centre of a held object of radius ``radius_m`` ends up, in the grasp frame [m] (3,).

        With one moving finger (hrp2_like) closing pushes the object against the fixed finger, so a ball
        of radius r is held at y = +-(0.065 - r) (right hand +, left hand -); zero for symmetric grippers.
        Aim this point (not the grasp frame origin) at an object that must not be pushed.
        """
        check_side(side)
        if radius_m <= 0.0:
            raise InvalidRequestError(f"object radius must be positive, got {radius_m} m")
        offset = np.zeros(3)
        fixed_y = self._desc.fixed_finger_y_m
        if fixed_y is not None:
            y = fixed_y[side]
            if radius_m > abs(y):
                raise InvalidRequestError(
                    f"an object of radius {radius_m} m does not fit in the {self.name} gripper "
                    f"(largest radius {abs(y):.3f} m)"
                )
            offset[1] = y - np.sign(y) * radius_m
        return offset

    def frame_id(self, name: str) -> int:
        """Pinocchio frame id of ``name``; InvalidRequestError if the model has no such frame."""
        if not self.model.existFrame(name):
            raise InvalidRequestError(
                f"{self.name} has no frame {name!r}; role frames are {vars(self.frames)}"
            )
        return int(self.model.getFrameId(name))

    def new_data(self) -> pin.Data:
        """Fresh pinocchio data for this model (one per thread/user)."""
        return self.model.createData()

    def neutral(self) -> np.ndarray:
        """Pinocchio neutral configuration (base at the origin, all joints 0) (nq)."""
        return pin.neutral(self.model)

    # ------------------------------------------------------------------------------------- kinematics
    def check_q(self, q: np.ndarray, field: str = "q") -> np.ndarray:
        """``q`` as a float array of shape (nq,), else InvalidRequestError naming ``field`` (the request's
        field it came from, e.g. ``q_start``)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.nq,):
            raise InvalidRequestError(f"{self.name}: {field} must have shape ({self.nq},), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise InvalidRequestError(f"{self.name}: {field} contains non-finite values")
        return q

    def forward(self, q: np.ndarray, data: pin.Data | None = None) -> pin.Data:
        """Joint and frame placements at ``q`` (``data.oMi``, ``data.oMf``); uses internal data if None.

        The internal data is shared: pass your own ``data`` when results must outlive the next call.
        """
        data = self._data if data is None else data
        pin.framesForwardKinematics(self.model, data, self.check_q(q))
        return data

    def frame_pose(self, q: np.ndarray, frame: str, data: pin.Data | None = None) -> pin.SE3:
        """World pose of ``frame`` at ``q`` (a copy)."""
        fid = self.frame_id(frame)
        data = self.forward(q, data)
        return pin.SE3(data.oMf[fid])

    def sole_pose(self, q: np.ndarray, side: str, data: pin.Data | None = None) -> pin.SE3:
        """World pose ``T_world_<side>_sole`` at ``q``."""
        return self.frame_pose(q, self.frames.sole(side), data)

    def camera_pose(self, q: np.ndarray, camera: str, data: pin.Data | None = None) -> pin.SE3:
        """World pose ``T_world_camera_optical`` of camera ``camera`` (a key of ``cameras``) at ``q``."""
        if camera not in self.cameras:
            raise InvalidRequestError(
                f"{self.name} has no camera {camera!r}; cameras are {sorted(self.cameras)}",
                {"valid": sorted(self.cameras)},
            )
        return self.frame_pose(q, self.cameras[camera].frame, data)

    def build_geometry_model(self, kind: str = "collision") -> pin.GeometryModel:
        """Pinocchio/coal geometry model of the URDF shapes (``kind`` "collision" or "visual"); meshes are
        resolved through ``package_dirs``."""
        types = {"collision": pin.GeometryType.COLLISION, "visual": pin.GeometryType.VISUAL}
        if kind not in types:
            raise InvalidRequestError(f"geometry kind must be one of {sorted(types)}, got {kind!r}")
        return pin.buildGeomFromUrdf(
            self.model, str(self.urdf_path), types[kind], package_dirs=[str(d) for d in self.package_dirs]
        )

    def com(self, q: np.ndarray, data: pin.Data | None = None) -> np.ndarray:
        """Centre of mass in world [m] (3,)."""
        data = self._data if data is None else data
        return np.array(pin.centerOfMass(self.model, data, self.check_q(q)))

    # ------------------------------------------------------------------------------------- support
    def sole_corners(self, q: np.ndarray, side: str, data: pin.Data | None = None) -> np.ndarray:
        """World (x, y, z) of the 4 sole rectangle corners of ``side``, counter-clockwise seen from above
        when the sole is flat (4, 3) [m]."""
        T = self.sole_pose(q, side, data)
        half_l, half_w = self.sole_size_m[0] / 2.0, self.sole_size_m[1] / 2.0
        local = np.array(
            [[half_l, half_w, 0.0], [-half_l, half_w, 0.0], [-half_l, -half_w, 0.0], [half_l, -half_w, 0.0]]
        )
        return local @ T.rotation.T + T.translation

    def support_polygon(
        self, q: np.ndarray, feet: Sequence[str] = ("left", "right"), data: pin.Data | None = None
    ) -> np.ndarray:
        """Convex hull in world xy of the sole rectangles of ``feet``, counter-clockwise (N, 2) [m]."""
        if not feet:
            raise InvalidRequestError("support_polygon needs at least one foot ('left' and/or 'right')")
        pts = np.vstack([self.sole_corners(q, side, data)[:, :2] for side in feet])
        return convex_hull_ccw(pts)

    def mid_feet_pose(self, q: np.ndarray, data: pin.Data | None = None) -> tuple[float, float, float]:
        """(x [m], y [m], yaw [rad]) of the mid-feet frame: midpoint of the sole centres, mean sole yaw."""
        T_l = self.sole_pose(q, "left", data)
        T_r = self.sole_pose(q, "right", data)
        mid = 0.5 * (T_l.translation + T_r.translation)
        yaw_l, yaw_r = yaw_of(T_l.rotation), yaw_of(T_r.rotation)
        yaw = yaw_r + 0.5 * math.remainder(yaw_l - yaw_r, 2.0 * math.pi)
        return float(mid[0]), float(mid[1]), float(math.remainder(yaw, 2.0 * math.pi))

    def place_on_ground(self, q: np.ndarray, x: float, y: float, yaw: float) -> np.ndarray:
        """``q`` with the base moved so that the mid-feet frame is at (x, y, yaw) and the mean sole height
        is z = 0 (joints unchanged; the base keeps its roll/pitch relative to the feet)."""
        q = self.check_q(q).copy()
        data = self.new_data()
        x0, y0, yaw0 = self.mid_feet_pose(q, data)
        z0 = 0.5 * (
            data.oMf[self.frame_id(self.frames.left_sole)].translation[2]
            + data.oMf[self.frame_id(self.frames.right_sole)].translation[2]
        )
        T_world_mid_old = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw0), np.array([x0, y0, z0]))
        T_world_mid_new = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw), np.array([x, y, 0.0]))
        T_world_base = pin.XYZQUATToSE3(q[:FREE_FLYER_NQ])
        T_new = T_world_mid_new * T_world_mid_old.inverse() * T_world_base
        q[:FREE_FLYER_NQ] = pin.SE3ToXYZQUAT(T_new)
        return q

    def half_sitting_at(self, x: float, y: float, yaw: float) -> np.ndarray:
        """Half-sitting with the mid-feet frame at (x [m], y [m], yaw [rad]), soles at z = 0."""
        return self.place_on_ground(self.q_half_sitting, x, y, yaw)

    # ------------------------------------------------------------------------------------- capsules
    def _resolve_capsules(self) -> tuple[Capsule, ...]:
        data = self.new_data()
        pin.framesForwardKinematics(self.model, data, pin.neutral(self.model))
        out: list[Capsule] = []
        for spec in self._desc.capsules:
            fid = self.frame_id(spec.frame)
            if spec.p1_frame is not None:
                p1 = data.oMf[fid].actInv(data.oMf[self.frame_id(spec.p1_frame)].translation)
            elif spec.p1_local is not None:
                p1 = np.asarray(spec.p1_local, dtype=float)
            else:
                raise ValueError(f"{self.name}: capsule {spec.name} needs p1_local or p1_frame")
            out.append(
                Capsule(
                    spec.name,
                    spec.frame,
                    tuple(map(float, spec.p0_local)),
                    tuple(float(v) for v in p1),
                    float(spec.radius_m),
                )
            )
        return tuple(out)

    def capsule(self, name: str) -> Capsule:
        """The capsule called ``name``."""
        for c in self.capsules:
            if c.name == name:
                return c
        raise InvalidRequestError(
            f"{self.name} has no capsule {name!r}; capsules are {[c.name for c in self.capsules]}"
        )

    def capsule_segments(
        self, q: np.ndarray, data: pin.Data | None = None
    ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """World end points (p0, p1) [m] of every capsule at ``q``."""
        data = self.forward(q, data)
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for c in self.capsules:
            T = data.oMf[self.frame_id(c.frame)]
            out[c.name] = (T.act(np.asarray(c.p0_local)), T.act(np.asarray(c.p1_local)))
        return out

    def collision_pair_distances(
        self, q: np.ndarray, data: pin.Data | None = None
    ) -> dict[tuple[str, str], float]:
        """Signed distance [m] between the capsules of every checked pair (negative: penetration)."""
        from services.model.geometry import segment_distance

        segs = self.capsule_segments(q, data)
        radius = {c.name: c.radius_m for c in self.capsules}
        return {
            (a, b): segment_distance(*segs[a], *segs[b]) - radius[a] - radius[b]
            for a, b in self.collision_pairs
        }

    def __repr__(self) -> str:
        return f"RobotModel({self.name!r}, nq={self.nq}, nv={self.nv}, mass={self.total_mass_kg:.2f} kg)"
