"""``humanoid up``: start-up, restart after SIGKILL, clean stop (no process, no /dev/shm file left)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from services.bus import keys
from services.bus.codec import decode
from services.bus.config import BusConfig
from services.bus.mcaplog import LogReader
from services.bus.schemas.common import Heartbeat, LauncherEvent
from services.bus.session import Client, close_session, open_session
from services.bus.shm import orphaned

pytestmark = pytest.mark.integration
REPO = Path(__file__).resolve().parent.parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


HUMANOID = [sys.executable, "-m", "services.cli"]


def _humanoid(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*HUMANOID, *args], capture_output=True, text=True, timeout=timeout, cwd=REPO)


def _children_of(launcher_pid: int) -> set[int]:
    """Processes started by this launcher (they carry ``--parent-pid <launcher pid>``)."""
    found = set()
    marker = f"--parent-pid\x00{launcher_pid}\x00".encode()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError):
                if marker in (entry / "cmdline").read_bytes():
                    found.add(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with contextlib.suppress(OSError):  # a zombie is dead
        if Path(f"/proc/{pid}/stat").read_text().split(") ")[1].startswith("Z"):
            return False
    return True


def _wait(predicate, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


class Up:
    """A ``humanoid up`` process on a private hub, and a client session connected to it."""

    def __init__(self, *args: str) -> None:
        self.bus = BusConfig().with_hub_port(free_port())
        self.proc = subprocess.Popen(
            [*HUMANOID, "up", "--hub", self.bus.hub, *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=REPO,
            start_new_session=True,
        )
        self.output: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.session = open_session(self.bus)
        self.client = Client(self.session, self.bus.robot)

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.output.append(line)

    def heartbeat_pid(self, service: str, timeout_s: float = 10.0) -> int:
        got: list[Heartbeat] = []
        sub = self.session.declare_subscriber(
            keys.heartbeat(self.bus.robot, service),
            lambda s: got.append(decode(s.payload.to_bytes(), Heartbeat)),
        )
        try:
            _wait(lambda: got, timeout_s, f"a heartbeat of {service}")
        finally:
            sub.undeclare()
        return got[-1].pid

    def close(self) -> None:
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        close_session(self.session)


def test_restart_after_sigkill_status_and_clean_stop(tmp_path):
    orphans_before = {p.name for p in orphaned()}
    log_file = tmp_path / "up.mcap"
    up = Up("--services", "diag", "--record", str(log_file))
    try:
        up.client.wait_for(["diag", "record"], timeout_s=30.0)
        events: list[LauncherEvent] = []
        sub = up.session.declare_subscriber(
            keys.key(up.bus.robot, "launcher", "events"),
            lambda s: events.append(decode(s.payload.to_bytes(), LauncherEvent)),
        )
        old_pid = up.heartbeat_pid("diag")
        recorder_pid = up.heartbeat_pid("record")
        assert _children_of(up.proc.pid) >= {old_pid, recorder_pid}

        os.kill(old_pid, signal.SIGKILL)

        # The launcher's "started"/"ready" of the first diag may reach the new subscription: skip them.
        def diag_events() -> list[LauncherEvent]:
            first = ("started", "ready")
            return [e for e in events if e.service == "diag" and not (e.event in first and e.pid == old_pid)]

        _wait(lambda: any(e.event == "ready" for e in diag_events()), 30.0, "diag restarted")
        sub.undeclare()
        assert [e.event for e in diag_events()][:4] == [
            "died",
            "restarting",
            "started",
            "ready",
        ]
        assert diag_events()[0].exit_code == -signal.SIGKILL

        status = _humanoid("status", "--json", "--hub", up.bus.hub)
        assert status.returncode == 0, status.stderr
        services = {s["service"]: s for s in json.loads(status.stdout)["services"]}
        assert set(services) == {"diag", "record"}
        new_pid = services["diag"]["pid"]
        assert new_pid not in (None, old_pid)
        assert services["diag"]["heartbeat_age_s"] is not None

        started = time.monotonic()
        up.proc.send_signal(signal.SIGTERM)
        assert up.proc.wait(timeout=10.0) == 0
        print(f"humanoid up stopped {time.monotonic() - started:.2f} s after SIGTERM")
        _wait(lambda: not any(_alive(p) for p in (old_pid, new_pid, recorder_pid)), 5.0, "children gone")
        assert not _children_of(up.proc.pid)
        text = "".join(up.output)
        assert "SERVICE" in text and "diag" in text and f"log written to {log_file}" in text
    finally:
        up.close()
    leftovers = {p.name for p in orphaned()} - orphans_before
    assert not leftovers, f"zenoh shared-memory files left in /dev/shm: {sorted(leftovers)}"
    info = LogReader(log_file).info()
    assert info.complete
    topics = {c.topic: c.messages for c in info.channels}
    assert topics.get(f"hrp/{up.bus.robot}/launcher/events", 0) >= 4
    assert topics.get(f"hrp/{up.bus.robot}/diag/heartbeat", 0) >= 1


def test_services_exit_when_the_launcher_is_killed():
    up = Up("--services", "diag")
    try:
        up.client.wait_for(["diag"], timeout_s=30.0)
        pid = up.heartbeat_pid("diag")
        os.kill(up.proc.pid, signal.SIGKILL)
        up.proc.wait()
        _wait(lambda: not _alive(pid), 10.0, "diag to notice its launcher is gone")
    finally:
        up.close()


def test_ready_timeout_names_the_missing_service():
    result = _humanoid(
        "up", "--services", "diag", "--ready-timeout", "0.05", "--hub", f"tcp/127.0.0.1:{free_port()}"
    )
    assert result.returncode == 1
    assert "service(s) diag did not declare a liveliness token" in result.stderr


def test_unknown_service_lists_the_known_ones():
    result = _humanoid("up", "--services", "diag,warp_drive", "--hub", f"tcp/127.0.0.1:{free_port()}")
    assert result.returncode == 2
    assert "unknown service(s) warp_drive; services found: " in result.stderr
    assert "diag" in result.stderr.split("services found:")[1]


def test_hub_port_in_use_is_a_clear_error():
    port = free_port()
    blocker = open_session(BusConfig().with_hub_port(port), as_hub=True)
    try:
        result = _humanoid("up", "--services", "diag", "--hub", f"tcp/127.0.0.1:{port}")
    finally:
        close_session(blocker)
    assert result.returncode != 0
    assert "is another `humanoid up` running?" in result.stderr


def test_two_hosts_by_configuration(tmp_path):
    """The README's worked example, with 127.0.0.1 as the robot PC and 127.0.0.2 as the laptop."""
    robot_hub = f"tcp/127.0.0.1:{free_port()}"
    robot_yaml = tmp_path / "robot.yaml"
    robot_yaml.write_text(f"bus:\n  hub: {robot_hub}\n  listen: [tcp/127.0.0.1:0]\n")
    up = subprocess.Popen(
        [*HUMANOID, "up", "--services", "diag", "--config", str(robot_yaml)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        cwd=REPO,
        start_new_session=True,
    )
    laptop = BusConfig(hub=f"tcp/127.0.0.2:{free_port()}", listen=("tcp/127.0.0.2:0",), connect=(robot_hub,))
    session = open_session(laptop, as_hub=True)  # the laptop's launcher session
    try:
        client = Client(session, laptop.robot)
        client.wait_for(["diag"], timeout_s=30.0)
        from services.bus.schemas.diag import ECHO, EchoRequest

        assert client.call(ECHO, EchoRequest(text="across"), timeout_s=10.0).text == "across"
    finally:
        close_session(session)
        up.send_signal(signal.SIGTERM)
        try:
            up.wait(timeout=10.0)
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(up.pid, signal.SIGKILL)
