"""Layouts and payloads ``contacts/plan`` was never tested on, and an independent check of its answers.

The family (``cases()``): the chair scene of Escande et al. §3.1 moved and turned as a whole (the robot
seated in it), other seat and table heights (the seated posture made again for the new seat), the
table far out of reach, beside the chair or absent, a box in the way to the goal, a goal out of reach
or inside the table, a final contact no pair allows, and odd but valid payloads (a budget of 50 ms or
of 600 s with few nodes, ``max_nodes`` 1, ``pairs`` empty). Each case says what kind of answer is
right: ``plan`` (a plan whose contacts and postures check out), ``refused`` (a typed ``infeasible``
or ``timeout``, ``details["reason"]`` one of the schema's reasons, with ``residual_m``), ``invalid``
(``invalid_request``: a start that is not feasible, a spoiled ``q_start``, a surface the layout lacks)
or ``either``.

``verify_plan`` checks a reply without the planner's code: each contact's spot (pinocchio forward
kinematics) on the surface named (the scene's top as ``sim.parts`` builds it), each witness clear of
every object but the ones it touches (pybullet's shapes, as the sim simulates them), statically
balanced (a linear program over friction-cone forces at the patches' corners, scipy's ``linprog``:
not the planner's Bretl-Lall projection), and the motion through the witnesses within the joint limits.

Used by ``scripts/bench contacts --scenes`` and ``tests/test_contacts_unseen.py``.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

SCENES = Path(__file__).resolve().parents[2] / "sim" / "scenes"
SEAT, TOP = "chair.seat", "table.top"
SEATED = [["left_sole", "floor"], ["right_sole", "floor"], ["left_thigh", SEAT], ["right_thigh", SEAT]]
STANDING = [["left_sole", "floor"], ["right_sole", "floor"]]
# the chair scenario's pairs (services/contacts/chair_egress.PAIRS): feet on the floor, thighs on the seat,
# hands on the table and the seat, forearms on the table
PAIRS = [
    *[[f"{s}_sole", "floor"] for s in ("left", "right")],
    *[[f"{s}_thigh", SEAT] for s in ("left", "right")],
    *[[f"{s}_hand", e] for s in ("left", "right") for e in (TOP, SEAT)],
    *[[f"{s}_forearm", TOP] for s in ("left", "right")],
]
REASONS = ("no_path_within_budget", "tree_exhausted", "goal_out_of_reach", "final_contact_not_allowed")
CONTACT_TOLERANCE_M = 0.01  # a spot this close to its surface's plane touches it [m]
TILT_TOLERANCE_RAD = 0.1
PENETRATION_M = 0.01  # deeper into an object it does not touch is a collision (pybullet's shapes) [m]
FRICTION_EDGES = 4


@dataclass(frozen=True)
class Case:
    """A scene (a document written as ``<scene>.yaml``, or a shipped scene's name) and a request's
    fields beside ``scene`` and ``q_start`` (the scene's start configuration), with the answer's kind:
    ``plan``, ``refused`` or ``either``; ``execute``: a plan found is played in the sim."""

    name: str
    scene: str
    request: dict[str, Any]
    expect: str
    doc: dict[str, Any] | None = None
    execute: bool = False
    note: str = ""
    q_edit: str = ""  # "quat_zero" / "joint_past_limit": q_start spoiled (see start_q)


def start_q(case: Case, q0: np.ndarray) -> np.ndarray:
    """The case's ``q_start``: the scene's start ``q0``, spoiled as ``case.q_edit`` says."""
    q = np.array(q0, float)
    if case.q_edit == "quat_zero":
        q[3:7] = 0.0
    elif case.q_edit == "joint_past_limit":
        q[7] = 9.0
    return q


def base_doc() -> dict[str, Any]:
    """The shipped chair scene (the robot seated at the table) as a document."""
    return yaml.safe_load((SCENES / "chair_egress.yaml").read_text())


def turned(doc: dict[str, Any], yaw: float, dx: float, dy: float, name: str) -> dict[str, Any]:
    """``doc`` turned by ``yaw`` [rad] about the world origin then moved by (dx, dy) [m], as a whole:
    the robot (seated) with its chair and table."""
    out = copy.deepcopy(doc)
    c, s = math.cos(yaw), math.sin(yaw)

    def move(x: float, y: float) -> list[float]:
        return [round(c * x - s * y + dx, 6), round(s * x + c * y + dy, 6)]

    robot = out["robot"]
    robot["x"], robot["y"] = move(robot["x"], robot["y"])
    robot["yaw"] = round(robot.get("yaw", 0.0) + yaw, 6)
    for obj in out["objects"]:
        obj["xy"] = move(*obj["xy"])
        obj["yaw"] = round(obj.get("yaw", 0.0) + yaw, 6)
    out["name"] = name
    return out


def left_goal(doc: dict[str, Any], side_m: float = 0.6) -> dict[str, Any]:
    """The §3.1 goal of a turned chair scene: the waist ``side_m`` to the seated robot's left (beside the
    table) along the world axis closest to its left, exceeded upward or downward."""
    robot = doc["robot"]
    yaw = robot.get("yaw", 0.0)
    left = (-math.sin(yaw), math.cos(yaw))
    axis = 0 if abs(left[0]) > abs(left[1]) else 1
    origin = (robot["x"] + 0.11 * math.cos(yaw), robot["y"] + 0.11 * math.sin(yaw))  # the shipped y = 0
    below = left[axis] < 0
    value = origin[axis] - side_m if below else origin[axis] + side_m
    return {"goal_axis": "xy"[axis], "goal_value_m": round(value, 6), "goal_below": below}


def with_heights(doc: dict[str, Any], seat_m: float, table_m: float, name: str) -> dict[str, Any]:
    """``doc`` with the chair's seat and the table's top at other heights [m] (the seated posture is
    made again for the new seat by :func:`reseat`)."""
    out = copy.deepcopy(doc)
    for obj in out["objects"]:
        if obj["kind"] == "chair":
            obj["size"][2] = seat_m
        if obj["kind"] == "table":
            obj["size"][2] = table_m
    out["name"] = name
    return out


def reseat(doc: dict[str, Any]) -> dict[str, Any]:
    """``doc`` with the robot's seated posture made again by the posture generator for its chair
    (``chair_egress.seated_posture``; the thighs on the seat, the soles flat on the floor)."""
    import pinocchio as pin

    from services.contacts.chair_egress import seated_posture
    from services.contacts.environment import environment_of
    from services.model import load_robot
    from sim.scene import layout, parse_scene
    from sim.world import start_configuration

    robot = load_robot("hrp2_like")
    lay = layout(parse_scene(doc, source=doc["name"]))
    q = seated_posture(robot, environment_of(lay), start_configuration(robot, lay))
    rpy = pin.rpy.matrixToRpy(pin.Quaternion(q[3:7]).toRotationMatrix())
    out = copy.deepcopy(doc)
    out["robot"] = {
        "x": round(float(q[0]), 5),
        "y": round(float(q[1]), 5),
        "yaw": round(float(rpy[2]), 5),
        "posture": {
            "base_z": round(float(q[2]), 5),
            "pitch": round(float(rpy[1]), 5),
            "joints": {n: round(float(q[robot.joint_index(n).idx_q]), 5) for n in robot.joint_names},
        },
    }
    return out


def without(doc: dict[str, Any], kind: str, name: str) -> dict[str, Any]:
    out = copy.deepcopy(doc)
    out["objects"] = [o for o in out["objects"] if o["kind"] != kind]
    out["name"] = name
    return out


def moved_object(doc: dict[str, Any], kind: str, xy: list[float], yaw: float, name: str) -> dict[str, Any]:
    out = copy.deepcopy(doc)
    for obj in out["objects"]:
        if obj["kind"] == kind:
            obj["xy"], obj["yaw"] = list(xy), yaw
    out["name"] = name
    return out


def with_box(doc: dict[str, Any], xy: list[float], size: list[float], name: str) -> dict[str, Any]:
    out = copy.deepcopy(doc)
    out["objects"].append({"name": "crate", "kind": "box", "size": size, "colour": "blue", "xy": xy})
    out["name"] = name
    return out


def standing_doc(name: str) -> dict[str, Any]:
    """The robot standing (half-sitting) at the origin facing +x, a box 1 m ahead."""
    return {
        "name": name,
        "description": "the robot standing, a box ahead (contacts_unseen)",
        "robot": {"x": 0.0, "y": 0.0, "yaw": 0.4},
        "objects": [
            {"name": "crate", "kind": "box", "size": [0.4, 0.4, 0.5], "colour": "blue", "xy": [1.2, 0.5]}
        ],
    }


def cases(quick: bool = False) -> list[Case]:
    """The generated family (``quick``: the cheap cases only, for the tests)."""
    base = base_doc()
    fast = {"time_budget_s": 60.0, "max_nodes": 60, "n_interpolation": 4}
    # the right thigh leaves the seat: the final contacts without it, no pair added, the goal (waist z > -1 m)
    # met at once
    thigh_off = {**fast, "pairs": [], "final_contacts": SEATED[:3], "goal_axis": "z", "goal_value_m": -1.0}
    out: list[Case] = []
    t90 = turned(base, math.pi / 2, 1.3, -0.7, "cu_turned90")
    # short plans in turned, moved layouts: a thigh, then a sole, leaves its support (§2.3's removal)
    out.append(
        Case(
            "turned90_release",
            t90["name"],
            thigh_off,
            "plan",
            t90,
            execute=True,
            note="turned 90 deg and moved: the right thigh leaves the seat",
        )
    )
    t200 = turned(base, 3.5, -0.8, 0.9, "cu_turned200")
    out.append(
        Case(
            "turned200_release",
            t200["name"],
            {
                **fast,
                "pairs": [],
                "final_contacts": [SEATED[0], *SEATED[2:]],
                "goal_axis": "z",
                "goal_value_m": -1.0,
            },
            "either",
            t200,
            execute=True,
            note="turned 200 deg: the right sole leaves the floor",
        )
    )
    standing = standing_doc("cu_standing")
    out.append(
        Case(
            "standing_step",
            standing["name"],
            {
                **fast,
                "start_contacts": STANDING,
                "pairs": STANDING,
                "goal_axis": "x",
                "goal_value_m": 0.12,
                "max_nodes": 40,
            },
            "plan",
            standing,
            execute=True,
            note="standing, turned 0.4 rad: a static step to x 0.12 m",
        )
    )
    out.append(
        Case(
            "goal_out_of_reach",
            t90["name"],
            {**fast, **left_goal(t90, 4.0)},
            "refused",
            t90,
            note="the goal 4 m to the side, past the floor",
        )
    )
    out.append(
        Case(
            "goal_too_high",
            "chair_egress",
            {**fast, "goal_axis": "z", "goal_value_m": 1.6},
            "refused",
            note="the waist at 1.6 m",
        )
    )
    out.append(
        Case(
            "final_not_allowed",
            "chair_egress",
            {**fast, "pairs": [["left_hand", TOP]], "final_contacts": [["left_knee", "floor"]]},
            "refused",
            note="a final contact no pair allows",
        )
    )
    out.append(
        Case(
            "max_nodes_1",
            t90["name"],
            {**fast, **left_goal(t90), "max_nodes": 1},
            "refused",
            t90,
            note="max_nodes 1: the root only",
        )
    )
    out.append(
        Case("budget_50ms", "chair_egress", {**fast, "time_budget_s": 0.05}, "refused", note="a 50 ms budget")
    )
    out.append(
        Case(
            "removals_only",
            "chair_egress",
            {**fast, "pairs": []},
            "refused",
            note="no contact may be added: the tree is exhausted",
        )
    )
    # payloads a client may get wrong: typed invalid_request naming the field
    for name, extra, edit, note in (
        ("start_not_balanced", {"start_contacts": SEATED[:1]}, "", "seated, declared on the left sole alone"),
        ("start_spot_twice", {"start_contacts": [*SEATED, SEATED[0]]}, "", "a start spot given twice"),
        ("quat_zero", {}, "quat_zero", "q_start's quaternion all zeros (crashed the search: internal)"),
        ("joint_past_limit", {}, "joint_past_limit", "q_start with a joint at 9 rad"),
    ):
        out.append(Case(name, "chair_egress", {**fast, **extra}, "invalid", q_edit=edit, note=note))
    out.append(
        Case(
            "goal_met_max_nodes_1",
            "chair_egress",
            {**fast, "final_contacts": SEATED, "goal_axis": "z", "goal_value_m": -1.0, "max_nodes": 1},
            "plan",
            note="max_nodes 1, the start already the goal: a one-set plan (was max_nodes)",
        )
    )
    if quick:
        return out
    out.append(
        Case(
            "turned90_egress",
            t90["name"],
            {
                "time_budget_s": 400.0,
                "max_nodes": 500,
                **left_goal(t90),
                "n_interpolation": 6,
                "pairs": PAIRS,
            },
            "either",
            t90,
            note="the whole egress turned 90 deg, the chair scenario's pairs (shipped: 21 sets, 261 nodes)",
        )
    )
    out.append(
        Case(
            "oblique_egress",
            "cu_oblique",
            {
                "time_budget_s": 120.0,
                "max_nodes": 300,
                **left_goal(turned(base, 0.6, 0.4, 0.3, "x")),
                "n_interpolation": 4,
            },
            "either",
            turned(base, 0.6, 0.4, 0.3, "cu_oblique"),
            note="turned 0.6 rad",
        )
    )
    high = reseat(with_heights(base, 0.34, 0.70, "cu_high"))
    out.append(
        Case(
            "high_seat_release",
            high["name"],
            thigh_off,
            "plan",
            high,
            execute=True,
            note="seat 0.34 m, table 0.70 m (reseated): the right thigh leaves the seat",
        )
    )
    low = with_heights(base, 0.30, 0.58, "cu_low_table")  # seats below 0.30 m: no seated witness
    out.append(
        Case(
            "low_seat_egress",
            low["name"],
            {
                "time_budget_s": 120.0,
                "max_nodes": 300,
                "goal_axis": "y",
                "goal_value_m": 0.6,
                "n_interpolation": 4,
            },
            "either",
            low,
            note="table top at 0.58 m",
        )
    )
    far = moved_object(base, "table", [1.6, 0.0], 0.0, "cu_table_far")
    out.append(
        Case(
            "table_far_egress",
            far["name"],
            {
                "time_budget_s": 90.0,
                "max_nodes": 200,
                "goal_axis": "y",
                "goal_value_m": 0.6,
                "n_interpolation": 4,
            },
            "either",
            far,
            note="the table out of reach (T without the lean)",
        )
    )
    out.append(
        Case(
            "table_far_hand",
            far["name"],
            {
                **fast,
                "pairs": [["left_hand", TOP]],
                "final_contacts": [*SEATED, ["left_hand", TOP]],
                "goal_axis": "z",
                "goal_value_m": -1.0,
            },
            "refused",
            far,
            note="a hand on a table out of reach",
        )
    )
    side = moved_object(base, "table", [0.2, -0.75], 1.5708, "cu_table_side")
    out.append(
        Case(
            "table_side_egress",
            side["name"],
            {
                "time_budget_s": 90.0,
                "max_nodes": 200,
                "goal_axis": "y",
                "goal_value_m": 0.6,
                "n_interpolation": 4,
            },
            "either",
            side,
            note="the table turned, on the right",
        )
    )
    bare = without(base, "table", "cu_no_table")
    out.append(
        Case(
            "no_table_egress",
            bare["name"],
            {
                "time_budget_s": 90.0,
                "max_nodes": 200,
                "goal_axis": "y",
                "goal_value_m": 0.6,
                "n_interpolation": 4,
            },
            "either",
            bare,
            note="no table",
        )
    )
    out.append(
        Case(
            "no_table_surface",
            bare["name"],
            {**fast, "surfaces": ["floor", TOP]},
            "invalid",
            bare,
            note="a surface the layout does not have (invalid_request)",
        )
    )
    boxed = with_box(base, [0.25, 0.75], [0.5, 0.4, 0.9], "cu_boxed")
    out.append(
        Case(
            "box_in_the_way",
            boxed["name"],
            {
                "time_budget_s": 90.0,
                "max_nodes": 200,
                "goal_axis": "y",
                "goal_value_m": 0.6,
                "n_interpolation": 4,
            },
            "either",
            boxed,
            note="a crate where the robot would stand beside the table",
        )
    )
    out.append(
        Case(
            "goal_inside_table",
            "chair_egress",
            {
                "time_budget_s": 60.0,
                "max_nodes": 150,
                "goal_axis": "x",
                "goal_value_m": 0.73,
                "n_interpolation": 4,
            },
            "refused",
            note="the waist past the table's centre, standing",
        )
    )
    out.append(
        Case(
            "huge_budget_few_nodes",
            "chair_egress",
            {"time_budget_s": 600.0, "max_nodes": 5, "goal_axis": "y", "goal_value_m": 0.6},
            "refused",
            note="600 s but 5 nodes",
        )
    )
    out.append(
        Case(
            "slope_tiny",
            "chair_egress",
            {**fast, "slope_k": 0.001, "max_nodes": 30},
            "either",
            note="f_T's slope 0.001",
        )
    )
    return out


def write_scenes(family: list[Case], folder: Path) -> Path:
    """Each generated scene of ``family`` as ``folder/<scene>.yaml`` (the services' ``scene_dirs``)."""
    folder.mkdir(parents=True, exist_ok=True)
    for case in family:
        if case.doc is not None:
            (folder / f"{case.scene}.yaml").write_text(yaml.safe_dump(case.doc, sort_keys=False))
    return folder


# ---------------------------------------------------------------------------------------------- checks
def _surfaces(lay) -> dict[str, tuple[np.ndarray, np.ndarray, tuple[float, float], float, str]]:
    """Contact surfaces straight from the scene (``sim.parts``): name -> (centre [m], rotation, half
    sizes [m], friction, owner). The floor's frame is the robot's start frame (the schema's convention),
    2.5 m each way."""
    from sim.parts import parts_of

    c, s = math.cos(lay.robot_yaw_rad), math.sin(lay.robot_yaw_rad)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    floor = np.array([*lay.robot_xy, 0.0])
    out = {"floor": (floor, R, (2.5, 2.5), lay.scene.floor_friction, "floor")}
    for obj in lay.objects:
        spec = obj.spec
        if spec.kind not in ("box", "table", "chair") or not spec.is_static:
            continue
        top = parts_of(spec)[0]
        c, s = math.cos(obj.yaw_rad), math.sin(obj.yaw_rad)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        up = np.array([0.0, 0.0, top.half_extents[2]])
        centre = np.asarray(obj.position, float) + R @ (np.array(top.xyz) + up)
        label = {"box": "top", "table": "top", "chair": "seat"}[spec.kind]
        out[f"{spec.name}.{label}"] = (centre, R, tuple(top.half_extents[:2]), spec.friction, spec.name)
    return out


class PlanChecker:
    """Checks a plan's witnesses and motion in one scene without the planner's code (see the module)."""

    def __init__(self, scene_path: str | Path) -> None:
        import pinocchio as pin
        import pybullet as p

        from services.contacts.spots import robot_spots
        from services.model import load_robot
        from services.model.pybullet_robot import PybulletRobot
        from sim.objects import build_scene
        from sim.scene import layout, load_scene
        from sim.world import start_configuration

        self.pin, self.p = pin, p
        self.robot = load_robot("hrp2_like")
        self.layout = layout(load_scene(scene_path))
        self.surfaces = _surfaces(self.layout)
        self.spots = {s.name: s for s in robot_spots(self.robot)}
        self.data = self.robot.new_data()
        self.client = p.connect(p.DIRECT)
        _, self.bodies = build_scene(self.layout, self.client)
        self.pyrobot = PybulletRobot(self.robot, self.client, start_configuration(self.robot, self.layout))

    def close(self) -> None:
        self.p.disconnect(self.client)

    def spot_pose(self, q: np.ndarray, spot: str) -> tuple[np.ndarray, np.ndarray]:
        pin = self.pin
        s = self.spots[spot]
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        T = self.data.oMf[self.robot.frame_id(s.frame)] * s.placement
        return T.translation.copy(), T.rotation.copy()

    def contact_problems(self, q: np.ndarray, contacts: list) -> list[str]:
        out = []
        for c in contacts:
            if c.surface not in self.surfaces:
                out.append(f"{c.spot} on {c.surface}: no such surface in the scene")
                continue
            centre, R, half, _, _ = self.surfaces[c.surface]
            p, Rs = self.spot_pose(q, c.spot)
            local = R.T @ (p - centre)
            tilt = math.acos(max(-1.0, min(1.0, float(Rs[:, 2] @ R[:, 2]))))
            if abs(local[2]) > CONTACT_TOLERANCE_M or tilt > TILT_TOLERANCE_RAD:
                out.append(
                    f"{c.spot} not on {c.surface}: {local[2]:+.3f} m off its plane, tilted {tilt:.2f} rad"
                )
            elif (
                abs(local[0]) > half[0] + CONTACT_TOLERANCE_M or abs(local[1]) > half[1] + CONTACT_TOLERANCE_M
            ):
                out.append(f"{c.spot} off {c.surface}'s edges: ({local[0]:+.3f}, {local[1]:+.3f}) m")
            elif math.hypot(local[0] - c.x, local[1] - c.y) > 0.02:
                out.append(f"{c.spot} on {c.surface} 2 cm away from the (x, y) the plan says")
        return out

    def collisions(self, q: np.ndarray, touching: set[str]) -> list[str]:
        """Robot links deeper than PENETRATION_M into an object not in ``touching`` (owners) [pybullet]."""
        p = self.p
        self.pyrobot.reset(q)
        out = []
        for name, body in self.bodies.items():
            if name in touching:
                continue
            for pt in p.getClosestPoints(self.pyrobot.body_id, body, 0.0, physicsClientId=self.client):
                if pt[8] < -PENETRATION_M:
                    out.append(f"{self.pyrobot.link_name(pt[3])} {-pt[8] * 100:.1f} cm into {name}")
                    break
        return out

    def balance_residual(self, q: np.ndarray, contacts: list) -> float:
        """The smallest |sum of forces - weight| (N, with the moments' over a 1 m lever) that forces in
        the linearized friction cones at the contact patches' corners leave (0: statically balanced)."""
        from scipy.optimize import linprog

        pin = self.pin
        mass = self.robot.total_mass_kg
        com = pin.centerOfMass(self.robot.model, self.data, q)
        columns = []
        for c in contacts:
            _, R, _, mu, _ = self.surfaces[c.surface]
            p, Rs = self.spot_pose(q, c.spot)
            n = R[:, 2]
            t1, t2 = R[:, 0], R[:, 1]
            hx, hy = self.spots[c.spot].half_size_m
            for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
                corner = p + Rs @ np.array([sx * hx, sy * hy, 0.0])
                for k in range(FRICTION_EDGES):
                    a = 2.0 * math.pi * k / FRICTION_EDGES
                    g = n + mu / math.sqrt(2.0) * (math.cos(a) * t1 + math.sin(a) * t2)
                    columns.append(np.concatenate([g, np.cross(corner - com, g)]))
        if not columns:
            return math.inf
        A = np.array(columns).T  # (6, m): wrench about the CoM of each generator
        b = np.array([0.0, 0.0, mass * 9.81, 0.0, 0.0, 0.0])
        m = A.shape[1]
        # min sum(s+ + s-) s.t. A l + s+ - s- = b, l, s >= 0
        cost = np.concatenate([np.zeros(m), np.ones(12)])
        A_eq = np.hstack([A, np.eye(6), -np.eye(6)])
        res = linprog(cost, A_eq=A_eq, b_eq=b, bounds=(0, None), method="highs")
        return float(res.fun) if res.status == 0 else math.inf

    def check(self, reply, q_start: np.ndarray, balance_tol_n: float = 1.0) -> list[str]:
        """Everything found wrong with ``reply`` (a PlanReply), [] when it checks out."""
        out: list[str] = []
        W = np.asarray(reply.witnesses)
        if not np.allclose(W[0], q_start, atol=1e-6):
            out.append("the first witness is not q_start")
        lower, upper = self.robot.model.lowerPositionLimit[7:], self.robot.model.upperPositionLimit[7:]
        for i, (contacts, q) in enumerate(zip(reply.sets, W, strict=True)):
            here = f"set {i} ({reply.changes[i]})"
            previous = reply.sets[i - 1] if i else []
            owners = {
                self.surfaces[c.surface][4] for c in [*contacts, *previous] if c.surface in self.surfaces
            }
            out += [f"{here}: {e}" for e in self.contact_problems(q, contacts)]
            out += [f"{here}: {e}" for e in self.collisions(q, owners)]
            # §2.3: the son's new contact is checked out of the stability; the father's set holds it
            support = contacts if not reply.changes[i].startswith("+") else previous
            residual = self.balance_residual(q, support)
            if residual > balance_tol_n:
                out.append(f"{here}: not statically balanced on {len(support)} contacts ({residual:.1f} N)")
            if np.any(q[7:] < lower - 1e-6) or np.any(q[7:] > upper + 1e-6):
                out.append(f"{here}: a joint outside its limits")
        motion = np.asarray(reply.q)
        if motion.shape[0]:
            if not np.all(np.isfinite(motion)):
                out.append("the motion has non-finite values")
            if np.any(motion[:, 7:] < lower - 1e-3) or np.any(motion[:, 7:] > upper + 1e-3):
                out.append("the motion leaves the joint limits")
            for i, k in enumerate(reply.set_samples):
                if np.max(np.abs(motion[k] - W[i])) > 1e-3:
                    out.append(f"the motion's sample {k} is not witness {i}")
                    break
        return out


def answer_problems(case: Case, code: str, details: dict[str, Any]) -> list[str]:
    """What is wrong with a refusal of ``case`` (code, details): [] when it is typed as documented."""
    if code == "invalid_request":
        return [] if case.expect == "invalid" else [f"invalid_request for a valid request: {details}"]
    if case.expect == "invalid":
        return [f"{code} where invalid_request was due"]
    if code not in ("infeasible", "timeout"):
        return [f"code {code}"]
    if details.get("reason") not in REASONS:
        return [f"reason {details.get('reason')!r} not one of {REASONS}"]
    if not isinstance(details.get("residual_m"), (int, float)):
        return ["no residual_m"]
    return []
