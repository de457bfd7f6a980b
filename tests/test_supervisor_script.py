"""The supervisor's script language, console mapping and retry runner (no bus needed)."""

from __future__ import annotations

import math
import threading

import pytest

from services.errors import InvalidRequestError, UnavailableError
from supervisor.console import interpret
from supervisor.report import ActionReport
from supervisor.retry import RetryPolicy, RetryRule
from supervisor.runner import Runner
from supervisor.script import EITHER_HAND, parse_script

KNOWN = ("orange_ball", "green_box", "yellow_table")


def test_script_parses_actions_options_bindings_and_comments() -> None:
    steps = parse_script(
        """
        # fetch
        localize green_box
        goto green_box distance=0.7   # stand in front
        grasp right as ball
        put ball on=yellow_table
        """
    )
    assert [s.action for s in steps] == ["localize", "goto", "grasp", "put"]
    assert steps[1].kwargs == {"distance": "0.7"}
    assert steps[2].bind == "ball"
    assert steps[3].line == 6


def test_script_errors_name_every_bad_line_and_suggest() -> None:
    with pytest.raises(InvalidRequestError) as info:
        parse_script("localise orange_ball\ngrasp middle\ngoto box speed=2\nturn")
    message = info.value.message
    assert "line 1: unknown action 'localise'; did you mean 'localize'?" in message
    assert "line 2: hand 'middle' is not one of left, right" in message
    assert "line 3: 'goto' has no option 'speed' (options: distance)" in message
    assert "line 4: 'turn' takes turn angle_deg, got 0 argument(s)" in message


@pytest.mark.parametrize(
    ("line", "said"),
    [
        ("goto green_box distance=abc", "'goto' distance 'abc' is not a number"),
        ("turn left", "'turn' angle_deg 'left' is not a number"),
        ("walk 0.3 nan", "'walk' left_m 'nan' is not a number"),
    ],
)
def test_a_number_argument_is_checked_when_the_script_is_read(line: str, said: str) -> None:
    """It failed only when the action ran: after connecting, after the actions before it."""
    with pytest.raises(InvalidRequestError, match=said):
        parse_script(f"localize green_box\n{line}\n")
    assert [s.text() for s in parse_script("turn -120\nwalk -0.3 0 15\ngoto x distance=0.7")] == [
        "turn -120",
        "walk -0.3 0 15",
        "goto x distance=0.7",
    ]


def test_empty_script_is_an_error() -> None:
    with pytest.raises(InvalidRequestError, match="no action"):
        parse_script("# nothing\n\n")


@pytest.mark.parametrize(
    ("text", "actions"),
    [
        ("take the orange ball", ["localize", "reach", "grasp"]),
        ("Go to the yellow table.", ["localize", "goto"]),
        ("put it on the table", ["localize", "put"]),
        ("look at the green box", ["look_at"]),
        ("turn left", ["turn"]),
    ],
)
def test_console_maps_plain_commands_to_actions(text: str, actions: list[str]) -> None:
    assert [s.action for s in interpret(text, KNOWN).steps] == actions


def test_console_resolves_short_names_and_turn_angles() -> None:
    assert interpret("put it on the table", KNOWN).steps[1].kwargs == {"on": "yellow_table"}
    assert interpret("turn right 45 degrees", KNOWN).steps[0].args == ("-45",)
    assert interpret("turn around", KNOWN).steps[0].args == ("180",)
    assert interpret("stop", KNOWN).control == "stop"


def test_console_suggests_the_closest_command_and_lists_known_objects() -> None:
    with pytest.raises(InvalidRequestError, match="The closest I know: 'take the orange ball'"):
        interpret("tkae the orange ball", KNOWN)
    with pytest.raises(InvalidRequestError, match="Known objects: orange ball, green box, yellow table"):
        interpret("go to the kitchen", KNOWN)


def _flaky(failures: list[str]):
    """An action that fails with the given reasons in turn, then succeeds."""
    calls = []

    def action(step):
        calls.append(step)
        if len(calls) <= len(failures):
            return ActionReport(step.action, step.args, ok=False, reason=failures[len(calls) - 1])
        return ActionReport(step.action, step.args, details={"object": "orange_ball"})

    return action, calls


