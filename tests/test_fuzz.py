"""Property-based fuzzing of every endpoint of a running stack (issue 16, item 6).

One stack for the module (every service that has endpoints, each its own process over real zenoh,
pybullet DIRECT); for each endpoint, hypothesis draws payloads from the request schema and mutates
them (``tests/fuzzing.py``). The property: every payload gets an answer, and the answer is ``ok`` or a
typed error other than ``internal``; no service dies. The whole module stays within about two
minutes (``TIME_PER_ENDPOINT_S``); ``scripts/bench fuzz`` is the long run.
"""

from __future__ import annotations

import time

import pytest
from fuzzing import ASKED_FOR_INTERNAL, payloads, reference_q, send
from hypothesis import HealthCheck, Phase, given, settings

from services.bus.discovery import discover
from services.bus.schemas import endpoints

pytestmark = pytest.mark.integration

#: Wall time spent drawing payloads for one endpoint [s]; examples past it are skipped, not sent.
TIME_PER_ENDPOINT_S = 5.0
#: An answer within this long, or the payload counts as unanswered [s]. Generous: a valid planning
#: request runs for its own time budget (<= the schema's bound) on a loaded machine.
REPLY_TIMEOUT_S = 45.0
EXAMPLES = 40
ENDPOINTS = sorted(endpoints().values(), key=lambda s: s.path)


@pytest.fixture(scope="module")
def stack(module_bus_harness):
    """Every service that serves an endpoint, started once for the module."""
    found, _ = discover()
    services = sorted({spec.service for spec in ENDPOINTS if spec.service in found})
    procs = {}
    for name in services:
        procs[name] = module_bus_harness.spawn_service(found[name].module, name=name, timeout_s=120)
    q_ref = reference_q(module_bus_harness.session, module_bus_harness.bus.robot) if "sim" in procs else ()
    return module_bus_harness, procs, q_ref


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
