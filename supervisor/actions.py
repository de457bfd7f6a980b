"""The supervisor's actions: each a sequence of service calls that returns an :class:`ActionReport`.

The generic action commands of the ball-fetching experiment (Fig. 11 of ``001_771c0ce3779b0683.txt``,
"Experiments"): "detection and localization of a learned object, locomotion to a location, and hand
reaching to a position in 3D, with other simple tasks like turning on the spot and gripper opening and
closing". Object positions come only from ``perception/locate`` (kept in :class:`Memory`); the robot's
state from its proprioception (``sim/state``); planners' trajectories are played by ``sim/execute``
(:class:`Body`), where a fall or a collision becomes the failure reason ``fell`` / ``collision``.

Failures are raised as the typed errors of services/errors.py: bus errors (from the services) or
world outcomes (FellError, CollisionError, NotGraspedError, StoppedError);
the runner turns both into failed reports and applies the retry policy.

The actions are split by concern: ``looking.py`` (detect, localize, look_at), ``locomotion.py`` (goto,
turn, walk), ``manipulation.py`` (reach, grasp, open), ``put.py`` (put), ``remedies.py`` (relocalize,
replan, wait_service); this module assembles them into the runner's tables.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from supervisor.body import Body, Progress
from supervisor.calls import ServiceCaller
from supervisor.config import SupervisorConfig
from supervisor.health import HealthMonitor
from supervisor.locomotion import LocomotionActions
from supervisor.looking import LookingActions
from supervisor.manipulation import ManipulationActions
from supervisor.memory import Memory
from supervisor.perceive import Eyes
from supervisor.planners import Planners
from supervisor.put import PutActions
from supervisor.remedies import Remedies
from supervisor.report import ActionReport
from supervisor.runner import Action, Remedy
from supervisor.script import Step
from supervisor.stand_up import stand_up


class Actions(LookingActions, LocomotionActions, ManipulationActions, PutActions, Remedies):
    """The action table and remedies over the services (see the module docstring)."""

    def __init__(
        self,
        bus: ServiceCaller,
        health: HealthMonitor,
        *,
        stop: threading.Event | None = None,
        progress: Progress | None = None,
        config: SupervisorConfig | None = None,
    ) -> None:
        self.bus = bus
        self.health = health
        self.stop = stop or threading.Event()
        self.progress: Progress = progress or (lambda _text: None)
        self.config = config or SupervisorConfig()
        self.memory = Memory()
        self.body = Body(bus, self.stop)
        self.eyes = Eyes(bus, self.body, self.memory, self.config)
        self.planners = Planners(bus, self.body, self.memory, self.config)
        self.last_reach: tuple[str, str] | None = None  # (hand, target) of the last reach

    # The tables the runner uses ---------------------------------------------------------------------
    def table(self) -> dict[str, Action]:
        names = ("detect", "localize", "goto", "turn", "walk", "reach", "grasp", "open", "put", "look_at")
        table = {name: self._timed(getattr(self, f"do_{name}")) for name in names}
        table["stand_up"] = self._timed(lambda step: stand_up(self.bus, self.body, self.progress, step.args))
        return table

    def remedies(self) -> dict[str, Remedy]:
        return {"relocalize": self.relocalize, "replan": self.replan, "wait_service": self.wait_service}

    def _timed(self, fn: Callable[[Step], ActionReport]) -> Callable[[Step], ActionReport]:
        """Run an action and fill in its sim time from proprioception."""

        def run(step: Step) -> ActionReport:
            start = self.body.state().sim_time_s
            report = fn(step)
            end = self.body.state().sim_time_s
            return ActionReport(
                report.action,
                report.args,
                ok=report.ok,
                reason=report.reason,
                message=report.message,
                details=report.details,
                sim_time_s=end - start,
            )

        return run