def test_runner_retries_within_the_policy_runs_remedies_and_binds_names() -> None:
    grasp, calls = _flaky(["not_grasped"])
    remedies_run = []
    events = []
    runner = Runner(
        {
            "grasp": grasp,
            "put": lambda step: ActionReport("put", step.args, details={"on": step.kwargs["on"]}),
        },
        remedies={"relocalize": lambda step, report: remedies_run.append(report.reason)},
        on_event=events.append,
    )
    result = runner.run(parse_script("grasp right as ball\nput ball on=yellow_table"))
    assert result.ok and result.retries == 1
    assert remedies_run == ["not_grasped"]
    assert result.reports[1].args == ("orange_ball",)  # the bound name was resolved
    assert [e.kind for e in events] == [
        "started",
        "failed",
        "retried",
        "started",
        "finished",
        "started",
        "finished",
    ]
    assert len(calls) == 2


def test_runner_gives_up_after_the_bounded_retries_and_stops_the_script() -> None:
    grasp, calls = _flaky(["not_grasped"] * 10)
    policy = RetryPolicy((("not_grasped", RetryRule(2, "none")),))
    result = Runner({"grasp": grasp, "open": grasp}, policy=policy).run(
        parse_script("grasp right\nopen right")
    )
    assert not result.ok
    assert result.failure is not None and result.failure.reason == "not_grasped"
    assert result.failure.attempts == 3 and len(calls) == 3 and len(result.reports) == 1


def test_runner_turns_typed_exceptions_into_reports_and_honours_stop() -> None:
    def down(step):
        raise UnavailableError("footsteps is restarting")

    stop = threading.Event()
    policy = RetryPolicy((("unavailable", RetryRule(5, "none")),))
    runner = Runner({"reach": down}, policy=policy, stop=stop, on_event=lambda e: stop.set())
    report = runner.run(parse_script("reach right orange_ball")).reports[0]
    assert not report.ok and report.reason in ("unavailable", "stopped")
    assert report.attempts <= 2


def test_supervisor_config_defaults_yaml_override_and_errors(tmp_path):
    from services.errors import InvalidRequestError
    from supervisor.config import SupervisorConfig, load_supervisor_config

    assert load_supervisor_config(None) == SupervisorConfig()
    path = tmp_path / "stack.yaml"
    path.write_text("bus: {}\nsupervisor:\n  far_m: 3\n  carry_m: [0.3, 0.2, 0.9]\n")
    config = load_supervisor_config(path)
    assert config.far_m == 3 and config.carry_m == (0.3, 0.2, 0.9) and config.near_m == 1.8
    path.write_text("supervisor:\n  far: 3\n")
    with pytest.raises(InvalidRequestError, match=r"unknown SupervisorConfig option.*far.*valid options"):
        load_supervisor_config(path)
    path.write_text("supervisor:\n  near_m: 2.5\n")
    with pytest.raises(InvalidRequestError, match=r"near_m .* must be below far_m"):
        load_supervisor_config(path)
    path.write_text("supervisor:\n  goto_farther_m: [0.15, -0.3]\n")
    with pytest.raises(InvalidRequestError, match=r"goto_farther_m must be >= 0 m, got \[0.15, -0.3\]"):
        load_supervisor_config(path)
    path.write_text("supervisor:\n  straight_back_deg: 120\n")  # every way out would be "back"
    with pytest.raises(InvalidRequestError, match=r"straight_back_deg must be <= 90 deg, got 120"):
        load_supervisor_config(path)


def test_supervisor_config_arm_timing_per_motion_and_its_bounds():
    """The unguarded arm motions named in ``fast_arm_motions`` get reaching's timing fields, the others
    none (reaching's default); names and values outside reaching's bounds are refused at start-up."""
    from services.errors import InvalidRequestError
    from supervisor.config import SupervisorConfig

    config = SupervisorConfig()
    assert config.arm_timing("raise") == {"hand_speed_m_s": 0.4, "min_duration_s": 0.6, "final_hold_s": 0.15}
    assert config.arm_timing("lift") == {}  # the grasped object off its support: default timing
    assert SupervisorConfig(fast_arm_motions=()).arm_timing("carry") == {}
    with pytest.raises(InvalidRequestError, match="fast_arm_motions"):
        SupervisorConfig(fast_arm_motions=("grasp",))
    with pytest.raises(InvalidRequestError, match="fast_arm_speed_m_s"):
        SupervisorConfig(fast_arm_speed_m_s=1.0)
    with pytest.raises(InvalidRequestError, match="fast_arm_min_s"):
        SupervisorConfig(fast_arm_min_s=0.1)
    with pytest.raises(InvalidRequestError, match="fast_arm_hold_s"):
        SupervisorConfig(fast_arm_hold_s=-0.1)


