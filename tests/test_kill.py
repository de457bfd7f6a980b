"""SIGKILL of a service in the middle of an action (issue 16, item 7): one stack, one test per service.

Every service of the fetch runs under the real launcher (``humanoid up``'s: a dead service is started
again), the supervisor on top. Each planner test runs the shortest supervisor action that calls the
planner and kills the planner's process group (SIGKILL) as the supervisor's first request to it goes
out: the action must still complete, through the launcher's restart and the supervisor's retry
(``unavailable`` or ``timeout``, remedy ``wait_service``). The sim is different: its world (scene,
objects, the robot's place) dies with it, so a fetch whose sim is killed must end quickly with a
failure that says so (``the simulation is gone``), never hang nor go on in the fresh empty world.

The walking kill in the middle of a whole fetch is in tests/test_supervisor_fetch.py; here the actions
are short (a look, a turn, a short goto, a reach in front of the robot).
"""

from __future__ import annotations

import math
import os
import signal
import threading

import pytest
from conftest import free_port, run_in_thread

from services.bus.config import BusConfig
from services.bus.schemas.supervisor import REASON_WORLD_LOST
from supervisor.core import Supervisor
from supervisor.fetch import reset_scene, running_stack
from supervisor.runner import RunReport
from supervisor.script import parse_script

pytestmark = pytest.mark.integration

#: A hang guard only (the actions take seconds): a supervisor still running after this has hung [s].
HANG_S = 300.0


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    bus = BusConfig().with_hub_port(free_port())
    logs = tmp_path_factory.mktemp("logs")
    with running_stack(bus, log_dir=str(logs)) as launcher, Supervisor.connect(bus) as sup:
        assert sup.wait_for_services(60.0) == []
        reset_scene(sup, "ball_fetch", None)
        yield launcher, sup


def _run_killing(launcher, sup: Supervisor, victim: str, run, path: str = "") -> tuple[object, int]:
    """``run()`` while ``victim`` is SIGKILLed as the supervisor's first request to it (to its endpoint
    ``path`` if given) goes out: the kill lands before the request can be served. ``run``'s result and
    the victim's first pid."""
    child = launcher.children[victim]
    first_pid = child.proc.pid
    killed = threading.Event()

    def kill_on_first_call(spec) -> None:
        if spec.service == victim and spec.path.startswith(path) and not killed.is_set():
            killed.set()
            os.killpg(first_pid, signal.SIGKILL)

    sup.bus.on_call = kill_on_first_call
    try:
        result = run_in_thread(run, HANG_S)
    finally:
        sup.bus.on_call = None
    assert killed.is_set(), f"the action never called {victim}"
    return result, first_pid


def _assert_completed_after_restart(launcher, sup: Supervisor, victim: str, script: str) -> RunReport:
    report, first_pid = _run_killing(launcher, sup, victim, lambda: sup.run(parse_script(script)))
    details = "\n".join(r.summary() for r in report.reports)
    assert report.ok, details
    child = launcher.children[victim]
    assert child.proc.pid != first_pid and child.attempt >= 2, "the launcher did not restart it"
    assert report.retries >= 1, details
    failed = [e for e in sup.events if e.kind == "failed" and e.reason in ("unavailable", "timeout")]
    assert failed and victim in failed[-1].message, failed
    return report


def _ahead(sup: Supervisor, forward_m: float, left_m: float, z_m: float) -> str:
    """'x,y,z' of a point ``forward_m`` ahead and ``left_m`` to the left of the robot [m]."""
    x, y, yaw = sup.actions.body.base_xy_yaw()
    c, s = math.cos(yaw), math.sin(yaw)
    return f"{x + c * forward_m - s * left_m:.3f},{y + s * forward_m + c * left_m:.3f},{z_m:.3f}"


def test_perception_killed_mid_localize(stack) -> None:
    launcher, sup = stack
    _assert_completed_after_restart(launcher, sup, "perception", "localize green_box")


def test_walking_killed_mid_turn(stack) -> None:
    launcher, sup = stack
    _assert_completed_after_restart(launcher, sup, "walking", "turn 20")


def test_navigation_killed_mid_goto(stack) -> None:
    launcher, sup = stack
    x, y, yaw = sup.actions.body.base_xy_yaw()
    goal = f"{x + 0.4 * math.cos(yaw):.3f},{y + 0.4 * math.sin(yaw):.3f},{math.degrees(yaw):.1f}"
    _assert_completed_after_restart(launcher, sup, "navigation", f"goto {goal}")


def test_footsteps_killed_mid_reach(stack) -> None:
    launcher, sup = stack
    _assert_completed_after_restart(launcher, sup, "footsteps", f"reach right {_ahead(sup, 0.4, -0.2, 0.85)}")


def test_reaching_killed_mid_reach(stack) -> None:
    launcher, sup = stack
    _assert_completed_after_restart(launcher, sup, "reaching", f"reach left {_ahead(sup, 0.4, 0.2, 0.85)}")


def test_sim_killed_mid_fetch_ends_it_saying_the_world_was_lost(stack) -> None:
    """The sim killed at the fetch's first motion: the fetch fails within seconds of the sim's return,
    naming the lost world, instead of going on in the fresh (empty) world the launcher brought back."""
    launcher, sup = stack
    reset_scene(sup, "ball_fetch", None)  # the fetch's world
    steps = parse_script("turn 20\nlocalize green_box\ngoto green_box distance=0.34")
    report, first_pid = _run_killing(launcher, sup, "sim", lambda: sup.run(steps), path="sim/execute")
    assert launcher.children["sim"].proc.pid != first_pid  # the launcher brought a sim back...
    assert not report.ok
    failure = report.failure
    assert failure is not None and failure.action == "turn", [r.summary() for r in report.reports]
    # ...but the fetch did not go on in its empty world: it failed, saying why
    assert failure.reason == "unavailable" and "the simulation is gone" in failure.message, failure.summary()
    assert failure.details.get("reason") == REASON_WORLD_LOST
    # the attempt the sim died under fails as any service's death does (retried: a planner comes back
    # whole); the next finds the world lost, which is final (it used to be retried 3 times more)
    assert failure.attempts <= 2, failure.summary()
    assert len(report.reports) == 1
