"""The ``put`` action: a held object onto a place (a part of :class:`supervisor.actions.Actions`).

"Hand reaching to a position in 3D ... gripper opening" (Fig. 11 of ``001_771c0ce3779b0683.txt``): the
object is brought above the place (footsteps/plan's last steps, ``reaching/reach``), lowered by a
guarded move until it touches the place (``sim/execute`` with ``touch``), released and the hand
withdrawn. The shared hand motions (``_move_hand``, ``_last_steps``, ...) are in ``manipulation.py``.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Sequence

import numpy as np

from services.bus.schemas import sim as sim_msg
from services.errors import (
    HumanoidError,
    InfeasibleError,
    InvalidRequestError,
    NotFoundError,
    NotGraspedError,
    WorldOutcomeError,
)
from supervisor.body import Executed
from supervisor.parts import ActionParts
from supervisor.planners import LastSteps, Plan
from supervisor.report import ActionReport
from supervisor.scene_map import BoxEstimate, box_estimate, neighbours, ray_entry
from supervisor.script import Step

#: A ball whose bottom is within this [m] of a place's top, over its map rectangle grown by as much, lies
#: on the place (the put's release point keeps clear of it).
ON_TOP_M = 0.05


def toward_edge(centre: np.ndarray, contacts: list[np.ndarray], edge_deg: float) -> np.ndarray | None:
    """Whether a lowered object touched a surface only on its side: every contact point [m] (world)
    more than ``edge_deg`` off straight below ``centre`` (the object's, or the grasp frame's) [m] (its
    side on an edge, the object hanging over it: released there it falls off). The horizontal unit
    vector from ``centre`` toward those contacts (where the surface is), or None when a contact lies
    under it (it stands on the top) or there is none."""
    sideways = np.zeros(2)
    for contact in contacts:
        offset = np.asarray(contact, dtype=float) - np.asarray(centre, dtype=float)
        across = float(np.linalg.norm(offset[:2]))
        if math.degrees(math.atan2(across, -offset[2])) <= edge_deg:
            return None
        sideways += offset[:2] / max(across, 1e-9)
    norm = float(np.linalg.norm(sideways))
    return sideways / norm if norm > 1e-9 else None


def clear_of(
    xy: np.ndarray, robot_xy: np.ndarray, balls: Sequence[np.ndarray], clear_m: float, forearm_m: float
) -> bool:
    """Whether every ball centre (x, y) [m] lies ``clear_m`` or farther from the release point ``xy``
    [m] and from the forearm's way to it: the segment from ``xy`` ``forearm_m`` toward ``robot_xy``
    (the hand comes down from the robot's side, its forearm behind it)."""
    toward = np.asarray(robot_xy, dtype=float) - xy
    norm = float(np.linalg.norm(toward))
    end = xy + toward * min(1.0, forearm_m / norm) if norm > 1e-9 else xy
    for ball in balls:
        d = end - xy
        t = float(np.clip(np.dot(ball - xy, d) / max(float(np.dot(d, d)), 1e-12), 0.0, 1.0))
        if float(np.linalg.norm(ball - (xy + t * d))) < clear_m:
            return False
    return True


def arm_only(collisions: Sequence[sim_msg.Contact], obj: str) -> bool:
    """Whether a lowering that stopped on the place was stopped by the robot's own links only, not by
    the held object ``obj`` (its contacts' ``robot_link`` is ``held:<obj>``): a wrist force sensor
    feels both alike, but only the object's contact says it stands on the place."""
    return bool(collisions) and all(c.robot_link != f"held:{obj}" for c in collisions)


class PutActions(ActionParts):
    """The put action (a part of :class:`supervisor.actions.Actions`; the hand motions it shares with the
    grasp are :class:`supervisor.manipulation.ManipulationActions`')."""

    do_look_at: Callable[[Step], ActionReport]
    _back_off: Callable[[str, list[str]], None]
    _move_hand: Callable[..., int]
    _raise_hand: Callable[..., None]
    _last_steps: Callable[..., LastSteps | None]
    _walk_nearer: Callable[[str, np.ndarray, str], bool]
    _final_hand: Callable[..., list[float] | None]
    _as_planned: Callable[..., int | None]
    _hand_at: Callable[..., bool]
    _lift_and_carry: Callable[..., None]

    def do_put(self, step: Step) -> ActionReport:
        """Put the held object on a place: look at the place, step up to it (footsteps/plan), bring the
        object above it, lower it until it touches the place (a guarded move: perception's estimate of
        a table's height is rough), open the hand, withdraw it. Lowered down to ``put_lowest_m``
        without touching: raise it, localize the place again from here and try once more."""
        obj = step.args[0]
        place = step.kwargs.get("on")
        if not place:
            raise InvalidRequestError("put needs a place: `put OBJECT on=PLACE`")
        held = self.body.held()
        hand = next((side for side, name in held.items() if name == obj), None)
        if hand is None:
            holding = ", ".join(f"{n} in the {s} hand" for s, n in held.items()) or "nothing"
            raise NotGraspedError(f"cannot put {obj}: the robot holds {holding}", {"object": obj})
        allowed = [obj]
        missed: np.ndarray | None = None  # where the object went down onto nothing
        for attempt in (1, 2):
            # Look at the place (again, on the second attempt: from nearer, with the object above it).
            self.progress(self.do_look_at(Step(step.line, "look_at", (place,))).message)
            point = self._put_point(place, missed=missed)
            decided = self._last_steps(hand, point, point, f"step up to {place}", allowed=allowed)
            if decided is None and self._walk_nearer(place, point, f"step up to {place}"):
                self.do_look_at(Step(step.line, "look_at", (place,)))
                point = self._put_point(place, missed=missed)
                decided = self._last_steps(hand, point, point, f"step up to {place}", allowed=allowed)
            self._raise_hand(hand, float(point[2]), f"raise {obj}", allowed=allowed)
            final = self._final_hand(decided, place, "put")
            # ... and the whole final posture planned with it (reaching executes it: paper 000 §7; the
            # hand's task in footsteps/plan was this very point)
            posture = decided.q_final if decided is not None and final is not None else None
            what = f"bring {obj} above {place}"
            if self._as_planned(hand, point, what, allowed, final, place, posture=posture) is None:
                self._move_hand(hand, point, what, allowed=allowed, stepping=True)
            what = f"lower {obj} onto {place}"
            executed, low_z = self._lower_onto(hand, point, place, final, allowed, what)
            if executed.touched:
                executed = self._onto_the_top(hand, obj, place, executed, allowed, final)
                break
            if attempt == 2:
                raise NotFoundError(
                    f"lowered {obj} down to {low_z:.2f} m twice without touching {place}: it is not "
                    f"where perception saw it, even seen again from here",
                    {"object": place, "reason": "no_surface"},
                )
            self.progress(
                f"lowered {obj} down to {low_z:.2f} m without touching {place}: raising it and "
                f"localizing {place} again"
            )
            # Measured: the place's map rectangle holds a point with nothing under it.
            self.memory.drop_footprint(place)
            missed = point
            # raised again, then carried for the next last steps
            self._lift_and_carry(hand, allowed, f"raise {obj} again", up=point, motions=("raise", "carry"))
            if self._view_again(place, point):
                missed = None  # mapped anew from a whole view: the put point comes from that rectangle
        robot = self.body.robot
        at = robot.grasp_position(executed.q, hand)
        reply = self.body.gripper(hand, "open")
        self.memory.holding.pop(hand, None)
        if reply.released != obj:
            raise NotGraspedError(
                f"opening the {hand} hand released {reply.released or 'nothing'}, not {obj}"
            )
        self.progress(f"released {obj} on {place}: withdrawing the {hand} hand")
        note = ""
        try:
            withdraw = ("withdraw", "withdraw")
            self._lift_and_carry(hand, [place, obj], f"withdraw from {place}", motions=withdraw)
        except WorldOutcomeError as exc:  # the object is on the place: the put is done, the withdrawal is not
            note = f" (withdrawing the hand stopped: {exc.message})"
            touched = [c.other for c in exc.details.get("collisions", [])]
            with contextlib.suppress(HumanoidError):
                self._back_off(hand, sorted({*touched, place, obj}))
        return ActionReport(
            "put",
            step.args,
            message=f"{obj} put on {place} at ({at[0]:.2f}, {at[1]:.2f}, {at[2]:.2f}) m{note}",
            details={"point": at.tolist(), "on": place, "hand": hand},
        )

    def _view_again(self, place: str, missed: np.ndarray) -> bool:
        """After a put at ``missed`` (world [m]) touched nothing: see ``place`` again from where its
        whole outline is in view. From beside it (nearer than perception's footprint depth, cut by the
        image borders, the arm and the held object in front) it has no floor rectangle, and the middle
        of its silhouette was no better (fetch seeds 21, 23). Navigation walks back to ``put_view_m``
        from the point that missed (checked against the map), facing it; there perception maps it
        from its outline again (occluded edges left out). Whether it got a floor rectangle (else the
        retry goes toward the middle of its silhouette, as before)."""
        x, y, _yaw = self.body.base_xy_yaw()
        away = np.array([x, y]) - missed[:2]
        u = away / max(float(np.linalg.norm(away)), 1e-6)
        stand = missed[:2] + u * self.config.put_view_m
        what = f"view {place} again"
        self.body.straighten()
        try:
            plan = self.planners.goto_pose(float(stand[0]), float(stand[1]), math.atan2(-u[1], -u[0]))
        except InfeasibleError as exc:
            self.progress(f"{what}: no walk back to {self.config.put_view_m:.1f} m from it ({exc.message})")
            return False
        self.progress(
            f"{what}: from {self.config.put_view_m:.1f} m, its whole outline in view ({plan.describe()})"
        )
        self.body.execute(plan.q, what=what, progress=self.progress)
        self.body.straighten()
        with contextlib.suppress(NotFoundError):
            self.eyes.look_at(missed, f"look at {place}")
            self.eyes.localize(place, turn=lambda *_: None, progress=self.progress, look_around=False)
        sighting = self.memory.sightings.get(place)
        if sighting is not None:
            self.progress(f"{what}: {sighting.describe()}")
        return sighting is not None and sighting.footprint is not None

    @staticmethod
    def _contacts(executed: Executed) -> str:
        """The contacts that stopped ``executed``, for the transcript: link (x, y, z) m, ..."""
        return ", ".join(
            f"{k.robot_link} at ({k.position[0]:.2f}, {k.position[1]:.2f}, {k.position[2]:.2f})"
            for k in executed.reply.collisions
        )

    def _beside_edge(self, hand: str, obj: str, executed: Executed) -> np.ndarray | None:
        """:func:`toward_edge` of the contacts of the held ``obj`` that stopped ``executed``, seen from
        the ``hand``'s grasp frame; None when it stands on the top, or when only the arm touched
        (:func:`arm_only`, :meth:`_onto_the_top`)."""
        held = [c.position for c in executed.reply.collisions if c.robot_link == f"held:{obj}"]
        if not held:
            return None
        centre = self.body.robot.grasp_position(executed.q, hand)
        return toward_edge(centre, [np.asarray(p, dtype=float) for p in held], self.config.put_edge_deg)

    def _onto_the_top(
        self,
        hand: str,
        obj: str,
        place: str,
        executed: Executed,
        allowed: list[str],
        final: list[float] | None,
    ) -> Executed:
        """After a lowering stopped on touching ``place``, until the held object itself stands on it:

        * only the arm touched (:func:`arm_only`: the wrist below the object came onto the top, the
          object hanging beside or above it; released there it rolled off the near edge, fetch seed
          52): a collision, not a put. The touch measured the top there; the object is lifted by
          ``put_height_m``, moved ``put_edge_shift_m`` further along the approach (from the robot's
          mid-feet point toward the object: the arm reaches over the near edge, the top lies ahead)
          and lowered again, once; an arm touch after that move is taken as the object on the top;
        * the object touched only on its side (:meth:`_beside_edge`: hanging over an edge; released
          there it falls off, fetch seed 5): raised by ``put_height_m``, moved ``put_edge_shift_m``
          toward the contacts (onto the top) and lowered again.

        At most ``put_edge_tries`` such moves. The last lowering's execution."""
        c = self.config
        moved_for_arm = False
        for _ in range(c.put_edge_tries):
            here = self.body.robot.grasp_position(executed.q, hand)
            if arm_only(executed.reply.collisions, obj) and not moved_for_arm:
                x, y, _yaw = self.body.base_xy_yaw(executed.q)
                ahead = here[:2] - (x, y)
                inward = ahead / max(float(np.linalg.norm(ahead)), 1e-6)
                moved_for_arm = True
                self.progress(
                    f"the arm, not {obj}, touched {place}: lifting it and moving it "
                    f"{c.put_edge_shift_m:.2f} m further onto the top"
                )
            else:
                inward = self._beside_edge(hand, obj, executed)
                if inward is None:
                    return executed
                self.progress(
                    f"{obj} touched {place} on its side (over an edge): moving it "
                    f"{c.put_edge_shift_m:.2f} m onto the top and lowering it again"
                )
            up = here + np.array([0.0, 0.0, c.put_height_m])
            off = [*allowed, place]  # it starts on the top or its edge
            self._move_hand(hand, up, f"lift {obj} off {place}", allowed=off, stepping=False)
            over = up + np.array([inward[0], inward[1], 0.0]) * c.put_edge_shift_m
            self._move_hand(hand, over, f"{obj} over the top", allowed=allowed, stepping=False)
            what = f"lower {obj} onto {place} again"
            executed, low_z = self._lower_onto(hand, over, place, final, allowed, what)
            if not executed.touched:
                raise NotFoundError(
                    f"moved {obj} {c.put_edge_shift_m:.2f} m onto the top of {place} and "
                    f"lowered it to {low_z:.2f} m without touching it",
                    {"object": place, "reason": "no_surface"},
                )
        return executed

    def _lower_onto(
        self,
        hand: str,
        above: np.ndarray,
        place: str,
        final: list[float] | None,
        allowed: list[str],
        what: str,
    ) -> tuple[Executed, float]:
        """Lower the held object from ``above`` (world [m]) by ``put_depth_m`` (not below
        ``put_lowest_m``) until it touches ``place``: the execution (its ``touched`` reported) and the
        lowest height planned [m]."""
        low = above.copy()
        low[2] = max(self.config.put_lowest_m, above[2] - self.config.put_depth_m)
        plan = self._lowering(hand, low, final)
        self.progress(
            f"{what} from ({above[0]:.2f}, {above[1]:.2f}, {above[2]:.2f}) m: {plan.describe()}, "
            "until it touches"
        )
        executed = self.body.execute(
            plan.q, what=what, allowed_contacts=allowed, progress=self.progress, touch=place
        )
        if executed.touched:
            self.progress(f"{what}: touched by {self._contacts(executed)}")
        return executed, float(low[2])

    def _lowering(self, hand: str, low: np.ndarray, final: list[float] | None) -> Plan:
        """The guarded lowering of a held object to ``low`` (no stepping): the hand keeping the
        orientation of footsteps/plan's final posture when it is in it (``final``), else position only
        (also when reaching refuses the former)."""
        if final is not None and self._hand_at(hand, final):
            with contextlib.suppress(InfeasibleError):
                return self.planners.reach(hand, low, orientation=final, allow_stepping=False)
        return self.planners.reach(hand, low, yaw_rad=None, allow_stepping=False)

    def _put_point(self, place: str, *, missed: np.ndarray | None = None) -> np.ndarray:
        """Where the object goes before being lowered: inside the place's near face (as the map
        estimates it), above the highest its top can be (capped: a rough silhouette overestimates).
        After a put that went down at ``missed`` onto nothing: from there toward the middle of the
        place's silhouette in its last sighting (a point on the place itself, whatever the map's
        rectangle), by ``put_retry_shift_m`` at most (the feet stay near where they are: a map box from
        a close-up silhouette can be smaller than the place, the legs of a table outside it)."""
        sighting = self.memory.get(place)
        box = box_estimate(sighting)
        top = min(box.top_z_m, self.config.put_highest_m)
        if missed is not None:
            to_middle = sighting.position_m[:2] - missed[:2]
            dist = float(np.linalg.norm(to_middle))
            shift = min(dist, self.config.put_retry_shift_m) / max(dist, 1e-6)
            xy = missed[:2] + shift * to_middle
            return np.array([xy[0], xy[1], top + self.config.put_height_m])
        x, y, _ = self.body.base_xy_yaw()
        centre = np.array(box.center_m[:2])
        to_centre = centre - (x, y)
        dist = float(np.linalg.norm(to_centre))
        u = to_centre / max(dist, 1e-6)
        face = min(dist, ray_entry(box, np.array([x, y]), u))
        ahead = min(dist, max(0.0, face) + self.config.put_inside_m)
        xy = self._clear_of_balls(np.array([x, y]) + u * ahead, box, place, np.array([x, y]))
        return np.array([xy[0], xy[1], top + self.config.put_height_m])

    def _clear_of_balls(
        self, xy: np.ndarray, box: BoxEstimate, place: str, robot_xy: np.ndarray
    ) -> np.ndarray:
        """``xy`` [m], or, when a ball seen on the place (not held) lies within ``put_clear_m`` of it or
        of the forearm's way over the place (:func:`clear_of`), the nearest point of the place's top
        (``put_edge_margin_m`` inside its map rectangle, on a 2 cm grid) clear of them all; ``xy`` when
        there is none. A ball is on the place when its centre lies over the place's map rectangle
        (grown by ``ON_TOP_M``: the map's error) and its bottom within ``ON_TOP_M`` of the top (a ball
        on the floor in front of a table is not)."""
        c = self.config
        reach = c.put_clear_m + c.put_forearm_m + max(box.size_m[:2])  # any ball on the place's top
        over = box.footprint.grown(ON_TOP_M)
        balls = [
            centre[:2]
            for centre, radius in neighbours(self.memory, xy, reach, exclude={place})
            if over.contains(centre[:2]) and abs(centre[2] - radius - box.top_z_m) <= ON_TOP_M
        ]
        if not balls or clear_of(xy, robot_xy, balls, c.put_clear_m, c.put_forearm_m):
            return xy
        rect = box.footprint
        half = np.asarray(rect.size_m) / 2.0 - c.put_edge_margin_m
        if (half <= 0.0).any():
            return xy
        grid = np.stack(np.meshgrid(*(np.arange(-h, h + 1e-9, 0.02) for h in half)), axis=-1).reshape(-1, 2)
        points = rect.to_world(grid)
        free = [p for p in points if clear_of(p, robot_xy, balls, c.put_clear_m, c.put_forearm_m)]
        if not free:
            return xy
        best = min(free, key=lambda p: float(np.linalg.norm(p - xy)))
        self.progress(
            f"the balls seen on {place} lie near the release point: releasing at ({best[0]:.2f}, "
            f"{best[1]:.2f}) instead, clear of them"
        )
        return np.asarray(best, dtype=float)
