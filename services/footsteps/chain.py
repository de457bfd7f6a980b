"""The virtual kinematic structure of section 3.1 of the footstep paper (Kanoun, Laumond, Yoshida).

For a robot that makes ``p`` steps, footprints F_0 ... F_{p-1} are virtual rigid bodies; F_i is joined
to F_{i-1} by two prismatic joints (along F_{i-1}'s x and y) and a revolute joint about the vertical,
whose values are Q_i = (dx_i, dy_i, dtheta_i) (eq. 8): the pose of F_i in the frame of F_{i-1}. The
root footprint F_0 is fixed at the initial support foot. The humanoid hangs from the last footprint
F_{p-1} (its *root foot*, Fig. 2); its other foot, the *front foot*, makes the last step p and only
has to stay flat on the ground. The configuration is (Q_1, ..., Q_{p-1}, q) (eq. 9).

Construction (the "augmented" form the issue allows): one pinocchio model whose first joints are the
chain (PX, PY, RZ per footprint, so that the joint values are exactly Q_i and the relative step bounds
of section 3.3 are the joint limits), with the robot model appended under the frame of F_{p-1}
(``pin.appendModel``): the robot's free-flyer then gives the base pose *in the last footprint frame*.
The rigid attachment of the root foot to F_{p-1} is the top-priority equality
:class:`~services.footsteps.constraints.RootSoleOnFootprintTask`. The general IK solver runs on this
model unchanged.

Sides alternate along the chain from the front foot backwards: F_{p-1} is the root foot (the side
opposite the front foot), F_{p-2} the front foot's side, ... The chain starts *folded* (Fig. 6):
every footprint sits on the initial sole of its side, so every support polygon is the start polygon.
Algorithm 1 adds a footprint *at the root* (:meth:`VirtualChain.with_root_footprint`): the new F_0 is
the other initial foot, and the old F_0 becomes F_1 with Q_1 its (folded) pose relative to the new
root, so that the world state is unchanged and the configuration carries over. The first stepping
foot therefore alternates with the number of steps; section 5.2's choice of the start foot is the
choice of the front foot side for a given number of steps (both are tried by the planner).

``p = 0`` (no step) uses the same model as ``p = 1``; the planner then also holds the front foot at
its initial pose.

Frames: the model is expressed in the frame of the root footprint F_0 (a flat frame on the ground,
``T_world_root`` in the world), so that it depends only on the robot, the sides and the step bounds,
not on where the robot stands: models are built once and shared (:func:`chain_model`). Targets and
obstacles are brought into that frame (:meth:`VirtualChain.model_point`), footprints and
configurations are returned in the world.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.footsteps.geometry import compose, relative_pose, se3_of
from services.model import FootstepBounds, RobotModel
from services.model.ground import sole_pose_of
from services.walking.footsteps import Side, SolePose, other_side

FREE_FLYER_NQ = 7
_JOINT_SUFFIXES = ("dx", "dy", "dtheta")
MODEL_CACHE_SIZE = 128  # chain models kept (a few hundred kB each)
_models: OrderedDict[tuple, tuple[RobotModel, pin.Model]] = OrderedDict()
_models_lock = threading.Lock()


def footprint_frame(i: int) -> str:
    """Name of the frame of footprint F_i in the chain model."""
    return f"footprint{i}"


@dataclass(frozen=True)
class Stance:
    """The two initial sole footprints [m, rad] (world frame, flat ground)."""

    left: SolePose
    right: SolePose

    def of(self, side: Side) -> SolePose:
        """Initial footprint of ``side``."""
        return self.left if side == "left" else self.right


class VirtualChain:
    """The virtual tree for ``n_steps`` steps with the robot's front foot on ``front_side``.

    Attributes:
        model: pinocchio model: chain joints (3 per footprint F_1 .. F_{p-1}) then the robot's joints.
        chain_nq: 3 (p - 1) (0 when p <= 1); the robot's q starts at ``chain_nq``, its v at the same index.
        sides: side of each footprint F_0 .. F_{p-1} (one entry F_0 when p = 0).
        front_side / root_side: the robot's front foot and root foot sides.
        bounds: the relative step bounds of every support polygon (default the robot's).
        front_sole_frame / root_sole_frame: the robot's sole frame names.
    """

    def __init__(
        self,
        robot: RobotModel,
        front_side: Side,
        n_steps: int,
        start: Stance,
        bounds: FootstepBounds | None = None,
    ) -> None:
        if front_side not in ("left", "right"):
            raise InvalidRequestError(f"front_side must be 'left' or 'right', got {front_side!r}")
        if n_steps < 0:
            raise InvalidRequestError(f"the number of steps must be >= 0, got {n_steps}")
        self.robot = robot
        self.front_side: Side = front_side
        self.root_side: Side = other_side(front_side)
        self.n_steps = int(n_steps)
        self.start = start
        # relative step bounds (section 3.3): the robot's, or a region inside them
        self.bounds: FootstepBounds = bounds or robot.params.footstep_bounds
        self.n_footprints = max(self.n_steps, 1)
        # F_{p-1} is the root foot; sides alternate backwards.
        self.sides: tuple[Side, ...] = tuple(
            self.root_side if (self.n_footprints - 1 - i) % 2 == 0 else self.front_side
            for i in range(self.n_footprints)
        )
        self.chain_nq = 3 * (self.n_footprints - 1)
        self.front_sole_frame = robot.frames.sole(front_side)
        self.root_sole_frame = robot.frames.sole(self.root_side)
        # the model's frame: the root footprint F_0, flat on the ground
        self.T_world_root = se3_of(start.of(self.sides[0]))
        self.T_root_world = self.T_world_root.inverse()
        self.model = chain_model(robot, self.sides, self.bounds)
        self.footprint_frame_ids = tuple(
            int(self.model.getFrameId(footprint_frame(i))) for i in range(self.n_footprints)
        )
        self.front_sole_fid = int(self.model.getFrameId(self.front_sole_frame))
        self.robot_nq = robot.model.nq
        # the structure, for caches of objects built on the model (data, solvers, tasks)
        self.key = (id(robot), self.sides, self.bounds)

    # ------------------------------------------------------------------------------------ frames
    def model_point(self, p_world: np.ndarray | tuple[float, ...]) -> np.ndarray:
        """A world point [m] (3-D, or 2-D on the ground) in the model's frame (that of F_0)."""
        p = np.asarray(p_world, dtype=float)
        if p.shape == (2,):
            return self.T_root_world.act(np.array([p[0], p[1], 0.0]))[:2]
        return self.T_root_world.act(p)

    def world_placement(self, T_model: pin.SE3) -> pin.SE3:
        """A placement of the model's frame (e.g. ``data.oMf[i]``) in the world."""
        return self.T_world_root * T_model

    # ------------------------------------------------------------------------------------ configuration
    def robot_slice(self) -> slice:
        """Slice of the robot's configuration in q~ (its free-flyer is relative to F_{p-1})."""
        return slice(self.chain_nq, self.chain_nq + self.robot_nq)

    def footprint_poses(self, q_tilde: np.ndarray) -> list[SolePose]:
        """World poses of F_0 .. F_{p-1} (F_0 alone when p <= 1)."""
        poses = [self.start.of(self.sides[0])]
        for i in range(1, self.n_footprints):
            poses.append(compose(poses[-1], q_tilde[3 * (i - 1) : 3 * i]))
        return poses

    def world_pose_of_last_footprint(self, q_tilde: np.ndarray) -> pin.SE3:
        """Flat frame of F_{p-1} in the world."""
        return se3_of(self.footprint_poses(q_tilde)[-1])

    def robot_q_world(self, q_tilde: np.ndarray) -> np.ndarray:
        """The robot's configuration (robot nq) with its free-flyer in the world frame."""
        q = np.array(q_tilde[self.robot_slice()], dtype=float)
        T_fp_base = pin.XYZQUATToSE3(q[:FREE_FLYER_NQ])
        q[:FREE_FLYER_NQ] = pin.SE3ToXYZQUAT(self.world_pose_of_last_footprint(q_tilde) * T_fp_base)
        return q

    def folded_q(self, q_robot_world: np.ndarray) -> np.ndarray:
        """q~ of the folded chain (every footprint on the initial sole of its side) carrying the robot
        at ``q_robot_world`` (world free-flyer)."""
        q_tilde = np.zeros(self.chain_nq + self.robot_nq)
        for i in range(1, self.n_footprints):
            Q = relative_pose(self.start.of(self.sides[i]), self.start.of(self.sides[i - 1]))
            q_tilde[3 * (i - 1) : 3 * i] = Q
        q = np.array(q_robot_world, dtype=float)
        T_world_base = pin.XYZQUATToSE3(q[:FREE_FLYER_NQ])
        q[:FREE_FLYER_NQ] = pin.SE3ToXYZQUAT(
            self.world_pose_of_last_footprint(q_tilde).inverse() * T_world_base
        )
        q_tilde[self.robot_slice()] = q
        return q_tilde

    def with_root_footprint(self, q_tilde: np.ndarray) -> tuple[VirtualChain, np.ndarray]:
        """Algorithm 1 line 15: q~ <- (dx, dy, dtheta, q~), one more footstep at the root of the chain.

        The new root footprint is the other initial foot and the new Q_1 places the old root footprint
        (fixed at its initial sole) relative to it, so every world pose is unchanged. From p = 0 to
        p = 1 the model is the same (the front foot is released instead).
        """
        new = VirtualChain(self.robot, self.front_side, self.n_steps + 1, self.start, self.bounds)
        if new.n_footprints == self.n_footprints:
            return new, np.array(q_tilde, dtype=float)
        Q_new = relative_pose(self.start.of(self.sides[0]), self.start.of(new.sides[0]))
        return new, np.concatenate([Q_new, np.asarray(q_tilde, dtype=float)])

    def chain_joint_names(self, i: int) -> list[str]:
        """Names of the three joints of Q_i (1 <= i <= p - 1)."""
        if not 1 <= i < self.n_footprints:
            raise InvalidRequestError(
                f"footprint {i} has no joint (chain has F_0 .. F_{self.n_footprints - 1})"
            )
        return [f"{footprint_frame(i)}_{s}" for s in _JOINT_SUFFIXES]

    def front_footprint(self, data: pin.Data) -> SolePose:
        """Ground footprint of the robot's front sole in the state held by ``data`` (world)."""
        return sole_pose_of(self.world_placement(data.oMf[self.front_sole_fid]))

    def __repr__(self) -> str:
        return (
            f"VirtualChain({self.robot.name}, steps={self.n_steps}, front={self.front_side}, "
            f"sides={'/'.join(s[0].upper() for s in self.sides)}, nq={self.model.nq})"
        )


def chain_model(robot: RobotModel, sides: tuple[Side, ...], bounds: FootstepBounds) -> pin.Model:
    """The pinocchio model of the chain F_0 .. F_{p-1} (``sides``) with the robot appended under
    F_{p-1}, in the frame of F_0 (shared: models are read-only; cached, thread-safe)."""
    key = (id(robot), sides, bounds)
    with _models_lock:
        hit = _models.get(key)
        if hit is not None and hit[0] is robot:
            _models.move_to_end(key)
            return hit[1]
    model = _build(robot, sides, bounds)
    with _models_lock:
        _models[key] = (robot, model)  # (the robot is kept alive with it: id(robot) stays unique)
        while len(_models) > MODEL_CACHE_SIZE:
            _models.popitem(last=False)
    return model


def _build(robot: RobotModel, sides: tuple[Side, ...], bounds: FootstepBounds) -> pin.Model:
    chain = pin.Model()
    n_footprints = len(sides)
    chain.name = f"footprints_{n_footprints}"
    parent_frame = chain.addFrame(
        pin.Frame(footprint_frame(0), 0, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME)
    )
    joint = 0
    for i in range(1, n_footprints):
        limits = bounds.for_swing(sides[i])  # F_i in the frame of F_{i-1} (section 4)
        for axis, (jmodel, suffix) in enumerate(
            zip((pin.JointModelPX(), pin.JointModelPY(), pin.JointModelRZ()), _JOINT_SUFFIXES, strict=True)
        ):
            lo, hi = limits[axis]
            joint = chain.addJoint(
                joint,
                jmodel,
                pin.SE3.Identity(),
                f"{footprint_frame(i)}_{suffix}",
                np.array([1e3]),
                np.array([1e3]),
                np.array([lo]),
                np.array([hi]),
            )
            chain.appendBodyToJoint(joint, pin.Inertia.Zero(), pin.SE3.Identity())
        parent_frame = chain.addFrame(
            pin.Frame(footprint_frame(i), joint, parent_frame, pin.SE3.Identity(), pin.FrameType.OP_FRAME)
        )
    model = pin.appendModel(chain, robot.model, parent_frame, pin.SE3.Identity())
    model.name = f"{robot.name}+{chain.name}"
    return model
