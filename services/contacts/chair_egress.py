"""The chair scenario of Escande et al. §3.1 (Fig. 3-4): start contacts, seated posture, the rough
trajectory's key postures and the goal, for the ``chair_egress`` scene (``sim/scenes``).

Run ``python -m services.contacts.chair_egress`` to regenerate the seated posture written in the scene
file (``robot.posture``): a witness posture of the start contacts (thighs on the seat, soles flat on
the floor) made by the posture generator.
"""

from __future__ import annotations

import argparse
import contextlib
import math

import numpy as np
import pinocchio as pin

from services.contacts.environment import Environment
from services.contacts.posture import PostureConfig, PostureGenerator
from services.contacts.search import Goal
from services.contacts.sets import Contact
from services.errors import InfeasibleError
from services.ik import PostureTask
from services.model import RobotModel
from services.model.ground import yaw_of

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
# the same, relative to the seated waist (the shipped scene's at x = -0.11 m) for any layout [m]
FRONT_M, BESIDE_M = 0.41, 0.85
PAST_GOAL_M = 0.25  # T's last key posture past the goal's coordinate (0.85 against 0.6 m) [m]
# the hands of the leaning key posture on a top in front: inside its near edge, apart, within reach [m]
HANDS_IN_M, HANDS_APART_M, HANDS_EDGE_MARGIN_M, HANDS_REACH_M = 0.08, 0.25, 0.05, 0.8
TOP_ABOVE_SEAT_MAX_M = 0.6  # a top higher than this above the seat is not leant on [m]


def seated_guess(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """Hips at a right angle, knees bent further so that the feet are under the knees' back (where a
    person puts them before getting up), ankles flat (an initial guess, not a witness)."""
    q = q.copy()
    # the waist upright, heading as in q (the chair may face any way)
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, yaw_of_q(q))).coeffs()
    for side in ("L", "R"):
        q[robot.joint_index(f"{side}LEG_JOINT2").idx_q] = -1.57
        q[robot.joint_index(f"{side}LEG_JOINT3").idx_q] = 2.0
        q[robot.joint_index(f"{side}LEG_JOINT4").idx_q] = -0.43
    return q


def seated_posture(
    robot: RobotModel, env: Environment, q_init: np.ndarray, seat_x_m: float = 0.18, seat: str = SEAT
) -> np.ndarray:
    """A witness of the seated start: both thighs on the ``seat`` ``seat_x_m`` from its centre (y =
    +-0.06 m), the soles flat on the floor wherever the legs put them, statically stable on the thighs
    (for any chair of any height, turned any way: the contacts are in the seat's frame)."""
    # the CoM well inside the thighs' region: seated in the sim, the robot then does not rock back
    gen = PostureGenerator(robot, env, _spots(robot), PostureConfig(com_margin_m=0.05))
    thighs = (
        Contact("left_thigh", seat, seat_x_m, 0.06, 0.0),
        Contact("right_thigh", seat, seat_x_m, -0.06, 0.0),
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
        extra_touching=(("left_sole", "floor"), ("right_sole", "floor")),
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


def leaning_posture(
    robot: RobotModel,
    env: Environment,
    q_start: np.ndarray,
    start: tuple[Contact, ...] | None = None,
    hands: tuple[Contact, ...] | None = None,
) -> np.ndarray:
    """Key posture 2 (Fig. 4): still seated, leaning forward with both hands on the table. Made with
    the posture generator (``hands``, default :data:`LEANING_HANDS_XY` on ``table.top``, placed; the
    ``start`` contacts, default :data:`START_PAIRS` where their spots are at ``q_start``, kept);
    raises InfeasibleError."""
    gen = PostureGenerator(robot, env, _spots(robot))
    from services.contacts.sets import contact_at

    if start is None:
        start = tuple(contact_at(gen.spots[s], e, env, gen.spot_pose(q_start, s)) for s, e in START_PAIRS)
    if hands is None:
        hands = tuple(
            Contact(f"{side}_hand", "table.top", x, y, 0.0)
            for side, (x, y) in zip(("left", "right"), LEANING_HANDS_XY, strict=True)
        )
    yaw = yaw_of_q(q_start)
    guess = np.asarray(q_start, float).copy()
    guess[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, LEANING_PITCH_RAD, yaw)).coeffs()
    for side in ("L", "R"):
        guess[robot.joint_index(f"{side}ARM_JOINT0").idx_q] = -1.2
        guess[robot.joint_index(f"{side}ARM_JOINT3").idx_q] = -0.3
    result = gen.generate((*start, *hands), start, guess, PostureTask(gen.model, guess, gain=0.5))
    if not result.ok:
        raise InfeasibleError(f"no leaning posture with the hands on the table: {result.reason}")
    return result.q


def yaw_of_q(q: np.ndarray) -> float:
    """The waist's heading [rad] (world frame) of configuration ``q``."""
    return yaw_of(pin.Quaternion(np.asarray(q[3:7], float)).normalized().toRotationMatrix())


def _ahead(q: np.ndarray, forward_m: float, left_m: float) -> tuple[float, float]:
    """The world (x, y) [m] ``forward_m`` ahead of and ``left_m`` left of the waist of ``q``."""
    yaw = yaw_of_q(q)
    c, s = math.cos(yaw), math.sin(yaw)
    return (float(q[0]) + c * forward_m - s * left_m, float(q[1]) + s * forward_m + c * left_m)


