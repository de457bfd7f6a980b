"""Access control for a deployment on several hosts (issue 16, item 5): ``examples/secure_stack.yaml``.

The test generates a CA and certificates (openssl), points the example configuration at them, and runs
a real sim service and real client sessions over TLS with mutual authentication: the supervisor may
reset the sim, a planner may read its state but neither reset nor execute, nobody reads the ground
truth, and a certificate of the CA whose name no policy knows gets nothing at all.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO, free_port

from services.bus.config import load_bus_config
from services.bus.schemas import sim as sim_msg
from services.bus.session import Client, close_session, open_session
from services.errors import RequestTimeoutError, UnavailableError

pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command"),
]

EXAMPLE = REPO / "examples" / "secure_stack.yaml"
IDENTITIES = ("hub", "sim", "supervisor", "navigation", "stranger")
#: A denied call gets no reply: the queryable is not even announced to the caller.
DENIED_WAIT_S = 3.0


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True)


def make_certificates(folder: Path) -> None:
    """A CA and, for each identity, a key and a certificate signed by it (CN = the identity)."""
    folder.mkdir(parents=True, exist_ok=True)
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    _openssl("req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", "2",
             "-subj", "/CN=humanoid test CA", cwd=folder)  # fmt: skip
    (folder / "san.ext").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    for name in IDENTITIES:
        _openssl("req", *ec, "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={name}",
                 cwd=folder)  # fmt: skip
        _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
                 "-CAcreateserial", "-out", f"{name}.pem", "-days", "2", "-extfile", "san.ext",
                 cwd=folder)  # fmt: skip


@pytest.fixture(scope="module")
def secure(tmp_path_factory):
    """The example configuration with generated certificates and a free hub port; a hub session and a
    sim service that use it."""
    tmp = tmp_path_factory.mktemp("secure")
    certs = tmp / "certs"
    make_certificates(certs)
    text = EXAMPLE.read_text().replace("/etc/humanoid/certs", str(certs))
    doc = yaml.safe_load(text)
    doc["bus"]["hub"] = f"tls/127.0.0.1:{free_port()}"
    config = tmp / "secure_stack.yaml"
    config.write_text(yaml.safe_dump(doc))
    bus = load_bus_config(config)
    hub = open_session(bus, as_hub=True)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    sim = subprocess.Popen(
        [sys.executable, "-m", "sim.service", "--config", str(config), "--log-level", "WARNING"],
        cwd=REPO,
        env=env,
        start_new_session=True,
    )
    sessions = {}
    try:
        for name in ("supervisor", "navigation", "stranger"):
            sessions[name] = open_session(dataclasses.replace(bus, identity=name))
        supervisor = Client(sessions["supervisor"], bus.robot)
        deadline = time.monotonic() + 90
        while "sim" not in supervisor.alive_services():
            assert sim.poll() is None, "the sim exited at start-up (TLS configuration?)"
            assert time.monotonic() < deadline, "the sim never became alive over TLS"
            time.sleep(0.2)
        yield bus, {name: Client(s, bus.robot) for name, s in sessions.items()}
    finally:
        for session in sessions.values():
            close_session(session)
        if sim.poll() is None:
            os.killpg(sim.pid, signal.SIGTERM)
            try:
                sim.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(sim.pid, signal.SIGKILL)
                sim.wait()
        close_session(hub)


def _denied(client: Client, spec, request) -> bool:
    try:
        client.call(spec, request, timeout_s=DENIED_WAIT_S)
    except (UnavailableError, RequestTimeoutError):
        return True
    return False


def test_only_the_supervisor_may_reset_and_execute(secure):
    _bus, clients = secure
    supervisor, planner = clients["supervisor"], clients["navigation"]
    reset = supervisor.call(sim_msg.RESET, sim_msg.ResetRequest(scene="empty"), timeout_s=60)
    assert reset.scene == "empty"
    state = planner.call(sim_msg.STATE, sim_msg.StateRequest(), timeout_s=20)
    assert state.q.shape == reset.q.shape
    hold = sim_msg.ExecuteRequest(q=np.repeat(state.q[None, :], 5, axis=0))
    assert supervisor.call(sim_msg.EXECUTE, hold, timeout_s=60).outcome == "completed"
    assert _denied(planner, sim_msg.RESET, sim_msg.ResetRequest(scene="empty"))
    assert _denied(planner, sim_msg.EXECUTE, hold)


def test_ground_truth_is_denied_to_everyone_and_strangers_get_nothing(secure):
    _bus, clients = secure
    for name in ("supervisor", "navigation"):
        assert _denied(clients[name], sim_msg.GROUND_TRUTH, sim_msg.GroundTruthRequest()), name
    stranger = clients["stranger"]  # a certificate of the CA, but no policy names it
    assert "sim" not in stranger.alive_services(timeout_s=1.0)
    assert _denied(stranger, sim_msg.STATE, sim_msg.StateRequest())
