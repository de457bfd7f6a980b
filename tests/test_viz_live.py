"""The live Foxglove view: the viz service in its own process serves a running stack (sim + walking) over
Foxglove's WebSocket protocol; a client speaking that protocol sees the robot's base frame move as the
sim's base does, and misbehaving viewers (connecting in a loop, subscribing to unknown channels, not
reading) cost the stack nothing that breaks it."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from services.bus.schemas import sim as sim_msg
from services.bus.schemas import walking as walk_msg
from services.viz import common as c
from services.viz.wsclient import FoxgloveClient
from tests.conftest import free_port

pytestmark = pytest.mark.integration


def protobuf_class(schema_name: str, schema_data: bytes):
    """The message class of a Foxglove protobuf schema (a serialized FileDescriptorSet)."""
    files = descriptor_pb2.FileDescriptorSet.FromString(schema_data)
    pool = descriptor_pool.DescriptorPool()
    for f in files.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def _schema_data(name: str) -> bytes:
    import foxglove.messages as fm

    return bytes(getattr(fm, name.removeprefix("foxglove.")).get_schema().data)


#: The entities of /world/objects in the scene of the stack below (sim/scenes/footsteps_reach.yaml).
SCENE_OBJECTS = {"object/stand", "object/orange_ball", "object/obstacle_disk"}


@pytest.fixture(scope="module")
def log_path(tmp_path_factory):
    return tmp_path_factory.mktemp("viz") / "live.mcap"


@pytest.fixture(scope="module")
def stack(module_bus_harness, log_path):
    h = module_bus_harness
    port = free_port()
    procs = h.spawn_services(
        {
            "record": ("services.bus.recorder", "--output", str(log_path)),
            # a scene with objects (for /world/objects), none on the walk's way: the disk starts 0.7 m ahead
            "sim": ("sim.service", "--scene", "footsteps_reach"),
            "walking": ("services.walking.service",),
            "diag": ("services.bus.diag",),
            "viz": ("services.viz.service", "--port", str(port)),
        }
    )
    return h, port, procs["viz"]


def _walk(h) -> sim_msg.ExecuteReply:
    state = h.client.call(sim_msg.STATE, sim_msg.StateRequest(), 30.0)
    steps = [walk_msg.Step(pose=[0.2 * (i // 2 + 1), 0.095 if i % 2 else -0.095, 0.0]) for i in range(4)]
    plan = h.client.call(
        walk_msg.PLAN, walk_msg.PlanRequest(steps=steps, q_start=state.q, model=state.model), 60.0
    )
    return h.client.call(sim_msg.EXECUTE, sim_msg.ExecuteRequest(q=plan.q, hold_s=0.3), 120.0)


def _walk_seen(got: list, end_x: float, FrameTransforms) -> bool:
    """Whether a viewer's messages ``got`` hold the footsteps, what is there and, last of the
    transforms, the base at ``end_x`` [m] (where the walk ended)."""
    if not {c.WORLD_OBJECTS, c.PLAN_FOOTSTEPS} <= {m.topic for m in got}:
        return False
    last = next((m for m in reversed(got) if m.topic == c.TF), None)
    if last is None:
        return False
    base = next(t for t in FrameTransforms.FromString(last.data).transforms if t.parent_frame_id == "world")
    return abs(base.translation.x - end_x) < 0.02


def test_a_foxglove_client_sees_the_base_move_as_the_sim_does(stack):
    h, port, _viz = stack
    FrameTransforms = protobuf_class("foxglove.FrameTransforms", _schema_data("foxglove.FrameTransforms"))
    SceneUpdate = protobuf_class("foxglove.SceneUpdate", _schema_data("foxglove.SceneUpdate"))
    with FoxgloveClient(f"ws://127.0.0.1:{port}") as client:
        assert client.wait_for_topics([c.TF, c.ROBOT, c.WORLD_OBJECTS, c.PLAN_FOOTSTEPS, c.LOG])
        ads = client.topics()
        assert ads[c.TF].encoding == "protobuf" and ads[c.TF].schema_name == "foxglove.FrameTransforms"
        client.subscribe([c.TF, c.ROBOT, c.WORLD_OBJECTS, c.PLAN_FOOTSTEPS])
        got: list = []
        stop = threading.Event()

        def read() -> None:
            while not stop.is_set():
                msg = client.receive(0.2)
                if msg is not None:
                    got.append(msg)

        reader = threading.Thread(target=read)
        reader.start()
        try:
            time.sleep(0.5)
            start = h.client.call(sim_msg.STATE, sim_msg.StateRequest(), 30.0).q
            result = _walk(h)
            # Until the walk's end reached the viewer (its last transform, the footsteps, what is
            # there): a hang guard of 11 s, the assertions below say what is missing.
            deadline = time.monotonic() + 11.0
            while time.monotonic() < deadline and not _walk_seen(list(got), result.q[0], FrameTransforms):
                time.sleep(0.05)
        finally:
            stop.set()
            reader.join()
    assert result.outcome == "completed", result.message
    base_x = []
    for msg in got:
        if msg.topic == c.TF:
            tfs = FrameTransforms.FromString(msg.data).transforms
            base = next(t for t in tfs if t.parent_frame_id == "world")
            assert base.child_frame_id == "base_link"
            assert len(tfs) > 20  # the links, soles, grasp frames and cameras under the base
            base_x.append(base.translation.x)
    assert len(base_x) >= 5, f"{len(base_x)} transforms received"
    assert base_x[0] == pytest.approx(start[0], abs=0.02)
    assert base_x[-1] == pytest.approx(result.q[0], abs=0.02)  # where the sim's base ended
    assert result.q[0] - start[0] > 0.3 and np.all(np.diff(base_x) > -0.02)  # it walked forward
    scenes = [SceneUpdate.FromString(m.data) for m in got if m.topic == c.ROBOT]
    assert scenes and {e.frame_id for e in scenes[0].entities} >= {"base_link"}
    assert all(e.frame_locked for e in scenes[0].entities)
    footsteps = [SceneUpdate.FromString(m.data) for m in got if m.topic == c.PLAN_FOOTSTEPS]
    assert footsteps and len(footsteps[-1].entities[0].cubes) == 4  # the walk's four soles
    objects = [SceneUpdate.FromString(m.data) for m in got if m.topic == c.WORLD_OBJECTS]
    assert objects and {e.id for e in objects[-1].entities} == SCENE_OBJECTS  # the sim's, as they are


def test_misbehaving_viewers_do_not_hurt_the_stack(stack):
    h, port, viz = stack[:3]
    for _ in range(10):  # connect and disconnect in a loop
        with FoxgloveClient(f"ws://127.0.0.1:{port}") as client:
            client.wait_for_topics([c.TF], timeout_s=2.0)
            client.subscribe([c.TF])
    slow = FoxgloveClient(f"ws://127.0.0.1:{port}")  # subscribes to everything, never reads
    slow.wait_for_topics([c.TF, c.ROBOT])
    slow.subscribe(list(slow.topics()))
    odd = FoxgloveClient(f"ws://127.0.0.1:{port}")  # unknown channels
    odd.wait_for_topics([c.TF])
    odd.subscribe_channel_ids([987654, 123456789])
    try:
        result = _walk(h)
        assert result.outcome == "completed", result.message
        assert viz.poll() is None  # the viz service is still there
        assert {"sim", "walking", "viz"} <= h.client.alive_services()
        with FoxgloveClient(f"ws://127.0.0.1:{port}") as fresh:  # and still serves a new viewer
            assert fresh.wait_for_topics([c.TF, c.ROBOT])
            fresh.subscribe([c.ROBOT])
            robot = fresh.receive(5.0)  # the body is sent again to a new subscriber
            assert robot is not None and robot.topic == c.ROBOT
    finally:
        slow.close()
        odd.close()


def test_a_service_warning_reaches_the_log_panel(stack):
    """A service's Python warning (diag drops an undecodable ping) -> its ``log`` key -> foxglove.Log."""
    h, port, _viz = stack
    Log = protobuf_class("foxglove.Log", _schema_data("foxglove.Log"))
    with FoxgloveClient(f"ws://127.0.0.1:{port}") as client:
        assert client.wait_for_topics([c.LOG])
        client.subscribe([c.LOG])
        time.sleep(0.3)
        h.session.put(f"hrp/{h.bus.robot}/diag/ping", b"\xff not a ping")  # kept as octets in the log
        deadline = time.monotonic() + 10.0
        lines = []
        while time.monotonic() < deadline and not lines:
            got = client.receive(0.5)
            if got is not None and got.topic == c.LOG:
                log = Log.FromString(got.data)
                if log.name.startswith("diag") and "dropped a diag/ping message" in log.message:
                    lines.append(log)
    assert lines, "no log line of diag on /log"
    assert lines[0].level == 3 and lines[0].file.endswith("service.py") and lines[0].line > 0  # WARNING


