"""The simulated world: a robot and a scene in pybullet (DIRECT mode), no bus.

::

    world = World("hrp2_like", "ball_fetch", seed=3)
    state = world.state()                                   # q, v, sim time
    result = world.execute(q_trajectory)                    # (N, nq) sampled every 5 ms
    images = world.render("wide", 640, 480)                 # stereo pair from the head
    world.gripper("right", "close")                         # grasps what is between the fingers
    world.ground_truth()                                    # object poses (tests/benchmarks only)

Physics runs at 1 kHz; every joint is position controlled (pybullet motors, forces capped at the URDF
effort limits), commands interpolated linearly between the 5 ms trajectory samples with velocity
feed-forward. Gripper joints are driven only by :meth:`World.gripper` (their values in trajectories are
ignored). Not thread-safe (pybullet is not): one caller at a time.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as p

from services.errors import InvalidRequestError, NotFoundError
from services.model import RobotModel, load_robot
from services.model.pybullet_robot import PybulletRobot
from services.model.specs import check_side
from sim import grasp, render
from sim.compliance import Admittance, ForceTarget
from sim.config import SimConfig
from sim.contacts import Contact, ContactRules, floor_force
from sim.objects import build_scene
from sim.results import CameraImage, ExecutionResult, GripperResult, ObjectState, RobotState
from sim.scene import Layout, SceneSpec, layout, load_scene
from sim.stabilizer import Stabilizer, StabilizerGains
from sim.start_contacts import StartContacts

GRIPPER_ACTIONS = ("open", "close")
_FINGER_STALL_SPEED = 2e-3  # [m/s or rad/s]: a closing finger slower than this has stopped
_FINGER_DONE_TOL = 1e-3  # [m or rad]: a finger this close to its target has arrived

TickHook = Callable[["World"], None]
FALL_MARGIN_M = 0.15  # a base this far below a planned posture under the fall height has fallen [m]
FALL_MARGIN_RAD = 0.35  # a base this much more tilted than a planned tilted posture has fallen [rad]


def start_configuration(robot: RobotModel, scene_layout: Layout) -> np.ndarray:
    """The robot's configuration at a reset: half-sitting with the soles' midpoint at the scene's
    start pose, or the scene's ``robot.posture`` (e.g. seated) with the base there."""
    x, y = scene_layout.robot_xy
    yaw = scene_layout.robot_yaw_rad
    q = robot.half_sitting_at(x, y, yaw)
    posture = scene_layout.scene.robot_posture
    if posture is None:
        return q
    for name, value in posture.joints:
        if name not in robot.joint_names:
            raise InvalidRequestError(
                f"scene {scene_layout.scene.name}: robot.posture names an unknown joint {name!r}; "
                f"joints: {robot.joint_names}"
            )
        q[robot.joint_index(name).idx_q] = value
    q[:3] = (x, y, posture.base_z_m)
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, posture.pitch_rad, yaw)).coeffs()
    return q


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence pybullet's C-level prints (URDF loading logs every merged link on stdout)."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # no real stdout (pytest capture, notebooks)
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), fd)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, fd)
        os.close(saved)


