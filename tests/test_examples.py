"""The examples that regenerate the papers' figures (README, "The papers, where") start and take the same
``--out DIR`` (no test ran them before session 11: an import broken by a later change went unseen).
Running them whole takes 15-35 s each (`examples/*.py`); here each one's ``--help`` runs in its own
interpreter, which imports all it needs."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
EXAMPLES = sorted(p.name for p in (REPO / "examples").glob("*.py"))


def test_every_example_is_listed():
    assert set(EXAMPLES) >= {
        "contacts_chair.py",
        "footsteps_scenarios.py",
        "navigation_plots.py",
        "reaching_plots.py",
        "walking_plots.py",
    }


@pytest.mark.parametrize("name", EXAMPLES)
def test_an_example_starts_and_takes_an_output_directory(name: str):
    result = subprocess.run(
        [sys.executable, str(REPO / "examples" / name), "--help"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    options = result.stdout.split("options:", 1)[-1]
    assert re.search(r"--out \S+\s+[^-]*directory", options), options
