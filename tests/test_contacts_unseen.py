"""``contacts/plan`` on layouts and payloads no other test uses (scripts/bench.d/_contacts_scenes.py), over
the bus of one real contacts service reading the generated scenes from its ``scene_dirs``: the chair
scene turned by 90 degrees and moved (a plan, checked without the planner's code: contacts on their
surfaces by forward kinematics, no collision in pybullet's shapes, static balance by an LP); a standing
robot turned 0.4 rad taking a static step (a new contact found inside C, §2.6); a goal out of reach, a
final contact no pair allows, ``max_nodes`` 1 and a 50 ms budget (typed refusals with their reason and
``residual_m``, within the budget); the service is the same process at the end (no crash, no restart).
The whole family, with longer searches and the sim's execution: ``scripts/bench contacts --scenes``."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import msgspec
import pytest

from services.bus.schemas import contacts as msg
from services.errors import HumanoidError
from services.model import load_robot
from sim.scene import find_scene, layout, load_scene
from sim.world import start_configuration

FAMILY_PY = Path(__file__).resolve().parents[1] / "scripts" / "bench.d" / "_contacts_scenes.py"
CASES = (
    "turned90_release",
    "standing_step",
    "goal_out_of_reach",
    "final_not_allowed",
    "max_nodes_1",
    "budget_50ms",
    "start_not_balanced",
    "start_spot_twice",
    "quat_zero",
    "joint_past_limit",
    "goal_met_max_nodes_1",
)


def _family():
    spec = importlib.util.spec_from_file_location("_contacts_scenes", FAMILY_PY)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["_contacts_scenes"] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def family():
    return _family()


@pytest.fixture(scope="module")
def stack(module_bus_harness, family, tmp_path_factory):
    cases = {c.name: c for c in family.cases(quick=True) if c.name in CASES}
    folder = family.write_scenes(list(cases.values()), tmp_path_factory.mktemp("contacts_scenes"))
    proc = module_bus_harness.spawn_service(
        "services.contacts.service", "--scene-dir", str(folder), name="contacts", timeout_s=60
    )
    return module_bus_harness, proc, cases, folder


def _ask(stack, family, name: str):
    harness, _, cases, folder = stack
    case = cases[name]
    path = find_scene(case.scene, [folder])
    q0 = start_configuration(load_robot("hrp2_like"), layout(load_scene(path)))
    request = msg.PlanRequest(
        scene=case.scene,
        q_start=family.start_q(case, q0),
        **{"start_contacts": family.SEATED, **case.request},
    )
    try:
        answer = harness.client.call(msg.PLAN, request, timeout_s=request.time_budget_s + 60.0)
    except HumanoidError as exc:
        answer = exc
    return case, path, q0, answer


@pytest.mark.integration
@pytest.mark.parametrize("name", ["turned90_release", "standing_step"])
def test_a_plan_in_a_layout_not_seen_checks_out_independently(stack, family, name) -> None:
    _, path, q0, reply = _ask(stack, family, name)
    assert not isinstance(reply, HumanoidError), reply
    assert len(reply.sets) >= 2 and reply.q.shape[0] > 2
    checker = family.PlanChecker(path)
    try:
        assert checker.check(reply, q0) == []
        # the check can fail: the last witness 4 cm up (off its supports) or 30 cm ahead (off balance,
        # into the furniture or off the contacts' places)
        for shift, kind in (((0.0, 0.0, 0.04), "plane"), ((0.3, 0.0, 0.0), "")):
            witnesses = reply.witnesses.copy()
            witnesses[-1, :3] += shift
            problems = checker.check(msgspec.structs.replace(reply, witnesses=witnesses, q=reply.q[:0]), q0)
            assert problems and kind in " ".join(problems), problems
    finally:
        checker.close()


@pytest.mark.integration
@pytest.mark.parametrize(
    ("name", "code", "reason"),
    [
        ("goal_out_of_reach", "infeasible", msg.REASON_GOAL_OUT_OF_REACH),
        ("final_not_allowed", "infeasible", msg.REASON_FINAL_CONTACT_NOT_ALLOWED),
        ("max_nodes_1", "timeout", msg.NO_PATH_WITHIN_BUDGET),
        ("budget_50ms", "timeout", msg.NO_PATH_WITHIN_BUDGET),
    ],
)
def test_an_impossible_or_starved_request_is_refused_typed_with_its_residual(
    stack, family, name, code, reason
) -> None:
    case, _, _, answer = _ask(stack, family, name)
    assert isinstance(answer, HumanoidError), f"{name}: a plan where none can be"
    assert (answer.code, answer.details.get("reason")) == (code, reason), answer
    assert family.answer_problems(case, answer.code, answer.details) == []
    # The service's own typed answer within its budget (a hang would end in the client's timeout after
    # budget + 60 s, without the reason); how long it takes is scripts/bench contacts --scenes' to say.
    assert answer.details["residual_m"] > 0.0


@pytest.mark.integration
@pytest.mark.parametrize(
    ("name", "field"),
    [
        ("start_not_balanced", "start_contacts"),
        ("start_spot_twice", "start_contacts"),
        ("quat_zero", "q_start"),
        ("joint_past_limit", "q_start"),
    ],
)
def test_a_start_that_is_not_feasible_is_an_invalid_request_naming_its_field(
    stack, family, name, field
) -> None:
    _, _, _, answer = _ask(stack, family, name)
    assert isinstance(answer, HumanoidError) and answer.code == "invalid_request", answer
    assert answer.details.get("field") == field, answer


@pytest.mark.integration
def test_a_start_that_already_meets_the_goal_is_a_one_set_plan_even_with_max_nodes_1(stack, family) -> None:
    *_, reply = _ask(stack, family, "goal_met_max_nodes_1")
    assert not isinstance(reply, HumanoidError), reply
    assert reply.changes == ["start"] and reply.nodes_generated == 0


@pytest.mark.integration
def test_the_service_survived_every_case(stack) -> None:
    harness, proc, _, _ = stack
    assert proc.poll() is None and "contacts" in harness.client.alive_services()


def test_the_search_is_the_same_when_the_whole_layout_turns(family, tmp_path) -> None:
    """f_T's F in the start's heading frame, the floor's frame the robot's, T made from the layout:
    the chair scene turned by 90 degrees and moved grows the same first six nodes (four removals, then
    a hand on the table; contacts in their surfaces' frames, f_T values) as the shipped one (in world
    coordinates F's log3 made them differ from the first addition on)."""
    import math

    import yaml

    from services.contacts import chair_egress
    from services.contacts.planner import PlanProblem, build
    from services.contacts.search import ContactPlanner, Goal, SearchConfig

    doc = family.turned(family.base_doc(), math.pi / 2, 1.3, -0.7, "cu_turned")
    (tmp_path / "cu_turned.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    side = family.left_goal(doc)
    robot = load_robot("hrp2_like")
    grown = []
    for path, goal in (
        ("chair_egress", Goal("y", 0.6, chair_egress.FINAL_PAIRS)),
        (
            str(tmp_path / "cu_turned.yaml"),
            Goal(side["goal_axis"], side["goal_value_m"], chair_egress.FINAL_PAIRS, -1.0),
        ),
    ):
        q0 = start_configuration(robot, layout(load_scene(path)))
        problem = PlanProblem(
            scene=path,
            q_start=q0,
            start_pairs=chair_egress.START_PAIRS,
            goal=goal,
            pairs=chair_egress.PAIRS,
            search=SearchConfig(max_nodes=6),
            interpolation=None,
        )
        gen, trajectory, start, pairs = build(robot, problem)
        planner = ContactPlanner(gen, trajectory, goal, pairs, problem.search)
        planner.plan(start, q0)
        grown.append(planner.nodes)
    assert side["goal_below"] and len(grown[0]) == 6
    assert [n.change for n in grown[0]] == [n.change for n in grown[1]]
    assert [n.f for n in grown[0]] == pytest.approx([n.f for n in grown[1]], abs=1e-4)