class World:
    """A robot standing in a scene; see the module docstring."""

    def __init__(
        self,
        model: str | RobotModel = "hrp2_like",
        scene: str | Path | SceneSpec = "empty",
        seed: int | None = None,
        config: SimConfig | None = None,
    ) -> None:
        self.config = config or SimConfig()
        self.robot: RobotModel = load_robot(model) if isinstance(model, str) else model
        self.client: int = p.connect(p.DIRECT)
        self.sim_time_s = 0.0
        self._steps = 0
        self.on_tick: TickHook | None = None  # called every control period (5 ms of sim time)
        self._data = self.robot.new_data()
        self.reset(scene, seed)

    @property
    def solver_iterations(self) -> int:
        """pybullet constraint-solver iterations per physics step: the config's, else the robot's."""
        if self.config.solver_iterations is not None:
            return self.config.solver_iterations
        return self.robot.pybullet_solver_iterations

    # ---------------------------------------------------------------------------------- life cycle
    def close(self) -> None:
        """Disconnect from pybullet (the world is unusable afterwards)."""
        if self.client >= 0:
            with contextlib.suppress(p.error):
                p.disconnect(self.client)
            self.client = -1

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def reset(self, scene: str | Path | SceneSpec | None = None, seed: int | None = None) -> Layout:
        """Rebuild the world: the scene (default: the current one) laid out with ``seed`` (None: nominal),
        the robot in half-sitting at the scene's start pose, grippers open; objects then settle for
        ``config.settle_s``. Sim time keeps running (it never goes back)."""
        if scene is None:
            spec = self.layout.scene
        elif isinstance(scene, SceneSpec):
            spec = scene
        else:
            spec = load_scene(scene)
        new_layout = layout(spec, seed)
        cfg = self.config
        c = self.client
        p.resetSimulation(physicsClientId=c)
        p.setGravity(0.0, 0.0, -9.81, physicsClientId=c)
        p.setPhysicsEngineParameter(
            fixedTimeStep=cfg.physics_dt_s, numSolverIterations=self.solver_iterations, physicsClientId=c
        )
        self.layout = new_layout
        self.floor_id, self.bodies = build_scene(new_layout, c)
        self.body_names = {body: name for name, body in self.bodies.items()}
        self.movable = {b: n for n, b in self.bodies.items() if not new_layout.object(n).spec.is_static}
        q0 = start_configuration(self.robot, new_layout)
        with _quiet_stdout():
            self.pyrobot = PybulletRobot(self.robot, c, q0)
        self._index_robot()
        self.held: dict[str, str] = {}
        self._constraints: dict[str, int] = {}
        self.q_cmd = q0.copy()
        self.q_planned = q0.copy()  # the posture the robot should be in (its fall limits)
        for side in ("left", "right"):
            self._finger_target[side] = self.robot.params.gripper.open_q
            self._command_finger(side, self.robot.params.gripper.open_q)
        self._command_body(self.q_cmd, np.zeros(self.robot.nv))
        self.hold(cfg.settle_s)
        return new_layout

    def _index_robot(self) -> None:
        robot, pyrobot = self.robot, self.pyrobot
        self.robot_id = pyrobot.body_id
        self.link_name = dict(pyrobot.link_names)
        self.grippers = {}
        gripper_names = set()
        for side in ("left", "right"):
            joint = robot.gripper_joint(side)
            gripper_names.add(joint)
            jid = int(pyrobot.joint_ids[robot.joint_names.index(joint)])
            self.grippers[side] = grasp.gripper_links(self.client, self.robot_id, side, jid)
        self.foot_links = {side: pyrobot.link_index(robot.frames.sole(side)) for side in ("left", "right")}
        body = [i for i, n in enumerate(robot.joint_names) if n not in gripper_names]
        self._body_joint_names = [robot.joint_names[i] for i in body]
        self._body_ids = [int(pyrobot.joint_ids[i]) for i in body]
        self._body_iq = np.array([robot.joint_index(robot.joint_names[i]).idx_q for i in body])
        self._body_iv = np.array([robot.joint_index(robot.joint_names[i]).idx_v for i in body])
        self._body_force = [float(pyrobot.effort_max[i]) for i in body]
        self._finger_target: dict[str, float] = {}
        n = len(body)
        self._kp = [self.config.position_gain] * n
        self._kd = [self.config.velocity_gain] * n
        self._base_fid = robot.frame_id(robot.frames.base)
        self._sole_fids = {side: robot.frame_id(robot.frames.sole(side)) for side in ("left", "right")}
        cfg = self.config
        self.stabilizer = (
            Stabilizer(
                robot,
                self._body_joint_names,
                StabilizerGains(
                    cfg.stabilizer_gain,
                    cfg.stabilizer_damping_s,
                    cfg.stabilizer_max_rad,
                    cfg.stabilizer_loaded_n,
                ),
            )
            if cfg.stabilizer
            else None
        )

    # ---------------------------------------------------------------------------------- low level
    def _command_body(self, q: np.ndarray, v: np.ndarray) -> None:
        self._command_joints(
            self.client,
            self.robot_id,
            self._body_ids,
            self._kp,
            self._kd,
            self._body_force,
            q[self._body_iq].tolist(),
            v[self._body_iv].tolist(),
        )

    @staticmethod
    def _command_joints(
        client: int,
        robot_id: int,
        ids: list[int],
        kp: list[float],
        kd: list[float],
        forces: list[float],
        q_body: list[float],
        v_body: list[float],
    ) -> None:
        """The one motor command of the body joints: position targets ``q_body`` [rad or m] and
        feed-forward velocities ``v_body`` of the joints ``ids`` (pybullet indices, e.g.
        ``_body_ids``) with the gains ``kp``, ``kd`` and the force caps ``forces`` [N or N m]. Takes
        the world's attributes as arguments so that the stepping loop hoists them once."""
        p.setJointMotorControlArray(
            robot_id,
            ids,
            p.POSITION_CONTROL,
            targetPositions=q_body,
            targetVelocities=v_body,
            positionGains=kp,
            velocityGains=kd,
            forces=forces,
            physicsClientId=client,
        )

    def _command_finger(self, side: str, target: float) -> None:
        g = self.grippers[side]
        info = p.getJointInfo(self.robot_id, g.joint_id, physicsClientId=self.client)
        p.setJointMotorControl2(
            self.robot_id,
            g.joint_id,
            p.POSITION_CONTROL,
            targetPosition=target,
            force=float(info[10]),
            maxVelocity=float(info[11]),
            positionGain=self.config.position_gain,
            velocityGain=self.config.velocity_gain,
            physicsClientId=self.client,
        )

    def _finger_q(self, side: str) -> tuple[float, float]:
        s = p.getJointState(self.robot_id, self.grippers[side].joint_id, physicsClientId=self.client)
        return float(s[0]), float(s[1])

    def _physics_step(self) -> None:
        p.stepSimulation(physicsClientId=self.client)
        self._steps += 1
        self.sim_time_s = self._steps * self.config.physics_dt_s

    def _step_commanded(self, targets: list[list[float]], v_ff: list[float]) -> None:
        """One physics step per row of ``targets`` (the body joints' position targets [rad or m], the
        order of ``_body_ids``), each commanded with the feed-forward velocities ``v_ff`` first: the
        loop of :meth:`step` with the motor command inside, written out (it runs 1000 times per
        simulated second, :meth:`_command_joints` with its arguments hoisted)."""
        client, robot_id, ids = self.client, self.robot_id, self._body_ids
        kp, kd, forces = self._kp, self._kd, self._body_force
        substeps, dt_s = self.config.substeps, self.config.physics_dt_s
        command = self._command_joints
        for target in targets:
            command(client, robot_id, ids, kp, kd, forces, target, v_ff)
            p.stepSimulation(physicsClientId=client)
            self._steps += 1
            self.sim_time_s = self._steps * dt_s
            if self._steps % substeps == 0 and self.on_tick is not None:
                self.on_tick(self)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps with the current commands (the ``on_tick`` hook runs every
        control period)."""
        for _ in range(n):
            self._physics_step()
            if self._steps % self.config.substeps == 0 and self.on_tick is not None:
                self.on_tick(self)

    def step_control(self) -> None:
        """Advance one control period (5 ms) holding the current commands."""
        self.step(self.config.substeps)

    def hold(self, duration_s: float) -> None:
        """Keep the current commands for ``duration_s`` of sim time [s] (standing still)."""
        self.step(round(duration_s / self.config.physics_dt_s))

    # ---------------------------------------------------------------------------------- state
    def state(self) -> RobotState:
        """Current robot state (q, v in the pinocchio layout) and sim time."""
        return RobotState(self.pyrobot.read_q(), self.pyrobot.read_v(), self.sim_time_s)

    def base_pose(self) -> pin.SE3:
        """World pose of the robot's base (URDF base frame) ``T_world_base``."""
        return self.pyrobot.base_pose()

    def base_velocity(self) -> tuple[np.ndarray, np.ndarray]:
        """Linear velocity of the base's centre of mass and angular velocity, in world [m/s, rad/s]."""
        lin, ang = p.getBaseVelocity(self.robot_id, physicsClientId=self.client)
        return np.array(lin), np.array(ang)

    def ground_truth(self) -> dict[str, ObjectState]:
        """Pose and description of every scene object (for tests and benchmarks only)."""
        held_by = {name: side for side, name in self.held.items()}
        out = {}
        for obj in self.layout.objects:
            pos, quat = p.getBasePositionAndOrientation(self.bodies[obj.name], physicsClientId=self.client)
            s = obj.spec
            out[obj.name] = ObjectState(
                name=obj.name,
                kind=s.kind,
                position=np.array(pos),
                quaternion=np.array(quat),
                colour=s.colour,
                size_m=s.size_m,
                radius_m=s.radius_m,
                length_m=s.length_m,
                mass_kg=s.mass_kg,
                held_by=held_by.get(obj.name, ""),
            )
        return out

    def set_object_pose(self, name: str, position: np.ndarray, quaternion: np.ndarray | None = None) -> None:
        """Teleport an object (at rest) to ``position`` [m] / ``quaternion`` xyzw (tests and set-ups only;
        contacts see the new pose after the next step)."""
        if name not in self.bodies:
            raise NotFoundError(
                f"no object {name!r} in scene {self.layout.scene.name}; objects: {sorted(self.bodies)}"
            )
        if name in self.held.values():
            raise InvalidRequestError(f"{name} is held by a gripper; open it before moving the object")
        quat = [0.0, 0.0, 0.0, 1.0] if quaternion is None else [float(v) for v in quaternion]
        body = self.bodies[name]
        p.resetBasePositionAndOrientation(
            body, [float(v) for v in position], quat, physicsClientId=self.client
        )
        p.resetBaseVelocity(body, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=self.client)

    def tilt_rad(self, T_world_base: pin.SE3 | None = None) -> float:
        """Angle between the base's z axis and the vertical [rad]."""
        R = (T_world_base or self.base_pose()).rotation
        return float(math.acos(max(-1.0, min(1.0, R[2, 2]))))

    def fall_limits(self, q_planned: np.ndarray) -> tuple[float, float]:
        """(base height [m], tilt [rad]) under / beyond which the robot has fallen while it should be at
        ``q_planned``: the robot's fall height and angle, moved with a planned posture lower or more
        tilted than them (seated on a chair, leaning on a table) to that much below or more tilted."""
        prm = self.robot.params
        planned = pin.XYZQUATToSE3(np.asarray(q_planned[:7], dtype=float))
        height = min(prm.fall_base_height_m, float(planned.translation[2]) - FALL_MARGIN_M)
        return height, max(prm.fall_tilt_rad, self.tilt_rad(planned) + FALL_MARGIN_RAD)

    def fallen(self) -> bool:
        """True if the base is below the fall height or tilted beyond the fall angle of the posture last
        planned (:meth:`fall_limits`: the start posture, then each trajectory sample played)."""
        T = self.base_pose()
        height, tilt = self.fall_limits(self.q_planned)
        return T.translation[2] < height or self.tilt_rad(T) > tilt

    def contact_rules(
        self, allowed: tuple[str, ...] = (), leaving: tuple[str, ...] = (), supports: tuple[str, ...] = ()
    ) -> ContactRules:
        """The planned-contact rules for the current held objects and ``allowed`` object names."""
        unknown = sorted((set(allowed) | set(leaving) | set(supports)) - set(self.bodies) - {"floor"})
        if unknown:
            raise NotFoundError(
                f"allowed_contacts names unknown objects {unknown}; objects in scene "
                f"{self.layout.scene.name}: {sorted(self.bodies)}"
            )
        hands = frozenset().union(*(g.hand_links for g in self.grippers.values()))
        return ContactRules(
            client=self.client,
            robot_id=self.robot_id,
            floor_id=self.floor_id,
            names=self.body_names,
            link_name=self.link_name,
            foot_links=frozenset(self.foot_links.values()),
            hand_links=hands,
            held={name: self.bodies[name] for name in self.held.values()},
            allowed=frozenset(allowed),
            min_force_n=self.config.contact_force_n,
            leaving=set(leaving) - {"floor"},
            supports=frozenset(supports),
        )

    def collisions(self, allowed: tuple[str, ...] = ()) -> list[Contact]:
        """Unplanned robot-scene contacts now (see :mod:`sim.contacts`)."""
        return self.contact_rules(allowed).collisions()

    # ---------------------------------------------------------------------------------- execution
    def execute(
        self,
        q_trajectory: np.ndarray,
        dt_s: float | None = None,
        allowed_contacts: tuple[str, ...] = (),
        stop_on_collision: bool = True,
        hold_s: float = 0.0,
        leaving: tuple[str, ...] = (),
        supports: tuple[str, ...] = (),
        effort_scale: Mapping[str, float] | None = None,
        force_targets: Sequence[ForceTarget] = (),
    ) -> ExecutionResult:
        """Play a joint trajectory through position control; ``effort_scale`` (joint name -> a fraction
        in (0, 1] of its effort limit) caps those joints' motors during this execution only: a compliant
        limb in a closed kinematic loop (a hand on a table while a sole is on the floor: under full
        effort the rigid loop's internal forces drove the arm to its torque limits, sim/README.md);
        ``force_targets``: limbs in contact whose commanded positions yield to their contact force
        against its planned profile (damping control, :mod:`sim.compliance`).
        Other arguments: :meth:`_execute`."""
        forces = list(self._body_force)
        for name, scale in (effort_scale or {}).items():
            if name not in self._body_joint_names:
                raise InvalidRequestError(
                    f"effort_scale names {name!r}, not a body joint of {self.robot.name}",
                    {"field": "effort_scale"},
                )
            if not 0.0 < float(scale) <= 1.0:
                raise InvalidRequestError(
                    f"effort_scale of {name} must be in (0, 1], got {scale}", {"field": "effort_scale"}
                )
            i = self._body_joint_names.index(name)
            forces[i] = self._body_force[i] * float(scale)
        saved, self._body_force = self._body_force, forces
        try:
            return self._execute(
                q_trajectory,
                dt_s,
                allowed_contacts,
                stop_on_collision,
                hold_s,
                leaving,
                supports,
                force_targets,
            )
        finally:
            if effort_scale:  # the motors back at their full effort, holding the last command
                self._body_force = saved
                self._command_body(self.q_cmd, np.zeros(self.robot.nv))

    def _execute(
        self,
        q_trajectory: np.ndarray,
        dt_s: float | None,
        allowed_contacts: tuple[str, ...],
        stop_on_collision: bool,
        hold_s: float,
        leaving: tuple[str, ...],
        supports: tuple[str, ...],
        force_targets: Sequence[ForceTarget] = (),
    ) -> ExecutionResult:
        """Play a joint trajectory through position control.

        Args:
            q_trajectory: (N, nq) configurations (pinocchio layout) every ``dt_s``; sample 0 is the
                start and must be within ``config.max_start_jump_rad`` of the current joints. The base
                part is the planned base pose (used for ``base_error_m`` only: the base is not actuated).
            dt_s: sample period [s], a multiple of the physics step (default ``config.control_dt_s``).
            allowed_contacts: objects the hands (and held objects) may touch.
            stop_on_collision: stop at the first unplanned contact (the robot then holds its last command).
            hold_s: keep the last sample commanded this long after the end [s] (still monitored).
            leaving: objects the robot touches now and moves away from: their contacts with any link
                are allowed until they first break (:attr:`sim.contacts.ContactRules.leaving`).
            supports: objects any link may touch during the whole motion (a multi-contact motion's
                supports: a chair the robot gets up from, a table it leans on; ``floor`` lets any link
                touch the floor).
            force_targets: limbs whose commands yield to their contact force (:mod:`sim.compliance`).
        """
        cfg = self.config
        q_traj = self._check_trajectory(q_trajectory)
        dt = cfg.control_dt_s if dt_s is None else float(dt_s)
        substeps = round(dt / cfg.physics_dt_s)
        if dt <= 0 or abs(dt / cfg.physics_dt_s - substeps) > 1e-6:
            raise InvalidRequestError(
                f"dt_s={dt} must be a positive multiple of the physics step {cfg.physics_dt_s} s"
            )
        if hold_s < 0:
            raise InvalidRequestError(f"hold_s must be >= 0, got {hold_s}")
        rules = self.contact_rules(tuple(allowed_contacts), tuple(leaving), tuple(supports))
        admittance = (
            Admittance(
                self.robot,
                self.client,
                self.robot_id,
                {**self.bodies, "floor": self.floor_id},
                {n: int(i) for n, i in zip(self.robot.joint_names, self.pyrobot.joint_ids, strict=True)},
                self._body_joint_names,
                force_targets,
                len(q_traj),
                dt,
            )
            if force_targets
            else None
        )
        rules.already_touching = rules.touching_pairs()
        start_points = rules.robot_contact_points()
        if start_points:  # a motion starting in contact may leave it, not push into it (sim.start_contacts)
            rules.start = StartContacts.measure(
                self.robot,
                self._data,
                self.link_name,
                start_points,
                self.pyrobot.read_q(),
                q_traj,
                cfg.start_contact_push_m,
            )
        n_hold = round(hold_s / dt)
        monitor = _Monitor(self)
        # the soles the only supports: a multi-contact motion's body leans on its supports as planned
        stabilizer = self.stabilizer if not (supports or force_targets) else None
        if self.stabilizer is not None and stabilizer is None:  # none kept for after it, from another posture
            self.stabilizer.reset()
        start_time = self.sim_time_s
        outcome, message = "completed", f"executed {len(q_traj)} samples"
        executed = 1
        collided: dict[tuple[str, str], Contact] = {}
        fall = (0.0, 0.0)
        # The body joints' targets at every physics step of every control period, computed at once:
        # linear interpolation from one sample to the next (sample k at the end of period k).
        body = q_traj[:, self._body_iq]
        a = (np.arange(1, substeps + 1) / substeps)[:, None]  # (substeps, 1)
        for k in range(1, len(q_traj) + n_hold):
            k_prev, k_next = min(k - 1, len(q_traj) - 1), min(k, len(q_traj) - 1)
            q_next = q_traj[k_next]
            b_prev, b_next = body[k_prev], body[k_next]
            v_ff = ((b_next - b_prev) / dt).tolist()
            offsets = 0.0 if admittance is None else admittance.update(k_prev, self.pyrobot.read_q())
            if stabilizer is not None:
                offsets = offsets + stabilizer.offsets
            self._step_commanded(((1.0 - a) * b_prev + a * b_next + offsets).tolist(), v_ff)
            self.q_cmd = q_next.copy()
            if stabilizer is not None:
                self.q_cmd[self._body_iq] += stabilizer.offsets
            self.q_planned = q_next.copy()
            executed = min(k + 1, len(q_traj))
            # one contact query per period for the slip monitor and the collision rules
            points = p.getContactPoints(bodyA=self.robot_id, physicsClientId=self.client)
            T_base = monitor.update(self.q_cmd, points)
            if stabilizer is not None and stabilizer.free_of_contacts(
                rules.pushing_force(points) >= cfg.stabilizer_contact_n
            ):  # the corrections of the next period, from the state now
                omega = p.getBaseVelocity(self.robot_id, physicsClientId=self.client)[1]
                stabilizer.update(
                    self._data,
                    monitor.q,
                    omega,
                    q_traj[k_prev],
                    q_next,
                    dt,
                    {side: monitor.forces[link] for side, link in self.foot_links.items()},
                )
            height, tilt = float(T_base.translation[2]), self.tilt_rad(T_base)
            # A planned posture lower or more tilted than the fall limits (seated on a chair, leaning on
            # a table) moves the limits with it: a fall is then a base that much below or more tilted
            # than planned.
            fall_height, fall_tilt = self.fall_limits(q_next)
            if height < fall_height or tilt > fall_tilt:
                outcome, fall = "fell", (height, tilt)
                message = (
                    f"the robot fell at t={self.sim_time_s - start_time:.3f} s into the motion: base height "
                    f"{height:.3f} m (limit {fall_height:.3f} m), tilt "
                    f"{math.degrees(tilt):.1f} deg (limit {math.degrees(fall_tilt):.1f} deg)"
                )
                break
            for contact in rules.collisions(points, k_next):
                collided.setdefault((contact.robot_link, contact.other), contact)
            if collided and stop_on_collision:
                break
        if outcome != "fell" and collided:
            outcome = "collision"
            pairs = ", ".join(f"{c.robot_link} touched {c.other}" for c in collided.values())
            message = f"unplanned contact at t={self.sim_time_s - start_time:.3f} s: {pairs}"
        if outcome != "completed":  # hold still where the robot is instead of finishing the motion
            if stabilizer is not None:
                stabilizer.reset()
            self.q_cmd = self.pyrobot.read_q()
            self._command_body(self.q_cmd, np.zeros(self.robot.nv))
        err_max, err_rms, worst = monitor.tracking()
        return ExecutionResult(
            outcome=outcome,
            message=message,
            state=self.state(),
            samples_executed=executed,
            duration_s=self.sim_time_s - start_time,
            tracking_error_rad=err_max,
            tracking_rms_rad=err_rms,
            worst_joint=worst,
            base_error_m=monitor.base_error_m,
            foot_slip_m=monitor.foot_slip_m,
            collisions=tuple(collided.values()),
            fall_base_height_m=fall[0],
            fall_tilt_rad=fall[1],
        )

    def _check_trajectory(self, q_trajectory: np.ndarray) -> np.ndarray:
        q = np.asarray(q_trajectory, dtype=float)
        nq = self.robot.nq
        if q.ndim != 2 or q.shape[1] != nq or q.shape[0] < 1:
            raise InvalidRequestError(
                f"trajectory must have shape (N >= 1, nq={nq}) for {self.robot.name}, got {q.shape}"
            )
        if not np.all(np.isfinite(q)):
            bad = int(np.argwhere(~np.isfinite(q))[0][0])
            raise InvalidRequestError(f"trajectory sample {bad} contains non-finite values")
        names = self._body_joint_names
        lo, hi = self.robot.q_lower[self._body_iq], self.robot.q_upper[self._body_iq]
        joints = q[:, self._body_iq]
        tol = 1e-3
        below, above = joints < lo - tol, joints > hi + tol
        if below.any() or above.any():
            k, j = np.argwhere(below | above)[0]
            raise InvalidRequestError(
                f"trajectory sample {k}: joint {names[j]} = {joints[k, j]:.4f} is outside its limits "
                f"[{lo[j]:.4f}, {hi[j]:.4f}]"
            )
        current = self.pyrobot.read_q()[self._body_iq]
        jump = np.abs(joints[0] - current)
        j = int(np.argmax(jump))
        if jump[j] > self.config.max_start_jump_rad:
            raise InvalidRequestError(
                f"the trajectory starts {jump[j]:.3f} rad away from the current position of joint {names[j]} "
                f"(limit {self.config.max_start_jump_rad} rad): plan from the current state (sim/state)",
                {"joint": names[j], "jump_rad": float(jump[j])},
            )
        q = q.copy()
        for k in range(len(q)):  # keep quaternions unit for pinocchio
            norm = np.linalg.norm(q[k, 3:7])
            q[k, 3:7] = q[k, 3:7] / norm if norm > 1e-9 else (0.0, 0.0, 0.0, 1.0)
        return q

    # ---------------------------------------------------------------------------------- grasping
    def gripper(self, side: str, action: str) -> GripperResult:
        """Open or close the gripper of ``side``.

        ``close`` moves the finger until it stops on something or reaches the closed position; an object
        squeezed between the jaws (contacts on both) is then attached (``grasped``), else
        ``not_grasped``. ``open`` releases the held object (``released``) or just opens (``opened``).
        """
        check_side(side)
        if action not in GRIPPER_ACTIONS:
            raise InvalidRequestError(
                f"gripper action must be one of {list(GRIPPER_ACTIONS)}, got {action!r}"
            )
        spec = self.robot.params.gripper
        if action == "close":
            if side in self.held:
                return self._gripper_result(side, action, "grasped")
            self._move_finger(side, spec.closed_q)
            names = grasp.squeezed_objects(
                self.client, self.robot_id, self.grippers[side], self.movable, self.config.contact_force_n
            )
            names = [n for n in names if n not in self.held.values()]
            if not names:
                return self._gripper_result(side, action, "not_grasped")
            name = names[0]
            self._constraints[side] = grasp.attach(
                self.client, self.robot_id, self.grippers[side].palm_link, self.bodies[name]
            )
            self.held[side] = name
            # Keep the finger where it stopped on the object (no further squeezing).
            self._finger_target[side] = self._finger_q(side)[0]
            self._command_finger(side, self._finger_target[side])
            return self._gripper_result(side, action, "grasped")
        released = self.held.pop(side, "")
        if side in self._constraints:
            grasp.detach(self.client, self._constraints.pop(side))
        self._move_finger(side, spec.open_q)
        return self._gripper_result(side, action, "released" if released else "opened", released)

    def _move_finger(self, side: str, target: float) -> None:
        self._finger_target[side] = target
        self._command_finger(side, target)
        cfg = self.config
        moved = False
        for _ in range(max(1, round(cfg.gripper_timeout_s / cfg.control_dt_s))):
            self.step_control()
            q, v = self._finger_q(side)
            if abs(q - target) < _FINGER_DONE_TOL:
                break
            moved = moved or abs(v) > _FINGER_STALL_SPEED
            if moved and abs(v) < _FINGER_STALL_SPEED:  # stopped on an object
                break

    def _gripper_result(self, side: str, action: str, outcome: str, released: str = "") -> GripperResult:
        return GripperResult(
            side, action, outcome, self.held.get(side, ""), released, self._finger_q(side)[0], self.sim_time_s
        )

    # ---------------------------------------------------------------------------------- images
    def camera_names(self) -> list[str]:
        """Valid ``render`` camera names: stereo pairs then single cameras."""
        return [*self.robot.stereo_pairs, *self.robot.cameras]

    def render(
        self,
        camera: str,
        width_px: int = 640,
        height_px: int = 480,
        *,
        depth: bool = False,
        segmentation: bool = False,
    ) -> list[CameraImage]:
        """Images of a head stereo pair (``wide``, ``narrow``: left then right) or of one camera."""
        if camera in self.robot.stereo_pairs:
            pair = self.robot.stereo_pairs[camera]
            names = [pair.left, pair.right]
        elif camera in self.robot.cameras:
            names = [camera]
        else:
            raise NotFoundError(f"unknown camera {camera!r}; valid cameras: {self.camera_names()}")
        data = self.robot.forward(self.pyrobot.read_q(), self._data)
        images = []
        for name in names:
            spec = self.robot.cameras[name]
            T_world_camera = data.oMf[self.robot.frame_id(spec.frame)].homogeneous.copy()
            images.append(
                render.render_camera(
                    self,
                    name,
                    spec,
                    T_world_camera,
                    width_px,
                    height_px,
                    depth=depth,
                    segmentation=segmentation,
                )
            )
        return images

    def snapshot(
        self,
        viewpoint: str = "overview",
        width_px: int = 640,
        height_px: int = 480,
        eye: tuple[float, float, float] | None = None,
        target: tuple[float, float, float] | None = None,
    ) -> bytes:
        """A PNG of the scene from an external camera (``render.VIEWPOINTS`` or ``eye``/``target`` [m])."""
        return render.snapshot_png(self, viewpoint, width_px, height_px, eye, target)


