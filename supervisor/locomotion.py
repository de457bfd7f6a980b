"""Locomotion actions: ``goto``, ``turn``, ``walk`` (and stepping back to make room).

"Locomotion to a location" and "turning on the spot" (Fig. 11 of ``001_771c0ce3779b0683.txt``): every
motion is a planner's (``navigation/goto``, ``walking/goal``) played by ``sim/execute``; this module
decides which to ask for and in which order.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from services.bus.schemas import navigation as nav_msg
from services.errors import InfeasibleError, InvalidRequestError
from supervisor.parts import ActionParts
from supervisor.planners import Plan
from supervisor.report import ActionReport
from supervisor.scene_map import BoxEstimate, box_estimate, boxes, distance_to_box, is_obstacle
from supervisor.script import Step, parse_point


def away_from(box: BoxEstimate, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
    """The unit direction (forward, left) in the robot's frame at (x, y, yaw) [m, rad] (its mid-feet
    frame) away from ``box``'s floor rectangle: from its point nearest the robot to the robot (an
    object straight ahead: straight back, the usual step before turning away from it; one beside the
    robot: sideways); straight back when the robot stands inside it."""
    rect = box.footprint
    away = np.array([x_m, y_m]) - rect.nearest_point((x_m, y_m))
    norm = float(np.linalg.norm(away))
    if norm < 1e-6:
        return -1.0, 0.0
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    forward = (c * away[0] + s * away[1]) / norm
    left = (-s * away[0] + c * away[1]) / norm
    return forward, left


class LocomotionActions(ActionParts):
    """The locomotion actions (a part of :class:`supervisor.actions.Actions`)."""

    _survey: Callable[[set[str]], None]  # LookingActions

    def do_goto(self, step: Step) -> ActionReport:
        """Walk in front of an object (``distance`` from its face, facing it) or to a pose 'x,y,yaw_deg'."""
        target = step.args[0]
        distance = float(step.kwargs.get("distance", self.config.goto_distance_m))
        pose = parse_point(target, 3, "goto target")
        self.body.straighten()
        self._survey(exclude={target})
        # Room to start the car-like path. A start still overlapping an object of the map is navigation's
        # to leave: it walks to the nearest free pose first, computed from the overlap (fetch seed 49).
        self._make_room(f"room to walk to {target}")
        if pose is None:
            sighting = self.memory.get(target)
            if not is_obstacle(sighting):
                raise InvalidRequestError(
                    f"{target} is small ({sighting.size_m[0]:.2f} m): walk to what it is on, or reach it"
                )
            self._approach(target)
            plan = self._goto_object(target, distance)
            what = f"walk to {target}"
        else:
            plan = self.planners.goto_pose(pose[0], pose[1], math.radians(pose[2]))
            what = f"walk to ({pose[0]:.2f}, {pose[1]:.2f})"
        self.progress(f"{what}: {plan.describe()}")
        executed = self.body.execute(plan.q, what=what, progress=self.progress)
        x, y, yaw = self.body.base_xy_yaw(executed.q)
        return ActionReport(
            "goto",
            step.args,
            message=f"at ({x:.2f}, {y:.2f}) facing {math.degrees(yaw):.0f} deg after {plan.describe()}",
            details={"pose": [x, y, yaw], "steps": plan.n_steps, "planned_goal": plan.goal},
        )

    def _goto_object(self, target: str, distance: float) -> Plan:
        """navigation/goto in front of ``target``; when no place to stand is free at ``distance`` (the
        map's box is a rough estimate), ``goto_farther_m`` farther, each in turn (reaching steps the
        rest of the way)."""
        *first, last = (distance, *(distance + extra for extra in self.config.goto_farther_m))
        for at in first:
            try:
                return self.planners.goto_object(target, at)
            except InfeasibleError as exc:
                if exc.details.get("reason") != nav_msg.REASON_NO_FREE_APPROACH_POSE:
                    raise
                self.progress(f"no place to stand {at:.2f} m from {target}: trying farther")
        return self.planners.goto_object(target, last)

    def _make_room(self, what: str, room: tuple[float, str, float, float] | None = None) -> None:
        """Step away when an object seen is closer than ``clearance_m`` to the robot: turning on the spot
        would sweep the arms into it, and a car-like path needs room to turn at its start (a start
        inside an obstacle's margin is navigation's to leave: it computes the way out). Away from the
        object's map box (:func:`away_from`: straight back when it is ahead; a table or chair beside
        the robot, the step goes sideways too: straight back the hand beside the chair touched it,
        fetch seed 18), else, when walking refuses that, straight back. ``room``: what
        :meth:`_room_needed` said from the robot's stance now (None: asked here)."""
        if room is None:
            room = self._room_needed()
        if room is None:
            return
        back, name, forward, left = room
        try:
            plan = self.planners.walk(back * forward, back * left, 0.0)
        except InfeasibleError as exc:
            if self._straight_back(forward):  # that was the step straight back already
                self.progress(f"{what}: no step back from {name}: {exc.message}")
                return
            self.progress(f"{what}: no step away from {name}: {exc.message}; straight back")
            try:
                plan = self.planners.step_back(back)
            except InfeasibleError as exc:  # something behind too: the planner that follows decides
                self.progress(f"{what}: no step back from {name}: {exc.message}")
                return
            forward, left = -1.0, 0.0
        direction = f"{math.degrees(math.atan2(left, forward)):+.0f} deg from ahead"
        self.progress(f"{what}: stepping {back:.2f} m away from {name}, {direction} ({plan.describe()})")
        self.body.execute(plan.q, what=f"step back from {name}", progress=self.progress)

    def _room_needed(self) -> tuple[float, str, float, float] | None:
        """How far [m] to step, from which object, and in which unit direction (forward, left) of the
        robot's frame (:func:`away_from` its map box), when an object seen is nearer than
        ``clearance_m`` to the robot's mid-feet point (enough to reach ``clearance_m`` +
        ``room_margin_m``, at most ``max_step_back_m``); None when none is."""
        x, y, yaw = self.body.base_xy_yaw()
        near = [(distance_to_box(box, x, y), box.name, box) for box in boxes(self.memory)]
        if not near:
            return None
        distance, name, box = min(near, key=lambda item: item[0])
        if distance >= self.config.clearance_m:
            return None
        c = self.config
        back = min(c.clearance_m - distance + c.room_margin_m, c.max_step_back_m)
        return (back, name, *away_from(box, x, y, yaw))

    def _straight_back(self, forward: float) -> bool:
        """Whether a way out whose forward component (of a unit direction, :func:`away_from`) is
        ``forward`` is straight back, within ``straight_back_deg``."""
        return forward < -math.cos(math.radians(self.config.straight_back_deg))

    def _approach(self, name: str) -> None:
        """Far objects are seen roughly (a table 3 m away: its silhouette is a thin top on thin legs):
        walk to ``near_m`` short of the middle of its map box first (the middle of its silhouette can be
        a leg), facing it, and localize it again from there."""
        centre = np.asarray(box_estimate(self.memory.get(name)).center_m[:2])
        x, y, _yaw = self.body.base_xy_yaw()
        to = centre - (x, y)
        dist = float(np.linalg.norm(to))
        if dist <= self.config.far_m:
            return
        u = to / dist
        stop = centre - u * self.config.near_m
        what = f"approach {name}"
        try:
            plan = self.planners.goto_pose(float(stop[0]), float(stop[1]), math.atan2(u[1], u[0]))
        except InfeasibleError as exc:
            self.progress(f"{what}: no walk to {self.config.near_m:.1f} m short of it: {exc.message}")
            try:
                plan = self.planners.goto_object(name, self.config.near_face_m)
            except InfeasibleError as again:
                # Only a closer look is lost: the walk to the object itself plans with what is known.
                self.progress(f"{what}: none to a free face of it either ({again.message}): going on")
                return
        self.progress(
            f"{what} (seen {dist:.1f} m away: will look again from {self.config.near_m:.1f} m): "
            f"{plan.describe()}"
        )
        self.body.execute(plan.q, what=what, progress=self.progress)
        self.body.straighten()
        self.eyes.localize(name, turn=self._turn_rad, progress=self.progress)
        self.eyes.look_at(self.memory.get(name).position_m, f"look at {name}")
        self.eyes.locate(name)
        self._survey(exclude={name})
        self._make_room(f"room to walk to {name}")  # seen nearer now than from afar

    def do_turn(self, step: Step) -> ActionReport:
        """Turn on the spot by ``angle_deg`` (positive = left)."""
        try:
            angle = math.radians(float(step.args[0]))
        except ValueError:
            raise InvalidRequestError(f"turn angle {step.args[0]!r} is not a number of degrees") from None
        steps = self._turn_rad(angle, f"turn {step.args[0]} deg")
        _x, _y, yaw = self.body.base_xy_yaw()
        return ActionReport(
            "turn",
            step.args,
            message=f"now facing {math.degrees(yaw):.0f} deg ({steps} steps)",
            details={"yaw": yaw},
        )

    def do_walk(self, step: Step) -> ActionReport:
        """Walk relative to the robot: ``forward_m`` ahead, ``left_m`` to the left [m], then facing
        ``yaw_deg`` more (positive = left; default 0), as ``walking/goal`` plans it: steps within the
        robot's bounds, checked against the map (``infeasible`` naming the box in the way)."""
        try:
            forward, left, *yaw = (float(v) for v in step.args)
        except ValueError:
            raise InvalidRequestError(
                f"walk {' '.join(step.args)!r}: expected FORWARD_M LEFT_M [YAW_DEG] numbers"
            ) from None
        yaw_rad = math.radians(yaw[0]) if yaw else 0.0
        self.body.straighten()
        plan = self.planners.walk(forward, left, yaw_rad)
        what = f"walk {forward:+.2f} m forward, {left:+.2f} m left"
        self.progress(f"{what}: {plan.describe()}")
        executed = self.body.execute(plan.q, what=what, progress=self.progress)
        x, y, heading = self.body.base_xy_yaw(executed.q)
        return ActionReport(
            "walk",
            step.args,
            message=f"at ({x:.2f}, {y:.2f}) facing {math.degrees(heading):.0f} deg ({plan.n_steps} steps)",
            details={"pose": [x, y, heading], "steps": plan.n_steps},
        )

    def _turn_rad(self, angle_rad: float, what: str) -> int:
        """Turn on the spot (walking/plan of a turn-in-place footstep sequence); the steps taken."""
        if abs(angle_rad) < math.radians(self.config.min_turn_deg):
            return 0
        self.body.straighten()
        room = self._room_needed()
        if room is not None and self._straight_back(room[2]):
            # Stepping back for room and the turn: one walk of the walking planner (one start, one stop),
            # checked against the map where each part is (the turn's room where it starts). Only when the
            # way out is straight back (an object beside the robot: :meth:`_make_room` steps sideways).
            back, name = room[:2]
            try:
                plan = self.planners.turn(angle_rad, back_m=back)
            except InfeasibleError as exc:
                self.progress(f"{what}: no step back {back:.2f} m from {name} and turn ({exc.message})")
            else:
                self.progress(f"{what}, stepping back {back:.2f} m from {name} first: {plan.describe()}")
                self.body.execute(plan.q, what=what, progress=self.progress)
                return plan.n_steps
        if room is not None:
            self._make_room(f"room to {what}", room)
        plan = self.planners.turn(angle_rad)
        self.progress(f"{what}: {plan.describe()}")
        self.body.execute(plan.q, what=what, progress=self.progress)
        return plan.n_steps
