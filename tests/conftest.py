"""Shared fixtures: a private zenoh hub per test (or module), and service processes cleaned up after.

Every harness listens on its own free loopback port, so test files can run side by side::

    def test_echo(bus_harness):
        bus_harness.spawn_service("services.bus.diag")          # waits for hrp/<robot>/diag/alive
        reply = bus_harness.client.call(ECHO, EchoRequest(text="hi"), timeout_s=5)

Service processes are started like the launcher starts them (``python -m MODULE --hub ...``, own
process group) and stopped with SIGTERM, then SIGKILL, at teardown.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parent.parent


def free_port() -> int:
    """A TCP port free on loopback now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_in_thread(fn: Callable[[], Any], timeout_s: float) -> Any:
    """``fn()`` on a thread; its result, or fail when it hangs past ``timeout_s`` (a hang guard only)."""
    out: list = []
    thread = threading.Thread(target=lambda: out.append(fn()), daemon=True)
    thread.start()
    thread.join(timeout_s)
    assert not thread.is_alive(), f"still running after {timeout_s:.0f} s: the supervisor hangs"
    return out[0]


class BusHarness:
    """A hub session on a free port, a client, and the service processes of one test (or module)."""

    def __init__(self, robot: str = "hrp2") -> None:
        from services.bus.config import BusConfig
        from services.bus.session import Client, open_session

        self.port = free_port()
        self.bus = BusConfig(robot=robot).with_hub_port(self.port)
        self.session = open_session(self.bus, as_hub=True)
        self.client = Client(self.session, self.bus.robot)
        self.procs: list[subprocess.Popen[bytes]] = []

    @property
    def hub(self) -> str:
        return self.bus.hub

    def bus_args(self) -> list[str]:
        return ["--hub", self.bus.hub, "--robot", self.bus.robot]

    def spawn(self, argv: list[str], **kwargs) -> subprocess.Popen[bytes]:
        """Start ``argv`` (a list; ``sys.executable`` is prepended) in its own process group."""
        env = {**os.environ, "PYTHONUNBUFFERED": "1", **kwargs.pop("env", {})}
        proc = subprocess.Popen([sys.executable, *argv], start_new_session=True, env=env, cwd=REPO, **kwargs)
        self.procs.append(proc)
        return proc

    def spawn_service(
        self, module: str, *args: str, name: str | None = None, timeout_s: float = 30.0, **kwargs
    ) -> subprocess.Popen[bytes]:
        """``python -m module --hub ... --robot ...``; waits until service ``name`` is alive."""
        proc = self.spawn(["-m", module, *self.bus_args(), "--log-level", "WARNING", *args], **kwargs)
        self.wait_alive(name or module.rsplit(".", 1)[-1], proc, timeout_s)
        return proc

    def spawn_services(
        self, services: dict[str, tuple[str, ...]], timeout_s: float = 60.0
    ) -> dict[str, subprocess.Popen[bytes]]:
        """Several services at once: ``{name: (module, *args)}`` all started, then each waited for
        until alive (their start-ups overlap instead of queueing: a module's stack starts faster)."""
        procs = {
            name: self.spawn(["-m", module, *self.bus_args(), "--log-level", "WARNING", *args])
            for name, (module, *args) in services.items()
        }
        for name, proc in procs.items():
            self.wait_alive(name, proc, timeout_s)
        return procs

    def spawn_script(
        self, path: str | Path, *args: str, name: str, timeout_s: float = 30.0, **kwargs
    ) -> subprocess.Popen[bytes]:
        """``python path --hub ... --robot ...`` (a test file that runs a service as a script)."""
        proc = self.spawn([str(path), *self.bus_args(), "--log-level", "WARNING", *args], **kwargs)
        self.wait_alive(name, proc, timeout_s)
        return proc

    def wait_alive(
        self, name: str, proc: subprocess.Popen[bytes] | None = None, timeout_s: float = 30.0
    ) -> None:
        deadline = time.monotonic() + timeout_s
        while name not in self.client.alive_services():
            if proc is not None and proc.poll() is not None:
                raise RuntimeError(f"service {name} exited with {proc.returncode} before becoming alive")
            if time.monotonic() > deadline:
                raise TimeoutError(f"service {name} not alive within {timeout_s} s")
            time.sleep(0.02)

    def wait_gone(self, name: str, timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while name in self.client.alive_services():
            if time.monotonic() > deadline:
                raise TimeoutError(f"service {name} still alive after {timeout_s} s")
            time.sleep(0.02)

    @staticmethod
    def stop(proc: subprocess.Popen[bytes], timeout_s: float = 5.0) -> int:
        """SIGTERM the process group, SIGKILL it after ``timeout_s``; the exit code."""
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, signal.SIGKILL)  # anything it left in its group
        return proc.returncode

    def close(self) -> None:
        """Stop every service process, all at once (each gets SIGTERM first, then each is waited for as
        :meth:`stop` does: they shut down side by side, not one after the other), then the hub."""
        from services.bus.session import close_session

        for proc in self.procs:
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGTERM)
        for proc in self.procs:
            self.stop(proc)  # a second SIGTERM is ignored by a stopping service
        close_session(self.session)


@pytest.fixture
def bus_harness() -> Iterator[BusHarness]:
    """A private hub for one test; its service processes are stopped at teardown."""
    harness = BusHarness()
    try:
        yield harness
    finally:
        harness.close()


@pytest.fixture(scope="module")
def module_bus_harness() -> Iterator[BusHarness]:
    """A private hub shared by the tests of one module."""
    harness = BusHarness()
    try:
        yield harness
    finally:
        harness.close()
