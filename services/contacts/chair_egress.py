"""The chair scenario of Escande et al. §3.1 (Fig. 3-4): start contacts, seated posture, the rough
trajectory's key postures and the goal, for the ``chair_egress`` scene (``sim/scenes``).

Run ``python -m services.contacts.chair_egress`` to regenerate the seated posture written in the scene
file (``robot.posture``): a witness posture of the start contacts (thighs on the seat, soles flat on
the floor) made by the posture generator.
"""

from __future__ import annotations

import argparse

import numpy as np
import pinocchio as pin

from services.contacts.environment import Environment
from services.contacts.posture import PostureConfig, PostureGenerator
from services.contacts.sets import Contact
from services.errors import InfeasibleError
from services.ik import PostureTask
from services.model import RobotModel

SEAT = "chair.seat"
START_PAIRS = (("left_sole", "floor"), ("right_sole", "floor"), ("left_thigh", SEAT), ("right_thigh", SEAT))
FINAL_PAIRS = (("left_sole", "floor"), ("right_sole", "floor"))
GOAL_AXIS, GOAL_VALUE_M = "y", 0.6  # the waist must exceed y = 0.6 m (beside the table, §3.1)
SPOTS = (
    "left_sole",
    "right_sole",
    "left_thigh",
    "right_thigh",
    "left_hand",
    "right_hand",
    "left_forearm",
    "right_forearm",
)
SURFACES = ("floor", SEAT, "table.top")
# which surfaces each kind of spot may use (the paper's remark in §5: trying the feet on the chair
# wastes nodes): feet on the floor, thighs on the seat, hands and forearms on the table or the seat
PAIRS = tuple(
    [(f"{s}_sole", "floor") for s in ("left", "right")]
    + [(f"{s}_thigh", SEAT) for s in ("left", "right")]
    + [(f"{s}_hand", e) for s in ("left", "right") for e in ("table.top", SEAT)]
    + [(f"{s}_forearm", "table.top") for s in ("left", "right")]
)
# the hands of the second key posture, on the table's top (x, y [m] in its frame)
LEANING_HANDS_XY = ((-0.22, 0.25), (-0.22, -0.25))
LEANING_PITCH_RAD = 0.35
# key postures of T (Fig. 4): seated, standing in front of the chair, standing beside the table
STAND_XY = ((0.30, 0.0), (0.30, 0.85))  # T goes on past the goal: its slope still pulls there


def seated_guess(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """Hips at a right angle, knees bent further so that the feet are under the knees' back (where a
    person puts them before getting up), ankles flat (an initial guess, not a witness)."""
    q = q.copy()
    q[3:7] = (0.0, 0.0, 0.0, 1.0)  # the waist upright
    for side in ("L", "R"):
        q[robot.joint_index(f"{side}LEG_JOINT2").idx_q] = -1.57
        q[robot.joint_index(f"{side}LEG_JOINT3").idx_q] = 2.0
        q[robot.joint_index(f"{side}LEG_JOINT4").idx_q] = -0.43
    return q


def seated_posture(
    robot: RobotModel, env: Environment, q_init: np.ndarray, seat_x_m: float = 0.18
) -> np.ndarray:
    """A witness of the seated start: both thighs on the seat ``seat_x_m`` from its centre (y = +-0.06
    m), the soles flat on the floor wherever the legs put them, statically stable on the thighs."""
    # the CoM well inside the thighs' region: seated in the sim, the robot then does not rock back
    gen = PostureGenerator(robot, env, _spots(robot), PostureConfig(com_margin_m=0.05))
    thighs = (
        Contact("left_thigh", SEAT, seat_x_m, 0.06, 0.0),
        Contact("right_thigh", SEAT, seat_x_m, -0.06, 0.0),
    )
    from services.contacts.contact_tasks import OnPlaneTask

    floor = env.surface("floor")
    soles = [OnPlaneTask(gen.model, gen.spots[s].frame_name, floor) for s in ("left_sole", "right_sole")]
    guess = seated_guess(robot, q_init)
    result = gen.generate(
        thighs,
        thighs,
        guess,
        PostureTask(gen.model, guess, gain=0.5),
        extra=soles,
        extra_touching=(START_PAIRS[0], START_PAIRS[1]),
    )
    if not result.ok:
        raise InfeasibleError(f"no seated posture: {result.reason}")
    return result.q


def _spots(robot: RobotModel):
    from services.contacts.spots import robot_spots

    return robot_spots(robot)


def standing(robot: RobotModel, x: float, y: float) -> np.ndarray:
    """Half-sitting with the soles' midpoint at (x, y), facing +x."""
    return robot.half_sitting_at(x, y, 0.0)


def leaning_posture(robot: RobotModel, env: Environment, q_start: np.ndarray) -> np.ndarray:
    """Key posture 2 (Fig. 4): still seated, leaning forward with both hands on the table. Made with
    the posture generator (hands placed on the table, start contacts kept); raises InfeasibleError."""
    gen = PostureGenerator(robot, env, _spots(robot))
    from services.contacts.sets import contact_at

    start = tuple(contact_at(gen.spots[s], e, env, gen.spot_pose(q_start, s)) for s, e in START_PAIRS)
    hands = tuple(
        Contact(f"{side}_hand", "table.top", x, y, 0.0)
        for side, (x, y) in zip(("left", "right"), LEANING_HANDS_XY, strict=True)
    )
    guess = np.asarray(q_start, float).copy()
    guess[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, LEANING_PITCH_RAD, 0.0)).coeffs()
    for side in ("L", "R"):
        guess[robot.joint_index(f"{side}ARM_JOINT0").idx_q] = -1.2
        guess[robot.joint_index(f"{side}ARM_JOINT3").idx_q] = -0.3
    result = gen.generate((*start, *hands), start, guess, PostureTask(gen.model, guess, gain=0.5))
    if not result.ok:
        raise InfeasibleError(f"no leaning posture with the hands on the table: {result.reason}")
    return result.q


def key_postures(robot: RobotModel, env: Environment, q_start: np.ndarray) -> list[np.ndarray]:
    """T's key postures (Fig. 4): the start, leaning forward with the hands on the table, standing in
    front of the chair, standing beside the table."""
    lean = leaning_posture(robot, env, q_start)
    return [np.asarray(q_start, float), lean] + [standing(robot, x, y) for x, y in STAND_XY]


def main(argv: list[str] | None = None) -> int:
    """Print the seated posture as the scene file's ``robot.posture`` entry."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="chair_egress")
    args = parser.parse_args(argv)
    from services.contacts.environment import environment_of
    from services.model import load_robot
    from sim.scene import layout, load_scene
    from sim.world import start_configuration

    robot = load_robot("hrp2_like")
    lay = layout(load_scene(args.scene))
    q = seated_posture(robot, environment_of(lay), start_configuration(robot, lay))
    rpy = pin.rpy.matrixToRpy(pin.Quaternion(q[3:7]).toRotationMatrix())
    joints = ", ".join(f"{n}: {q[robot.joint_index(n).idx_q]:.5f}" for n in robot.joint_names)
    print(
        f"  x: {q[0]:.5f}\n  y: {q[1]:.5f}\n  yaw: {rpy[2]:.5f}\n"
        f"  posture: {{base_z: {q[2]:.5f}, pitch: {rpy[1]:.5f}, joints: {{{joints}}}}}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
