"""Bus building blocks without a network: codec, frames, keys, config, schemas, ids, shm cleanup."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from services.bus import keys
from services.bus.codec import decode, encode, from_builtins, split, to_builtins
from services.bus.config import BusConfig, load_bus_config, load_section
from services.bus.discovery import discover
from services.bus.frames import frame_kind, parse_frame, summarize
from services.bus.schemas import endpoints, topics
from services.bus.schemas.diag import EchoRequest, StereoFrame
from services.bus.session import RequestIds, request_id_bytes, request_id_from
from services.bus.shm import orphaned
from services.bus.spec import json_schema
from services.errors import InvalidRequestError


def test_plain_messages_are_json_and_arrays_travel_as_raw_bytes():
    assert encode(EchoRequest(text="hi")) == b'{"text":"hi","blob":null}'
    left = np.arange(48 * 64 * 3, dtype=np.uint8).reshape(48, 64, 3)
    frame = encode(StereoFrame(seq=1, stamp_s=2.0, left=left, right=left[:, ::-1]))
    header, blob = split(frame)
    assert frame.startswith(b"HRPB") and len(blob) == 2 * left.nbytes
    assert b"base64" not in bytes(header) and len(header) < 300
    back = decode(frame, StereoFrame)
    assert np.array_equal(back.left, left) and np.array_equal(back.right, left[:, ::-1])


def test_decode_names_field_and_expected_type():
    with pytest.raises(InvalidRequestError, match=r"Expected `str`, got `int` - at `\$.text`"):
        decode(b'{"text": 1}', EchoRequest)
    with pytest.raises(InvalidRequestError, match="malformed payload for EchoRequest"):
        decode(b"\x00\x01", EchoRequest)
    bad_ref = b'{"blob": {"__nd__": [0, 800], "dtype": "<f8", "shape": [100]}}'
    with pytest.raises(InvalidRequestError, match="array reference in a plain JSON message"):
        decode(bad_ref, EchoRequest)
    frame = bytearray(encode(EchoRequest(blob=np.zeros(4))))
    with pytest.raises(InvalidRequestError, match="outside the message"):
        decode(bytes(frame[:-8]), EchoRequest)


def test_builtins_round_trip_for_the_command_line():
    msg = from_builtins({"text": "a", "blob": [[1, 2], [3, 4]]}, EchoRequest)
    assert msg.blob.shape == (2, 2)
    assert to_builtins(msg) == {"text": "a", "blob": [[1.0, 2.0], [3.0, 4.0]]}


def test_frame_kinds_and_summaries():
    image = np.zeros((48, 64, 3), np.uint8)
    binary = encode(StereoFrame(seq=1, stamp_s=0.0, left=image, right=image))
    assert frame_kind(binary) == "hrpb"
    assert frame_kind(b'{"a": 1}') == "json"
    assert frame_kind(b"") == frame_kind(b"{broken") == frame_kind(os.urandom(8) + b"x") == "octets"
    assert frame_kind(b'{"\xff\xfe": 1}') == "octets"  # invalid UTF-8 in a string (it raised)
    assert summarize(binary)["left"] == "<ndarray uint8 (48, 64, 3)>"
    assert summarize(b"\x00\x01") == "<2 bytes: 0001>"
    doc, refs = parse_frame(binary)
    assert doc["seq"] == 1 and [r.path for r in refs] == ["left", "right"]


def test_keys():
    assert keys.key("hrp2", "footsteps", "plan") == "hrp/hrp2/footsteps/plan"
    assert keys.request_mirror("hrp2", "diag", "echo") == "hrp/hrp2/diag/echo/request"
    assert keys.parse("hrp/hrp2/diag/echo/reply") == ("hrp2", "diag", "echo/reply")
    with pytest.raises(ValueError, match="lower_snake_case"):
        keys.key("hrp2", "Diag", "echo")


def test_config_defaults_stay_on_this_machine_and_yaml_overrides(tmp_path):
    bus = BusConfig()
    assert bus.mode == "peer" and not bus.multicast_scouting
    assert all(e.startswith("tcp/127.0.0.1:") for e in (*bus.listen, bus.hub))
    path = tmp_path / "stack.yaml"
    path.write_text("bus:\n  robot: talos\n  connect: [tcp/10.0.0.2:7447]\nrecord:\n  state_every: 4\n")
    loaded = load_bus_config(path, hub="tcp/127.0.0.1:9000")
    assert (loaded.robot, loaded.connect, loaded.hub) == (
        "talos",
        ("tcp/10.0.0.2:7447",),
        "tcp/127.0.0.1:9000",
    )
    from services.bus.recorder import RecorderConfig

    assert load_section(path, "record", RecorderConfig).state_every == 4
    path.write_text("bus:\n  robt: talos\n")
    with pytest.raises(InvalidRequestError, match=r"unknown BusConfig option.*robt.*valid options: robot"):
        load_bus_config(path)
    with pytest.raises(InvalidRequestError, match="does not exist"):
        load_bus_config(tmp_path / "missing.yaml")


def test_json_schemas_are_inlined_for_foxglove():
    schema = json_schema(StereoFrame)
    assert "$ref" not in str(schema) and "$defs" not in schema
    assert schema["properties"]["seq"] == {"type": "integer"}
    for spec in [*endpoints().values(), *topics().values()]:
        for type_ in (
            getattr(spec, "request", None),
            getattr(spec, "reply", None),
            getattr(spec, "message", None),
        ):
            if type_ is not None:
                assert "$ref" not in str(json_schema(type_)), type_


def test_request_ids_fit_mcap_sequence_numbers():
    ids = RequestIds()
    values = [ids.next() for _ in range(1000)]
    assert all(0 < v < 2**32 for v in values) and len(set(values)) == 1000
    assert request_id_from(request_id_bytes(values[0])) == values[0]
    assert request_id_from(b"abc") is None


def test_discovery_finds_diag_without_importing_services():
    found, _problems = discover()
    assert found["diag"].module == "services.bus.diag"
    assert found["record"].module == "services.bus.recorder"


def test_shm_cleanup_spares_segments_a_living_process_this_one_included_holds(tmp_path):
    held = tmp_path / "1.zenoh"
    orphan = tmp_path / "2.zenoh"
    mine = tmp_path / "3.zenoh"
    old = time.time() - 10
    for path in (held, orphan, mine):
        path.write_bytes(b"x")
        os.utime(path, (old, old))
    holder = subprocess.Popen(
        [sys.executable, "-c", f"import fcntl,time; f=open({str(held)!r}); fcntl.flock(f, fcntl.LOCK_SH); "
         "print('locked', flush=True); time.sleep(60)"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "locked"
        with open(mine) as f:
            fcntl.flock(f, fcntl.LOCK_SH)
            found = {p.name for p in orphaned(tmp_path)}
        # Only the orphan: this process's own segment is its live pool (every session of it sends through it).
        assert found == {"2.zenoh"}
    finally:
        holder.kill()
        holder.wait()
    assert {p.name for p in orphaned(tmp_path)} == {"1.zenoh", "2.zenoh", "3.zenoh"}  # their holders are gone


def _frame(header: dict, blob: bytes) -> bytes:
    import json
    import struct

    raw = json.dumps(header).encode()
    return b"HRPB" + struct.pack("<I", len(raw)) + raw + blob


_NAN = np.array([[0.0, float("nan")]]).tobytes()


@pytest.mark.parametrize(
    ("payload", "type_name", "message"),
    [
        (b'{"q": ' + b"[" * 5000 + b"]" * 5000 + b"}", "ExecuteRequest", "nested too deeply"),
        (b'{"q": [[0.0]], "allowed_contacts": ["\xff"]}', "ExecuteRequest",
         'not valid UTF-8.*"allowed_contacts"'),
        (b'{"q": [["a", "b"]]}', "ExecuteRequest", r"array of numbers.*at `\$\.q`"),
        # numpy reads "0.5" as a number and null as NaN: neither is a number in JSON
        (b'{"q": [["0.5", "1e0"]]}', "ExecuteRequest", r"found the string '0.5' among them - at `\$\.q`"),
        (b'{"q": [[0.5, null]]}', "ExecuteRequest", r"found null among them - at `\$\.q`"),
        # one 1 MB string among 200 numbers: refused before numpy makes a 800 MB array of strings of it
        (b'{"q": [[' + b"0.0, " * 200 + b'"' + b"x" * 1_000_000 + b'"]]}', "ExecuteRequest",
         r"numbers only\) - at `\$\.q`"),
        (b'{"q": [[0.0]], "colour": 1}', "ExecuteRequest", "unknown field `colour`"),
        (b'{"q": [[0.0]], "dt_s": 1e300}', "ExecuteRequest", r"<= 0.1 - at `\$\.dt_s`"),
        (b'{"q": [[0.0]], "dt_s": 1e999}', "ExecuteRequest", "out of range"),
        (b'{"q": [[0.0]], "dt_s": NaN}', "ExecuteRequest", 'non-finite number .* after field "dt_s"'),
        (b'{"q": [[0.0]], "hold_s": -Infinity}', "ExecuteRequest", 'non-finite .* field "hold_s"'),
        (b'{"q": [[0.0, Infinity]]}', "ExecuteRequest", 'non-finite number .* after field "q"'),
        (b'{"scene": "../../etc/passwd"}', "ResetRequest", r"matching regex.*at `\$\.scene`"),
        (b'{"seed": -1}', "ResetRequest", r">= 0 - at `\$\.seed`"),
        (_frame({"q": {"__nd__": [0, 8], "shape": [1]}}, bytes(8)), "ExecuteRequest", "missing dtype"),
        (_frame({"q": {"__nd__": [0, 8], "dtype": "<M8[s]", "shape": [1]}}, bytes(8)), "ExecuteRequest",
         "only bool, integer and float"),
        (_frame({"q": {"__nd__": [0, 16], "dtype": "<f8", "shape": [1, 2]}}, _NAN), "ExecuteRequest",
         "non-finite"),
        (_frame({"q": {"__nd__": [0, 16], "dtype": "<f8", "shape": [3]}}, _NAN), "ExecuteRequest",
         "needs 24 bytes"),
        (b"HRPB\xff\xff\xff\xff{}", "ExecuteRequest", "truncated binary frame"),
    ],
)  # fmt: skip
def test_requests_are_validated_at_the_edge_with_the_field_and_the_rule(payload, type_name, message):
    from services.bus.codec import decode_request
    from services.bus.schemas import sim

    with pytest.raises(InvalidRequestError, match=message):
        decode_request(payload, getattr(sim, type_name))


def test_request_limits_are_schema_constraints():
    from services.bus.codec import MAX_REQUEST_BYTES, decode_request
    from services.bus.schemas import navigation, walking

    steps = [{"pose": [0.1 * i, 0.0, 0.0]} for i in range(201)]
    with pytest.raises(InvalidRequestError, match=r"length <= 200 - at `\$\.steps`"):
        from_builtins({"steps": steps}, walking.PlanRequest)
    with pytest.raises(InvalidRequestError, match=r"<= 100.0 - at `\$\.goal_pose\[0\]`"):
        from_builtins({"q_start": [0.0], "goal_pose": [1000.0, 0.0, 0.0]}, navigation.GotoRequest)
    with pytest.raises(InvalidRequestError, match=r"> 0.0 - at `\$\.step_height_m`"):
        from_builtins({"steps": steps[:2], "step_height_m": 0.0}, walking.PlanRequest)
    with pytest.raises(InvalidRequestError, match="exceeds the limit"):
        decode_request(b" " * (MAX_REQUEST_BYTES + 1), walking.PlanRequest)
    # a reply may carry NaN (e.g. an unbounded value); only requests are held to finite arrays
    nan = encode(EchoRequest(blob=np.array([np.nan])))
    assert np.isnan(decode(nan, EchoRequest).blob[0])


def _structs(annotation, seen: set) -> None:
    """Every msgspec Struct type reachable from ``annotation`` (its fields, lists, unions)."""
    import typing

    import msgspec

    if isinstance(annotation, type) and issubclass(annotation, msgspec.Struct):
        if annotation not in seen:
            seen.add(annotation)
            for f in msgspec.structs.fields(annotation):
                _structs(f.type, seen)
        return
    for arg in typing.get_args(annotation):
        _structs(arg, seen)


def test_every_request_refuses_unknown_fields_and_bounds_its_budgets():
    """The kind, not the instance: a request type (or one nested in it) added later without
    ``forbid_unknown_fields`` would silently ignore a misspelt field; a budget field without the
    limits' bound would let one request hold a service for as long as it asks."""
    from services.bus.limits import MAX_BUDGET_S

    for path, spec in sorted(endpoints().items()):
        seen: set = set()
        _structs(spec.request, seen)
        lax = sorted(t.__name__ for t in seen if not t.__struct_config__.forbid_unknown_fields)
        assert not lax, f"{path}: {lax} accept unknown fields"
        schema = json_schema(spec.request)
        props = schema.get("properties", {})
        for name in ("time_budget_s", "total_budget_s"):
            if name in props:
                text = str(props[name])
                # planners: MAX_BUDGET_S; a contact plan and a played motion: minutes (their own bounds)
                bounds = (f"'maximum': {MAX_BUDGET_S}", "'maximum': 600.0")
                assert any(b in text for b in bounds), f"{path}.{name} is not bounded: {text}"


