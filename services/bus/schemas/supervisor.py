"""Messages of the ``supervisor`` (scripted actions, failure reports, retries; supervisor/).

The supervisor is a client of the other services, not a queryable service: it publishes what it does
on ``hrp/<robot>/supervisor/events`` so that ``humanoid echo supervisor/events`` shows a run live and
``humanoid up --record FILE`` logs it in the MCAP file next to the requests it caused.
"""

from __future__ import annotations

import msgspec

from services.bus.spec import TopicSpec

#: ``details["reason"]`` of the ``unavailable`` failure the supervisor reports when the sim process died and
#: was restarted: the world it held (scene, objects, the robot's place) is gone. Final: never retried.
REASON_WORLD_LOST = "world_lost"
#: ``details["reason"]`` of the ``infeasible`` failure of a reach when something on the map lies in both
#: hands' way to the object and the jaws' approach clear of it was refused (``details.gaps_m``: the
#: clearances per hand's side [m], ``needed_gap_m``), given before the hand comes down. Retried once after a
#: fresh look (the map may show room then).
REASON_NO_CLEAR_WAY = "no_clear_way"
#: ``details["reason"]`` of the ``infeasible`` failure of a reach refused from near an object that rests on
#: nothing known (a ball on the floor): ``height_m``, ``hand_height_m``, ``distance_m`` and reaching's
#: refusal (``refused``). Final: looking again does not raise the object.
REASON_OUT_OF_REACH = "out_of_reach"

#: Kinds of :class:`SupervisorEvent`.
EVENT_KINDS = (
    "run_started",
    "started",
    "progress",
    "finished",
    "failed",
    "retried",
    "stopped",
    "run_finished",
)


class SupervisorEvent(msgspec.Struct, kw_only=True, frozen=True):
    """One step of a run.

    ``kind``: ``run_started`` / ``run_finished`` (a script or console command as a whole: ``ok`` says
    how it ended), ``started`` (an action attempt begins), ``progress`` (what the running action is
    doing: "walking 2.9 m, 14 steps"), ``finished`` (the action succeeded), ``failed`` (an attempt
    failed: ``reason`` is a supervisor.report.REASONS code), ``retried`` (another attempt follows,
    ``message`` names the remedy), ``stopped`` (the operator said "stop").
    """

    kind: str
    run_id: str  # identifies one script run or console command, e.g. "fetch.txt@1732240000"
    step: str = ""  # the action as written, e.g. "reach right orange_ball"
    line: int = 0  # script line (0 for console commands)
    attempt: int = 0  # 1 for the first attempt of a step
    reason: str = ""  # failure reason code (failed, retried, stopped)
    message: str = ""  # for people
    ok: bool = True  # run_finished: whether the run succeeded
    retries: int = 0  # run_finished: retries over the run
    sim_time_s: float = 0.0  # sim time when the event was emitted, from sim/clock [s] (0 if unknown)
    wall_time_s: float = 0.0  # time.time() of the supervisor [s]


EVENTS = TopicSpec(
    "supervisor",
    "events",
    SupervisorEvent,
    "supervisor actions: started, progress, finished, failed, retried, stopped; runs started/finished",
)
