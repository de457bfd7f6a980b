"""The sim service over a real zenoh bus: a spawned ``python -m sim.service`` process and a hub session
in this process (free loopback port, a robot name of its own)."""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from services.bus.config import BusConfig
from services.bus.schemas import sim as msg
from services.bus.session import Client, TypedSubscriber, close_session, open_session
from services.errors import InvalidRequestError, NotFoundError, RequestTimeoutError
from services.model import load_robot
from sim import motions

pytestmark = pytest.mark.integration


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def _sim_service(*options: str):
    """(client, session, bus) of a spawned sim service started with ``options``; stopped on exit."""
    bus = BusConfig(robot=f"simtest{os.getpid()}x{_free_port()}").with_hub_port(_free_port())
    session = open_session(bus, as_hub=True)
    command = [
        sys.executable,
        "-m",
        "sim.service",
        "--hub",
        bus.hub,
        "--robot",
        bus.robot,
        "--log-level",
        "WARNING",
    ]
    proc = subprocess.Popen([*command, *options], stdout=subprocess.DEVNULL)
    try:
        client = Client(session, bus.robot, default_timeout_s=60.0)
        client.wait_for(["sim"], timeout_s=60.0)
        yield client, session, bus
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        close_session(session)


@pytest.fixture(scope="module")
def sim():
    """(client, session, bus) talking to a sim service with the footsteps_reach scene."""
    with _sim_service("--scene", "footsteps_reach") as handles:
        yield handles


def test_state_describes_the_robot_and_the_scene(sim):
    client, _, _ = sim
    state = client.call(msg.STATE, msg.StateRequest())
    robot = load_robot("hrp2_like")
    assert (state.model, state.scene, state.seed) == ("hrp2_like", "footsteps_reach", None)
    assert state.joint_names == list(robot.joint_names)
    assert state.q.shape == (robot.nq,) and state.v.shape == (robot.nv,)
    assert not state.fallen and state.held == {}


def test_execute_a_squat_over_the_bus_while_state_is_published(sim):
    client, session, bus = sim
    state = client.call(msg.STATE, msg.StateRequest())
    traj = motions.squat_trajectory(
        load_robot("hrp2_like"), state.q, depth_m=0.05, down_s=0.6, pause_s=0.1, up_s=0.6
    )
    joint_states = TypedSubscriber(session, bus.robot, msg.JOINT_STATE, capacity=1024)
    clocks = TypedSubscriber(session, bus.robot, msg.CLOCK, capacity=1024)
    base_poses = TypedSubscriber(session, bus.robot, msg.BASE_POSE, capacity=1024)
    time.sleep(0.3)  # let the subscriptions reach the service
    try:
        reply = client.call(msg.EXECUTE, msg.ExecuteRequest(q=traj), timeout_s=120.0)
        assert reply.outcome == "completed", reply.message
        assert reply.samples_executed == len(traj)
        assert reply.base_error_m < 0.01 and reply.tracking_error_rad < 0.01 and reply.foot_slip_m < 1e-3
        assert reply.collisions == []
        times = []
        while len(times) < len(traj) - 1:
            js = joint_states.recv(timeout_s=10.0)
            if js.sim_time_s > state.sim_time_s:
                times.append(js.sim_time_s)
        assert np.diff(times) == pytest.approx(0.005)  # 200 Hz of sim time
        assert times[-1] == pytest.approx(reply.sim_time_s)
        assert clocks.recv(timeout_s=5.0).sim_time_s > state.sim_time_s - 1e-9
        pose = base_poses.recv(timeout_s=5.0)
        assert len(pose.position) == 3 and len(pose.quaternion) == 4
    finally:
        for sub in (joint_states, clocks, base_poses):
            sub.undeclare()
    after = client.call(msg.STATE, msg.StateRequest())
    assert after.sim_time_s == pytest.approx(reply.sim_time_s)  # physics frozen while idle (default)


def test_bad_trajectory_is_an_invalid_request_naming_the_problem(sim):
    client, _, _ = sim
    with pytest.raises(InvalidRequestError, match="shape"):
        client.call(msg.EXECUTE, msg.ExecuteRequest(q=np.zeros((3, 4))))
    with pytest.raises(NotFoundError, match="valid cameras"):
        client.call(msg.RENDER, msg.RenderRequest(camera="fisheye"))


def test_render_a_stereo_pair_over_the_bus(sim):
    client, _, _ = sim
    reply = client.call(
        msg.RENDER, msg.RenderRequest(camera="wide", width_px=320, height_px=240, segmentation=True)
    )
    assert [im.name for im in reply.images] == ["wide_left", "wide_right"]
    assert reply.baseline_m == pytest.approx(0.144)
    truth = {o.name: o for o in client.call(msg.GROUND_TRUTH, msg.GroundTruthRequest()).objects}
    for im in reply.images:
        assert im.rgb.shape == (240, 320, 3) and im.rgb.dtype == np.uint8
        ball_id = next(int(k) for k, v in im.labels.items() if v == "orange_ball")
        rows, cols = np.nonzero(im.segmentation == ball_id)
        p_cam = np.linalg.inv(im.T_world_camera) @ np.r_[truth["orange_ball"].position, 1.0]
        uv = (im.K @ p_cam[:3])[:2] / p_cam[2]
        assert np.hypot(cols.mean() + 0.5 - uv[0], rows.mean() + 0.5 - uv[1]) < 2.0