def hands_on_a_top(env: Environment, q_start: np.ndarray, seat: str) -> tuple[Contact, ...] | None:
    """The hands of the leaning key posture for any layout (§3.1, Fig. 4): on the flat top (a table's
    or a box's, not the floor nor the ``seat``) that faces the seated robot within reach, both
    :data:`HANDS_IN_M` inside its edge nearest the robot and :data:`HANDS_APART_M` to each side of the
    robot's line, turned with the robot; None when no top is in reach (T then has no leaning posture).
    For the shipped scene: (-0.22, +-0.25) on ``table.top``, :data:`LEANING_HANDS_XY`."""
    seat_z = float(env.surface(seat).T_world_surface.translation[2])
    waist = np.array([float(q_start[0]), float(q_start[1])])
    best: tuple[float, tuple[Contact, ...]] | None = None
    for surface in env.surfaces:
        if surface.name in ("floor", seat):
            continue
        top_z = float(surface.T_world_surface.translation[2])
        if not seat_z < top_z <= seat_z + TOP_ABOVE_SEAT_MAX_M:
            continue
        local = surface.T_world_surface.actInv(
            pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw_of_q(q_start)), np.array([*waist, top_z]))
        )
        rx, ry = float(local.translation[0]), float(local.translation[1])
        heading = yaw_of(local.rotation)
        hx, hy = surface.half_size_m
        # the edge facing the robot: the one the robot's line of sight crosses (heading along +-x or +-y)
        axis = 0 if abs(math.cos(heading)) >= abs(math.sin(heading)) else 1
        sign = -1.0 if (math.cos(heading) if axis == 0 else math.sin(heading)) > 0 else 1.0
        half_along, half_across = (hx, hy) if axis == 0 else (hy, hx)
        inner = round(sign * (half_along - HANDS_IN_M), 6)
        margin = half_across - HANDS_EDGE_MARGIN_M
        # the robot's left along the edge: +y of the surface when it faces +x, -x when it faces +y, ...
        left = math.copysign(1.0, math.cos(heading)) if axis == 0 else -math.copysign(1.0, math.sin(heading))
        across = ry if axis == 0 else rx
        points = []
        for offset in (HANDS_APART_M, -HANDS_APART_M):  # the left hand, the right hand
            lateral = round(float(np.clip(across + left * offset, -margin, margin)), 6)
            points.append((inner, lateral) if axis == 0 else (lateral, inner))
        world = [surface.placement(x, y, 0.0).translation[:2] for x, y in points]
        reach = max(float(np.linalg.norm(w - waist)) for w in world)
        ahead = [float(np.dot(w - waist, _ahead(q_start, 1.0, 0.0) - waist)) for w in world]
        if reach > HANDS_REACH_M or min(ahead) <= 0.0 or margin <= 0.0:
            continue
        theta = round(heading, 6)
        hands = tuple(
            Contact(f"{side}_hand", surface.name, x, y, theta)
            for side, (x, y) in zip(("left", "right"), points, strict=True)
        )
        if best is None or reach < best[0]:
            best = (reach, hands)
    return None if best is None else best[1]


def key_postures(
    robot: RobotModel,
    env: Environment,
    q_start: np.ndarray,
    start: tuple[Contact, ...] | None = None,
    goal: Goal | None = None,
) -> list[np.ndarray]:
    """T's key postures (§2.7, Fig. 4) for a robot seated on any chair of any layout: the start;
    leaning forward with the hands on the top in front of it (:func:`hands_on_a_top`; left out when no
    top is in reach or no such posture exists); standing :data:`FRONT_M` in front of the seat (in the
    seated robot's frame); standing past the ``goal`` (its coordinate exceeded by :data:`PAST_GOAL_M`
    along its axis from the front stance; without a goal, or for one the front stance already meets,
    :data:`BESIDE_M` to the robot's left: the shipped scene's :data:`STAND_XY`). The seat is
    the surface of ``start``'s thighs (default :data:`START_PAIRS`)."""
    seat = next((c.surface for c in start or () if c.spot.endswith("_thigh")), SEAT)
    yaw = yaw_of_q(q_start)
    front = _ahead(q_start, FRONT_M, 0.0)
    beside = _ahead(q_start, FRONT_M, BESIDE_M)
    if goal is not None and past_goal(front, goal) != front:
        beside = past_goal(front, goal)  # else (a height goal, or one met in front): beside, to the left
    keys = [np.asarray(q_start, float)]
    hands = hands_on_a_top(env, q_start, seat)
    if hands is not None:
        # none found: T without the lean, still a rough trajectory of the egress (§2.7: given by hand)
        with contextlib.suppress(InfeasibleError):
            keys.append(leaning_posture(robot, env, q_start, start, hands))
    return keys + [robot.half_sitting_at(x, y, yaw) for x, y in (front, beside)]


def past_goal(xy: tuple[float, float], goal: Goal) -> tuple[float, float]:
    """``xy`` [m] moved along the goal's axis until :data:`PAST_GOAL_M` past its value (T goes on past
    the goal: its slope still pulls there); unchanged for a height goal or when already past it."""
    if goal.axis == "z":
        return xy
    i = "xy".index(goal.axis)
    out = list(xy)
    target = goal.value_m + goal.sense * PAST_GOAL_M
    if goal.sense * (out[i] - target) < 0.0:
        out[i] = target
    return (out[0], out[1])


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
