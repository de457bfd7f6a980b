"""Property-based fuzzing of every endpoint of a running stack (issue 16, items 2, 3 and 6).

One stack for the module (every service that has endpoints, each its own process over real zenoh,
pybullet DIRECT); for each endpoint, hypothesis draws payloads from the request schema and mutates
them (``tests/fuzzing.py``). The property: every payload gets an answer, and the answer is ``ok`` or a
typed error other than ``internal``; no service dies. The whole module stays within about two
minutes (``TIME_PER_ENDPOINT_S``); ``scripts/bench fuzz`` is the long run. Before it, on the same
stack, the limits that bound each request's work, scenes loaded by name only, and the time budgets: an
expensive request of each planner with a tiny budget gets ``timeout`` within the budget plus a second.
"""

from __future__ import annotations

import contextlib
import time

import budgets
import msgspec
import numpy as np
import pytest
from budgets import seated_q
from fuzzing import ASKED_FOR_INTERNAL, payloads, reference_q, send
from hypothesis import HealthCheck, Phase, given, settings

from services.bus.discovery import discover
from services.bus.schemas import contacts, diag, endpoints, navigation, sim, walking
from services.errors import InfeasibleError, InvalidRequestError, NotFoundError, RequestTimeoutError

pytestmark = pytest.mark.integration

#: Wall time spent drawing payloads for one endpoint [s]; examples past it are skipped, not sent.
TIME_PER_ENDPOINT_S = 5.0
#: An answer within this long, or the payload counts as unanswered [s]. Generous: a valid planning
#: request runs for its own time budget (<= the schema's bound) on a loaded machine.
REPLY_TIMEOUT_S = 45.0
EXAMPLES = 60
ENDPOINTS = sorted(endpoints().values(), key=lambda s: s.path)


@pytest.fixture(scope="module")
def stack(module_bus_harness, tmp_path_factory):
    """Every service that serves an endpoint, started once for the module (the sim with a folder of
    test scenes: ``module_bus_harness.scene_dir``)."""
    found, _ = discover()
    services = sorted({spec.service for spec in ENDPOINTS if spec.service in found})
    scene_dir = module_bus_harness.scene_dir = tmp_path_factory.mktemp("scenes")
    extra = {"sim": ("--scene-dir", str(scene_dir))}
    procs = {}
    for name in services:
        procs[name] = module_bus_harness.spawn_service(
            found[name].module, *extra.get(name, ()), name=name, timeout_s=120
        )
    q_ref = reference_q(module_bus_harness.session, module_bus_harness.bus.robot) if "sim" in procs else ()
    return module_bus_harness, procs, q_ref


def test_scenes_are_loaded_by_name_and_their_errors_do_not_echo_the_file(stack):
    harness, _procs, _q = stack
    (harness.scene_dir / "broken.yaml").write_text("name: broken\nobjects: [{kind: secret_value_42}]\n")
    (harness.scene_dir / "deep.yaml").write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    call = harness.client.call
    for name in ("broken", "deep"):
        with pytest.raises(InvalidRequestError, match="not a valid scene file") as err:
            call(sim.RESET, sim.ResetRequest(scene=name), timeout_s=30)
        assert "secret_value_42" not in str(err.value) and str(harness.scene_dir) not in str(err.value)
    with pytest.raises(NotFoundError, match=r"available scenes: .*ball_fetch.*broken"):
        call(sim.RESET, sim.ResetRequest(scene="moon"), timeout_s=30)
    raw = b'{"scene": "/etc/hostname.yaml"}'
    with pytest.raises(InvalidRequestError, match=r"at `\$\.scene`"):
        harness.client.call_raw("sim", "reset", raw, timeout_s=30)
    assert call(sim.RESET, sim.ResetRequest(scene="empty"), timeout_s=60).scene == "empty"


