"""What every part of the supervisor's actions uses, declared once: the mixins of
:class:`supervisor.actions.Actions` (looking, locomotion, manipulation, put, remedies) derive from
:class:`ActionParts`, and :class:`~supervisor.actions.Actions` sets these attributes."""

from __future__ import annotations

from supervisor.body import Body, Progress
from supervisor.calls import ServiceCaller
from supervisor.config import SupervisorConfig
from supervisor.memory import Memory
from supervisor.perceive import Eyes
from supervisor.planners import Planners


class ActionParts:
    """The bus, the robot's body, the memory of what was seen, the eyes, the planners, the tunables
    and the progress line of the actions."""

    bus: ServiceCaller
    body: Body
    memory: Memory
    eyes: Eyes
    planners: Planners
    config: SupervisorConfig
    progress: Progress