def test_a_reach_or_grasp_naming_no_hand_leaves_it_to_the_supervisor() -> None:
    reach, grasp, named = parse_script("reach orange_ball\ngrasp as ball\nreach left 1,2,0.8")
    assert reach.args == (EITHER_HAND, "orange_ball")
    assert grasp.args == (EITHER_HAND,) and grasp.bind == "ball"
    assert named.args == ("left", "1,2,0.8")
    with pytest.raises(InvalidRequestError, match="takes reach hand target"):
        parse_script("reach")
    # A hand with its target forgotten is an error, not a search for an object called "right".
    with pytest.raises(InvalidRequestError, match="takes reach hand target, got 1"):
        parse_script("reach right")
    # Only reach and grasp choose: "open" must name the hand it opens, refused before anything runs.
    with pytest.raises(InvalidRequestError, match="takes open hand, got 0"):
        parse_script("open")


def test_an_object_out_of_reach_from_near_is_not_looked_for_again() -> None:
    from services.bus.schemas.supervisor import REASON_NO_CLEAR_WAY, REASON_OUT_OF_REACH
    from services.bus.schemas.walking import REASON_LEANING
    from supervisor.retry import DEFAULT_POLICY

    assert DEFAULT_POLICY.rule("infeasible", REASON_OUT_OF_REACH).retries == 0
    assert DEFAULT_POLICY.rule("infeasible", REASON_LEANING).retries == 0  # leaning on what it touched
    assert REASON_LEANING in DEFAULT_POLICY.final  # a remedy failing so ends the retries (the runner)
    assert DEFAULT_POLICY.rule("infeasible", REASON_NO_CLEAR_WAY).retries == 1  # a fresh look may show room
    assert DEFAULT_POLICY.rule("infeasible").retries == 1


def test_stand_up_goal_is_beside_the_seated_robot_whichever_way_it_faces() -> None:
    """The waist's goal 0.6 m to the seated robot's left, as the one coordinate contacts/plan takes: in
    the shipped scene (facing +x at y = 0) beyond y = 0.6 m, as before; a chair turned a quarter (facing
    +y): x below -0.6 m; turned half: y below -0.6 m; turned 200 deg: still y, below."""
    from supervisor.stand_up import beside_goal

    assert beside_goal((-0.11, 0.0), 0.0, 0.6) == ("y", pytest.approx(0.6), False)
    assert beside_goal((0.0, 0.0), math.pi / 2, 0.6) == ("x", pytest.approx(-0.6), True)
    assert beside_goal((1.0, 2.0), math.pi, 0.6) == ("y", pytest.approx(1.4), True)
    axis, value, below = beside_goal((0.0, 0.0), math.radians(200), 0.6)
    assert (axis, below) == ("y", True) and value == pytest.approx(-0.6 * math.cos(math.radians(20)))


def test_a_fall_during_a_remedy_ends_the_retries_with_that_reason() -> None:
    """The robot fell while the remedy moved it: the next attempt would only find it on the ground, so
    the action fails with ``fell`` at once (before, the retry ran and failed on "the robot is on the
    ground")."""
    from services.errors import FellError

    grasp, calls = _flaky(["collision"] * 5)

    def replan(step, report):
        raise FellError("fell while backing out")

    policy = RetryPolicy((("collision", RetryRule(2, "replan")),))
    runner = Runner({"grasp": grasp}, policy=policy, remedies={"replan": replan})
    result = runner.run(parse_script("grasp right"))
    assert not result.ok and result.failure.reason == "fell" and len(calls) == 1