def test_recorded_log_reads_back_with_the_official_reader_and_decodes(stack, log_path):
    """Runs after the other tests of the module (pytest keeps file order): the recorder saw them.

    The warning of the test above reached this test's viewer through viz; it may still be on its way
    to the recorder (stopped right then, under load, the recorder had not read it yet): the recorder
    is stopped once ``record/status`` counts it written."""
    import json

    from mcap.reader import make_reader

    from services.bus import keys
    from services.bus import world as world_keys
    from services.bus.foxglove import schema_problems
    from services.bus.schemas.record import STATUS, StatusRequest

    h = stack[0]
    recorder = next(p for p in h.procs if "services.bus.recorder" in " ".join(map(str, p.args)))
    warning = keys.key(h.bus.robot, "diag", "log")
    truth = world_keys.mirror_key(h.bus.robot)  # the sim's ground truth's copy: /world/objects

    def written(key: str) -> int:
        return h.client.call(STATUS, StatusRequest(), 10.0).per_key.get(key, 0)

    # no viewer watches /world/objects now (the live view asks the sim only then): after the gripper
    # opens, the recorder itself asks what is there
    truths = written(truth)
    h.client.call(sim_msg.GRIPPER, sim_msg.GripperRequest(side="right", action="open"), 30.0)
    deadline = time.monotonic() + 30.0  # a hang guard: the assertions below say what is missing
    while time.monotonic() < deadline:
        if written(warning) > 0 and written(truth) > truths:
            break
        time.sleep(0.05)
    assert h.stop(recorder) == 0
    topics: dict[str, int] = {}
    robot = h.bus.robot
    world: list[tuple[int, set[str]]] = []  # /world/objects: (log time [ns], entity ids)
    executed: list[int] = []  # log times of sim/execute's replies [ns]
    with open(log_path, "rb") as stream:
        reader = make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        for schema, channel, message in reader.iter_messages():
            topics[channel.topic] = topics.get(channel.topic, 0) + 1
            if channel.topic == c.WORLD_OBJECTS:
                update = protobuf_class(schema.name, schema.data).FromString(message.data)
                world.append((message.log_time, {e.id for e in update.entities}))
            if channel.topic in (f"hrp/{robot}/sim/execute/reply", f"hrp/{robot}/sim/gripper/reply"):
                executed.append(message.log_time)
            if channel.topic == f"hrp/{robot}/sim/joint_state":  # rounded, as numbers Foxglove plots
                assert channel.metadata["hrp.decimals"] == "6"
                assert len(json.loads(message.data)["q"]["values"]) >= 37
            if channel.message_encoding == "protobuf":
                protobuf_class(schema.name, schema.data).FromString(message.data)
            else:
                assert channel.message_encoding == "json"
                json.loads(message.data)
                if schema is not None:
                    assert schema.encoding == "jsonschema"
                    assert schema_problems(json.loads(schema.data), channel.topic) == []
    assert summary is not None and summary.statistics.message_count == sum(topics.values())
    for topic in (
        c.TF,
        c.ROBOT,
        c.PLAN_FOOTSTEPS,
        c.PLAN_COM_ZMP,
        c.LOG,
        f"hrp/{robot}/sim/joint_state",
        f"hrp/{robot}/diag/log",
    ):
        assert topics.get(topic, 0) > 0, topic
    # One copy of the 200 Hz joint state, at its own rate; the transforms at about 30 Hz.
    assert [t for t in topics if t.startswith(f"hrp/{robot}/sim/joint_state")] == [
        f"hrp/{robot}/sim/joint_state"
    ]
    assert topics[c.TF] < topics[f"hrp/{robot}/sim/joint_state"] / 2
    # What is there, as the live view shows it: the recorder asked the sim when the log began and
    # after each motion, the gripper's last (the copy of the reply, converted as the live view does)
    assert world and executed, (len(world), len(executed))
    assert world[0][1] == SCENE_OBJECTS and world[0][0] < executed[0]
    assert any(t > executed[-1] and ids == SCENE_OBJECTS for t, ids in world), (world, executed)


