"""Force-aware execution of a limb in contact: damping control of its contact force (as HRP-2's
controller does for its feet and hands), no bus, no planner.

A multi-contact motion played by position control closes a rigid loop (floor - leg - body - arm -
table): the contact forces are set by millimetre errors of the loop, not by the plan. Measured on the
chair egress: 300-500 N on a hand where the plan needed 103-150 N (the arm saturated and gave way), and
30-50 N where it needed 173 N (the robot tipped over its stance sole's edge). Here the commanded
position of each limb named in a :class:`ForceTarget` is corrected, every control period, along its
surface's normal by an offset ``d`` [m] (positive: away from the surface)::

    d_dot = (f_measured - f_planned) / DAMPING_N_S_M - d / RECOVERY_S,   |d| <= MAX_OFFSET_M

(Kajita et al.'s damping control: a limb that carries more than planned yields, one that carries less
presses; without a force error the offset returns to the plan). The offset becomes joint offsets of
the limb's joints by the damped least-squares inverse of the translation Jacobian (world axes) of its
contact point at the measured configuration. ``f_measured`` is the sum of the normal forces of pybullet's
contact points between the limb's links (the tip joint's link and every link under it: the gripper's)
and the scene object; ``f_planned`` comes with the trajectory (one value per sample).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin
import pybullet as p

from services.errors import InvalidRequestError
from services.model import RobotModel
from sim.force_target import ForceTarget

DAMPING_N_S_M = 4000.0  # D [N s/m]: a force error of 100 N moves the contact 2.5 cm/s
RECOVERY_S = 2.0  # T [s]: with no force error the offset decays to the plan with this time constant
MAX_OFFSET_M = 0.03  # |d| at most this [m]
JACOBIAN_DAMPING = 1e-4  # [m^2]: the damped least-squares inverse of the tip's translation Jacobian
_BODY_B, _LINK_A, _NORMAL_FORCE = 2, 3, 9  # indices in pybullet.getContactPoints tuples


class Admittance:
    """The damping control of a trajectory's force targets in one pybullet world (module docstring)."""

    def __init__(
        self,
        robot: RobotModel,
        client: int,
        robot_id: int,
        bodies: dict[str, int],
        joint_ids: dict[str, int],
        body_joint_names: Sequence[str],
        targets: Sequence[ForceTarget],
        n_samples: int,
        dt_s: float,
    ) -> None:
        """``bodies``: scene object name -> pybullet body id; ``joint_ids``: joint name -> pybullet
        joint index; ``body_joint_names``: the commanded joints in the order of the commands. Raises
        InvalidRequestError on an unknown joint or object, a normal that is not a unit vector, or a
        force profile that is not one finite value per sample."""
        self.robot, self.client, self.robot_id, self.dt_s = robot, client, robot_id, dt_s
        self._data = robot.model.createData()
        self._n_body = len(body_joint_names)
        self._limbs = []
        for t in targets:
            unknown = [j for j in t.joints if j not in joint_ids or j not in body_joint_names]
            if not t.joints or unknown:
                raise InvalidRequestError(
                    f"force target: unknown or uncommanded joints {unknown or '(none given)'}",
                    {"field": "force_targets"},
                )
            if t.other not in bodies:
                raise InvalidRequestError(
                    f"force target: no object {t.other!r} in the scene; objects: {sorted(bodies)}",
                    {"field": "force_targets"},
                )
            normal = np.asarray(t.normal, float)
            if normal.shape != (3,) or not abs(np.linalg.norm(normal) - 1.0) < 1e-3:
                raise InvalidRequestError(
                    f"force target: normal must be a unit 3-vector, got {t.normal}",
                    {"field": "force_targets"},
                )
            force = np.asarray(t.force_n, float)
            if force.shape != (n_samples,) or not np.all(np.isfinite(force)):
                raise InvalidRequestError(
                    f"force target: force_n must have one finite value per sample ({n_samples}), got "
                    f"shape {force.shape}",
                    {"field": "force_targets"},
                )
            tip = joint_ids[t.joints[0]]
            self._limbs.append(
                {
                    "links": self._links_under(tip),
                    "body": bodies[t.other],
                    "normal": normal,
                    "force": force,
                    "cols": [body_joint_names.index(j) for j in t.joints],
                    "iv": [robot.model.joints[robot.model.getJointId(j)].idx_v for j in t.joints],
                    "tip": robot.model.getJointId(t.joints[0]),
                    "point": np.asarray(t.point_m, float),
                    "offset": 0.0,
                    "measured": 0.0,
                }
            )

    def _links_under(self, tip: int) -> frozenset[int]:
        """The pybullet link of joint ``tip`` and every link under it."""
        parent = {
            j: p.getJointInfo(self.robot_id, j, physicsClientId=self.client)[16]
            for j in range(p.getNumJoints(self.robot_id, physicsClientId=self.client))
        }
        out = set()
        for link in parent:
            k = link
            while k >= 0 and k != tip:
                k = parent[k]
            if k == tip:
                out.add(link)
        return frozenset(out)

    def measured_force(self, limb: dict) -> float:
        """Normal force [N] of the limb's object on its links now."""
        total = 0.0
        for c in p.getContactPoints(bodyA=self.robot_id, bodyB=limb["body"], physicsClientId=self.client):
            if c[_LINK_A] in limb["links"]:
                total += c[_NORMAL_FORCE]
        return total

    def update(self, sample: int, q_measured: np.ndarray) -> np.ndarray:
        """Advance the offsets by one control period at trajectory ``sample`` from the forces now;
        returns the offsets of the commanded joints (order of ``body_joint_names``) [rad]."""
        out = np.zeros(self._n_body)
        if not self._limbs:
            return out
        model, data = self.robot.model, self._data
        pin.computeJointJacobians(model, data, q_measured)
        for limb in self._limbs:
            f = self.measured_force(limb)
            limb["measured"] = f
            error = f - float(limb["force"][min(sample, len(limb["force"]) - 1)])
            d = limb["offset"] + self.dt_s * (error / DAMPING_N_S_M - limb["offset"] / RECOVERY_S)
            limb["offset"] = float(np.clip(d, -MAX_OFFSET_M, MAX_OFFSET_M))
            J6 = pin.getJointJacobian(model, data, limb["tip"], pin.LOCAL_WORLD_ALIGNED)[:, limb["iv"]]
            r = data.oMi[limb["tip"]].rotation @ limb["point"]  # joint origin -> contact point (world)
            J = J6[:3] - pin.skew(r) @ J6[3:]
            dx = limb["offset"] * limb["normal"]
            out[limb["cols"]] += J.T @ np.linalg.solve(J @ J.T + JACOBIAN_DAMPING * np.eye(3), dx)
        return out