@pytest.mark.parametrize(
    ("section", "yaml_text", "message"),
    [
        ("record", "record:\n  foxglove_views: 'no'\n", r"Expected `bool`, got `str` - at `\$\.foxglove_"),
        ("bus", "bus:\n  listen: tcp/127.0.0.1:0\n", r"Expected `array`, got `str` - at `\$\.listen`"),
        ("bus", "bus:\n  robot: 5\n", r"Expected `str`, got `int` - at `\$\.robot`"),
        ("sim", "sim:\n  seed: [1]\n", r"at `\$\.seed`"),
    ],
)
def test_configuration_errors_name_the_field(tmp_path, section, yaml_text, message):
    from services.bus.recorder import RecorderConfig
    from sim.config import SimConfig

    path = tmp_path / "stack.yaml"
    path.write_text(yaml_text)
    types = {"record": RecorderConfig, "bus": BusConfig, "sim": SimConfig}
    with pytest.raises(InvalidRequestError, match=message):
        load_section(path, section, types[section])


def test_identity_selects_each_process_certificate():
    bus = BusConfig(zenoh={"transport/link/tls/listen_certificate": "/certs/{identity}.pem"})
    conf = bus.zenoh_config(identity="sim")
    assert conf.get_json("transport/link/tls/listen_certificate") == '"/certs/sim.pem"'
    named = BusConfig(identity="supervisor", zenoh=bus.zenoh).zenoh_config(identity="sim")
    assert named.get_json("transport/link/tls/listen_certificate") == '"/certs/supervisor.pem"'


def test_diag_is_started_only_when_asked():
    from services.bus.discovery import default_services

    found, _problems = discover()
    names = default_services(found)
    assert "diag" in found and "diag" not in names and "record" not in names and "sim" in names
