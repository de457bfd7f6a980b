"""Remedies the retry policy applies before retrying a failed action: ``relocalize``, ``replan``,
``wait_service`` (supervisor/retry.py maps failure reasons to them)."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

import numpy as np

from services.bus.schemas import sim as sim_msg
from services.bus.schemas import walking as walk_msg
from services.errors import FellError, InfeasibleError, InvalidRequestError, UnavailableError
from supervisor.health import HealthMonitor
from supervisor.parts import ActionParts
from supervisor.report import ActionReport
from supervisor.scene_map import boxes, distance_to_box, is_obstacle
from supervisor.script import Step, parse_point


def _arm_link(link: str) -> bool:
    """Whether a robot link (or ``held:<object>``) of a collision report is an arm, a hand or held."""
    upper = link.upper()
    return link.startswith("held:") or any(part in upper for part in ("ARM", "HAND", "GRIPPER", "WRIST"))


class Remedies(ActionParts):
    """The remedies (a part of :class:`supervisor.actions.Actions`)."""

    health: HealthMonitor
    stop: threading.Event
    last_reach: tuple[str, str] | None
    do_reach: Callable[[Step], ActionReport]
    _turn_rad: Callable[[float, str], int]
    _survey: Callable[[set[str]], None]
    _move_hand: Callable[..., int]
    _arm_motion: Callable[..., None]
    _support: Callable[[str], list[str]]

    def relocalize(self, step: Step, report: ActionReport) -> None:
        """Localize the step's object again (for a grasp: after a miss, ``not_grasped`` with nothing in
        the hand, the hand and the stance made ready first, :meth:`_ready_after_a_miss`; then the
        reached object, then reach again)."""
        if step.action == "grasp":
            if self.last_reach is None:
                return
            hand, target = self.last_reach
            missed = report.reason == "not_grasped" and hand not in self.body.held()
            if missed:
                self._ready_after_a_miss(hand, target)
            if parse_point(target, 3, "target") is None:
                # after a miss the hand hangs beside the body, out of view; else (a collision, a
                # refusal) it may still be at the object, hiding it: backed off it when it does
                self.eyes.localize(
                    target,
                    turn=self._turn_rad,
                    progress=self.progress,
                    clear_view=None
                    if missed
                    else (lambda: self._back_off(hand, [target, *self._support(target)])),
                )
            self.progress(f"reaching {target} again")
            self.do_reach(Step(step.line, "reach", (hand, target)))
            return
        target = {"reach": 1, "goto": 0, "look_at": 0, "detect": 0, "localize": 0}.get(step.action)
        if target is None or target >= len(step.args):
            return
        name = step.args[target]
        if parse_point(name, 3, "target") is None and name not in self.memory.holding.values():
            self.eyes.localize(name, turn=self._turn_rad, progress=self.progress)

    def _ready_after_a_miss(self, hand: str, target: str) -> None:
        """After the ``hand`` closed on nothing at ``target``, before looking again and reaching again.

        The open hand is where the lowering left it, beside the object, maybe on its support (contacts
        the lowering was allowed); a head turn allows none, so a look from there stopped at once
        (fetch seed 46: the wrist on the box), and the stopped turn left a sole 2.5 mm up and tilted
        0.020 rad, from which reaching refused to plan the retry (``invalid_request``). So: the hand
        straight up off the object and its support (``back_off_m`` x 1.5), then down beside the body
        where it hangs in the half-sitting posture (out of the cameras' view of the object: with the
        hand at the carry point instead, the ball was not found from the next stance, and seen 4.4
        cm off from the one before), the chest upright, and ``walking/goal`` squares the stance
        (``kind: square``: the rear foot stepped beside the front one, checked against the map; no
        step when the stance is square already) so that the retry plans from a square stance. A part
        a planner refuses is reported and skipped."""
        object_target = parse_point(target, 3, "target") is None
        allowed = [target, *self._support(target)] if object_target else []
        robot = self.body.robot
        up = robot.grasp_position(self.body.q(), hand) + np.array([0.0, 0.0, 1.5 * self.config.back_off_m])
        try:
            self._move_hand(hand, up, f"lift the {hand} hand off {target}", allowed=allowed, stepping=False)
            x, y, yaw = self.body.base_xy_yaw()
            rest = robot.grasp_position(robot.place_on_ground(robot.q_half_sitting, x, y, yaw), hand)
            what = f"the {hand} hand down beside the body"
            self._arm_motion(hand, rest, what, allowed=allowed, motion="withdraw")
        except (InfeasibleError, InvalidRequestError) as exc:
            self.progress(f"the {hand} hand stays where it is ({exc.message})")
        self.body.straighten()
        self.settle()  # a sole left up or tilted (a stopped look, seed 46): no stance is planned from there
        try:
            plan = self.planners.square()
        except (InfeasibleError, InvalidRequestError) as exc:
            square = exc.details.get("reason") == walk_msg.REASON_ALREADY_SQUARE
            if isinstance(exc, InvalidRequestError) and not square:
                raise  # a request walking could not read: not a stance to keep
            self.progress(f"the stance stays as it is ({exc.message})")
            return
        self.progress(f"square the stance: {plan.describe()}")
        self.body.execute(plan.q, what="square the stance", progress=self.progress)

    def replan(self, step: Step, report: ActionReport) -> None:
        """After a collision, one sequence, each motion planned by a planner, then the retry plans again
        from the state the robot is in (planners are stateless, the actions plan from ``sim/state``):

        1. a leg or the body touched, or the robot stopped with a foot up: play the end of the stopped
           motion backward (:meth:`Body.back_out`);
        2. each hand that touched backs off (reaching, no stepping, the touched objects allowed); when
           reaching refuses and the motion that touched was stopped, that motion is backed out instead
           (the hand came there with the body: its own back-off would move the CoM out of the support,
           table_to_box); when reaching refuses the start (a sole not flat), the feet settle first;
        3. :meth:`settle`: both soles back flat and the body over them (``walking/goal`` ``kind:
           settle`` from the measured configuration) when a sole was left up or tilted; ``infeasible``
           ``leaning`` (held up by what it touches) ends the retries;
        4. what was hit goes to the map if the map lacks it, the goal is localized again.

        A motion of the sequence may start in contact with what was hit: the sim lets it leave that
        contact, not push into it (sim/README "Contacts at the start")."""
        if self.body.state().fallen:
            raise FellError("the robot fell: it cannot replan from the ground")
        collisions: list[sim_msg.Contact] = report.details.get("collisions") or []
        touched = sorted({c.other for c in collisions})
        links = " ".join(c.robot_link.upper() for c in collisions)
        if self.body.interrupted is not None and (
            any(not _arm_link(c.robot_link) for c in collisions) or not self.body.standing()
        ):
            self.body.back_out(self.progress)  # a leg or the body hit it, or a foot is up: undo the end
        for hand, tag in (("right", "RARM"), ("left", "LARM")):
            if tag in links or ("held:" in links.lower() and hand in self.body.held()):
                try:
                    self._back_off(hand, touched)
                except (InfeasibleError, InvalidRequestError) as exc:
                    if self.body.interrupted is not None:
                        self.progress(f"the {hand} hand cannot back off alone ({exc.message}): backing out")
                        self.body.back_out(self.progress)
                    elif isinstance(exc, InvalidRequestError):  # e.g. a sole not flat: settled, then again
                        self.progress(f"the {hand} hand cannot back off from here ({exc.message})")
                        self.settle()
                        self._back_off(hand, touched)
                    else:
                        raise
        try:
            self.settle()
        except InfeasibleError as exc:
            if exc.details.get("reason") != walk_msg.REASON_LEANING or not touched:
                raise
            raise InfeasibleError(f"{exc.message} (it touched {', '.join(touched)})", exc.details) from exc
        self._remember_felt(collisions)
        self._map_what_was_hit([c.position for c in collisions])
        self.relocalize(step, report)

    def settle(self) -> None:
        """Both soles back flat on the ground and the body over them, planned by walking from the
        measured configuration (``walking/goal`` ``kind: settle``), when the planners would refuse to
        start from it (:meth:`Body.plannable`; walking also answers ``already_settled`` within 1 mm).
        A back-out or a stopped motion can leave a sole 3 mm - 1.4 cm up or tilted
        0.025-0.16 rad, from which reaching, footsteps and walking refuse to plan.

        When the robot is still not standing as the planners want it after a settle (both soles within
        5 mm and 0.02 rad: measured, :meth:`Body.plannable`), one more settle from there.

        Raises:
            InfeasibleError: ``details.reason`` ``leaning`` (final in the retry policy): the robot is held
                up by something it touches (walking refused, or the robot stays tilted after two
                settles: box_near's shank on the table left both soles tilted 1.2 deg); other refusals
                as walking gives them.
        """
        if self.body.plannable():  # the planners start from here: nothing to settle
            return
        said = ""
        for _ in range(2):  # a second settle from where the first one left the robot
            try:
                plan = self.planners.walk_goal(walk_msg.GoalRequest(q_start=self.body.q(), kind="settle"))
            except InvalidRequestError as exc:
                if exc.details.get("reason") == walk_msg.REASON_ALREADY_SETTLED:
                    return
                raise
            except InfeasibleError as exc:
                if exc.details.get("reason") != walk_msg.REASON_LEANING:
                    raise
                raise InfeasibleError(
                    f"the robot cannot settle its feet: {exc.message}", exc.details
                ) from exc
            self.progress(f"settle the feet: {plan.describe()}")
            done = self.body.execute(plan.q, what="settle the feet", progress=self.progress)
            said = ", ".join(
                f"{side} sole {1e3 * z:.1f} mm up, tilted {math.degrees(tilt):.2f} deg"
                for side, (z, tilt) in self.body.soles(done.q).items()
            )
            self.progress(f"the feet settled: {said}")
            if self.body.plannable(done.q):
                return
        raise InfeasibleError(
            f"the robot cannot settle its feet: it stays tilted after settling twice ({said}): it leans on "
            "something it touches",
            {"reason": walk_msg.REASON_LEANING},
        )

    def _remember_felt(self, collisions: list[sim_msg.Contact]) -> None:
        """Contacts of a hand with a small object other than the one reached for (a ball beside the
        target, seen in passing or not seen at all) go to the memory's felt points: the next reach
        approaches clear of them (ManipulationActions._clear_of_felt). Objects on the map (boxes,
        tables) are not felt points."""
        reached = self.last_reach[1] if self.last_reach is not None else None
        for contact in collisions:
            seen = self.memory.sightings.get(contact.other)
            if (
                _arm_link(contact.robot_link)
                and contact.other != reached
                and (seen is None or not is_obstacle(seen))
            ):
                self.memory.felt.append(np.asarray(contact.position, dtype=float))

    def _map_what_was_hit(self, contacts: list[list[float]]) -> None:
        """A contact off every mapped box (by more than ``self.config.mapped_margin_m``) hit something the map
        lacks: look at the first such contact point and put what is in view on the map."""
        mapped = boxes(self.memory)
        for point in contacts:
            if all(distance_to_box(box, point[0], point[1]) > self.config.mapped_margin_m for box in mapped):
                self.eyes.look_at(np.asarray(point, dtype=float), "look at what was hit")
                self._survey(exclude=set())
                return

    def _back_off(self, hand: str, touched: list[str]) -> None:
        """Move ``hand`` out of contact with ``touched`` (no stepping): back and up; when it was coming
        down onto the object it reaches, straight up first (the fingers leave the way they came, clear
        of the object and its neighbours), then back (out of the camera's line of sight to it)."""
        q = self.body.q()
        robot = self.body.robot
        here = robot.grasp_position(q, hand)
        _x, _y, yaw = self.body.base_xy_yaw(q)
        allowed = touched + list(self.body.held().values())
        back = -self.config.back_off_m * np.array([math.cos(yaw), math.sin(yaw), -1.0])
        self.progress(f"backing the {hand} hand off {', '.join(touched)}")
        if self.last_reach is not None and self.last_reach[0] == hand and hand not in self.body.held():
            if parse_point(self.last_reach[1], 3, "target") is None:
                allowed.append(self.last_reach[1])
            up = here + np.array([0.0, 0.0, 1.5 * self.config.back_off_m])
            self._move_hand(
                hand,
                up,
                f"lift the {hand} hand off",
                allowed=sorted(set(allowed)),
                stepping=False,
            )
            here, back = up, 2.0 * back * np.array([1.0, 1.0, 0.0])
        self._move_hand(
            hand,
            here + back,
            f"back the {hand} hand off",
            allowed=sorted(set(allowed)),
            stepping=False,
        )

    def wait_service(self, step: Step, report: ActionReport) -> None:
        """Wait for the failed service's liveliness token (the launcher restarts dead services)."""
        service = str(report.details.get("service", ""))
        if not service:
            return
        self.progress(f"waiting for service {service} to come back")
        started = time.monotonic()
        if not self.health.wait_alive(service, self.config.wait_service_s, self.stop):
            raise UnavailableError(
                f"service {service!r} did not come back within {self.config.wait_service_s:.0f} s; "
                "is `humanoid up` running?",
                {"service": service},
            )
        self.progress(f"service {service} is back after {time.monotonic() - started:.1f} s")
