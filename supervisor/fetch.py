"""The ball fetch end to end (Fig. 11 of ``001_771c0ce3779b0683.txt``), headless.

:func:`running_stack` starts every service of the fetch with the launcher of ``humanoid up`` (in this
process, on a background thread: restarts included, optionally recording an MCAP log); :func:`fetch`
resets the sim to the scene (optionally a seeded random layout), runs the fetch script with the
supervisor, saves a PNG snapshot of the final scene and returns a :class:`FetchSummary`.
``humanoid fetch`` (supervisor/cli.py), ``scripts/bench fetch`` and the tests use them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from services.bus.config import BusConfig
from services.bus.discovery import RECORDER, discover
from services.bus.launcher import Launcher, LauncherConfig
from services.bus.schemas import sim as sim_msg
from services.errors import UnavailableError
from supervisor.core import SERVICES, Supervisor
from supervisor.runner import RunReport
from supervisor.script import Step, load_script

FETCH_SCRIPT = Path(__file__).resolve().parent / "scripts" / "fetch.txt"
DEFAULT_SCENE = "ball_fetch"


@dataclass(frozen=True)
class FetchSummary:
    """How a fetch went: success, wall and sim time [s], retries, the failure (if any), files written."""

    ok: bool
    wall_s: float
    sim_s: float
    retries: int
    steps: int
    failure: str
    scene: str
    seed: int | None
    snapshot: str
    held_at_end: dict[str, str]

    def text(self) -> str:
        verdict = "SUCCESS" if self.ok else f"FAILED: {self.failure}"
        layout = "nominal layout" if self.seed is None else f"seed {self.seed}"
        lines = [
            f"fetch in {self.scene} ({layout}): {verdict}",
            f"  wall time {self.wall_s:.1f} s, sim time {self.sim_s:.1f} s "
            f"({self.sim_s / max(self.wall_s, 1e-9):.2f}x real time), {self.steps} step(s), "
            f"{self.retries} retries",
        ]
        if self.snapshot:
            lines.append(f"  final scene: {self.snapshot}")
        return "\n".join(lines)


@contextlib.contextmanager
def running_stack(
    bus: BusConfig,
    *,
    services: tuple[str, ...] = SERVICES,
    record: str | None = None,
    log_dir: str = "",
    out: IO[str] | None = None,
    config: LauncherConfig | None = None,
    config_path: str | None = None,
) -> Iterator[Launcher]:
    """The services (those of ``services`` that exist) under a launcher, ready; stopped on exit.

    ``config_path``: a YAML file every service reads its section of (e.g. the recorder's ``record:``).
    UnavailableError if one does not start (its log says why: ``log_dir``).
    """
    found, _problems = discover()
    entries = [found[name] for name in services if name in found]
    launcher_config = dataclasses.replace(config or LauncherConfig(), log_dir=log_dir)
    launcher = Launcher(
        bus, [*entries, found[RECORDER]], launcher_config, record=record, out=out, config_path=config_path
    )
    result: list[int] = []
    thread = threading.Thread(target=lambda: result.append(launcher.run()), name="launcher", daemon=True)
    thread.start()
    children = [*launcher.children.values(), *([launcher.recorder] if launcher.recorder else [])]
    try:
        while not all(c.state == "ready" for c in children):
            if not thread.is_alive():
                raise UnavailableError(
                    "the services did not all start"
                    + (f"; their logs are in {log_dir}" if log_dir else " (see the messages above)")
                )
            time.sleep(0.05)
        yield launcher
    finally:
        launcher.request_stop()
        thread.join(timeout=10.0)


def reset_scene(sup: Supervisor, scene: str, seed: int | None) -> sim_msg.ResetReply:
    """Reload the scene (a name in sim/scenes or a YAML path), nominal layout or seeded random."""
    return sup.bus.call(sim_msg.RESET, sim_msg.ResetRequest(scene=scene, seed=seed), 30.0)


def save_snapshot(
    sup: Supervisor,
    path: str | Path,
    viewpoint: str = "overview",
    look_at: list[float] | None = None,
) -> str:
    """A PNG of the scene from an external camera at ``path``: ``viewpoint``, or, with ``look_at``
    (a world point [m]), from 1.6 m beyond it as seen from the robot, 1.3 m higher: the robot faces
    the camera across what it worked on (the ball on the table)."""
    request = sim_msg.SnapshotRequest(viewpoint=viewpoint, width_px=960, height_px=720)
    if look_at is not None:
        x, y, _yaw = sup.actions.body.base_xy_yaw()
        away = np.array(look_at[:2]) - (x, y)
        away /= max(float(np.linalg.norm(away)), 1e-6)
        eye = [look_at[0] + 1.6 * away[0] + 0.5 * away[1], look_at[1] + 1.6 * away[1] - 0.5 * away[0], 2.0]
        request = sim_msg.SnapshotRequest(width_px=960, height_px=720, eye=eye, target=list(look_at))
    reply = sup.bus.call(sim_msg.SNAPSHOT, request, 30.0)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_bytes(reply.png.tobytes())
    return str(path)


def fetch(
    sup: Supervisor,
    *,
    scene: str = DEFAULT_SCENE,
    seed: int | None = None,
    steps: list[Step] | None = None,
    snapshot: str | Path | None = None,
    run_id: str = "",
) -> tuple[FetchSummary, RunReport]:
    """Reset the sim to ``scene``/``seed``, run the fetch script (or ``steps``), snapshot, summarise."""
    steps = steps if steps is not None else load_script(FETCH_SCRIPT)
    reset = reset_scene(sup, scene, seed)
    sup.actions.memory.clear()
    sim_start = reset.sim_time_s
    started = time.monotonic()
    report = sup.run(steps, run_id=run_id or f"fetch:{scene}:{seed}")
    wall = time.monotonic() - started
    state = sup.actions.body.state()
    put = next((r for r in reversed(report.reports) if r.ok and r.action == "put"), None)
    look_at = [float(v) for v in put.details["point"]] if put is not None and "point" in put.details else None
    shot = save_snapshot(sup, snapshot, look_at=look_at) if snapshot else ""
    failure = report.failure
    summary = FetchSummary(
        ok=report.ok,
        wall_s=wall,
        sim_s=state.sim_time_s - sim_start,
        retries=report.retries,
        steps=len(report.reports),
        failure=failure.summary() if failure else "",
        scene=reset.scene,
        seed=reset.seed,
        snapshot=shot,
        held_at_end=dict(state.held),
    )
    return summary, report
