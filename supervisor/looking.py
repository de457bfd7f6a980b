"""Perception actions: ``detect``, ``localize``, ``look_at`` (the Eyes of ``perceive.py`` behind them).

"Detection and localization of a learned object" (Fig. 11 of ``001_771c0ce3779b0683.txt``): object
positions come only from ``perception/locate`` and are kept in :class:`~supervisor.memory.Memory`.
"""

from __future__ import annotations

from collections.abc import Callable

from services.errors import NotFoundError
from supervisor.memory import Sighting
from supervisor.parts import ActionParts
from supervisor.report import ActionReport
from supervisor.script import Step


class LookingActions(ActionParts):
    """The perception actions (a part of :class:`supervisor.actions.Actions`)."""

    def do_detect(self, step: Step) -> ActionReport:
        """Is the object in view now (no motion)? not_found otherwise."""
        name = step.args[0]
        sighting = self.eyes.locate(name)
        return self._ok(step, f"sees {sighting.describe()}", sighting)

    _turn_rad: Callable[[float, str], int]  # LocomotionActions
    _make_room: Callable[[str], None]  # LocomotionActions

    def do_localize(self, step: Step) -> ActionReport:
        """Find the object, looking around (head scan, then turning on the spot) when not in view, then
        from viewpoints stepped aside past what may hide it (:meth:`Eyes.localize`)."""
        name = step.args[0]
        sighting, views = self.eyes.localize(
            name, turn=self._turn_rad, progress=self.progress, view_from=self._view_from
        )
        return self._ok(step, f"{sighting.describe()} ({views} view(s))", sighting, views=views)

    def _view_from(self, x_m: float, y_m: float, yaw_rad: float, what: str) -> None:
        """Walk to the pose (x, y, yaw) [m, rad] to look from: navigation/goto plans it against the map
        (after stepping back from what is too near to start), ``infeasible`` when it finds no walk."""
        self.body.straighten()
        self._make_room(f"room to {what}")
        plan = self.planners.goto_pose(x_m, y_m, yaw_rad)
        self.progress(f"{what}: {plan.describe()}")
        self.body.execute(plan.q, what=what, progress=self.progress)

    def do_look_at(self, step: Step) -> ActionReport:
        """Turn the head (and the body if the head cannot) toward a localized object, then see it again."""
        name = step.args[0]
        if name not in self.memory.sightings:
            self.eyes.localize(name, turn=self._turn_rad, progress=self.progress)
        self.eyes.face(self.memory.get(name).position_m, self._turn_rad, name)
        try:
            sighting = self.eyes.locate(name)
        except NotFoundError as exc:
            # Not where it was seen (or half out of one image): look around for it.
            self.progress(
                f"{name} not where it was seen ({exc.details.get('reason', 'not found')}): looking around"
            )
            sighting, _views = self.eyes.localize(name, turn=self._turn_rad, progress=self.progress)
        return self._ok(step, f"looking at {sighting.describe()}", sighting)

    def _survey(self, exclude: set[str]) -> None:
        """Put the big objects in view on the map (not ``exclude``, not what the hands hold)."""
        self.eyes.survey(self.progress, exclude={*exclude, *self.memory.holding.values()})

    def _ok(self, step: Step, message: str, sighting: Sighting, **details: object) -> ActionReport:
        return ActionReport(
            step.action,
            step.args,
            message=message,
            details={
                "object": sighting.name,
                "position": sighting.position_m.tolist(),
                "confidence": sighting.confidence,
                **details,
            },
        )
