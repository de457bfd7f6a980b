"""Foxglove compatibility without the bus: every schema the stack registers passes the rules of
Foxglove's JSON-schema reader, every frame's log form rebuilds the exact frame, and the converters make
decodable Foxglove messages for both robot models."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from services.bus import schemas
from services.bus.codec import decode, encode
from services.bus.foxglove import message_schema, schema_problems
from services.bus.logform import (
    DELTA_PLANES,
    OCTETS_SCHEMA,
    from_log_form,
    pack_array,
    to_log_form,
    unpack_array,
)
from services.bus.schemas import navigation as nav_msg
from services.bus.schemas import perception as per_msg
from services.bus.schemas import sim as sim_msg
from services.bus.schemas import walking as walk_msg
from services.bus.schemas.common import ErrorInfo, Heartbeat, LogLine
from services.bus.schemas.supervisor import SupervisorEvent
from services.bus.spec import json_schema
from services.model import load_robot
from services.viz import common as c
from services.viz.converter import Converter, encoded
from tests.test_viz_live import protobuf_class


def _registered_types() -> set[type]:
    types: set[type] = {Heartbeat, ErrorInfo, LogLine}
    for endpoint in schemas.endpoints().values():
        types |= {endpoint.request, endpoint.reply}
    types |= {topic.message for topic in schemas.topics().values()}
    return types


def test_every_registered_schema_passes_foxglove_json_schema_rules():
    types = _registered_types()
    assert len(types) > 30
    problems = [p for t in sorted(types, key=str) for p in schema_problems(message_schema(t), t.__name__)]
    assert problems == []
    assert schema_problems(OCTETS_SCHEMA) == []


def test_the_rules_reject_what_foxglove_rejects():
    # The plain msgspec schemas the first logs carried: untyped arrays, anyOf, arrays of arrays.
    assert any("q" in p for p in schema_problems(json_schema(sim_msg.JointState)))
    assert any("T_world_camera" in p for p in schema_problems(json_schema(per_msg.LocateReply)))
    assert any("anyOf" in p or "None" in p for p in schema_problems(json_schema(walk_msg.PlanRequest)))
    assert schema_problems({"type": "object"}) == ['(root): an object needs a "properties" mapping']
    bad = {"type": "object", "properties": {"a": {"type": ["number", "null"]}, "b": {"type": "null"}}}
    assert len(schema_problems(bad)) == 2


def _locate_reply(z: float = 0.7) -> per_msg.LocateReply:
    box = per_msg.PixelBox(u_px=1, v_px=2, width_px=3, height_px=4, angle_deg=0.5)
    footprint = per_msg.FootprintMsg(center=[1.0, 2.0], size=[0.5, 0.4], yaw=0.1, top_z=0.7, n_points=40)
    return per_msg.LocateReply(
        object="yellow_table", position=[1.0, 2.0, z], position_camera=[0.1, 0.2, 1.5],
        distance_m=1.5, size_m=[0.5, 0.4], confidence=0.8, method="edges", disparity_px=12.5,
        box_left=box, box_right=box, window_left=[1, 2, 3, 4], camera="wide",
        T_world_camera=np.eye(4).tolist(), rendered=True, sim_time_s=3.25, footprint=footprint,
    )  # fmt: skip


def test_log_form_rebuilds_every_kind_of_frame_exactly():
    rng = np.random.default_rng(3)
    image = sim_msg.CameraImage(
        name="wide_left", width_px=16, height_px=12, K=np.eye(3), T_world_camera=np.eye(4),
        rgb=rng.integers(0, 255, (12, 16, 3), dtype=np.uint8), depth_m=rng.random((12, 16), dtype=np.float32),
        labels={3: "robot"},
    )  # fmt: skip
    hand = walk_msg.HandTask(side="left", times_s=[1.0, 2.0], positions_m=[[0.3, 0.2, 0.9], [0.4, 0.2, 1.0]])
    frames = [
        (sim_msg.JointState, encode(sim_msg.JointState(sim_time_s=1.0, q=rng.random(37), v=rng.random(36)))),
        (sim_msg.RenderReply, encode(sim_msg.RenderReply(sim_time_s=2.0, images=[image, image]))),
        (walk_msg.PlanRequest, encode(walk_msg.PlanRequest(steps=[walk_msg.Step(pose=[0.2, 0.1, 0.0])],
                                                           hands=[hand], q_start=rng.random(37)))),
        (per_msg.LocateReply, encode(_locate_reply(float("nan")))),  # NaN: null in JSON
        (ErrorInfo, encode(ErrorInfo(code="invalid_request", message="é \\u0000 \"q\"", details={"a": [1]}))),
        (None, b"\xff\x00garbage"),
        (sim_msg.JointState, b"HRPB\x05\x00\x00\x00{bad"),
    ]  # fmt: skip
    for type_, frame in frames:
        kind, stored = to_log_form(frame, type_)
        doc = json.loads(stored)  # every log form is JSON
        assert isinstance(doc, dict)
        assert from_log_form(kind, stored, type_) == frame, type_
    kind, stored = to_log_form(frames[3][1], per_msg.LocateReply)
    assert json.loads(stored)["T_world_camera"][0] == {"values": [1.0, 0.0, 0.0, 0.0]}
    kind, stored = to_log_form(frames[0][1], sim_msg.JointState)
    assert kind == "hrpb" and set(json.loads(stored)["q"]) == {"dtype", "shape", "data"}


def test_delta_planes_arrays_are_exact_and_compress_smooth_trajectories():
    import zstandard

    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 15.0, 3001)
    smooth = np.stack([np.sin(t * (1 + k / 7)) * (k + 1) + rng.normal(0, 1e-9, t.size) for k in range(37)], 1)
    arrays = [
        smooth,
        smooth.astype("<f4"),
        rng.random((6, 4, 3)),
        rng.random(100),
        np.arange(70.0),
        smooth[:1],
    ]
    for a in arrays:
        raw = np.ascontiguousarray(a).tobytes()
        node = pack_array(raw, a.dtype.str, list(a.shape))
        assert node.get("layout") == (DELTA_PLANES if a.shape[0] > 1 else None), a.shape
        assert unpack_array(json.loads(json.dumps(node))) == raw
    special = np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324, 1.7e308] * 10)
    assert unpack_array(pack_array(special.tobytes(), "<f8", [70])) == special.tobytes()
    # A walking plan's joint trajectory: its log form compresses clearly better than the plain bytes.
    plain = {
        "dtype": "<f8",
        "shape": list(smooth.shape),
        "data": pack_array(smooth.tobytes(), "<f8", [1])["data"],
    }
    packed = pack_array(smooth.tobytes(), "<f8", list(smooth.shape))
    size = {
        k: len(zstandard.compress(json.dumps(n).encode())) for k, n in (("plain", plain), ("packed", packed))
    }
    assert size["packed"] < 0.8 * size["plain"], size
    with pytest.raises(ValueError, match="layout"):
        unpack_array({**packed, "layout": "zigzag"})


def test_a_sensor_stream_is_written_rounded_as_numbers():
    rng = np.random.default_rng(4)
    state = sim_msg.JointState(sim_time_s=1.005, q=rng.normal(0, 1, 37), v=rng.normal(0, 3, 36))
    kind, stored = to_log_form(encode(state), sim_msg.JointState, 6)
    doc = json.loads(stored)
    assert kind == "hrpb" and set(doc["q"]) == {"dtype", "shape", "values"} and len(doc["q"]["values"]) == 37
    back = decode(from_log_form(kind, stored, sim_msg.JointState), sim_msg.JointState)
    assert back.sim_time_s == 1.005
    assert np.abs(back.q - state.q).max() <= 0.5e-6 and np.abs(back.v - state.v).max() <= 0.5e-6
    assert back.q.dtype == np.float64 and back.q.shape == (37,)
    pose = sim_msg.BasePose(
        sim_time_s=2.0,
        position=[0.12345678, 1.0, 0.6],
        quaternion=[0.0, 0.0, 0.0, 1.0],
        linear_velocity=[1e-9, 0.0, 0.0],
        angular_velocity=[0.0, 0.0, 0.3333333333],
    )
    kind, stored = to_log_form(encode(pose), sim_msg.BasePose, 6)
    assert kind == "json" and json.loads(stored)["position"][0] == 0.123457
    assert (
        decode(from_log_form(kind, stored, sim_msg.BasePose), sim_msg.BasePose).angular_velocity[2]
        == 0.333333
    )
    assert schema_problems(message_schema(sim_msg.JointState)) == []


def _decode_all(views) -> dict[str, list]:
    out: dict[str, list] = {}
    for view in views:
        if view.message_encoding == "protobuf":
            msg = protobuf_class(view.schema_name, view.schema_data).FromString(view.data)
        else:
            assert schema_problems(json.loads(view.schema_data)) == []
            msg = json.loads(view.data)
        out.setdefault(view.topic, []).append(msg)
    return out


@pytest.mark.parametrize("model", ["hrp2_like", "talos"])
def test_the_robot_in_3d_for_both_models(model):
    robot = load_robot(model)
    conv = Converter()  # the model is recognised from the joint state's size
    q = robot.q_half_sitting.copy()
    q[:2] = (1.5, -0.5)
    t = time.time_ns()
    views = conv.views(
        "hrp/hrp2/sim/joint_state", encode(sim_msg.JointState(sim_time_s=0.0, q=q, v=np.zeros(robot.nv))), t
    )
    got = _decode_all(views)
    tfs = got[c.TF][0].transforms
    base = next(tf for tf in tfs if tf.parent_frame_id == c.WORLD)
    assert (base.child_frame_id, base.translation.x, base.translation.y) == (robot.frames.base, 1.5, -0.5)
    children = {tf.child_frame_id for tf in tfs}
    assert {cam.frame for cam in robot.cameras.values()} <= children
    entities = got[c.ROBOT][0].entities
    assert {e.frame_id for e in entities} <= children | {robot.frames.base}
    shapes = sum(len(e.cubes) + len(e.cylinders) + len(e.spheres) for e in entities)
    if model == "talos":  # meshes in the URDF: its collision capsules (a cylinder and two spheres each)
        assert shapes == 3 * len(robot.capsules)
    else:
        assert shapes == len(robot.build_geometry_model("collision").geometryObjects)
    # Decimated to 30 Hz: a joint state 5 ms later gives nothing, 40 ms later gives transforms again.
    js = encode(sim_msg.JointState(sim_time_s=0.005, q=q, v=np.zeros(robot.nv)))
    assert conv.views("hrp/hrp2/sim/joint_state", js, t + 5_000_000) == []
    assert [v.topic for v in conv.views("hrp/hrp2/sim/joint_state", js, t + 40_000_000)] == [c.TF]


def test_plans_map_cameras_and_text_become_foxglove_messages():
    conv = Converter("hrp2_like")
    t = time.time_ns()
    n = 50
    goto = nav_msg.GotoReply(
        model="hrp2_like", goal=[2.0, 0.0, 0.0],
        path_xy_m=np.column_stack([np.linspace(0, 2, n), np.zeros(n)]),
        path_theta_rad=np.zeros(n), path_s_m=np.linspace(0, 2, n), path_forward=np.ones(n, np.uint8),
        path_curve="dubins", left_start=[0.0, 0.095, 0.0], right_start=[0.0, -0.095, 0.0],
        step_sides=["right", "left"], step_poses=np.array([[0.2, -0.095, 0.0], [0.4, 0.095, 0.0]]),
        dt_s=0.005,
        q=np.zeros((n, 37)), com_m=np.column_stack([np.linspace(0, 2, n), np.zeros(n), np.full(n, 0.8)]),
        zmp_m=np.zeros((n, 2)), duration_s=1.0,
        reshaping=nav_msg.ReshapingReport(
            iterations=1, segments=[], min_clearance_m=None, zmp_margin_m=0.01, hand_error_m=0.0,
            collisions_per_iteration=[0], bar_height_nominal_m=np.zeros(0), bar_height_before_m=np.zeros(0),
            bar_height_planned_m=np.zeros(0), bar_height_m=np.zeros(0),
        ),
        timings_s={"total_s": 1.0},
    )  # fmt: skip
    request = nav_msg.GotoRequest(
        q_start=np.zeros(37),
        obstacles=[nav_msg.ObstacleMsg(name="box", center=[1, 1, 0.3], size=[0.4, 0.4, 0.6])],
    )
    image = sim_msg.CameraImage(
        name="wide_left", width_px=32, height_px=24, K=np.array([[30, 0, 16], [0, 30, 12], [0, 0, 1.0]]),
        T_world_camera=np.eye(4), rgb=np.full((24, 32, 3), 128, np.uint8),
    )  # fmt: skip
    event = SupervisorEvent(kind="failed", run_id="r", step="walk to table", attempt=1, reason="collision")
    views = [
        *conv.views("hrp/hrp2/navigation/goto/reply", encode(goto), t),
        *conv.views("hrp/hrp2/navigation/goto/request", encode(request), t),
        *conv.views("hrp/hrp2/perception/locate/reply", encode(_locate_reply()), t),
        *conv.views(
            "hrp/hrp2/sim/render/reply", encode(sim_msg.RenderReply(sim_time_s=1.0, images=[image])), t
        ),
        *conv.views("hrp/hrp2/supervisor/events", encode(event), t),
        *conv.views(
            "hrp/hrp2/walking/plan/error", encode(ErrorInfo(code="infeasible", message="too far")), t
        ),
    ]
    assert conv.errors == 0
    got = _decode_all(views)
    assert len(got[c.PLAN_PATH][0].entities[0].lines[0].points) == n
    steps = got[c.PLAN_FOOTSTEPS][0].entities[0].cubes
    assert [round(s.pose.position.x, 3) for s in steps] == [0.2, 0.4]
    assert steps[0].color.r > steps[0].color.b and steps[1].color.b > steps[1].color.r  # right red, left blue
    assert len(got[c.PLAN_SUPPORT][0].entities[0].lines) == 3  # before the walk and after each landing
    assert got[c.PLAN_SERIES][0]["com_z_m"][0] == 0.8
    assert got[c.MAP_OBSTACLES][0].entities[0].id == "map/box"
    assert got[c.MAP_SIGHTINGS][0].entities[0].id == "sighting/yellow_table"
    calibration = got[c.camera_calibration_topic("wide_left")][0]
    assert (
        calibration.frame_id == load_robot("hrp2_like").cameras["wide_left"].frame and calibration.K[0] == 30
    )
    assert got[c.camera_image_topic("wide_left")][0].format == "jpeg"
    logs = got[c.LOG]
    assert "walk to table" in logs[0].message and logs[0].name == "supervisor"
    assert "infeasible: too far" in logs[1].message and logs[1].name == "walking"
    assert encoded(
        c.TF, got and __import__("foxglove.messages").messages.FrameTransforms(), t
    ).schema_name == ("foxglove.FrameTransforms")


def _joint_state_log(path: Path, heartbeats: bool = False) -> Path:
    """An MCAP log (with the Foxglove views) of 20 joint states 50 ms apart, the base 1 cm further in x
    each (``heartbeats``: a sim heartbeat beside each); ``path``."""
    from services.bus.mcaplog import LogWriter

    robot = load_robot("hrp2_like")
    writer = LogWriter(path, views=Converter().views)
    t = time.time_ns()
    for i in range(20):
        q = robot.q_half_sitting.copy()
        q[0] = 0.01 * i
        frame = encode(sim_msg.JointState(sim_time_s=0.005 * i, q=q, v=np.zeros(robot.nv)))
        writer.write("hrp/hrp2/sim/joint_state", frame, t + i * 50_000_000)
        if heartbeats:
            writer.write("hrp/hrp2/sim/heartbeat", b"{}", t + i * 50_000_000)
    writer.close()
    return path


def _base_xs(client, n: int) -> list[float]:
    """The base's x [m, mm rounded] in the next ``n`` ``/tf`` messages a viewer subscribed to receives."""
    FrameTransforms = protobuf_class("foxglove.FrameTransforms", _schema_bytes())
    xs = []
    while len(xs) < n:
        got = client.receive(5.0)
        assert got is not None
        transforms = FrameTransforms.FromString(got.data).transforms
        xs.append(round(next(tf for tf in transforms if tf.parent_frame_id == "world").translation.x, 3))
    return xs