def test_work_is_bounded_before_it_starts_and_budgets_end_it(stack):
    harness, procs, q_ref = stack
    call = harness.client.call
    if "sim" in procs:
        q = np.asarray(call(sim.STATE, sim.StateRequest(), timeout_s=30).q)
        with pytest.raises(InvalidRequestError, match="at most 120 s"):
            call(sim.EXECUTE, sim.ExecuteRequest(q=np.repeat(q[None, :], 24_100, axis=0)), timeout_s=60)
        hold = sim.ExecuteRequest(q=np.repeat(q[None, :], 4000, axis=0), time_budget_s=0.2)
        with pytest.raises(RequestTimeoutError, match=r"time budget of 0\.2 s") as err:
            call(sim.EXECUTE, hold, timeout_s=60)
        assert 0 < err.value.details["played_s"] < 20.0
        assert call(sim.STATE, sim.StateRequest(), timeout_s=30).sim_time_s > 0  # still serving
    if "walking" in procs:
        steps = [walking.Step(pose=[0.1 * (i // 2), 0.095 * (1 - 2 * (i % 2)), 0.0]) for i in range(150)]
        with pytest.raises(InvalidRequestError, match="at most 120 s per walking/plan"):
            call(walking.PLAN, walking.PlanRequest(steps=steps), timeout_s=60)
    if "navigation" in procs and q_ref:
        far = navigation.GotoRequest(q_start=np.array(q_ref), goal_pose=[60.0, 0.0, 0.0])
        with pytest.raises(InvalidRequestError, match="at most 30 m per navigation/goto"):
            call(navigation.GOTO, far, timeout_s=60)
    if "diag" in procs:
        stream = diag.StreamRequest(count=100_000, width=64, height=48, time_budget_s=0.2)
        with pytest.raises(RequestTimeoutError, match=r"time budget of 0\.2 s") as err:
            call(diag.STREAM, stream, timeout_s=60)
        assert 0 < err.value.details["sent"] < 100_000


#: The tiny budget of the expensive requests below [s] (contacts/plan: ``CONTACTS_BUDGET_S``, its set-up
#: alone takes about a second).
TINY_BUDGET_S = 0.1
CONTACTS_BUDGET_S = 3.0
#: The answer must come within the budget plus this [s] here: loose, the machine is shared; the issue's
#: "plus a second" is measured by ``scripts/bench budgets`` (README "Reliability").
LOOSE_MARGIN_S = 5.0


@pytest.fixture(scope="module")
def q_seated() -> np.ndarray:
    return seated_q()


@pytest.mark.parametrize("service", budgets.SERVICES)
def test_a_tiny_budget_ends_an_expensive_request_with_timeout_and_the_service_serves_on(
    stack, service, q_seated
):
    """Issue 16: no request holds a service past its own budget plus a second; the reply is a typed
    ``timeout`` (with what was done), and the endpoint serves the next request."""
    harness, procs, q_ref = stack
    if service not in procs or not q_ref:
        pytest.skip(f"no {service} (or no sim) in this checkout")
    for case in budgets.expensive(service, np.array(q_ref), TINY_BUDGET_S, q_seated):
        budget_s, request = TINY_BUDGET_S, case.expensive
        if case.spec is contacts.PLAN:  # past its set-up (about a second), into the search
            budget_s = CONTACTS_BUDGET_S
            request = msgspec.structs.replace(request, time_budget_s=budget_s)
        started = time.monotonic()
        with pytest.raises(RequestTimeoutError) as err:
            harness.client.call(case.spec, request, timeout_s=REPLY_TIMEOUT_S)
        took = time.monotonic() - started
        assert took <= budget_s + LOOSE_MARGIN_S, f"{case.name}: timeout after {took:.2f} s: {err.value}"
        # the service's own typed reply, not this client giving up
        assert not err.value.message.startswith(f"{case.spec.path} gave no reply"), err.value
        # a typed answer: it serves again (a cheap request may find nothing)
        with contextlib.suppress(InfeasibleError, NotFoundError):
            harness.client.call(case.spec, case.cheap, timeout_s=REPLY_TIMEOUT_S)


@pytest.mark.parametrize("spec", ENDPOINTS, ids=[s.path for s in ENDPOINTS])
def test_every_payload_gets_a_typed_answer(stack, spec):
    harness, procs, q_ref = stack
    if spec.service not in procs:
        pytest.skip(f"no service {spec.service} in this checkout")
    started = time.monotonic()
    seen: list[str] = []

    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        database=None,
        derandomize=True,  # the same payloads every run: reproducible; scripts/bench fuzz explores
        phases=(Phase.generate,),
        suppress_health_check=list(HealthCheck),
    )
    @given(payloads(spec, q_ref))
    def check(case: tuple[str, bytes]) -> None:
        if time.monotonic() - started > TIME_PER_ENDPOINT_S:
            return
        kind, raw = case
        outcome, message = send(harness.session, harness.bus.robot, spec, raw, REPLY_TIMEOUT_S)
        seen.append(outcome)
        if spec.path in ASKED_FOR_INTERNAL and outcome == "internal":
            return  # diag/raise {"code": "bug"} answers internal by design
        assert outcome not in ("internal", "no_reply", "bad_error"), (
            f"{spec.path} answered {outcome} to a {kind} payload ({len(raw)} bytes, "
            f"starting {raw[:200]!r}): {message}"
        )

    check()
    assert seen, "no payload was sent"
    dead = {name: p.returncode for name, p in procs.items() if p.poll() is not None}
    assert not dead, f"services died during the fuzzing: {dead}"
