"""Expensive requests of every planner with a time budget, and a cheap one of the same endpoint (issue 16:
"no request holds a service past its own budget plus a second").

Used by ``tests/test_fuzz.py`` (a tiny budget each: the typed ``timeout`` arrives and the endpoint serves
the next request; the time is asserted only loosely, the machine is shared) and ``scripts/bench budgets``
(several budgets each, the overrun past the budget measured: the issue's figure).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from services.bus.schemas import contacts, footsteps, navigation, perception, reaching, walking
from services.bus.spec import EndpointSpec

#: The services :func:`expensive` has a request for.
SERVICES = ("walking", "navigation", "reaching", "footsteps", "perception", "contacts")
#: The chair scene's start contacts (the robot seated: soles on the floor, thighs on the seat).
SEATED = [
    ["left_sole", "floor"],
    ["right_sole", "floor"],
    ["left_thigh", "chair.seat"],
    ["right_thigh", "chair.seat"],
]


@dataclass(frozen=True)
class Case:
    """An endpoint, an expensive request of it with the budget asked for, a cheap request of it."""

    name: str
    spec: EndpointSpec
    expensive: Any
    cheap: Any


def seated_q() -> np.ndarray:
    """The robot seated on the chair of the ``chair_egress`` scene (pinocchio layout)."""
    from services.model import load_robot
    from sim.scene import layout, load_scene
    from sim.world import start_configuration

    return start_configuration(load_robot("hrp2_like"), layout(load_scene("chair_egress")))


def seated_contacts(q_seated: np.ndarray) -> list[contacts.ContactMsg]:
    """The contacts of :data:`SEATED` where the spots are at ``q_seated`` (the planner's start set)."""
    from services.contacts.planner import build, default_problem
    from services.model import load_robot

    robot = load_robot("hrp2_like")
    _gen, _trajectory, start, _pairs = build(robot, default_problem(robot, q_seated))
    return [contacts.ContactMsg(spot=c.spot, surface=c.surface, x=c.x, y=c.y, theta=c.theta) for c in start]


def expensive(service: str, q: np.ndarray, budget_s: float, q_seated: np.ndarray | None = None) -> list[Case]:
    """The cases of ``service`` with a ``budget_s`` [s] budget; ``q`` is the robot standing in the sim's
    scene, ``q_seated`` (contacts only) the robot on the chair (:func:`seated_q`)."""
    if service == "walking":  # 3 m: about 30 steps, 35 s of walk, seconds of planning
        x0, y0 = float(q[0]), float(q[1])  # the mid-feet point is under the base in half-sitting
        steps = [
            walking.Step(pose=[x0 + 0.15 * (i + 1), y0 + (-0.095 if i % 2 == 0 else 0.095), 0.0])
            for i in range(40)
        ]
        return [
            Case(
                "walking/goal 3 m",
                walking.GOAL,
                walking.GoalRequest(q_start=q, pose=[3.0, 0.0, 0.0], time_budget_s=budget_s),
                walking.GoalRequest(q_start=q, kind="turn", angle_rad=0.2),
            ),
            Case(  # the same kind of walk given as footsteps (40 steps, 6 m)
                "walking/plan 40 steps",
                walking.PLAN,
                walking.PlanRequest(q_start=q, steps=steps, time_budget_s=budget_s),
                walking.PlanRequest(q_start=q, steps=steps[:2]),
            ),
        ]
    if service == "navigation":  # the whole goto (path and stage 2) of an 8 m walk
        return [
            Case(
                "navigation/goto 8 m",
                navigation.GOTO,
                navigation.GotoRequest(q_start=q, goal_pose=[8.0, 0.0, 0.0], total_budget_s=budget_s),
                navigation.GotoRequest(q_start=q, goal_pose=[0.3, 0.0, 0.0]),
            )
        ]
    if service == "reaching":  # a target out of reach: the no-step motion, then reshaping by stepping
        return [
            Case(
                "reaching/reach out of reach",
                reaching.REACH,
                reaching.ReachRequest(
                    hand="right", target=[1.0, -0.3, 0.8], q_start=q, time_budget_s=budget_s
                ),
                reaching.ReachRequest(hand="right", target=[0.35, -0.2, 0.8], q_start=q),
            )
        ]
    if service == "footsteps":  # a target 4 m away: Algorithm 1 adds footsteps one by one
        far = footsteps.Task(kind="reach", target=[4.0, 1.0, 0.8])
        return [
            Case(
                "footsteps/plan 4 m",
                footsteps.PLAN,
                footsteps.PlanRequest(q_start=q, tasks=[far], time_budget_s=budget_s),
                footsteps.PlanRequest(q_start=q, tasks=[footsteps.Task(kind="posture")]),
            )
        ]
    if service == "perception":  # the largest render, by semi-global block matching
        return [
            Case(
                "perception/locate 2048 px sgbm",
                perception.LOCATE,
                perception.LocateRequest(
                    object="green_box", width_px=2048, height_px=2048, method="sgbm", time_budget_s=budget_s
                ),
                perception.LocateRequest(object="green_box", width_px=160, height_px=120),
            )
        ]
    if service == "contacts":
        assert q_seated is not None, "contacts needs the seated configuration (seated_q())"
        # one removal (the right thigh leaves the seat): the goal after one expansion, no search
        removal = {
            "scene": "chair_egress",
            "q_start": q_seated,
            "start_contacts": SEATED,
            "goal_axis": "x",
            "goal_value_m": -1.0,
            "final_contacts": SEATED[:3],
            "pairs": [],
        }
        # cheap: the start set is the goal (reached at the first expansion), no motion
        cheap = contacts.PlanRequest(**{**removal, "final_contacts": SEATED}, interpolate=False)
        seated = seated_contacts(q_seated)
        # the right thigh leaves the seat, re-planned from the seated configuration (executing set by set)
        leave = {
            "scene": "chair_egress",
            "q_measured": q_seated,
            "from_set": seated,
            "to_set": [c for c in seated if c.spot != "right_thigh"],
            "witness": q_seated,
        }
        return [
            Case(  # the chair egress (minutes of search): the search is cut
                "contacts/plan chair egress",
                contacts.PLAN,
                contacts.PlanRequest(
                    scene="chair_egress", q_start=q_seated, start_contacts=SEATED, time_budget_s=budget_s
                ),
                cheap,
            ),
            Case(  # found after 11 expansions (3-4 s at load 8), then 1000 postures to interpolate
                # (a minute): with a budget of more than about 6 s, the interpolation is cut
                "contacts/plan interpolation",
                contacts.PLAN,
                contacts.PlanRequest(**removal, n_interpolation=1000, time_budget_s=budget_s),
                cheap,
            ),
            Case(  # one transition with the most postures (100): 3.1 s in-process at load 2.5
                "contacts/transition n=100",
                contacts.TRANSITION,
                contacts.TransitionRequest(**leave, n_interpolation=100, time_budget_s=budget_s),
                contacts.TransitionRequest(**leave, n_interpolation=2),
            ),
        ]
    raise ValueError(f"no expensive request for {service!r}; services: {', '.join(SERVICES)}")