def test_a_render_that_would_end_past_its_budget_is_not_started(sim):
    """Issue 16: a draw is one pybullet call that cannot be stopped, so one estimated to end past the
    request's budget is refused before it starts (the sim never renders for a caller that stopped
    waiting), and the wait for the world busy with an execute is bounded by it; the endpoint serves on.
    ``sim/kinematics`` checks its budget between configurations."""
    client, session, bus = sim
    huge = msg.RenderRequest(width_px=2048, height_px=2048, depth=True, segmentation=True, time_budget_s=0.01)
    refused = "would run out during the render of a 2048 x 2048 px"
    with pytest.raises(RequestTimeoutError, match=refused) as err:
        client.call(msg.RENDER, huge)
    assert err.value.details["estimated_s"] > 0.01
    with pytest.raises(RequestTimeoutError, match="the render of a 2048 x 2048 px image"):
        client.call(msg.SNAPSHOT, msg.SnapshotRequest(width_px=2048, height_px=2048, time_budget_s=0.01))
    small = client.call(msg.RENDER, msg.RenderRequest(width_px=160, height_px=120, time_budget_s=30.0))
    assert [im.rgb.shape for im in small.images] == [(120, 160, 3)] * 2
    q = client.call(msg.STATE, msg.StateRequest()).q
    # a render waits for the world (busy with an execute) at most its budget
    hold = msg.ExecuteRequest(q=np.repeat(q[None, :], 4000, axis=0), time_budget_s=3.0)

    def play() -> None:
        with contextlib.suppress(RequestTimeoutError):  # the hold ends at its own budget
            client.call(msg.EXECUTE, hold, timeout_s=60.0)

    clocks = TypedSubscriber(session, bus.robot, msg.CLOCK, capacity=64)
    playing = threading.Thread(target=play, daemon=True)
    try:
        time.sleep(0.3)  # let the subscription reach the service
        playing.start()
        clocks.recv(timeout_s=30.0)  # physics runs: the execute holds the world
    finally:
        clocks.undeclare()  # a full channel would hold back the session's replies
    try:
        with pytest.raises(RequestTimeoutError, match="the wait for the world"):
            client.call(msg.RENDER, msg.RenderRequest(width_px=160, height_px=120, time_budget_s=0.2))
    finally:
        playing.join()
    # the forward kinematics of many configurations stops at its budget too
    many = msg.KinematicsRequest(q=np.repeat(q[None, :], 2000, axis=0), time_budget_s=1e-3)
    with pytest.raises(RequestTimeoutError, match="the forward kinematics, configuration"):
        client.call(msg.KINEMATICS, many)
    one = client.call(msg.KINEMATICS, msg.KinematicsRequest(q=q, time_budget_s=30.0))
    assert one.mid_feet.shape == (1, 3)


def test_gripper_snapshot_and_reset(sim):
    client, _, _ = sim
    reply = client.call(msg.GRIPPER, msg.GripperRequest(side="right", action="close"))
    assert (reply.outcome, reply.held) == ("not_grasped", "")
    assert client.call(msg.GRIPPER, msg.GripperRequest(side="right", action="open")).outcome == "opened"
    with pytest.raises(InvalidRequestError, match="side"):
        client.call(msg.GRIPPER, msg.GripperRequest(side="up", action="open"))

    shot = client.call(msg.SNAPSHOT, msg.SnapshotRequest(viewpoint="front", width_px=160, height_px=120))
    assert shot.png.dtype == np.uint8 and shot.png[:4].tobytes() == b"\x89PNG"

    before = client.call(msg.STATE, msg.StateRequest()).sim_time_s
    reset = client.call(msg.RESET, msg.ResetRequest(scene="ball_fetch", seed=4))
    assert (reset.scene, reset.seed) == ("ball_fetch", 4) and "orange_ball" in reset.objects
    assert reset.sim_time_s > before  # sim time never goes back
    truth = client.call(msg.GROUND_TRUTH, msg.GroundTruthRequest())
    assert truth.scene == "ball_fetch" and {o.name for o in truth.objects} == set(reset.objects)
    with pytest.raises(NotFoundError, match="available scenes"):
        client.call(msg.RESET, msg.ResetRequest(scene="moon_base"))


def test_realtime_mode_keeps_the_clock_running_while_idle():
    with _sim_service("--realtime") as (client, _, _):
        first = client.call(msg.STATE, msg.StateRequest())
        time.sleep(0.5)
        second = client.call(msg.STATE, msg.StateRequest())
        assert second.sim_time_s > first.sim_time_s  # stepping while idle (robot standing)
        assert not second.fallen
        assert np.linalg.norm(second.q[:3] - first.q[:3]) < 1e-3
