"""A walking stabilizer in the sim's execution: leg corrections from the measured body inclination,
as the real HRP-2's controller has (no bus, no planner; the planned motion is unchanged).

The sim plays the planners' joint trajectories through position control. Open loop, nothing damps the
robot's rocking on its compliant sole contacts: a weight transfer that comes in a jolt (a landing foot
10-90 ms early or late) feeds a roll from foot to foot that grows over steps (session 10: fetch seeds
16 and 43 fell at 0.1 s of double support, ``services/walking/README.md``). On the real robot the
stabilizer closes that loop (Kajita et al. 2010, "Biped walking stabilization based on linear
inverted pendulum tracking": body inclination control, and the feet's force difference control that
turns the body in double support by lengthening one leg and shortening the other). Here, every
control period (5 ms):

* the body inclination error ``e`` [rad]: the measured base orientation against the planned one (the
  trajectory's base part), a rotation vector (world), and its rate (the measured base angular velocity
  less the planned one) [rad/s];
* the correction ``c = gain * e + damping_s * e_rate`` (roll and pitch only, at most ``max_rad``);
* both feet are turned by ``c`` against the body, about the support's centre (the soles' centres
  weighted by their vertical floor forces: the stance sole in single support, between the soles in
  double support): with the soles on the ground the body turns back by ``c``; a foot in the air goes
  where the plan has it in the world although the body leans (it lands flat and on time). In double
  support this lengthens one leg and shortens the other (Kajita's force difference control by the
  inclination instead of the forces). The feet's twists become the legs' joint offsets by the inverse
  of each sole's Jacobian (world axes), recomputed every ``JACOBIAN_PERIODS``.

Measured on walks with 0.1 s of double support in the empty world (``sim/README.md``): the largest
base roll 0.3-0.5 deg without, 0.04-0.07 deg with it. The offsets persist between executions (a walk
is played in chunks) and are added to the commanded leg joints; the joint limits still apply in
pybullet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.model import RobotModel

SIDES = ("left", "right")


@dataclass(frozen=True)
class StabilizerGains:
    """The stabilizer's gains (:class:`sim.config.SimConfig` carries them).

    Attributes:
        gain: correction per radian of body inclination error [rad/rad].
        damping_s: correction per rad/s of inclination rate error [s] (0.1 s made walks oscillate and
            fall, 0.03 s left a 120 N push ringing for 0.5 s: the correction acts one period late).
        max_rad: largest correction [rad].
        loaded_n: the soles carry the robot when their vertical forces add up to this [N] (both soles
            together: ``SimConfig.stabilizer_loaded_n``).
    """

    gain: float = 1.0
    damping_s: float = 0.02
    max_rad: float = 0.05
    loaded_n: float = 30.0


JACOBIAN_PERIODS = 10  # the legs' Jacobians are recomputed every this many control periods (50 ms)
#: Control periods (5 ms) without a contact pushing on the robot (other than the soles' and the hands'
#: on what they hold) before the stabilizer corrects again: a resting contact's force flickers.
CONTACT_RELEASE_PERIODS = 20


class Stabilizer:
    """Leg corrections of one robot from its measured inclination (module docstring)."""

    def __init__(self, robot: RobotModel, body_joint_names: list[str], gains: StabilizerGains) -> None:
        """``body_joint_names``: the commanded joints, in the order of the offsets returned."""
        self.robot = robot
        self.gains = gains
        self.offsets = np.zeros(len(body_joint_names))  # [rad] added to the commands (persists)
        model = robot.model
        self._sole_fids = {side: robot.frame_id(robot.frames.sole(side)) for side in SIDES}
        self._legs: dict[str, tuple[list[int], list[int]]] = {}  # side -> (offset columns, idx_v)
        for side in SIDES:
            joints = []
            j = model.frames[self._sole_fids[side]].parentJoint
            while j > 0 and model.joints[j].nv == 1:  # the leg's joints, up to the free flyer
                joints.append(j)
                j = model.parents[j]
            self._legs[side] = (
                [body_joint_names.index(model.names[j]) for j in joints],
                [model.joints[j].idx_v for j in joints],
            )
        self._inverse: dict[str, np.ndarray] = {}
        self._periods = 0
        self._free = CONTACT_RELEASE_PERIODS  # control periods since a contact last pushed on the robot

    def free_of_contacts(self, pushed: bool) -> bool:
        """Whether to correct this period, given whether a contact other than the soles' (and the hands'
        on what they hold) pushes on the robot now: not while one does nor for
        ``CONTACT_RELEASE_PERIODS`` after (a tilt a hand on a box or a shank on a table holds is not
        the feet's to correct: session 11's seed 6 was left on a sole tilted 0.025 rad); the
        correction is held meanwhile."""
        self._free = 0 if pushed else self._free + 1
        return self._free >= CONTACT_RELEASE_PERIODS

    def reset(self) -> None:
        """No correction (the robot holds where it is after a fall or a collision)."""
        self.offsets[:] = 0.0

    def update(
        self,
        data: pin.Data,
        q_measured: np.ndarray,
        omega_measured: tuple[float, float, float],
        q_planned_prev: np.ndarray,
        q_planned: np.ndarray,
        dt_s: float,
        sole_forces: dict[str, float],
    ) -> np.ndarray:
        """The offsets [rad] of the commanded joints for the next control period (:attr:`offsets`).

        ``data``: the model's data, its joint placements at ``q_measured`` (``forwardKinematics``
        done, as :class:`sim.world._Monitor` does every period);
        ``omega_measured``: the base's angular velocity (world) [rad/s]; ``q_planned_prev`` /
        ``q_planned``: the last two planned samples, ``dt_s`` apart [s]; ``sole_forces``: each sole's
        vertical floor force [N]."""
        g = self.gains
        out = self.offsets
        total = sole_forces["left"] + sole_forces["right"]
        if total < g.loaded_n:  # nothing to turn the body about
            out[:] = 0.0
            return out
        ex, ey, _ = _rotation_between(q_measured, q_planned)  # world, measured from planned [rad]
        wx, wy, _ = _rotation_between(q_planned, q_planned_prev)  # planned over dt_s
        cx = g.gain * ex + g.damping_s * (omega_measured[0] - wx / dt_s)
        cy = g.gain * ey + g.damping_s * (omega_measured[1] - wy / dt_s)
        norm = math.hypot(cx, cy)
        if norm > g.max_rad:
            cx, cy = cx * g.max_rad / norm, cy * g.max_rad / norm
        model = self.robot.model
        if self._periods % JACOBIAN_PERIODS == 0 or not self._inverse:
            pin.computeJointJacobians(model, data, q_measured)
            for side in SIDES:
                J = pin.getFrameJacobian(model, data, self._sole_fids[side], pin.LOCAL_WORLD_ALIGNED)
                self._inverse[side] = np.linalg.pinv(J[:, self._legs[side][1]])  # 6 x n_leg
        self._periods += 1
        centres = {
            side: pin.updateFramePlacement(model, data, self._sole_fids[side]).translation.tolist()
            for side in SIDES
        }
        wl = sole_forces["left"] / total
        pivot = [wl * a + (1.0 - wl) * b for a, b in zip(centres["left"], centres["right"], strict=True)]
        for side in SIDES:
            rx, ry, rz = (a - b for a, b in zip(centres[side], pivot, strict=True))
            # the sole's twist against the body: turned by c = (cx, cy, 0) about the pivot
            twist = (cy * rz, -cx * rz, cx * ry - cy * rx, cx, cy, 0.0)
            out[self._legs[side][0]] = self._inverse[side] @ twist
        return out


def roll_pitch(q: np.ndarray) -> tuple[float, float]:
    """The base's roll and pitch [rad] (Z-Y-X Euler angles) of a configuration ``q`` (pinocchio
    layout, quaternion xyzw)."""
    x, y, z, w = q[3:7].tolist()
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    return roll, pitch


def _rotation_between(qa: np.ndarray, qb: np.ndarray) -> tuple[float, float, float]:
    """The rotation vector (world) [rad] from base orientation b to a (``R_a R_b^T``) of two
    configurations (pinocchio layout, quaternion xyzw), to second order in the angle (they differ by a
    few degrees at most)."""
    ax, ay, az, aw = qa[3:7].tolist()
    bx, by, bz, bw = qb[3:7].tolist()
    # a * conj(b): vector part aw (-bv) + bw av + av x (-bv); scalar aw bw + av . bv
    w = aw * bw + ax * bx + ay * by + az * bz
    x = -aw * bx + bw * ax - (ay * bz - az * by)
    y = -aw * by + bw * ay - (az * bx - ax * bz)
    z = -aw * bz + bw * az - (ax * by - ay * bx)
    k = 2.0 if w >= 0.0 else -2.0
    return k * x, k * y, k * z
