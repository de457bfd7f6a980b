"""Service log files: rotation by size while a process writes, and `humanoid logs` reading them back."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from services.bus.logfiles import RotatingLog, log_files
from services.cli import main


def test_a_process_output_is_rotated_and_read_back_in_order(tmp_path: Path, capsys) -> None:
    log = RotatingLog(tmp_path / "svc.log", max_bytes=1000, backups=2)
    proc = subprocess.Popen(
        [sys.executable, "-c", "for i in range(200): print(f'line {i:04d} ' + 'x' * 20)"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    log.follow(proc.stdout)
    proc.wait()
    log.close(timeout_s=5)
    files = log_files(tmp_path, "svc")
    assert [f.name for f in files] == ["svc.log.2", "svc.log.1", "svc.log"]  # oldest first, 2 kept
    assert all(f.stat().st_size <= 1000 for f in files)
    kept = "".join(f.read_text() for f in files).splitlines()
    numbers = [int(line.split()[1]) for line in kept]
    assert numbers == list(range(numbers[0], 200))  # contiguous up to the last line written
    assert main(["logs", "svc", "-n", "3", "--log-dir", str(tmp_path)]) == 0
    assert [line.split()[1] for line in capsys.readouterr().out.splitlines()] == ["0197", "0198", "0199"]
    assert main(["logs", "svc", "--all", "--log-dir", str(tmp_path)]) == 0
    assert capsys.readouterr().out.splitlines() == kept


def test_logs_without_a_log_says_where_it_looked(tmp_path: Path, capsys) -> None:
    assert main(["logs", "--log-dir", str(tmp_path)]) == 2
    assert f"no log in {tmp_path}/" in capsys.readouterr().err


def test_a_service_that_dies_at_start_shows_the_end_of_its_log(tmp_path: Path, monkeypatch, capsys) -> None:
    """Its output went to its log file, not the terminal: the launcher's error quotes the log's end."""
    from conftest import free_port

    from services.bus.config import BusConfig
    from services.bus.discovery import ServiceEntry
    from services.bus.launcher import Launcher, LauncherConfig

    (tmp_path / "broken_service.py").write_text(
        "import sys\nprint('loading the calibration')\n"
        "print('no calibration file: giving up', file=sys.stderr)\nsys.exit(3)\n"
    )
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    logs = tmp_path / "logs"
    entry = ServiceEntry("broken", "broken_service", tmp_path / "broken_service.py")
    config = LauncherConfig(log_dir=str(logs), ready_timeout_s=20.0)
    launcher = Launcher(BusConfig().with_hub_port(free_port()), [entry], config, out=sys.stdout)
    assert launcher.run() == 1
    err = capsys.readouterr().err
    assert f"the end of its log {logs / 'broken.log'}:" in err
    assert "  | loading the calibration\n  | no calibration file: giving up" in err
    assert (logs / "broken.log").read_text().splitlines() == [
        "loading the calibration",
        "no calibration file: giving up",
    ]