class _Monitor:
    """Tracking error, base error and foot slip accumulated during an execution."""

    def __init__(self, world: World) -> None:
        self.world = world
        self.err_max = 0.0
        self.err_sq = 0.0
        self.count = 0
        self.worst = ""
        self.base_error_m = 0.0
        self.foot_slip_m = 0.0
        self._anchor: dict[str, tuple[float, float] | None] = {"left": None, "right": None}
        self.q = np.zeros(0)  # the configuration read at the last update (pinocchio layout)
        self.forces: dict[int, float] = {}  # the floor's normal force on each sole link then [N]

    def update(self, q_cmd: np.ndarray, points: Sequence[tuple] | None = None) -> pin.SE3:
        """Account the state after a control period commanded at ``q_cmd``; the base pose (world).
        ``points``: the robot's contact points now (``pybullet.getContactPoints(bodyA=robot)``), else
        queried here."""
        w = self.world
        self.q = q = w.pyrobot.read_q()  # from pybullet: (nq,) floats, finite while the physics is
        if not math.isfinite(float(np.add.reduce(q))):  # a blown-up simulation: check_q's error, as before
            w.robot.check_q(q)
        err = np.abs(q[w._body_iq] - q_cmd[w._body_iq])
        j = int(err.argmax())
        if err[j] > self.err_max:
            self.err_max, self.worst = float(err[j]), w._body_joint_names[j]
        self.err_sq += float(np.add.reduce(err * err)) / err.size  # np.mean(err**2), without its overhead
        self.count += 1
        # Joint placements, then only the three frames used here (not every frame of the model).
        model, data = w.robot.model, w._data
        pin.forwardKinematics(model, data, q)
        T_base = pin.SE3(pin.updateFramePlacement(model, data, w._base_fid))
        dx, dy, dz = (q[:3] - q_cmd[:3]).tolist()
        self.base_error_m = max(self.base_error_m, math.sqrt(dx * dx + dy * dy + dz * dz))
        self.forces = forces = floor_force(w.client, w.robot_id, w.floor_id, w.foot_links.values(), points)
        for side, link in w.foot_links.items():
            if forces[link] < w.config.loaded_foot_force_n:
                self._anchor[side] = None
                continue
            x, y = pin.updateFramePlacement(model, data, w._sole_fids[side]).translation[:2].tolist()
            anchor = self._anchor[side]
            if anchor is None:
                self._anchor[side] = (x, y)
            else:
                self.foot_slip_m = max(self.foot_slip_m, math.hypot(x - anchor[0], y - anchor[1]))
        return T_base

    def tracking(self) -> tuple[float, float, str]:
        rms = math.sqrt(self.err_sq / self.count) if self.count else 0.0
        return self.err_max, rms, self.worst
