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
import json
import struct
import time
from concurrent.futures import ThreadPoolExecutor

import budgets
import msgspec
import numpy as np
import pytest
import stranger as stranger_client
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
    procs = module_bus_harness.spawn_services(
        {name: (found[name].module, *extra.get(name, ())) for name in services}, timeout_s=120
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


# ------------------------------------------------------------------------------ a stranger's client
# The requests below were written from the READMEs only (the endpoint tables of sim/README.md,
# services/*/README.md, services/bus/README.md), sent by tests/stranger.py (raw zenoh, no code of the
# stack). A well-formed request must never be refused as invalid; a malformed one must get
# ``invalid_request`` saying what is wrong; nothing may go unanswered or end in ``internal``.

#: The chair scene's start contacts, as services/contacts/README.md names the spots and surfaces.
STRANGER_SEATED = [
    ["left_sole", "floor"],
    ["right_sole", "floor"],
    ["left_thigh", "chair.seat"],
    ["right_thigh", "chair.seat"],
]
#: Endpoints whose documented request costs seconds of planning: not re-sent after the malformed ones.
STRANGER_EXPENSIVE = {
    "navigation/goto",
    "footsteps/plan",
    "reaching/reach",
    "contacts/plan",
    "contacts/transition",
    "perception/locate",
    "walking/goal",
}
#: The typed answers a well-formed request may get besides ok (a plan may be infeasible or cut).
STRANGER_TYPED = {"ok", "infeasible", "timeout", "not_found"}


@pytest.fixture(scope="module")
def stranger(stack):
    """The stranger's session, and the documented requests of every endpoint (built over the bus)."""
    harness, procs, _q = stack
    session = stranger_client.open_session(harness.hub)
    robot = harness.bus.robot
    stranger_client.wait_alive(session, robot, set(procs))

    def ask(path: str, doc: dict, timeout_s: float = 60.0, arrays: dict | None = None):
        return stranger_client.call(
            session, f"hrp/{robot}/{path}", stranger_client.frame(doc, arrays), timeout_s
        )

    requests: dict[str, tuple[dict, dict | None]] = {}
    if "sim" in procs:
        seated = ask("sim/reset", {"scene": "chair_egress"})
        assert seated.kind == "ok", seated
        q_seated = [float(v) for v in seated.body["q"]]
        reset = ask("sim/reset", {"scene": "ball_fetch"})
        assert reset.kind == "ok", reset
        q = [float(v) for v in reset.body["q"]]
        info = ask("sim/robot_info", {})
        assert info.kind == "ok" and info.body["nq"] == len(q), info
        frame_name = next(iter(info.body["frames"].values()))
        trajectory = np.repeat(np.array([q]), 40, axis=0)  # 0.2 s standing, as raw float64 bytes
        requests.update(
            {
                "sim/state": ({}, None),
                "sim/robot_info": ({}, None),
                "sim/ground_truth": ({}, None),
                "sim/reset": ({"scene": "ball_fetch"}, None),
                "sim/render": ({"camera": "wide", "width_px": 160, "height_px": 120, "depth": True}, None),
                "sim/snapshot": ({"viewpoint": "top", "width_px": 160, "height_px": 120}, None),
                "sim/gripper": ({"side": "right", "action": "open"}, None),
                "sim/kinematics": ({"q": q, "frames": [frame_name]}, None),
                "sim/execute": ({"hold_s": 0.1}, {"q": trajectory}),
                "navigation/goto": ({"q_start": q, "goal_pose": [0.5, 0.0, 0.0]}, None),
                "walking/plan": (
                    {"steps": [{"pose": [0.2, -0.095, 0.0]}, {"pose": [0.2, 0.095, 0.0]}]},
                    None,
                ),
                "walking/goal": ({"q_start": q, "kind": "turn", "angle_rad": 0.3}, None),
                "footsteps/plan": (
                    {
                        "q_start": q,
                        "tasks": [{"kind": "reach", "target": [0.9, -0.2, 0.8]}, {"kind": "posture"}],
                        "time_budget_s": 20.0,
                    },
                    None,
                ),
                "reaching/reach": ({"hand": "right", "target": [0.35, -0.2, 0.8], "q_start": q}, None),
                "contacts/plan": (
                    {
                        "scene": "chair_egress",
                        "q_start": q_seated,
                        "start_contacts": STRANGER_SEATED,
                        "final_contacts": STRANGER_SEATED,
                        "goal_axis": "x",
                        "goal_value_m": -1.0,
                        "pairs": [],
                        "interpolate": False,
                        "time_budget_s": 30.0,
                    },
                    None,
                ),
            }
        )
        if "contacts" in procs:  # a transition from the plan's own start set (its contacts' x, y, theta)
            plan = ask("contacts/plan", requests["contacts/plan"][0])
            assert plan.kind == "ok", plan
            start_set = plan.body["sets"][0]
            requests["contacts/transition"] = (
                {
                    "scene": "chair_egress",
                    "q_measured": q_seated,
                    "from_set": start_set,
                    "witness": q_seated,
                    "to_set": [c for c in start_set if c["spot"] != "right_thigh"],
                    "n_interpolation": 2,
                    "time_budget_s": 30.0,
                },
                None,
            )
    requests.update(
        {
            "perception/models": ({}, None),
            "perception/look_around": ({}, None),
            "perception/locate": ({"object": "green_box", "width_px": 320, "height_px": 240}, None),
            "diag/echo": ({"text": "hello"}, None),
            "diag/echo_worker": ({"text": "hello"}, {"blob": np.arange(5, dtype=np.uint8)}),
            "diag/raise": ({"code": "infeasible", "message": "asked for"}, None),
            "diag/stream": ({"count": 2, "width": 32, "height": 24}, None),
        }
    )
    try:
        yield session, robot, procs, requests
    finally:
        session.close()


def _first_float_path(doc) -> tuple:
    """The path to the first float in ``doc`` (keys and indices), or () when it has none."""
    if isinstance(doc, float):
        return ((),)
    items = doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(doc, list) else ()
    for key, value in items:
        found = _first_float_path(value)
        if found:
            return ((key, *found[0]),)
    return ()


def _with(doc, path: tuple, value):
    if not path:
        return value
    copy = dict(doc) if isinstance(doc, dict) else list(doc)
    copy[path[0]] = _with(doc[path[0]], path[1:], value)
    return copy


def _malformed(doc: dict) -> list[tuple[str, bytes, str]]:
    """``(what, payload, a word the error message must contain)`` for the documented request ``doc``."""
    out = [
        ("not JSON", b'{"', "malformed"),
        ("a JSON array, not an object", b"[1, 2]", "object"),
        ("an unknown field", json.dumps({**doc, "colour_of_the_sky": "blue"}).encode(), "colour_of_the_sky"),
        ("invalid UTF-8", b'{"\xff\xfe": 1}', "UTF-8"),
        ("a truncated binary frame", b"HRPB" + struct.pack("<I", 1000) + b"{}", "truncated"),
    ]
    if doc:
        name = next(iter(doc))
        out.append(("a wrong type", json.dumps({**doc, name: {"nested": [1]}}).encode(), f"$.{name}"))
        if name != "text":  # diag/echo's text is echoed back whatever its size (within the 64 MB frame)
            out.append(("a huge string", json.dumps({**doc, name: "x" * 2_000_000}).encode(), f"$.{name}"))
    found = _first_float_path(doc)
    if found:
        path = found[0]
        for literal in ("NaN", "Infinity", "-Infinity", "1e999"):
            raw = json.dumps(_with(doc, path, 0.123456789)).replace("0.123456789", literal, 1).encode()
            out.append(
                (f"{literal} in $.{path[0]}", raw, "non-finite" if literal != "1e999" else "out of range")
            )
    for name in ("q", "q_start", "q_measured"):
        if name in doc:  # a huge array, as a JSON list and as raw bytes with a lying shape
            out.append((f"a huge $.{name}", json.dumps({**doc, name: [0.0] * 1_000_000}).encode(), name))
            head = json.dumps({**doc, name: {"__nd__": [0, 8_000_000], "dtype": "<f8", "shape": [1000]}})
            raw = b"HRPB" + struct.pack("<I", len(head)) + head.encode() + bytes(8_000_000)
            out.append((f"a binary $.{name} whose shape lies", raw, "shape"))
    return out


STRANGER_PATHS = sorted(endpoints())


@pytest.mark.parametrize("path", STRANGER_PATHS)
def test_a_stranger_forms_each_request_from_the_docs_and_malformed_ones_are_named(stranger, path):
    session, robot, procs, requests = stranger
    service = path.split("/")[0]
    if service not in procs or path not in requests:
        pytest.skip(f"no {service} here")
    doc, arrays = requests[path]
    key = f"hrp/{robot}/{path}"
    expected_ok = "infeasible" if path == "diag/raise" else "ok"

    def documented() -> stranger_client.Answer:
        return stranger_client.call(session, key, stranger_client.frame(doc, arrays), REPLY_TIMEOUT_S)

    answer = documented()
    assert answer.code != "invalid_request", f"the docs did not let a stranger call {path}: {answer}"
    # the reply's zenoh encoding names its frame (a reader need not look at the bytes)
    assert answer.encoding == stranger_client.label_of(answer.raw), f"{path}: {answer.encoding!r}"
    assert answer.code in STRANGER_TYPED | {expected_ok}, f"{path}: {answer}"
    if path != "diag/raise":
        assert answer.code == "ok" or path in STRANGER_EXPENSIVE, f"{path}: {answer}"
    # zenoh's encoding and attachment are not read (the README): a JSON request labelled as CBOR, with
    # an attachment, is the same request; a CBOR body is refused saying what the endpoints read
    if path not in STRANGER_EXPENSIVE and arrays is None:
        relabelled = stranger_client.call(
            session,
            key,
            json.dumps(doc).encode(),
            REPLY_TIMEOUT_S,
            encoding="application/cbor",
            attachment=b"\x00\x01junk",
        )
        assert relabelled.code == expected_ok, f"{path} with another encoding label: {relabelled}"
    cbor_body = b"\xa1dtext\x62hi"  # {"text": "hi"} in CBOR
    cbor = stranger_client.call(session, key, cbor_body, REPLY_TIMEOUT_S, encoding="application/cbor")
    assert cbor.code == "invalid_request" and "JSON" in cbor.message, f"{path}, CBOR: {cbor}"
    for what, raw, word in _malformed(doc):
        bad = stranger_client.call(session, key, raw, REPLY_TIMEOUT_S, attachment=b"\xff" * 3)
        assert bad.code == "invalid_request", f"{path}, {what}: {bad}"
        assert word.lower() in bad.message.lower(), f"{path}, {what}: the message does not say it: {bad}"
        assert len(bad.raw) < 4096, f"{path}, {what}: a {len(bad.raw)}-byte error reply echoes the payload"
        assert bad.encoding == stranger_client.JSON_LABEL, f"{path}, {what}: labelled {bad.encoding!r}"
    empty = stranger_client.call(session, key, b"", REPLY_TIMEOUT_S)  # as {} (the README)
    assert empty.kind == "error" or empty.kind == "ok", f"{path}, empty payload: {empty}"
    if empty.code == "invalid_request":
        assert "missing required field" in empty.message, f"{path}, empty payload: {empty}"
    else:
        assert empty.code in STRANGER_TYPED | {expected_ok}, f"{path}, empty payload: {empty}"
    if path not in STRANGER_EXPENSIVE:  # and it serves on
        assert documented().code == expected_ok, f"{path} after the malformed requests"
    dead = {name: p.returncode for name, p in procs.items() if p.poll() is not None}
    assert not dead, f"services died: {dead}"


def test_a_stranger_calls_at_once_and_every_call_is_answered(stranger):
    """Concurrent calls from many threads of one session, good and bad, to several services at once."""
    session, robot, _procs, requests = stranger
    cases = [
        (p, *requests[p])
        for p in (
            "sim/state",
            "diag/echo",
            "perception/models",
            "walking/plan",
            "sim/robot_info",
            "diag/echo_worker",
        )
        if p in requests
    ]
    assert cases
    jobs = []
    for i in range(48):
        path, doc, arrays = cases[i % len(cases)]
        good = (i // len(cases)) % 3 != 0  # each endpoint gets good and bad requests
        raw = stranger_client.frame(doc, arrays) if good else b'{"bad": ' + b"1" * (i + 1)
        jobs.append((path, raw, "ok" if good else "invalid_request"))

    def one(job):
        path, raw, want = job
        return path, want, stranger_client.call(session, f"hrp/{robot}/{path}", raw, REPLY_TIMEOUT_S)

    with ThreadPoolExecutor(max_workers=16) as pool:
        results = list(pool.map(one, jobs))
    wrong = [(path, want, str(got)) for path, want, got in results if got.code != want]
    assert not wrong, f"{len(wrong)} of {len(results)} concurrent calls answered otherwise: {wrong[:5]}"


def test_a_stranger_asking_the_impossible_gets_infeasible_with_what_was_reached(stranger):
    """Goals no plan meets, formed from the READMEs: a typed ``infeasible`` (or ``timeout``) naming what
    was reached; a timeout is the request's own budget running out (its ``budget_s``, where it stopped),
    never a hang. (How soon after the budget it answers is measured by ``scripts/bench budgets``.)"""
    session, robot, procs, requests = stranger
    if "sim" not in procs:
        pytest.skip("no sim here")
    q = requests["navigation/goto"][0]["q_start"]
    budget_s = 5.0
    goals = {
        "footsteps/plan": {
            "q_start": q,
            "tasks": [{"kind": "reach", "target": [1.0, -0.2, 3.0]}],
            "time_budget_s": budget_s,
        },
        "reaching/reach": {
            "hand": "right",
            "target": [0.6, -0.2, 1.9],
            "q_start": q,
            "allow_stepping": False,
            "time_budget_s": budget_s,
        },
        "navigation/goto": {
            "q_start": q,
            "goal_pose": [2.0, 0.0, 0.0],
            "total_budget_s": budget_s,
            "obstacles": [
                {"name": "wall", "kind": "box", "center": [2.0, 0.0, 0.5], "size": [0.6, 0.6, 1.0]}
            ],
        },
        "walking/goal": {
            "q_start": q,
            "pose": [1.0, 0.0, 0.0],
            "time_budget_s": budget_s,
            "obstacles": [
                {"name": "wall", "kind": "box", "center": [0.6, 0.0, 0.5], "size": [0.2, 2.0, 1.0]}
            ],
        },
    }
    for path, doc in goals.items():
        if path.split("/")[0] not in procs:
            continue
        answer = stranger_client.call(
            session, f"hrp/{robot}/{path}", json.dumps(doc).encode(), REPLY_TIMEOUT_S
        )
        assert answer.code in ("infeasible", "timeout"), f"{path}: {answer}"
        details = answer.error.get("details")
        assert answer.message and details, f"{path}: no details of what was reached: {answer}"
        if answer.code == "timeout":  # the request's own budget ended it (not a default, not a hang)
            assert details.get("budget_s") == budget_s and details.get("stage"), f"{path}: {details}"


def test_a_stranger_who_does_not_know_the_robot_name_queries_with_a_wildcard(stranger):
    """``hrp/*/<service>/<endpoint>`` reaches the endpoint and gets its answer (the reply goes out on the
    endpoint's own key: zenoh refuses a reply on a key with wildcards, and the query went unanswered)."""
    session, _robot, procs, requests = stranger
    for path in ("sim/state", "diag/echo", "perception/models"):
        if path.split("/")[0] in procs:
            answer = stranger_client.call(
                session, f"hrp/*/{path}", stranger_client.frame(requests[path][0]), 30.0
            )
            assert answer.kind == "ok", f"hrp/*/{path}: {answer}"
            bad = stranger_client.call(session, f"hrp/*/{path}", b"[", 30.0)
            assert bad.code == "invalid_request", f"hrp/*/{path}: {bad}"


def test_a_stranger_tells_each_published_sample_kind_by_its_encoding_label(stranger):
    """Samples carry the replies' labels: diag's heartbeat (plain JSON), its stereo frames (binary
    frames) and the copies of a diag/stream request and reply, read by a raw zenoh subscriber."""
    session, robot, procs, requests = stranger
    if "diag" not in procs:
        pytest.skip("no diag here")
    seen: dict[str, tuple[str, bytes]] = {}

    def on_sample(sample) -> None:  # zenoh's thread: only a dict update
        seen.setdefault(str(sample.key_expr), (str(sample.encoding), sample.payload.to_bytes()[:4]))

    want = {f"hrp/{robot}/diag/{name}" for name in ("heartbeat", "frames", "stream/request", "stream/reply")}
    subscriber = session.declare_subscriber(f"hrp/{robot}/diag/**", on_sample)
    try:
        stream = stranger_client.frame(*requests["diag/stream"])
        deadline = time.monotonic() + 30.0  # a hang guard: the assertion below names what is missing
        while not want <= seen.keys() and time.monotonic() < deadline:
            answer = stranger_client.call(session, f"hrp/{robot}/diag/stream", stream, REPLY_TIMEOUT_S)
            assert answer.kind == "ok", answer
            time.sleep(0.1)
    finally:
        subscriber.undeclare()
    assert want <= seen.keys(), f"not seen: {sorted(want - seen.keys())}"
    labels = {key: label for key, (label, _) in seen.items()}
    assert labels[f"hrp/{robot}/diag/frames"] == stranger_client.HRPB_LABEL, labels
    assert labels[f"hrp/{robot}/diag/heartbeat"] == stranger_client.JSON_LABEL, labels
    for key, (label, head) in seen.items():
        assert label == stranger_client.label_of(head), f"{key}: labelled {label!r}"


def test_a_flooded_endpoint_refuses_at_once_and_its_service_serves_its_other_endpoints(stranger):
    """More requests than an endpoint's queue holds: the extra ones get ``unavailable`` (busy) at once, and
    the service's other endpoints answer meanwhile. (A full zenoh channel held zenoh's delivery to the
    whole service: the echo came only once the flood had drained below the queue's size.) Every answer
    is counted in the service's heartbeat, the refusals made in zenoh's threads included."""
    session, robot, procs, _requests = stranger
    if "diag" not in procs:
        pytest.skip("no diag here")
    slow = json.dumps({"count": 100_000, "width": 8, "height": 8, "time_budget_s": 0.1}).encode()
    flood = 64 + 1 + 24  # the queue (QUEUE_CAPACITY), the one being served, and more
    done: list[str] = []  # the codes, in the order they came
    failed: list[int] = []  # diag's heartbeats' requests_failed, in order

    def one(_i):
        answer = stranger_client.call(session, f"hrp/{robot}/diag/stream", slow, REPLY_TIMEOUT_S)
        done.append(answer.code)
        return answer

    def until(ready) -> None:  # a hang guard: the assertions below say what is wrong
        deadline = time.monotonic() + 30.0
        while not ready() and time.monotonic() < deadline:
            time.sleep(0.01)

    beat = session.declare_subscriber(
        f"hrp/{robot}/diag/heartbeat",
        lambda sample: failed.append(json.loads(sample.payload.to_bytes())["requests_failed"]),
    )
    try:
        until(lambda: failed)
        failed_before = failed[-1]
        with ThreadPoolExecutor(max_workers=flood) as pool:
            answers = pool.map(one, range(flood))
            until(lambda: "unavailable" in done)  # the queue is full now
            echo = stranger_client.call(session, f"hrp/{robot}/diag/echo", b'{"text": "still here"}', 30.0)
            streams_answered_at_echo = sum(code != "unavailable" for code in list(done))
            answers = list(answers)
        until(lambda: failed[-1] >= failed_before + flood)
    finally:
        beat.undeclare()
    assert echo.kind == "ok" and echo.body["text"] == "still here", echo
    codes = [a.code for a in answers]
    busy = [a for a in answers if a.code == "unavailable"]
    assert busy and set(codes) <= {"timeout", "unavailable"}, codes
    assert all(a.error["details"]["reason"] == "busy" and "busy" in a.message for a in busy), busy[0]
    # ordering, not timing: the echo was answered while streams the endpoint had taken were still queued
    accepted = flood - len(busy)
    assert streams_answered_at_echo < accepted, (
        f"diag/echo answered only after all {accepted} queued streams (the flood held the service)"
    )
    # every answer counted (all failed: busy or over their budget), none lost between threads
    assert failed[-1] - failed_before == flood, (failed_before, failed[-1], flood)
