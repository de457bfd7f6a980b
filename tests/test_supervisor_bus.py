"""The supervisor on a real bus with the sim, perception, walking and footsteps services: events,
health, perception actions, walks relative to the robot, the last steps of an approach.

The planner-dependent actions and the whole fetch are in test_supervisor_fetch.py.
"""

from __future__ import annotations

import os
import signal
import threading

import numpy as np
import pytest

from services.bus.schemas import sim as sim_msg
from services.bus.schemas.supervisor import EVENTS
from services.bus.session import TypedSubscriber
from services.errors import InvalidRequestError, UnavailableError
from supervisor.body import BACK_OUT_EASE_S
from supervisor.core import Supervisor
from supervisor.script import parse_script


@pytest.fixture(scope="module")
def stack(module_bus_harness, tmp_path_factory):
    h = module_bus_harness
    h.scene_dir = tmp_path_factory.mktemp("scenes")  # scenes the tests write; sim/reset loads them by name
    h.spawn_services(
        {
            "sim": ("sim.service", "--scene", "ball_fetch", "--scene-dir", str(h.scene_dir)),
            "perception": ("services.perception.service",),
            "walking": ("services.walking.service",),
            "footsteps": ("services.footsteps.service",),
        }
    )
    return h


@pytest.fixture
def sup(stack):
    s = Supervisor(stack.session, stack.bus.robot)
    stack.client.call(sim_msg.RESET, sim_msg.ResetRequest(scene="ball_fetch"), 30)
    try:
        yield s
    finally:
        s.close()


def test_detect_and_look_at_publish_events_and_use_perception(stack, sup) -> None:
    events = TypedSubscriber(stack.session, stack.bus.robot, EVENTS)
    try:
        report = sup.run(parse_script("detect orange_ball\nlook_at orange_ball"), run_id="t1")
        assert report.ok, report.failure
        seen = []
        while True:
            try:
                seen.append(events.recv(timeout_s=2.0))
            except TimeoutError:
                break
    finally:
        events.undeclare()
    kinds = [e.kind for e in seen]
    assert kinds[0] == "run_started" and kinds[-1] == "run_finished" and seen[-1].ok
    assert kinds.count("started") == 2 and kinds.count("finished") == 2
    assert {e.run_id for e in seen} == {"t1"}
    # The supervisor's belief comes from perception: within a few cm of where the sim put the ball.
    gt = {o.name: o for o in stack.client.call(sim_msg.GROUND_TRUTH, sim_msg.GroundTruthRequest(), 5).objects}
    seen_at = sup.actions.memory.get("orange_ball").position_m
    assert np.linalg.norm(seen_at - np.asarray(gt["orange_ball"].position)) < 0.05
    # look_at turned the head toward the ball: it is now near the image centre.
    assert sup.actions.eyes.off_centre() < 0.2


def test_unknown_object_and_unlocalized_target_fail_with_clear_reasons(sup) -> None:
    report = sup.run(parse_script("detect red_ball"))
    assert not report.ok and report.failure.reason == "invalid_request"
    assert "orange_ball" in report.failure.message  # the message lists the known objects
    report = sup.run(parse_script("goto yellow_table"))
    assert not report.ok and report.failure.reason == "not_found"
    assert "localize it first" in report.failure.message


def test_grasp_on_nothing_is_not_grasped_and_retried_then_reported(sup) -> None:
    report = sup.run(parse_script("grasp right as ball"))
    assert not report.ok
    failure = report.failure
    assert failure.reason == "not_grasped" and failure.attempts == 3  # 1 + 2 retries of the policy
    assert "closed on nothing" in failure.message
    kinds = [e.kind for e in sup.events]
    assert kinds.count("retried") == 2 and kinds.count("failed") == 3


def test_stop_aborts_before_the_next_call(sup) -> None:
    sup.runner.on_event = lambda event: sup.request_stop() if event.kind == "started" else None
    report = sup.run(parse_script("detect orange_ball\ndetect green_box"))
    assert not report.ok
    assert report.failure.reason == "stopped"
    assert len(report.reports) == 1


def test_health_monitor_sees_a_killed_service_go(module_bus_harness, stack) -> None:
    h = module_bus_harness
    proc = h.spawn_service("services.bus.diag", name="diag")
    sup = Supervisor(h.session, h.bus.robot)
    try:
        assert sup.health.wait_alive("diag", 5.0)
        sup.health.check("diag")
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        gone = threading.Event()
        for _ in range(200):
            if "diag" not in sup.health.alive():
                gone.set()
                break
            gone.wait(0.05)
        assert gone.is_set()
        with pytest.raises(UnavailableError, match="no liveliness token"):
            sup.health.check("diag")
        assert not sup.health.wait_alive("diag", 0.3)
    finally:
        sup.close()


