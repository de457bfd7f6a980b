"""The supervisor's ``stand_up`` over a real bus, with the real sim (pybullet DIRECT, the chair_egress
scene) and the real contacts service: the action plans from the measured seated configuration; with a
plan budget too short for the search, the failure is the planner's typed ``timeout`` reported with the
partial plan, and the robot stays seated (nothing executed).

A whole stand-up (a plan of 2-4 minutes and 15-20 transitions played set by set) does not fit the
suite's time; it is run by ``scripts/bench contacts`` and ``humanoid scenario chair-egress``.
"""

from __future__ import annotations

import pytest

from services.bus.schemas import sim as sim_msg
from supervisor.core import Supervisor
from supervisor.script import parse_script


@pytest.fixture(scope="module")
def stack(module_bus_harness):
    h = module_bus_harness
    h.spawn_service("sim.service", "--scene", "chair_egress", name="sim")
    h.spawn_service("services.contacts.service", name="contacts", timeout_s=60)
    return h


@pytest.mark.integration
def test_stand_up_plans_over_the_bus_and_reports_the_planners_timeout(stack) -> None:
    sup = Supervisor(stack.session, stack.bus.robot)
    try:
        before = stack.client.call(sim_msg.STATE, sim_msg.StateRequest(), 10)
        report = sup.run(parse_script("stand_up 0.6 4"))
        after = stack.client.call(sim_msg.STATE, sim_msg.StateRequest(), 10)
    finally:
        sup.close()
    assert not report.ok
    assert report.failure.reason == "timeout", report.failure
    assert "before reaching the goal" in report.failure.message
    assert not after.fallen and abs(after.q[2] - before.q[2]) < 0.01  # still seated: nothing played
    bad = Supervisor(stack.session, stack.bus.robot)
    try:
        refused = bad.run(parse_script("stand_up 0.6 0"))
    finally:
        bad.close()
    assert not refused.ok and refused.failure.reason == "invalid_request"
    assert "budget" in refused.failure.message
