"""The pure parts of the inspecting subcommands: field descriptions, rates, the graph, --field paths."""

from __future__ import annotations

from typing import Annotated

import msgspec
import pytest

from services.bus.cli import field_at
from services.bus.graph import build_graph, to_dot, to_mermaid
from services.bus.interfaces import struct_fields, units_of
from services.bus.rates import RateMeter
from services.cli import main


class _Inner(msgspec.Struct, kw_only=True, frozen=True):
    force_n: float  # contact force [N]


class _Probe(msgspec.Struct, kw_only=True, frozen=True):
    """A message to read."""

    gain: Annotated[float, msgspec.Meta(ge=0.0, le=2.5)] = 1.0  # how strongly [rad/s]
    # a comment above a field documents it too
    names: list[str] = []
    period_s: float = 0.005
    inner: list[_Inner] = []


def test_fields_have_types_defaults_units_limits_and_docs() -> None:
    fields = {f.path: f for f in struct_fields(_Probe)}
    gain = fields["gain"]
    assert (gain.type, gain.default, gain.units, gain.limits) == ("float", "1.0", "rad/s", ">= 0, <= 2.5")
    assert gain.doc == "how strongly [rad/s]"
    assert fields["names"].doc == "a comment above a field documents it too"
    assert fields["period_s"].units == "s"  # from the name's suffix
    assert fields["inner[].force_n"].units == "N" and fields["inner[].force_n"].depth == 1


@pytest.mark.parametrize(
    ("name", "comment", "units"),
    [
        ("q", "(N, nq) configurations; q[0] is the start", ""),
        ("center", "[x, y, z] [m]", "m"),
        ("goal", "[x, y, theta] [m, m, rad]", "m, m, rad"),
        ("dt_s", "", "s"),
        ("v", "speed [m/s]", "m/s"),
    ],
)
def test_units_are_brackets_that_hold_units(name: str, comment: str, units: str) -> None:
    assert units_of(name, comment) == units


def test_rate_meter_statistics() -> None:
    meter = RateMeter(window=5)
    assert meter.stats() is None
    for i, t in enumerate([0.0, 0.01, 0.02, 0.04, 0.05, 0.06]):
        meter.add(t, 100 + i)
    stats = meter.stats()
    assert stats.window == 5 and stats.count == 6
    assert stats.rate_hz == pytest.approx(4 / 0.05)
    assert (stats.period_min_s, stats.period_max_s) == (pytest.approx(0.01), pytest.approx(0.02))
    assert stats.size_min_b == 101 and stats.size_max_b == 105
    assert stats.bytes_per_s == pytest.approx((102 + 103 + 104 + 105) / 0.05)
    with pytest.raises(ValueError, match="at least 2"):
        RateMeter(window=1)


def test_graph_from_schemas_and_source() -> None:
    nodes = build_graph()
    assert "sim/execute" in nodes["sim"].serves and "sim/clock" in nodes["sim"].publishes
    assert {"sim/execute", "perception/locate", "navigation/goto"} <= set(nodes["supervisor"].calls)
    assert nodes["perception"].calls == ["sim/render", "sim/state"]
    assert nodes["record"].subscribes == ["**"]
    assert nodes["record"].calls == ["sim/ground_truth"]  # what is there, for the log's /world/objects
    assert nodes["viz"].calls == ["sim/ground_truth"]  # the live view's world (was: no edge at all)
    assert all(n.alive is None for n in nodes.values())
    dot = to_dot(nodes)
    assert (
        dot.startswith("digraph humanoid {")
        and '"supervisor" -> "sim" [label="execute", style=solid];' in dot
    )
    assert "supervisor -->|goto| navigation" in to_mermaid(nodes)


def test_field_paths() -> None:
    doc = {"position": [1.0, 2.0, 3.0], "images": [{"name": "wide_left"}]}
    assert field_at(doc, "position.2") == 3.0
    assert field_at(doc, "images/0/name") == "wide_left"
    with pytest.raises(KeyError, match="valid here: position, images"):
        field_at(doc, "pose")
    with pytest.raises(KeyError, match=r"valid here: 0\.\.2"):
        field_at(doc, "position.3")


def test_interface_of_a_message_type(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["interface", "JointState"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("message type sim.JointState (service sim)")
    assert "sim_time_s" in out and "m/s, rad/s" in out
    assert main(["interface", "PlanRequest"]) == 2  # two services have one
    assert "footsteps.PlanRequest, walking.PlanRequest" in capsys.readouterr().err
    assert main(["interface", "walking.PlanRequest"]) == 0