def test_console_reads_commands_suggests_and_runs_them(stack, sup) -> None:
    import io

    from supervisor.repl import ConsoleLoop

    out = io.StringIO()
    loop = ConsoleLoop(sup, sup.known_objects(), out)
    sup.out = out  # progress lines of the running actions go to the same place
    code = loop.run(["tkae the orange ball", "help", "look at the orange ball"])
    text = out.getvalue()
    assert code == 0, text
    assert "The closest I know: 'take the orange ball'" in text
    assert "Commands:" in text and "put it on the table" in text
    assert "ok: looking at orange_ball" in text
    assert "SUCCESS" in text


def test_console_exit_code_when_the_last_line_is_refused_or_unanswered(stack, sup) -> None:
    """Read from stdin by a script: a refused last line, or a question the input leaves unanswered, is
    a failure (exit code 1), not 0 as if it had been done."""
    import io

    from supervisor.repl import ConsoleLoop

    out = io.StringIO()
    assert ConsoleLoop(sup, sup.known_objects(), out).run(["juggle the orange ball"]) == 1, out.getvalue()
    out = io.StringIO()  # piped: the refused last line is heard while the first command still runs
    lines = ["find the orange ball", "juggle the orange ball"]
    assert ConsoleLoop(sup, sup.known_objects(), out).run(lines) == 1, out.getvalue()
    out = io.StringIO()  # perception knows every ball of the scene: "the ball" is ambiguous
    assert ConsoleLoop(sup, sup.known_objects(), out).run(["take the ball"]) == 1, out.getvalue()
    assert "which ball" in out.getvalue() and "without an answer" in out.getvalue()


def test_console_stop_aborts_the_running_command(stack, sup) -> None:
    import io

    from supervisor.repl import ConsoleLoop

    out = io.StringIO()
    sup.out = out
    code = ConsoleLoop(sup, sup.known_objects(), out).run(["find the yellow table", "stop"])
    text = out.getvalue()
    assert code == 1, text
    assert "stopping" in text and "stopped by the operator" in text
    assert sup.events[-1].kind == "run_finished" and not sup.events[-1].ok


def test_a_motion_stopped_by_a_collision_is_backed_out_over_the_bus(stack, sup, tmp_path) -> None:
    """The right arm swings into a crate and stops pressing on it; backing out plays the executed part
    backward (the crate may be touched until the contact breaks), after which the robot can hold still
    without touching anything."""
    from services.errors import CollisionError
    from sim import motions

    scene = stack.scene_dir / "crate.yaml"
    scene.write_text(
        "name: crate\ndescription: a crate beside the right arm\nrobot: {x: 0.0, y: 0.0, yaw: 0.0}\n"
        "floor: {colour: light_grey, friction: 1.0}\nobjects:\n"
        "  - {name: crate, kind: box, size: [0.3, 0.3, 1.0], colour: blue, xy: [0.45, -0.3], yaw: 0.0}\n"
    )
    stack.client.call(sim_msg.RESET, sim_msg.ResetRequest(scene="crate"), 30)
    body = sup.actions.body
    from services.model import load_robot

    swing = motions.joint_motion(load_robot(body.robot.name), body.q(), {"RARM_JOINT0": -1.2}, 1.0)
    with pytest.raises(CollisionError) as stopped:
        body.execute(swing, what="swing")
    assert stopped.value.code == "collision" and body.interrupted is not None
    assert body.interrupted.touched == ("crate",)
    executed_s = (body.interrupted.q.shape[0] - 1) * body.interrupted.dt_s
    assert executed_s < 0.5  # stopped early: backing out undoes all of it (at least 0.5 s otherwise)
    eased_s = min(executed_s, BACK_OUT_EASE_S)  # its last part played slowing down, in twice the time
    assert body.back_out() == pytest.approx(executed_s + eased_s, abs=0.011) and body.interrupted is None
    q = body.q()
    body.execute(np.repeat(q[None, :], 20, axis=0), what="hold still")  # completes: no contact left
    assert body.back_out() == 0.0  # nothing left to undo


