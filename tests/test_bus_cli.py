"""The ``humanoid`` command line of the bus: --help everywhere, call, echo, record, clear errors."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from services.bus.mcaplog import LogReader
from services.cli import build_parser, main

REPO = Path(__file__).resolve().parent.parent
BUS_COMMANDS = ("up", "status", "call", "echo", "record", "replay", "log-info")


def _humanoid(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "services.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
    )


def test_every_subcommand_has_help(capsys):
    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    assert set(BUS_COMMANDS) <= set(commands)
    for name in commands:
        with pytest.raises(SystemExit) as info:
            main([name, "--help"])
        assert info.value.code == 0
        assert "usage: humanoid" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["diag/ech", "{}"], "unknown endpoint 'diag/ech' (did you mean diag/echo"),
        (["diag/echo", "{text: 1"], "the request for diag/echo is not valid JSON"),
        (["diag/echo", "{text: 1"], "Example: humanoid call diag/echo '{}'"),  # nothing required
        (["walking/goal", "{not json"], "`humanoid interface walking/goal` describes each field"),
        (["diag/echo", "[1]"], "must be a JSON object, not list"),
        (["diag/echo", '{"txt": "a"}'], "unknown field(s) txt for diag/echo; fields: text (str, default"),
        (["diag/echo", '{"text": 5}'], "Expected `str`, got `int` - at `$.text`"),
        (["diag/raise", '{"code": "bug"}'], "missing required field `message`; fields: code (str, required)"),
    ],
)
def test_call_rejects_bad_requests_before_sending(capsys, args, message):
    assert main(["call", *args, "--hub", "tcp/127.0.0.1:1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err


@pytest.fixture(scope="module")
def diag(module_bus_harness):
    module_bus_harness.spawn_service("services.bus.diag")
    return module_bus_harness


@pytest.mark.integration
def test_call_prints_the_reply_as_json(diag):
    result = _humanoid("call", "diag/echo", '{"text": "hi", "blob": [[1, 2], [3, 4]]}', "--hub", diag.hub)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == {"text": "hi", "blob": [[1.0, 2.0], [3.0, 4.0]]}


@pytest.mark.integration
def test_call_reports_error_replies_and_missing_services(diag):
    result = _humanoid(
        "call", "diag/raise", '{"code": "infeasible", "message": "too far"}', "--hub", diag.hub
    )
    assert result.returncode == 1
    assert "error: infeasible: too far" in result.stderr
    result = _humanoid("call", "diag/echo", "--robot", "nobody", "--hub", diag.hub, "--timeout", "2")
    assert result.returncode == 3  # service unavailable
    assert "not alive" in result.stderr or "not running" in result.stderr


@pytest.mark.integration
def test_echo_summarises_binary_frames(diag):
    echo = subprocess.Popen(
        [sys.executable, "-m", "services.cli", "echo", "diag/frames", "--count", "1", "--hub", diag.hub],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 30.0
        while echo.poll() is None and time.monotonic() < deadline:
            diag.session.get("hrp/hrp2/diag/stream", payload=b'{"count": 1, "width": 64, "height": 48}')
            time.sleep(0.3)
        out, err = echo.communicate(timeout=10.0)
    finally:
        if echo.poll() is None:
            echo.kill()
    assert echo.returncode == 0, err
    assert "--- hrp/hrp2/diag/frames" in out
    assert '"left": "<ndarray uint8 (48, 64, 3)>"' in out


@pytest.mark.integration
def test_record_in_the_foreground_until_sigint(diag, tmp_path):
    path = tmp_path / "fg.mcap"
    proc = diag.spawn(["-m", "services.cli", "record", str(path), "--hub", diag.hub])
    diag.wait_alive("record", proc)
    diag.client.call_raw("diag", "echo", b'{"text": "logged"}', 5.0)
    time.sleep(0.3)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=10.0) == 0
    info = LogReader(path).info()
    assert info.complete
    assert {"hrp/hrp2/diag/echo/request", "hrp/hrp2/diag/echo/reply"} <= {c.topic for c in info.channels}


def test_a_foxglove_replay_filter_picks_bus_keys_and_keeps_the_views():
    """`humanoid replay F --foxglove --topics 'hrp/*/sim/*'` still serves the 3D views (/tf, ...)."""
    from services.bus.replay import key_filter

    accept = key_filter(["hrp/*/sim/*"], views=True)
    assert accept("hrp/hrp2/sim/clock") and accept("/tf") and accept("/robot/description")
    assert not accept("hrp/hrp2/perception/locate/reply") and not accept("hrp/hrp2/sim/heartbeat")
    assert not key_filter(["hrp/*/sim/*"])("/tf")  # on the bus there are no views
