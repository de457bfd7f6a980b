"""The examples that regenerate the papers' figures (README, "The papers, where") start and take the same
``--out DIR`` (no test ran them before session 11: an import broken by a later change went unseen).
Running them whole takes 15-35 s each (`examples/*.py`); here each one's ``--help`` runs (in one
interpreter apart from the suite's), which imports all it needs."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
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


#: Runs each example's ``--help`` in one interpreter (they share pinocchio, matplotlib, pybullet: one
#: import instead of five) and prints {name: [exit code, output]} as JSON.
_DRIVER = """
import contextlib, io, json, runpy, sys
out = {}
for path in sys.argv[1:]:
    sys.argv = [path, "--help"]
    buffer = io.StringIO()
    code = 0
    try:
        with contextlib.redirect_stdout(buffer):
            runpy.run_path(path, run_name="__main__")
    except SystemExit as exc:
        code = exc.code or 0
    except Exception as exc:  # an import or a name broken by a later change
        code, buffer = 1, io.StringIO(repr(exc))
    out[path.rsplit("/", 1)[-1]] = [code, buffer.getvalue()]
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def helps() -> dict[str, list]:
    paths = [str(REPO / "examples" / name) for name in EXAMPLES]
    result = subprocess.run(
        [sys.executable, "-c", _DRIVER, *paths], capture_output=True, text=True, timeout=180, cwd=REPO
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("name", EXAMPLES)
def test_an_example_starts_and_takes_an_output_directory(name: str, helps: dict[str, list]):
    code, text = helps[name]
    assert code == 0, text
    options = text.split("options:", 1)[-1]
    assert re.search(r"--out \S+\s+[^-]*directory", options), options


def test_the_chair_figures_draw_a_plan_saved_as_the_scenario_saves_it(tmp_path: Path):
    """examples/contacts_chair.py reads and writes the plan file of ``humanoid scenario chair-egress
    --save-plan`` / ``--plan`` (it had a format of its own the scenario could not play)."""
    import importlib.util

    from services.contacts import chair_egress
    from services.contacts.environment import environment_of
    from services.contacts.plan_file import save_plan
    from services.contacts.posture import PostureGenerator
    from services.contacts.sets import contact_at
    from services.contacts.spots import robot_spots
    from services.model import load_robot
    from sim.scene import layout, load_scene
    from sim.world import start_configuration

    spec = importlib.util.spec_from_file_location("contacts_chair", REPO / "examples" / "contacts_chair.py")
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    robot = load_robot("hrp2_like")
    lay = layout(load_scene("chair_egress"))
    env = environment_of(lay)
    gen = PostureGenerator(robot, env, robot_spots(robot))
    q0 = start_configuration(robot, lay)
    start = tuple(contact_at(gen.spots[s], e, env, gen.spot_pose(q0, s)) for s, e in chair_egress.START_PAIRS)
    path = save_plan(
        tmp_path / "plan.npz", [start, start], [q0, q0], ["start", "start again"], {"slope_k": 15.0}
    )
    data = example.figure_data(path)
    assert list(data["changes"]) == ["start", "start again"]
    assert np.allclose(data["s"], 0.0, atol=0.05) and data["f"][0] == pytest.approx(data["f"][1])
    assert example.plot_potential(data, tmp_path).is_file()
    # one plan to draw: --reuse (the last one planned) and --plan FILE together are refused, and a
    # plan that does not load leaves no output directory behind
    with pytest.raises(SystemExit) as usage:
        example.main(["--reuse", "--plan", str(path), "--out", str(tmp_path / "both")])
    assert usage.value.code == 2 and not (tmp_path / "both").exists()
    assert example.main(["--plan", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "none")]) == 2
    assert not (tmp_path / "none").exists()