def test_foxglove_own_reader_decodes_every_message_of_the_recorded_log(stack, log_path):
    """The same log through Foxglove's published code (scripts/foxglove_check, Node): every channel's
    every message decodes. Runs after the log was closed by the test above."""
    from services.viz import nodecheck

    reason = nodecheck.unavailable()
    if reason:
        pytest.skip(reason)
    report = nodecheck.check_log(log_path)
    bad = [ch for ch in report["channels"] if not ch["ok"]]
    assert bad == [] and report["exit_code"] == 0, bad
    assert report["channels_ok"] == report["channels_total"] > 10
    assert report["summary_message_count"] == report["messages"] > 0


def test_up_foxglove_starts_the_live_view_and_only_then(tmp_path):
    import subprocess
    import sys

    from tests.test_launcher import REPO, Up

    listed = subprocess.run(
        [sys.executable, "-m", "services.cli", "up", "--list"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
    )
    assert "diag" in listed.stdout and "viz" not in listed.stdout  # not started unless asked for
    port = free_port()
    up = Up("--services", "diag", "--foxglove", str(port))
    try:
        up.client.wait_for(["diag", "viz"], timeout_s=60.0)
        Log = protobuf_class("foxglove.Log", _schema_data("foxglove.Log"))
        with FoxgloveClient(f"ws://127.0.0.1:{port}") as client:
            assert client.wait_for_topics([c.TF, c.ROBOT, c.LOG])
            client.subscribe([c.LOG])
            got = client.receive(10.0)  # the latest log line is sent to a new subscriber
            assert got is not None and got.topic == c.LOG
            line = Log.FromString(got.data)
            assert line.name == "launcher" and ": ready" in line.message
    finally:
        up.close()