def test_a_recorded_log_is_served_to_foxglove(tmp_path):
    """``humanoid replay FILE --foxglove``: the log's channels, advertised and played to a viewer."""
    import threading

    from services.viz.player import serve_log
    from services.viz.wsclient import FoxgloveClient
    from tests.conftest import free_port

    path = _joint_state_log(tmp_path / "log.mcap")
    port = free_port()
    ready = threading.Event()
    player = threading.Thread(
        target=serve_log,
        args=(str(path),),
        kwargs={"port": port, "speed": 4.0, "on_ready": lambda _p: ready.set(), "wait_for_viewer_s": 10.0},
    )
    player.start()
    try:
        assert ready.wait(10.0)
        with FoxgloveClient(f"ws://127.0.0.1:{port}") as client:
            assert client.wait_for_topics([c.TF, c.ROBOT, "hrp/hrp2/sim/joint_state"])
            client.subscribe([c.TF])
            xs = _base_xs(client, 20)
    finally:
        player.join(timeout=20)
    assert xs == [round(0.01 * i, 3) for i in range(20)]


def test_a_log_served_to_foxglove_from_a_start_time_and_left_by_its_viewer(tmp_path, capfd, caplog):
    """``humanoid replay FILE --foxglove --start S --topics GLOB``: only what the bus replay would
    play; a viewer that unsubscribes and leaves raises nothing in the server's callbacks."""
    import threading

    from services.bus.replay import key_filter
    from services.viz.player import serve_log
    from services.viz.wsclient import FoxgloveClient
    from tests.conftest import free_port

    path = _joint_state_log(tmp_path / "log.mcap", heartbeats=True)
    port = free_port()
    ready = threading.Event()
    player = threading.Thread(
        target=serve_log,
        args=(str(path),),
        kwargs={
            "port": port,
            "speed": 4.0,
            "on_ready": lambda _p: ready.set(),
            "wait_for_viewer_s": 10.0,
            "start_s": 0.5,
            "accept": key_filter(["/tf", "hrp/*/sim/*"]),
        },
    )
    player.start()
    try:
        assert ready.wait(10.0)
        with FoxgloveClient(f"ws://127.0.0.1:{port}") as client:
            assert client.wait_for_topics([c.TF, "hrp/hrp2/sim/joint_state"])
            assert c.ROBOT not in client.topics() and "hrp/hrp2/sim/heartbeat" not in client.topics()
            client.subscribe([c.TF])
            xs = _base_xs(client, 10)
    finally:
        player.join(timeout=20)
    assert xs == [round(0.01 * i, 3) for i in range(10, 20)]
    assert "Callback failed" not in capfd.readouterr().err + caplog.text


def test_a_port_in_use_is_a_typed_error_naming_it():
    """A second `humanoid view` (or `up --foxglove`) on a taken port: InvalidRequestError, not a traceback."""
    import socket

    from services.errors import InvalidRequestError
    from services.viz.common import start_ws_server

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(
            InvalidRequestError, match=f"127.0.0.1:{port}.*another server holds the port: choose another"
        ):
            start_ws_server(name="test", host="127.0.0.1", port=port)


def _schema_bytes() -> bytes:
    from foxglove.messages import FrameTransforms

    return bytes(FrameTransforms.get_schema().data)


def test_the_committed_layout_is_the_generated_one():
    from services.viz.layout import LAYOUT_PATH, layout_json

    assert LAYOUT_PATH.read_text() == layout_json(), "regenerate it: python -m services.viz.layout"
    text = LAYOUT_PATH.read_text()
    for topic in (c.ROBOT, c.camera_image_topic("wide_left"), c.camera_image_topic("wide_right"), c.LOG):
        assert f'"{topic}' in text
