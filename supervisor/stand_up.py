"""The ``stand_up`` action: get out of a chair (script ``stand_up``, console "get up" / "stand up").

Calls ``contacts/plan`` (contact-before-motion planning, Escande et al.) from the robot's current
configuration in the sim's current scene, then plays the plan set by set: for each transition,
``contacts/transition`` re-plans it from the measured configuration (``sim/state``: the supports where
they are, not where they were planned) and ``sim/execute`` plays it, the chair and the table allowed
as supports. Failure reasons: the planner's typed
errors (``infeasible`` with the best set reached, ``timeout`` with the partial plan), ``fell`` /
``collision`` from the execution.

The supervisor imports no planner: the request names the start contacts of the seated robot and the
goal as data.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from services.bus.schemas import contacts as contacts_msg
from services.errors import FellError, InvalidRequestError
from supervisor.body import Body
from supervisor.calls import ServiceCaller
from supervisor.report import ActionReport

# The seated robot's contacts (soles on the floor, thighs on the chair's seat) and the goal: the waist
# BESIDE_M to the robot's left of where it sits, standing on both soles (in the chair_egress scene, §3.1
# of the paper: beyond y = 0.6 m, beside the table).
SEATED_CONTACTS = [
    ["left_sole", "floor"],
    ["right_sole", "floor"],
    ["left_thigh", "chair.seat"],
    ["right_thigh", "chair.seat"],
]
BESIDE_M = 0.6
PLAN_BUDGET_S = 300.0
SUPPORTS = ("chair", "table")
N_INTERPOLATION = 10  # posture generations per transition (§3.3's n)
TRANSITION_BUDGET_S = 60.0  # contacts/transition's time budget [s] (the whole re-planning of a transition)
# the wait for a reply past the request's own budget [s]: the reply (a timeout at the latest) comes
# within the budget plus about a second; the rest covers a planner restarted by the launcher
REPLY_MARGIN_S = 60.0


def beside_goal(waist_xy_m: tuple[float, float], yaw_rad: float, beside_m: float) -> tuple[str, float, bool]:
    """The goal of ``contacts/plan`` (``goal_axis``, ``goal_value_m``, ``goal_below``) for a waist at
    ``waist_xy_m`` [m] (world) to end ``beside_m`` [m] to the left of a robot seated facing ``yaw_rad``
    [rad]: the world axis nearest that direction, its coordinate there, passed downward when the
    direction points to that axis' negative side (a chair facing any way: the planner's goal is one
    coordinate)."""
    left = (-math.sin(yaw_rad), math.cos(yaw_rad))
    i = 0 if abs(left[0]) > abs(left[1]) else 1
    return "xy"[i], waist_xy_m[i] + beside_m * left[i], left[i] < 0.0


def stand_up(
    bus: ServiceCaller, body: Body, progress: Callable[[str], None], args: tuple[str, ...] = ()
) -> ActionReport:
    """Plan and execute getting up; ``args``: optional distance [m] of the waist to the robot's left at
    the end (``BESIDE_M``; :func:`beside_goal`), optional plan budget [s] (``PLAN_BUDGET_S``)."""
    state = body.state()
    if state.fallen:
        raise FellError("the robot is on the ground: reset the sim")
    beside = float(args[0]) if args else BESIDE_M
    budget = float(args[1]) if len(args) > 1 else PLAN_BUDGET_S
    if not 0.0 < budget <= 600.0:
        raise InvalidRequestError(f"stand_up: the plan budget must be in ]0, 600] s, got {budget}")
    _feet_x, _feet_y, yaw = body.base_xy_yaw(state.q)
    axis, value, below = beside_goal((float(state.q[0]), float(state.q[1])), yaw, beside)
    progress(
        f"stand up: planning contacts in scene {state.scene} (the waist's {axis} "
        f"{'below' if below else 'beyond'} {value:.2f} m, budget {budget:.0f} s)"
    )
    request = contacts_msg.PlanRequest(
        scene=state.scene,
        q_start=state.q,
        start_contacts=SEATED_CONTACTS,
        goal_axis=axis,
        goal_value_m=value,
        goal_below=below,
        time_budget_s=budget,
        interpolate=False,  # each transition is interpolated from the measured state
    )
    plan = bus.call(contacts_msg.PLAN, request, budget + REPLY_MARGIN_S)
    for k, (change, contacts) in enumerate(zip(plan.changes, plan.sets, strict=True)):
        progress(f"  set {k}: {change} -> {len(contacts)} contacts")
    progress(f"stand up: {len(plan.sets)} sets, {plan.nodes_generated} nodes in {plan.plan_s:.0f} s")
    played = 0.0
    for k in range(1, len(plan.sets)):
        released = [c for c in plan.sets[k - 2] if c not in plan.sets[k - 1]] if k > 1 else []
        step = bus.call(
            contacts_msg.TRANSITION,
            contacts_msg.TransitionRequest(
                scene=state.scene,
                q_measured=body.q(),
                from_set=plan.sets[k - 1],
                to_set=plan.sets[k],
                witness=plan.witnesses[k],
                released=released,
                n_interpolation=N_INTERPOLATION,
                time_budget_s=TRANSITION_BUDGET_S,
            ),
            TRANSITION_BUDGET_S + REPLY_MARGIN_S,
        )
        progress(
            f"  transition {k}/{len(plan.sets) - 1} ({plan.changes[k]}): supports off the plan by "
            f"{step.support_error_m * 100:.1f} cm, re-planned in {step.replan_s:.1f} s"
            + (f"; {step.collision}" if step.collision else "")
        )
        executed = body.execute(
            step.q,
            what=f"stand up, transition {k} ({plan.changes[k]})",
            dt_s=step.dt_s,
            progress=progress,
            hold_s=1.0 if k == len(plan.sets) - 1 else 0.0,
            supports=SUPPORTS,
            effort_scale=step.effort_scale,
        )
        played += executed.duration_s
    return ActionReport(
        "stand_up",
        args,
        message=f"stood up in {len(plan.sets)} contact sets ({played:.0f} s of motion)",
        details={"sets": len(plan.sets), "nodes_generated": plan.nodes_generated, "plan_s": plan.plan_s},
    )
