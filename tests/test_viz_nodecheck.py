"""scripts/foxglove_check (Foxglove's MCAP reader and protobuf decoding, in Node) tells a log Foxglove
loads from one it does not. Skipped, with the reason, where node or npm is missing; it sets itself up
(npm ci into ignored paths of the repo) on first use."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from mcap.writer import Writer

from services.bus.codec import encode
from services.bus.mcaplog import LogWriter
from services.bus.schemas import sim as sim_msg
from services.model import load_robot
from services.viz import common as c
from services.viz import nodecheck
from services.viz.converter import Converter

pytestmark = pytest.mark.skipif(bool(nodecheck.unavailable()), reason=nodecheck.unavailable() or "available")


def test_a_log_of_the_recorder_loads_and_a_broken_one_does_not(tmp_path):
    robot = load_robot("hrp2_like")
    good = tmp_path / "good.mcap"
    writer = LogWriter(good, views=Converter().views, decimals={"sim/joint_state": 6})
    t = time.time_ns()
    for i in range(40):
        q = robot.q_half_sitting.copy()
        q[0] = 0.01 * i
        frame = encode(sim_msg.JointState(sim_time_s=0.005 * i, q=q, v=np.zeros(robot.nv)))
        writer.write("hrp/hrp2/sim/joint_state", frame, t + i * 40_000_000)
    writer.write("hrp/hrp2/sim/clock", encode(sim_msg.Clock(sim_time_s=0.2)), t + 2_000_000_000)
    writer.close()
    report = nodecheck.check_log(good)
    assert report["exit_code"] == 0, report
    topics = {ch["topic"]: ch for ch in report["channels"]}
    assert topics["hrp/hrp2/sim/joint_state"]["decoded"] == 40
    assert topics[c.TF]["ok"] and topics[c.TF]["schema"] == "foxglove.FrameTransforms"

    # The same channels with a message Foxglove cannot decode, a value of the wrong type, an encoding
    # it has no decoder for: each channel is reported, with the message that failed.
    bad = tmp_path / "bad.mcap"
    with open(good, "rb") as stream:
        from mcap.reader import make_reader

        records = list(make_reader(stream).iter_messages())
    tf_schema = next(s for s, ch, _ in records if ch.topic == c.TF)
    with open(bad, "wb") as out:
        w = Writer(out)
        w.start()
        tf = w.register_channel(
            c.TF, "protobuf", w.register_schema(tf_schema.name, "protobuf", tf_schema.data)
        )
        w.add_message(tf, t, b"\xff\xff\xff\xff not protobuf", t)
        number = {"type": "object", "properties": {"sim_time_s": {"type": "number"}}}
        sid = w.register_schema("hrp.sim.Clock", "jsonschema", json.dumps(number).encode())
        clock = w.register_channel("hrp/hrp2/sim/clock", "json", sid)
        w.add_message(clock, t, b'{"sim_time_s": 0.5}', t)
        w.add_message(clock, t + 1, b'{"sim_time_s": "soon"}', t + 1)
        private = w.register_channel("hrp/hrp2/private", "hrpb", 0)
        w.add_message(private, t, b"HRPB....", t)
        w.finish()
    report = nodecheck.check_log(bad)
    assert report["exit_code"] == 1
    topics = {ch["topic"]: ch for ch in report["channels"]}
    assert not topics[c.TF]["ok"] and topics[c.TF]["decoded"] == 0
    assert topics["hrp/hrp2/sim/clock"]["decoded"] == 1
    assert "sim_time_s: string, not a number" in topics["hrp/hrp2/sim/clock"]["errors"][0]
    assert "not one Foxglove decodes" in topics["hrp/hrp2/private"]["errors"][0]
