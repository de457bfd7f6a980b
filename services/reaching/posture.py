"""The hand's references toward a requested final posture (a footstep plan's, paper 000 §7).

A footstep plan ends in a whole-body posture with the hand at its target (``footsteps/plan``'s
``q_final``); reaching executes it from the stance the robot walked to. A straight hand line with a
posture task below it does not get there when the two postures are far apart: the hand task, above,
drives the arm along another branch (an arm joint at its limit, the multibody ZMP out of the polygon).
So the hand's references follow the posture's own path instead: the joints interpolated from the start
to the final posture along the profile s, the hand where that blended posture puts it relative to its
feet, carried to the feet the robot stands on, and corrected along s by what separates the planned
hand from the requested target (the object seen again after the walk). The posture task of the tracker
(the same blend) and the hand task then agree all the way.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin


def blended_postures(q_start: np.ndarray, q_posture: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(n, nq) configurations whose joints go from ``q_start``'s to ``q_posture``'s along ``s`` (n,)
    (the free flyer's 7 coordinates stay ``q_start``'s: the feet tasks place the body)."""
    out = np.repeat(np.asarray(q_start, dtype=float)[None, :], s.shape[0], axis=0)
    out[:, 7:] += s[:, None] * (np.asarray(q_posture, dtype=float)[7:] - out[0, 7:])[None, :]
    return out


def posture_references(
    robot: Any,
    hand: str,
    postures: np.ndarray,
    s: np.ndarray,
    q_start: np.ndarray,
    target_m: np.ndarray,
    R_target: np.ndarray | None,
    clear_m: float = 0.03,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """The hand's and the CoM's references along ``postures`` (n, nq): where each puts the grasp frame
    of ``hand`` and the CoM relative to its left sole, carried to the left sole of ``q_start`` (world:
    the robot stands on it); the hand plus ``s`` times what separates the last one's hand from
    ``target_m`` (and ``R_target`` when given: position only otherwise). Returns the hand's positions
    (n, 3) [m], its orientations (n, 3, 3) or None, and the CoM (n, 2) [m] (horizontal)."""
    data = robot.new_data()
    frame, sole = robot.frames.grasp(hand), robot.frames.sole("left")
    T_sole_world = robot.frame_pose(q_start, sole, data)
    n = postures.shape[0]
    points = np.empty((n, 3))
    rotations = np.empty((n, 3, 3))
    com = np.empty((n, 2))
    for k in range(n):
        T_hand = robot.frame_pose(postures[k], frame, data)
        to_world = T_sole_world * robot.frame_pose(postures[k], sole, data).inverse()
        T = to_world * T_hand
        points[k], rotations[k] = T.translation, T.rotation
        com[k] = to_world.act(robot.com(postures[k], data))[:2]
    points += s[:, None] * (np.asarray(target_m, dtype=float) - points[-1])[None, :]
    # Not lower than the straight line from the hand to the target on the way (the target is above the
    # object: the blend's hand dipped 5 cm below it and the wrist touched the ball, fetch seed 6): the
    # path raised by an arc over the whole motion, its height the largest dip plus ``clear_m``.
    line = points[0, 2] + s * (points[-1, 2] - points[0, 2])
    dip = float(np.max(line - points[:, 2]))
    if dip > 0.0:
        points[:, 2] += (dip + clear_m) * np.sin(np.pi * s)
    if R_target is None:
        return points, None, com
    log_end = pin.log3(rotations[-1].T @ np.asarray(R_target, dtype=float))
    for k in range(n):
        rotations[k] = rotations[k] @ pin.exp3(s[k] * log_end)
    return points, rotations, com
