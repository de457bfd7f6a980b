"""The ball fetch end to end: every service under the launcher of `humanoid up`, the supervisor on top.

Success is judged on the sim's ground truth (supervisor/evaluate.py; the supervisor itself never reads
it). The services run under the real launcher, so that a service killed with SIGKILL is restarted.
A fetch takes one to two minutes of wall time on 2 shared cores, so the nominal fetch and the SIGKILL
of the walking service in its middle are one test.
"""

from __future__ import annotations

import io
import os
import signal
import threading
import time
from pathlib import Path

import pytest
from conftest import free_port, run_in_thread

from services.bus.config import BusConfig
from services.bus.schemas import footsteps as fs_msg
from services.bus.schemas import sim as sim_msg
from supervisor.core import Supervisor
from supervisor.evaluate import ball_on_table, record_config, requests_in_log
from supervisor.fetch import fetch, reset_scene, running_stack
from supervisor.repl import ConsoleLoop

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    bus = BusConfig().with_hub_port(free_port())
    logs = tmp_path_factory.mktemp("logs")
    # The recorder writes the footstep planner's messages (one chunk each: readable while it records).
    config = record_config(logs / "record.yaml", chunk_bytes=1)
    record = str(logs / "footsteps.mcap")
    with (
        running_stack(bus, log_dir=str(logs), record=record, config_path=config) as launcher,
        Supervisor.connect(bus) as sup,
    ):
        assert sup.wait_for_services(30.0) == []
        yield launcher, sup


def _ground_truth(sup: Supervisor) -> sim_msg.GroundTruthReply:
    return sup.bus.call(sim_msg.GROUND_TRUTH, sim_msg.GroundTruthRequest(), 10.0)


def test_fetch_succeeds_when_walking_is_killed_during_the_turn(stack, tmp_path) -> None:
    """The fetch script in the demo scene puts the ball on the table, although the walking service is
    killed (SIGKILL) while it plans the turn: the launcher restarts it, the supervisor reports the
    failure, waits for the service and retries."""
    launcher, sup = stack
    walking = launcher.children["walking"]
    first_pid = walking.proc.pid
    killed = threading.Event()
    in_turn = threading.Event()
    original = sup.runner.on_event

    def watch_steps(event) -> None:
        original(event)
        if event.kind == "started":
            in_turn.set() if event.step.startswith("turn") else in_turn.clear()

    def kill_during_walking_plan(spec) -> None:
        if spec.service == "walking" and in_turn.is_set() and not killed.is_set():
            # As the request goes out: the kill lands while walking plans (the first walking request of
            # the turn step may be a short step back, planned in a few tens of ms; a later kill could
            # miss it and the service would be back before the turn's own plan).
            killed.set()
            threading.Thread(target=os.killpg, args=(first_pid, signal.SIGKILL)).start()

    sup.runner.on_event = watch_steps
    sup.bus.on_call = kill_during_walking_plan
    start_ns = time.time_ns()
    try:
        summary, report = run_in_thread(lambda: fetch(sup, snapshot=tmp_path / "final.png"), 500)
    finally:
        sup.runner.on_event = original
        sup.bus.on_call = None
    details = summary.text() + "\n" + "\n".join(r.summary() for r in report.reports)
    assert summary.ok, details
    on_table, why = ball_on_table(_ground_truth(sup))
    assert on_table, why
    assert Path(summary.snapshot).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert summary.steps == 9 and summary.sim_s > 0
    # The kill: the launcher restarted walking; the supervisor reported the failure and retried.
    assert killed.is_set()
    assert walking.proc.pid != first_pid and walking.attempt >= 2
    turn = next(r for r in report.reports if r.action == "turn")
    assert turn.ok and turn.attempts >= 2 and summary.retries >= 1, details
    failures = [e for e in sup.events if e.kind == "failed" and e.step.startswith("turn")]
    assert failures and failures[0].reason in ("unavailable", "timeout"), failures
    assert "walking" in failures[0].message
    assert any(e.kind == "retried" and e.step.startswith("turn") for e in sup.events)
    assert any(e.kind == "progress" and "service walking is back" in e.message for e in sup.events)
    # The footstep planner planned the last steps of the grasp and of the put: counted in the log.
    time.sleep(0.5)  # the recorder's last chunk
    [calls] = requests_in_log(launcher.record, fs_msg.PLAN, [(start_ns, time.time_ns())])
    assert calls >= 2, calls


def test_console_takes_the_orange_ball(stack) -> None:
    _launcher, sup = stack
    reset_scene(sup, "ball_fetch", None)
    sup.actions.memory.sightings.clear()
    out = io.StringIO()
    sup.out = out
    try:
        code = ConsoleLoop(sup, sup.known_objects(), out).run(["go to the green box", "take the orange ball"])
    finally:
        sup.out = None
    assert code == 0, out.getvalue()
    assert sup.actions.body.state().held.get("right") == "orange_ball", out.getvalue()
    assert "ok: holding orange_ball" in out.getvalue()


def test_without_the_ball_the_robot_looks_around_and_reports_not_found(stack, tmp_path) -> None:
    _launcher, sup = stack
    summary, report = run_in_thread(lambda: fetch(sup, scene="ball_fetch_no_ball"), 400)
    assert not summary.ok
    failure = report.failure
    assert failure.action == "localize" and failure.args == ("orange_ball",)
    assert failure.reason == "not_found" and "nowhere around" in failure.message
    assert len(report.reports) == 3  # localize box, goto box, localize ball: then the script stops
    progress = [e.message for e in sup.events if e.kind == "progress"]
    assert any("head pan" in m for m in progress) and any("turning" in m for m in progress)
    assert sup.events[-1].kind == "run_finished" and not sup.events[-1].ok


def test_a_near_goal_beside_the_robot_is_walked_to_straight(stack) -> None:
    """Half a metre to the left and 0.3 m ahead, turned by 20 deg: navigation's forward-only car-like
    path would loop around; navigation walks there directly (sideways, forward and turning in the
    same steps) and the robot stands at the goal."""
    import math

    _launcher, sup = stack
    reset_scene(sup, "ball_fetch", None)
    sup.actions.memory.sightings.clear()
    body, planners = sup.actions.body, sup.actions.planners
    x, y, yaw = body.base_xy_yaw()
    goal = (x + 0.3, y + 0.5, yaw + math.radians(20.0))
    plan = planners.goto_pose(*goal)
    assert plan.planner == "navigation/goto, straight", plan.describe()
    executed = body.execute(plan.q, what="walk")
    ex, ey, eyaw = body.base_xy_yaw(executed.q)
    assert math.hypot(ex - goal[0], ey - goal[1]) < 0.03
    assert abs(math.remainder(eyaw - goal[2], 2 * math.pi)) < math.radians(3.0)
