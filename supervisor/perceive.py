"""Seeing objects: one ``perception/locate`` call, and the look-around search when not in view.

The search follows perception's plan for it (``perception/look_around``, services/perception/look_around.py):
the head scans rows of pan angles at a few gaze depressions (``views``), then the body turns on the
spot (``turns_rad``, relative to the heading at the start) and the head scans again. An object
that is seen off the image centre is looked at and localized again: the paper "localizes precisely the
colored ball" once it is close (Fig. 11 (c)); the centroid stereo is most accurate away from borders.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from services.bus.schemas import perception as perception_msg
from services.errors import InfeasibleError, NotFoundError
from supervisor.body import Body, Progress
from supervisor.calls import ServiceCaller
from supervisor.config import SupervisorConfig
from supervisor.memory import Memory, Sighting
from supervisor.scene_map import boxes, distance_to_box, is_obstacle, viewpoints_past

#: NotFoundError reasons of perception/locate that another viewpoint may fix ("": none given).
LOOK_AROUND_REASONS = (*perception_msg.VIEWPOINT_REASONS, "")
LOCATE_TIMEOUT_S = 20.0


class Eyes:
    """``perception/locate`` from the robot's current configuration, and the look-around search."""

    def __init__(
        self, bus: ServiceCaller, body: Body, memory: Memory, config: SupervisorConfig | None = None
    ) -> None:
        self.bus = bus
        self.config = config or SupervisorConfig()
        self.body = body
        self.memory = memory
        self._shapes: dict[str, str] | None = None  # perception's models: name -> shape, asked once
        self._last_box: tuple[float, float] | None = None  # image box centre [px] of the last sighting

    def locate(self, name: str, q: np.ndarray | None = None, camera: str = "wide") -> Sighting:
        """Localize ``name`` now (no motion) with the head's ``camera`` pair; NotFoundError from
        perception otherwise."""
        q = self.body.q() if q is None else q
        return self._locate(name, q, camera, others=True)

    def _locate(self, name: str, q: np.ndarray, camera: str, *, others: bool) -> Sighting:
        """:meth:`locate`; with ``others``, the balls perception saw in the same images besides
        ``name`` are remembered too (:meth:`_remember_in_passing`)."""
        reply = self.bus.call(
            perception_msg.LOCATE,
            perception_msg.LocateRequest(
                object=name, model=self.body.robot.name, q=q, camera=camera, others=others
            ),
            LOCATE_TIMEOUT_S,
        )
        T = np.asarray(reply.T_world_camera, dtype=float)
        sighting = Sighting(
            name=name,
            position_m=np.asarray(reply.position, dtype=float),
            size_m=(float(reply.size_m[0]), float(reply.size_m[1])),
            distance_m=float(reply.distance_m),
            confidence=float(reply.confidence),
            sim_time_s=float(reply.sim_time_s),
            camera_m=T[:3, 3].copy(),
            footprint=reply.footprint,
        )
        self._last_box = (reply.box_left.u_px, reply.box_left.v_px)
        kept = self.memory.remember(sighting)  # (with the better-supported footprint)
        # then what was seen in passing: its bookkeeping (a bus call for the models' shapes) failing
        # cannot lose the sighting asked for
        self._remember_in_passing(reply, sighting.camera_m)
        return kept

    def _remember_in_passing(self, reply: perception_msg.LocateReply, camera_m: np.ndarray) -> None:
        """The balls (models of shape "sphere") seen in the images of ``reply`` besides the object
        asked for go to memory, except a held one: the neighbours of a ball to grasp are then on the
        map before the first touch (the hand's approach keeps clear of them). Boxes, tables and chairs
        seen in passing are not: the survey maps them with their footprints (perception gives none in
        passing), and a sighting without one could replace a better one."""
        if not reply.others:
            return
        shapes = self._model_shapes()
        held = set(self.memory.holding.values())
        for seen in reply.others:
            if shapes.get(seen.object) != "sphere" or seen.object in held:
                continue
            self.memory.remember(
                Sighting(
                    name=seen.object,
                    position_m=np.asarray(seen.position, dtype=float),
                    size_m=(float(seen.size_m[0]), float(seen.size_m[1])),
                    distance_m=float(seen.distance_m),
                    confidence=float(seen.confidence),
                    sim_time_s=float(reply.sim_time_s),
                    camera_m=camera_m,
                )
            )

    def _model_shapes(self) -> dict[str, str]:
        """Perception's learned objects and their model shapes ("sphere": a ball; "blob"), asked once."""
        if self._shapes is None:
            reply = self.bus.call(perception_msg.MODELS, perception_msg.ModelsRequest(), LOCATE_TIMEOUT_S)
            self._shapes = {o.name: o.shape for o in reply.objects}
        return self._shapes

    def survey(self, progress: Progress, exclude: set[str]) -> list[str]:
        """Localize, in the current view, every learned object that is not a ball (models of shape
        "blob": boxes, tables, chairs) except ``exclude``: navigation avoids the obstacles it knows of
        ("avoiding known obstacles", Fig. 10 of the motion-autonomy paper), so whatever big object is in
        view goes on the map before a walk is planned. One seen but not localized by the wide pair (too
        close: out of one camera's view) is tried with the narrow, 90 deg one. Returns the names seen."""
        blobs = [name for name, shape in self._model_shapes().items() if shape != "sphere"]
        q = self.body.q()
        seen = []
        last_box = self._last_box
        for name in blobs:
            if name in exclude:
                continue
            try:  # each is asked for: nothing in passing
                self._locate(name, q, "wide", others=False)
            except NotFoundError as exc:
                if exc.details.get("reason") == perception_msg.REASON_NOT_IN_VIEW:
                    continue
                try:  # close by (out of one wide camera's view, cut by the borders): the near pair
                    self._locate(name, q, "narrow", others=False)
                except NotFoundError:
                    continue
            seen.append(name)
        self._last_box = last_box
        if seen:
            progress(f"in view: {', '.join(seen)} (on the map for navigation)")
        return seen

    def off_centre(self) -> float:
        """How far the last sighting's image box is from the image centre (fraction of the half-width)."""
        if self._last_box is None:
            return 0.0
        u, v = self._last_box
        width, height = (float(n) for n in self.body.robot.head.image_size_px)
        return max(abs(u - width / 2), abs(v - height / 2) * width / height) / (width / 2)

    def look_at(self, point_m: np.ndarray, what: str) -> None:
        q = self.body.q()
        pan, tilt = self.body.head_angles_towards(q, point_m)
        self.body.move_head(pan, tilt, what=what)

    def beyond_head(self, point_m: np.ndarray) -> float:
        """The bearing [rad] of ``point_m`` from the robot's heading when the head's pan range does not
        reach it (0 when it does)."""
        x, y, yaw = self.body.base_xy_yaw()
        bearing = math.remainder(math.atan2(point_m[1] - y, point_m[0] - x) - yaw, 2 * math.pi)
        (pan_lo, pan_hi), _ = self.body.head_limits()
        return 0.0 if pan_lo <= bearing <= pan_hi else bearing

    def face(self, point_m: np.ndarray, turn: Callable[[float, str], None], what: str) -> None:
        """Look at ``point_m`` [m], turning the body first (``turn(angle_rad, why)``) when the head's pan
        range does not reach it: the point then lies halfway into that range."""
        bearing = self.beyond_head(point_m)
        if bearing:
            (pan_lo, pan_hi), _ = self.body.head_limits()
            turn(bearing - math.copysign(min(abs(pan_lo), abs(pan_hi)) * 0.5, bearing), f"turn toward {what}")
        self.look_at(point_m, f"look at {what}")

    def localize(
        self,
        name: str,
        *,
        turn: Callable[[float, str], None],
        progress: Progress,
        look_around: bool = True,
        clear_view: Callable[[], None] | None = None,
        view_from: Callable[[float, float, float, str], None] | None = None,
    ) -> tuple[Sighting, int]:
        """Find ``name``: (sighting, views taken). Looks where it was last seen first, then scans with
        the head and turns the body (``turn(angle_rad, why)``) between scans. When perception says the
        robot's own arm hides it (``hidden_by_own_body``: the hand left on or in front of it after a
        failed grasp), ``clear_view()`` moves the arm away once (None: not done) and it is looked at
        again from there. Not seen all around, it is looked for past the objects on the map that may
        hide it (:meth:`_look_past`: ``view_from(x, y, yaw, why)`` walks to a viewpoint stepped aside;
        None: not done).

        NotFoundError (reason ``not_found_around``) listing what was tried if it is nowhere; its
        details' ``viewpoints`` name the viewpoints stepped to ([x, y, yaw, the object looked past]).
        """
        views = 0
        reasons: list[str] = []
        cleared = clear_view is None

        def attempt() -> Sighting | None:
            nonlocal views, cleared
            views += 1
            try:
                return self.locate(name)
            except NotFoundError as exc:
                reason = str(exc.details.get("reason", ""))
                reasons.append(reason or "not_found")
                if reason == perception_msg.REASON_HIDDEN_BY_OWN_BODY and not cleared and clear_view:
                    cleared = True
                    progress(f"{name} hidden by the robot's own arm: moving the arm out of the view")
                    clear_view()
                    return attempt()
                if reason not in LOOK_AROUND_REASONS or not look_around:
                    raise
                return None

        found = attempt()
        if found is None and name in self.memory.sightings:
            progress(f"looking where {name} was last seen")
            self.look_at(self.memory.sightings[name].position_m, f"look toward the last sighting of {name}")
            found = attempt()
        viewpoints: list[list[float | str]] = []
        if found is None:
            start = np.asarray(self.body.base_xy_yaw()[:2])
            found, turned = self._search(name, attempt, turn, progress)
            if found is None and view_from is not None and self.config.search_viewpoints > 0:
                found = self._look_past(name, start, turned, attempt, turn, view_from, progress, viewpoints)
        if found is None:
            tried = ", ".join(sorted(set(reasons)))
            past = "".join(
                f"; from ({x:.2f}, {y:.2f}) stepped aside past {what}" for x, y, _yaw, what in viewpoints
            )
            raise NotFoundError(
                f"{name} is nowhere around: looked in {views} directions (head scans and turning on the "
                f"spot all around{past}) and perception did not find it ({tried})",
                {"object": name, "reason": "not_found_around", "views": views, "viewpoints": viewpoints},
            )
        if self.off_centre() > self.config.recentre_fraction:
            progress(f"{name} seen at the image border: looking at it to localize it precisely")
            self.look_at(found.position_m, f"look at {name}")
            again = attempt()
            if look_around and _partial(again or found) and self.beyond_head(found.position_m):
                # The head cannot turn far enough: what is seen at the border is a part of a big object
                # (a table's leg: its middle, 0.6 m off the table's, and no floor rectangle; fetch layout
                # box_near then stepped into the table). Turned toward, it is seen whole.
                progress(f"{name} is beyond the head's reach: turning toward it to see it whole")
                self.face(found.position_m, turn, name)
                again = attempt() or again
            found = again if again is not None else found
        return found, views

    def _scan_order(self) -> list[tuple[float, float]]:
        """The head views of perception's look-around plan, nearest pan first and, at one pan, every
        tilt: what is ahead (the usual place of what is looked for) is seen before the sides."""
        views = [(float(pan), float(tilt)) for pan, tilt in self.body.robot.head.views]
        return sorted(views, key=lambda view: (round(abs(view[0]), 3), view[0], views.index(view)))

    def _search(
        self,
        name: str,
        attempt: Callable[[], Sighting | None],
        turn: Callable[[float, str], None],
        progress: Progress,
    ) -> tuple[Sighting | None, float]:
        """Head scans, turning on the spot between them: (the sighting or None, the angle turned [rad])."""
        turned = 0.0
        for offset in [0.0, *self.body.robot.head.turns_rad]:
            if offset != 0.0:
                progress(
                    f"{name} not in view: turning by {math.degrees(offset - turned):.0f} deg to look further"
                )
                turn(offset - turned, f"turn to look for {name}")
                turned = offset
            found = self._scan(name, attempt, progress)
            if found is not None:
                return found, turned
        return None, turned

    def _scan(self, name: str, attempt: Callable[[], Sighting | None], progress: Progress) -> Sighting | None:
        """One head scan (perception's look-around views) from where the robot stands."""
        for pan, tilt in self._scan_order():
            progress(
                f"looking for {name}: head pan {math.degrees(pan):.0f} deg, tilt {math.degrees(tilt):.0f} deg"
            )
            self.body.move_head(pan, tilt, what="head scan")
            found = attempt()
            if found is not None:
                return found
        return None

    def _look_past(
        self,
        name: str,
        start_xy: np.ndarray,
        turned: float,
        attempt: Callable[[], Sighting | None],
        turn: Callable[[float, str], None],
        view_from: Callable[[float, float, float, str], None],
        progress: Progress,
        viewpoints: list[list[float | str]],
    ) -> Sighting | None:
        """Look for ``name`` from viewpoints stepped aside past the objects on the map that may hide it
        (a chair between the robot and a box: from where the robot stands the search only turned on
        the spot, fetch layout ``chair_in_way``): both sides of each, nearest first
        (:func:`~supervisor.scene_map.viewpoints_past` from ``start_xy``, where the search looked
        from), at most ``search_viewpoints`` reached; navigation plans each walk there
        (``view_from``), a refused one is skipped. With nothing on the map, the robot turns back by
        ``turned`` to where the search started and maps what is in view there first (the survey).
        Each viewpoint reached is appended to ``viewpoints``; the sighting, or None."""
        hiding = [box for box in boxes(self.memory) if box.name != name]
        if not hiding:
            if turned:
                turn(-turned, f"turn back to look past what may hide {name}")
            views = self._scan_order()
            self.body.move_head(*views[0], what="head ahead")
            self.survey(progress, exclude={name})
            hiding = [box for box in boxes(self.memory) if box.name != name]
        hiding.sort(key=lambda box: distance_to_box(box, float(start_xy[0]), float(start_xy[1])))
        for box in hiding:
            for x, y, yaw in viewpoints_past(box, start_xy, self.config.search_aside_margin_m):
                if len(viewpoints) >= self.config.search_viewpoints:
                    return None
                what = f"step aside to look past {box.name} for {name}"
                progress(f"{name} not seen around: {what}, from ({x:.2f}, {y:.2f})")
                try:
                    view_from(x, y, yaw, what)
                except InfeasibleError as exc:
                    progress(f"no walk to ({x:.2f}, {y:.2f}): {exc.message}")
                    continue
                viewpoints.append([x, y, yaw, box.name])
                found = self._scan(name, attempt, progress)
                if found is not None:
                    return found
        return None


def _partial(sighting: Sighting) -> bool:
    """Whether ``sighting`` is of a big object (an obstacle: a box, a table, a chair) without a floor
    rectangle: perception saw only a part of it (cut by the image's border) or too near to tell."""
    return is_obstacle(sighting) and sighting.footprint is None
