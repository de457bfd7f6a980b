"""The fetch benchmark's CPU accounting (scripts/bench.d/fetch.py): CPU seconds per process, read from
/proc, through a fetch (no fetch runs here: the accounting is checked on real processes)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType, SimpleNamespace

import pytest

FETCH_BENCH = Path(__file__).resolve().parents[1] / "scripts" / "bench.d" / "fetch.py"


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_fetch_under_test", FETCH_BENCH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _burn(cpu_s: float) -> None:
    end = time.process_time() + cpu_s
    while time.process_time() < end:
        pass


def test_cpu_seconds_of_a_working_and_of_a_sleeping_child(bench: ModuleType) -> None:
    work = "import sys, time\nsys.stdin.readline()\nend = time.process_time() + 0.5\n"
    work += "while time.process_time() < end: pass\nprint(flush=True)\ntime.sleep(30)"
    busy = subprocess.Popen(
        [sys.executable, "-c", work], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    idle = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    children = {"busy": SimpleNamespace(pid=busy.pid), "idle": SimpleNamespace(pid=idle.pid)}
    try:
        time.sleep(1.0)  # both interpreters started (their start-up is not counted below)
        watch = bench.CpuWatch(SimpleNamespace(children=children, recorder=None))
        watch.reset()
        assert busy.stdin is not None and busy.stdout is not None
        busy.stdin.write("go\n")
        busy.stdin.flush()
        busy.stdout.readline()  # its 0.5 s of CPU done
        _burn(0.3)
        cpu = watch.read()
    finally:
        busy.kill()
        idle.kill()
        busy.wait()
        idle.wait()
    assert set(cpu) == {"busy", "idle", "supervisor"}
    assert cpu["idle"] < 0.05
    assert 0.45 < cpu["busy"] < 0.7  # its 0.5 s loop (10 ms ticks)
    assert cpu["supervisor"] >= 0.29  # this process's 0.3 s
    assert bench.process_cpu_s(busy.pid) == 0.0  # gone (reaped)
