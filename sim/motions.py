"""Reference motions for checking and benchmarking the simulation (not planners): squat-and-rise with
the soles fixed, a lean that throws the robot off balance, and joint-space interpolation.

Trajectories are (N, nq) arrays of pinocchio configurations sampled every ``dt_s`` (5 ms).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from services.errors import InfeasibleError
from services.model import RobotModel
from services.model.ground import smoothstep5 as smoothstep

LEG_SIDES = ("left", "right")


def _leg_velocity_indices(robot: RobotModel, side: str) -> np.ndarray:
    """Velocity indices of the joints between the base and the sole of ``side``."""
    model = robot.model
    joint = model.frames[robot.frame_id(robot.frames.sole(side))].parentJoint
    out = []
    while joint > 1:  # joint 1 is the free flyer
        out.append(model.joints[joint].idx_v)
        joint = model.parents[joint]
    return np.array(sorted(out))


def solve_legs(
    robot: RobotModel,
    q: np.ndarray,
    T_world_soles: dict[str, pin.SE3],
    iterations: int = 30,
    tolerance: float = 1e-9,
) -> np.ndarray:
    """``q`` with its leg joints changed so that each sole reaches ``T_world_soles[side]`` (base fixed)."""
    q = q.copy()
    data = robot.new_data()
    for side, target in T_world_soles.items():
        fid = robot.frame_id(robot.frames.sole(side))
        idx_v = _leg_velocity_indices(robot, side)
        idx_q = idx_v + 1  # 1-DoF joints after the free flyer: idx_q = idx_v + 1
        for _ in range(iterations):
            pin.forwardKinematics(robot.model, data, q)
            pin.updateFramePlacement(robot.model, data, fid)
            err = pin.log6(data.oMf[fid].actInv(target)).vector
            if err @ err < tolerance**2:
                break
            J = pin.computeFrameJacobian(robot.model, data, q, fid, pin.LOCAL)[:, idx_v]
            q[idx_q] += np.linalg.lstsq(J, err, rcond=None)[0]
        else:
            raise InfeasibleError(
                f"leg IK for the {side} sole did not converge (|error| {np.linalg.norm(err):.2e})"
            )
    return q


def squat_trajectory(
    robot: RobotModel,
    q_start: np.ndarray,
    depth_m: float = 0.06,
    down_s: float = 1.5,
    pause_s: float = 0.5,
    up_s: float = 1.5,
    dt_s: float = 0.005,
) -> np.ndarray:
    """Lower the base by ``depth_m`` [m] and rise back, soles fixed where they are in ``q_start``
    (smooth quintic profiles over ``down_s``, ``pause_s``, ``up_s`` [s])."""
    soles = {side: robot.sole_pose(q_start, side) for side in LEG_SIDES}
    t = np.arange(0.0, down_s + pause_s + up_s + 0.5 * dt_s, dt_s)
    offset = depth_m * (smoothstep(t / down_s) - smoothstep((t - down_s - pause_s) / up_s))
    out = np.empty((len(t), robot.nq))
    q = np.array(q_start, dtype=float)
    for k, dz in enumerate(offset):
        q_k = q.copy()
        q_k[2] = q_start[2] - dz
        q = solve_legs(robot, q_k, soles)
        out[k] = q
    return out


def joint_motion(
    robot: RobotModel, q_start: np.ndarray, targets: dict[str, float], duration_s: float, dt_s: float = 0.005
) -> np.ndarray:
    """Move the named joints from ``q_start`` to ``targets`` [rad] along a quintic profile (the base
    part stays at ``q_start``: it is the plan's assumption, not a command)."""
    t = np.arange(0.0, duration_s + 0.5 * dt_s, dt_s)
    s = smoothstep(t / duration_s)
    out = np.repeat(np.asarray(q_start, dtype=float)[None, :], len(t), axis=0)
    for name, value in targets.items():
        iq = robot.joint_index(name).idx_q
        out[:, iq] = q_start[iq] + s * (value - q_start[iq])
    return out


def lean_forward_trajectory(
    robot: RobotModel,
    q_start: np.ndarray,
    ankle_pitch_rad: float = -0.35,
    duration_s: float = 0.4,
    dt_s: float = 0.005,
) -> np.ndarray:
    """Pitch both ankles forward by ``ankle_pitch_rad`` in ``duration_s``: the body tips over the toes
    and the robot falls (a motion that must be reported as ``fell``)."""
    model = robot.model
    # The sole hangs from the ankle roll joint, whose parent is the ankle pitch joint.
    names = [
        model.names[model.parents[model.frames[robot.frame_id(robot.frames.sole(s))].parentJoint]]
        for s in LEG_SIDES
    ]
    targets = {n: float(q_start[robot.joint_index(n).idx_q]) + ankle_pitch_rad for n in names}
    traj = joint_motion(robot, q_start, targets, duration_s, dt_s)
    return np.vstack([traj, np.repeat(traj[-1:], round(1.5 / dt_s), axis=0)])