def test_walk_relative_to_the_robot_and_back(sup) -> None:
    """``walk 0.4 0.1 30``: 0.4 m forward, 0.1 m to the left, turned 30 deg left, the walking planner
    making the steps (walking/goal); ``walk -0.3 0`` then steps back along the new heading."""
    import math

    body = sup.actions.body
    x0, y0, yaw0 = body.base_xy_yaw()
    report = sup.run(parse_script("walk 0.4 0.1 30\nwalk -0.3 0"))
    assert report.ok, [r.message for r in report.reports]
    first = report.reports[0]
    assert first.details["steps"] >= 3
    x1, y1, yaw1 = first.details["pose"]
    c, s = math.cos(yaw0), math.sin(yaw0)
    forward, left = c * (x1 - x0) + s * (y1 - y0), -s * (x1 - x0) + c * (y1 - y0)
    assert (forward, left) == pytest.approx((0.4, 0.1), abs=0.05)
    assert math.degrees(math.remainder(yaw1 - yaw0, 2 * math.pi)) == pytest.approx(30.0, abs=4.0)
    x2, y2, _ = report.reports[1].details["pose"]
    back = math.cos(yaw1) * (x2 - x1) + math.sin(yaw1) * (y2 - y1)
    assert back == pytest.approx(-0.3, abs=0.05)
    # The feet side by side at the end: squaring that stance (the missed grasp's remedy) takes no step.
    with pytest.raises(InvalidRequestError, match="already square") as refused:
        sup.actions.planners.square()
    assert refused.value.details["reason"] == "already_square"  # the remedy keeps only this refusal


def test_the_robot_facts_come_from_the_services_and_match_the_model(sup) -> None:
    """The supervisor loads no model: sim/robot_info, sim/kinematics and perception/look_around give it
    the same joints, frames and kinematics as services.model (loaded here, by the test only)."""
    from services.model import load_robot
    from services.perception.look_around import head_joints, scan_angles

    robot = sup.actions.body.robot
    model = load_robot(robot.name)
    assert robot.joint_names == list(model.joint_names) and robot.nq == model.nq
    np.testing.assert_allclose(robot.q_half_sitting, model.q_half_sitting)
    assert robot.index("RARM_JOINT0") == model.joint_index("RARM_JOINT0").idx_q
    q = sup.actions.body.q()
    assert robot.mid_feet_pose(q) == pytest.approx(model.mid_feet_pose(q), abs=1e-9)
    np.testing.assert_allclose(
        robot.grasp_position(q, "right"), model.frame_pose(q, model.frames.grasp("right")).translation
    )
    offset = model.held_object_offset("right", 0.04)
    np.testing.assert_allclose(robot.held_object_offset("right", 0.04), offset)
    placed = robot.place_on_ground(model.q_half_sitting, 1.0, -0.5, 0.3)
    np.testing.assert_allclose(placed, model.place_on_ground(model.q_half_sitting, 1.0, -0.5, 0.3))
    heights = robot.sole_heights(np.stack([q, placed]))
    assert heights.shape == (2, 2) and np.all(np.abs(heights[1]) < 1e-9)
    head = head_joints(model)
    assert sup.actions.body.head_joints() == (head.pan, head.tilt)
    assert robot.head.views == [list(v) for v in scan_angles(model)]
    assert robot.head.image_size_px == [640, 480]
    # A bad request is a typed error naming what was wrong.
    from services.errors import InvalidRequestError

    with pytest.raises(InvalidRequestError, match="nq"):
        robot.kinematics(np.zeros(5))
    with pytest.raises(InvalidRequestError, match="no frame"):
        robot.frame_pose(q, "nowhere")


def test_the_last_steps_come_with_the_final_posture_footsteps_planned(stack, sup) -> None:
    """footsteps/plan decides the last steps and the final posture together (paper 000 §7): the walk of
    its footsteps (walking/plan) and, in its final posture, the hand on the target, with that hand's
    orientation handed on for reaching."""
    from scipy.spatial.transform import Rotation

    body, planners = sup.actions.body, sup.actions.planners
    x, y, yaw = body.base_xy_yaw()
    ahead, right = np.array([np.cos(yaw), np.sin(yaw)]), np.array([np.sin(yaw), -np.cos(yaw)])
    target = np.array([*(np.array([x, y]) + 0.9 * ahead + 0.2 * right), 0.8])  # out of reach: steps
    decided = planners.last_steps("right", target, target)
    assert decided.walk is not None and decided.walk.n_steps >= 1, decided.found
    assert decided.walk.planner == "footsteps/plan + walking/plan"
    robot = body.robot
    hand = robot.frame_pose(decided.q_final, robot.grasp_frame("right"))
    assert np.linalg.norm(hand.translation - target) < 5e-3
    turned = Rotation.from_quat(decided.hand_quat).inv() * Rotation.from_matrix(hand.rotation)
    assert turned.magnitude() < 1e-6
