"""The same robot in pybullet: load the URDF, map joint/link names to pybullet indices, place the base
from a pinocchio ``q``, read ``q``/``v`` back, position control. No scene logic here (the sim owns it).

pybullet facts handled here (CONVENTIONS §5):

- pybullet's base pose is the pose of the base link's *inertial* frame, not the URDF base frame:
  placing uses ``T_world_inertial = T_world_base * T_base_inertial`` (from ``getDynamicsInfo``).
- inertias come from the URDF (``URDF_USE_INERTIA_FROM_FILE``), not recomputed from collision shapes.
- after ``resetJointState`` contact queries still see the old pose until a ``stepSimulation``.
- ``package://`` mesh paths (talos) are resolved into a cached copy of the URDF with absolute paths.
- soles must be exactly flat: a robot whose foot collision mesh is not (``robot.pybullet_sole_box_m``,
  talos) gets a box of the sole rectangle under each foot instead, in this copy only.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as p

from services.errors import InvalidRequestError
from services.model.robot_model import FREE_FLYER_NQ, FREE_FLYER_NV, RobotModel
from services.model.urdf_flatten import flatten_fixed_joints, replace_foot_collisions_with_sole_boxes

_PACKAGE_RE = re.compile(r'filename="package://([^"]+)"')


def pybullet_urdf_path(robot: RobotModel, flatten: bool = True) -> tuple[Path, dict[str, str]]:
    """A URDF pybullet can load for ``robot`` and the map of merged link -> host link.

    ``package://`` paths are made absolute (resolved against ``robot.package_dirs``) and, if ``flatten``,
    fixed joints are folded into their parents with exact mass properties (see ``urdf_flatten``). If
    ``robot.pybullet_sole_box_m`` is set, the collision shapes of each foot are replaced with a box of the
    sole rectangle (``robot.sole_size_m``) that thick, its bottom face on the sole frame. The result is
    cached under the system temp directory, keyed by its content.
    """
    text = robot.urdf_path.read_text(encoding="utf-8")

    def resolve(match: re.Match[str]) -> str:
        rel = match.group(1)
        for root in robot.package_dirs:
            candidate = Path(root) / rel
            if candidate.exists():
                return f'filename="{candidate}"'
        raise InvalidRequestError(
            f"{robot.name}: mesh package://{rel} not found under {list(robot.package_dirs)}"
        )

    text = _PACKAGE_RE.sub(resolve, text)
    if robot.pybullet_sole_box_m is not None:
        soles = tuple(robot.frames.sole(side) for side in ("left", "right"))
        text, _ = replace_foot_collisions_with_sole_boxes(
            text, soles, robot.sole_size_m, robot.pybullet_sole_box_m
        )
    merged: dict[str, str] = {}
    if flatten:
        text, merged = flatten_fixed_joints(text)
    digest = hashlib.sha1(text.encode("utf-8")).hexdigest()[:16]
    cache = Path(tempfile.gettempdir()) / "humanoid_model_urdf"
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"{robot.name}_{digest}.urdf"
    if not path.exists():
        tmp = cache / f".{path.name}.{os.getpid()}.tmp"
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)  # atomic: concurrent processes write identical content
    return path, merged


class PybulletRobot:
    """A :class:`RobotModel` loaded in a pybullet client (DIRECT or GUI) as one multibody.

    Joint order of every array is ``robot.joint_names`` (pinocchio model order); full ``q``/``v`` follow
    the pinocchio layout (free-flyer first). Fixed links are folded into their parents by default (faster,
    exact mass properties); :meth:`link_index` still accepts their names and returns their host link.
    """

    def __init__(
        self,
        robot: RobotModel,
        client: int,
        q: np.ndarray | None = None,
        *,
        merge_fixed_links: bool = True,
        self_collision: bool = False,
        lateral_friction: float | None = 1.0,
        sole_spinning_friction: float = 0.01,
        sole_friction_anchor: bool = True,
        sole_contact_stiffness_n_m: float | None = 1e6,
        sole_contact_damping_n_s_m: float | None = 2e4,
    ) -> None:
        """Load ``robot`` into pybullet ``client`` and place it at ``q`` (default: half-sitting at origin).

        ``lateral_friction`` (if not None) is set on every link; pybullet's default is 0.5. The sole links
        get torsional friction ``sole_spinning_friction`` [m] and pybullet's friction anchor: without them a
        position-controlled robot standing on two flat box soles slowly spins in place (stick-slip of
        the 4-point box contacts, about 2 mm of foot slip in 10 s).

        The sole contacts are a spring-damper (``sole_contact_stiffness_n_m`` [N/m],
        ``sole_contact_damping_n_s_m`` [N s/m]; None for both: pybullet's rigid contact), like the rubber
        of a real sole (HRP-2's ankle has rubber bushes): a standing robot sinks about 0.1 mm. pybullet's
        rigid contact has no damping; a position-controlled robot on it rocks on its soles at about 3 Hz,
        undamped, and every weight transfer of a walk excites that rocking: with 0.1 s of double support
        5 of 9 walks tried fell (backward, curved, in place...); with these contacts none did
        (services/model/README.md).
        """
        if (sole_contact_stiffness_n_m is None) != (sole_contact_damping_n_s_m is None):
            raise InvalidRequestError("give both sole contact stiffness and damping, or neither")
        self.robot = robot
        self.client = client
        flags = p.URDF_USE_INERTIA_FROM_FILE
        if self_collision:
            flags |= p.URDF_USE_SELF_COLLISION | p.URDF_USE_SELF_COLLISION_EXCLUDE_ALL_PARENTS
        self.urdf_path, merged = pybullet_urdf_path(robot, flatten=merge_fixed_links)
        self.body_id: int = p.loadURDF(
            str(self.urdf_path), useFixedBase=False, flags=flags, physicsClientId=client
        )
        by_name: dict[str, int] = {}
        link_by_name: dict[str, int] = {p.getBodyInfo(self.body_id, physicsClientId=client)[0].decode(): -1}
        self._movable: list[int] = []
        for j in range(p.getNumJoints(self.body_id, physicsClientId=client)):
            info = p.getJointInfo(self.body_id, j, physicsClientId=client)
            link_by_name[info[12].decode()] = j
            if info[2] != p.JOINT_FIXED:
                by_name[info[1].decode()] = j
                self._movable.append(j)
        missing = [n for n in robot.joint_names if n not in by_name]
        extra = sorted(set(by_name) - set(robot.joint_names))
        if missing or extra:
            raise InvalidRequestError(
                f"{robot.name}: pybullet and pinocchio joints differ: missing {missing}, extra {extra}"
            )
        self.joint_ids: np.ndarray = np.array([by_name[n] for n in robot.joint_names], dtype=int)
        self.pybullet_joint_names: dict[int, str] = {by_name[n]: n for n in robot.joint_names}
        self._idx_q = np.array([robot.joint_index(n).idx_q for n in robot.joint_names], dtype=int)
        self._idx_v = np.array([robot.joint_index(n).idx_v for n in robot.joint_names], dtype=int)
        # pybullet link index -> URDF link name (links kept by the flattening only).
        self.link_names: dict[int, str] = {idx: name for name, idx in link_by_name.items()}
        for child, host in merged.items():
            link_by_name[child] = link_by_name[host]
        self._link_by_name = link_by_name
        dyn = p.getDynamicsInfo(self.body_id, -1, physicsClientId=client)
        # URDF base frame -> pybullet base (inertial) frame.
        self.T_base_inertial = pin.XYZQUATToSE3(np.array([*dyn[3], *dyn[4]], dtype=float))
        self.effort_max = np.array(robot.effort_max)[self._idx_v]
        # Turn off pybullet's default velocity motors so that only our commands act.
        p.setJointMotorControlArray(
            self.body_id,
            self._movable,
            p.VELOCITY_CONTROL,
            forces=[0.0] * len(self._movable),
            physicsClientId=client,
        )
        if lateral_friction is not None:
            for link in [-1, *range(p.getNumJoints(self.body_id, physicsClientId=client))]:
                p.changeDynamics(self.body_id, link, lateralFriction=lateral_friction, physicsClientId=client)
        self.sole_links: dict[str, int] = {
            side: self.link_index(robot.frames.sole(side)) for side in ("left", "right")
        }
        contact: dict[str, float] = {}
        if sole_contact_stiffness_n_m is not None and sole_contact_damping_n_s_m is not None:
            contact = {
                "contactStiffness": sole_contact_stiffness_n_m,
                "contactDamping": sole_contact_damping_n_s_m,
            }
        for link in self.sole_links.values():
            p.changeDynamics(
                self.body_id,
                link,
                spinningFriction=sole_spinning_friction,
                frictionAnchor=int(sole_friction_anchor),
                physicsClientId=client,
                **contact,
            )
        self.reset(robot.q_half_sitting if q is None else q)

    # ------------------------------------------------------------------------------------- names
    def link_index(self, link_name: str) -> int:
        """pybullet link index of a URDF link (-1 for the base); merged fixed links map to their parent."""
        try:
            return self._link_by_name[link_name]
        except KeyError:
            raise InvalidRequestError(
                f"{self.robot.name}: no link {link_name!r} in pybullet; links: {sorted(self._link_by_name)}"
            ) from None

    def link_name(self, link_index: int) -> str:
        """URDF link name of a pybullet link index (-1 is the base link)."""
        try:
            return self.link_names[link_index]
        except KeyError:
            raise InvalidRequestError(f"{self.robot.name}: no pybullet link index {link_index}") from None

    # ------------------------------------------------------------------------------------- state
    def reset(self, q: np.ndarray, v: np.ndarray | None = None) -> None:
        """Teleport to configuration ``q`` (nq, pinocchio layout) with velocity ``v`` (nv, default 0).

        Contacts see the new pose only after the next ``stepSimulation`` (pybullet behaviour).
        """
        q = self.robot.check_q(q)
        v = np.zeros(self.robot.nv) if v is None else np.asarray(v, dtype=float)
        if v.shape != (self.robot.nv,):
            raise InvalidRequestError(
                f"{self.robot.name}: v must have shape ({self.robot.nv},), got {v.shape}"
            )
        quat = q[3:7] / np.linalg.norm(q[3:7])
        T_world_base = pin.XYZQUATToSE3(np.concatenate([q[:3], quat]))
        T_world_inertial = T_world_base * self.T_base_inertial
        xyzquat = pin.SE3ToXYZQUAT(T_world_inertial)
        p.resetBasePositionAndOrientation(
            self.body_id, xyzquat[:3].tolist(), xyzquat[3:].tolist(), physicsClientId=self.client
        )
        # v_base (pinocchio): linear velocity of the base origin and angular velocity, in the base frame.
        R = T_world_base.rotation
        omega_world = R @ v[3:6]
        v_origin_world = R @ v[:3]
        r_world = T_world_inertial.translation - T_world_base.translation
        v_com_world = v_origin_world + np.cross(omega_world, r_world)
        p.resetBaseVelocity(
            self.body_id, v_com_world.tolist(), omega_world.tolist(), physicsClientId=self.client
        )
        for jid, iq, iv in zip(self.joint_ids, self._idx_q, self._idx_v, strict=True):
            p.resetJointState(self.body_id, int(jid), float(q[iq]), float(v[iv]), physicsClientId=self.client)

    def base_pose(self) -> pin.SE3:
        """World pose of the URDF base frame ``T_world_base``."""
        pos, orn = p.getBasePositionAndOrientation(self.body_id, physicsClientId=self.client)
        T_world_inertial = pin.XYZQUATToSE3(np.array([*pos, *orn], dtype=float))
        return T_world_inertial * self.T_base_inertial.inverse()

    def read_q(self) -> np.ndarray:
        """Current configuration (nq, pinocchio layout)."""
        q = np.zeros(self.robot.nq)
        q[:FREE_FLYER_NQ] = pin.SE3ToXYZQUAT(self.base_pose())
        states = p.getJointStates(self.body_id, self.joint_ids.tolist(), physicsClientId=self.client)
        q[self._idx_q] = [s[0] for s in states]
        return q

    def read_v(self) -> np.ndarray:
        """Current velocity (nv, pinocchio layout: base linear/angular velocity in the base frame)."""
        v = np.zeros(self.robot.nv)
        lin, ang = p.getBaseVelocity(self.body_id, physicsClientId=self.client)
        T_world_base = self.base_pose()
        R = T_world_base.rotation
        omega_world = np.array(ang)
        pos, _ = p.getBasePositionAndOrientation(self.body_id, physicsClientId=self.client)
        r_world = np.array(pos) - T_world_base.translation
        v_origin_world = np.array(lin) - np.cross(omega_world, r_world)
        v[:3] = R.T @ v_origin_world
        v[3:FREE_FLYER_NV] = R.T @ omega_world
        states = p.getJointStates(self.body_id, self.joint_ids.tolist(), physicsClientId=self.client)
        v[self._idx_v] = [s[1] for s in states]
        return v

    def joint_positions(self, q: np.ndarray) -> np.ndarray:
        """Actuated joint values of a full ``q``, in ``robot.joint_names`` order."""
        return np.asarray(q, dtype=float)[self._idx_q]

    # ------------------------------------------------------------------------------------- control
    def set_position_targets(
        self,
        q: np.ndarray,
        v: np.ndarray | None = None,
        *,
        position_gain: float = 0.3,
        velocity_gain: float = 1.0,
    ) -> None:
        """Position control of every actuated joint towards the joints of ``q`` (full nq vector, the base
        part is ignored), optional velocity feed-forward ``v`` (nv). Forces are capped at the URDF effort
        limits. Gains are pybullet's (dimensionless) motor gains; 0.3 / 1.0 hold half-sitting within 0.01 deg
        at 1 ms and 0.11 deg at 5 ms steps (pybullet's own default position gain 0.1 sags more at 5 ms)."""
        q = self.robot.check_q(q)
        n = len(self.joint_ids)
        kwargs: dict[str, object] = {
            "positionGains": [position_gain] * n,
            "velocityGains": [velocity_gain] * n,
        }
        if v is not None:
            kwargs["targetVelocities"] = np.asarray(v, dtype=float)[self._idx_v].tolist()
        p.setJointMotorControlArray(
            self.body_id,
            self.joint_ids.tolist(),
            p.POSITION_CONTROL,
            targetPositions=q[self._idx_q].tolist(),
            forces=self.effort_max.tolist(),
            physicsClientId=self.client,
            **kwargs,
        )
