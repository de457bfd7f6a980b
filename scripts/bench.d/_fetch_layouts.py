"""Fetch layouts outside the seeded family of ``ball_fetch`` (``scripts/bench fetch --layouts``).

``sim/reset`` with a seed draws one family of layouts: the green box 3.1-3.9 m ahead and within
+-0.3 rad of square, the orange ball on its near half between the two others, the yellow table
behind-right within +-0.3 m and +-0.3 rad, the chair between them. Each layout here is a scene file
written from ``sim/scenes/ball_fetch.yaml`` with some objects moved, turned or re-parented (the
``random:`` ranges dropped: a layout is one fixed arrangement), and the script a user who sees that
room would give (the ball to take, the surface to put it on, the side to turn to). Only objects of
the perception catalogue appear (``vision/models``): the stack knows no other names.

A layout is judged like a seed: the script succeeds and the sim's ground truth has ``ball`` resting on
``surface`` (``supervisor.evaluate.ball_on_table``).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

REPO = Path(__file__).resolve().parents[2]
BASE_SCENE = REPO / "sim" / "scenes" / "ball_fetch.yaml"

#: The fetch script of ``supervisor/scripts/fetch.txt`` with its names and turn as parameters.
SCRIPT = """\
localize {support}
goto {support} distance=0.7
localize {ball}
reach right {ball}
grasp right as ball
turn {turn_deg}
localize {surface}
goto {surface} distance=0.7
put ball on={surface}
"""


@dataclass(frozen=True)
class Layout:
    """One arrangement of the ball_fetch room and what to do in it.

    ``objects``: per object name, keys of its scene entry replaced (``None`` as a value removes the
    key); ``ball``, ``support``: what to take and what it rests on ("": the floor); ``surface``: where
    to put it; ``turn_deg``: the turn after the grasp (positive = left)."""

    name: str
    what: str
    objects: dict[str, dict[str, Any]] = field(default_factory=dict)
    ball: str = "orange_ball"
    support: str = "green_box"
    surface: str = "yellow_table"
    turn_deg: int = -120

    def scene(self) -> dict[str, Any]:
        """The scene document (ball_fetch's objects with this layout's changes, no ``random:``)."""
        doc = copy.deepcopy(yaml.safe_load(BASE_SCENE.read_text()))
        doc["name"] = self.scene_name
        doc["description"] = f"layout {self.name}: {self.what}"
        for obj in doc["objects"]:
            obj.pop("random", None)
            for key, value in self.objects.get(obj["name"], {}).items():
                if value is None:
                    obj.pop(key, None)
                else:
                    obj[key] = value
        doc["objects"] = _supports_first(doc["objects"])
        return doc

    @property
    def scene_name(self) -> str:
        return f"layout_{self.name}"

    def script(self) -> str:
        """The fetch script; without a ``support`` (a ball on the floor: the supervisor walks to what a
        ball is on, or reaches the ball itself) the first two lines are left out."""
        text = SCRIPT.format(
            support=self.support, ball=self.ball, surface=self.surface, turn_deg=self.turn_deg
        )
        return text if self.support else "\n".join(text.splitlines()[2:]) + "\n"


LAYOUTS: tuple[Layout, ...] = (
    Layout(
        "box_turned",
        "the box turned 0.75 rad (the seeds: within 0.3), its balls with it",
        {"green_box": {"yaw": 0.75}},
    ),
    Layout(
        "box_left",
        "the box far to the left (a quarter turn to see it), the table ahead-right",
        {
            "green_box": {"xy": [1.2, 3.2], "yaw": 1.3},
            "yellow_table": {"xy": [3.0, -0.6], "yaw": 1.6},
            "chair": {"xy": [-1.2, -1.4]},
        },
    ),
    Layout("box_near", "the box 1.9 m ahead (the seeds: 3.1-3.9 m)", {"green_box": {"xy": [1.9, 0.3]}}),
    Layout(
        "balls_tight",
        "the blue and purple balls 2 cm from the orange one, beside it",
        {"blue_ball": {"xy": [-0.06, 0.115]}, "purple_ball": {"xy": [-0.06, -0.115]}},
    ),
    Layout(
        "ball_near_edge",
        "the orange ball at the box's near edge (its side 1 cm inside)",
        {"orange_ball": {"xy": [-0.19, 0.0]}},
    ),
    Layout(
        "ball_far_side",
        "the orange ball on the box's far half, the others in front of it",
        {
            "orange_ball": {"xy": [0.15, 0.0]},
            "blue_ball": {"xy": [-0.1, 0.18]},
            "purple_ball": {"xy": [-0.1, -0.18]},
        },
    ),
    Layout(
        "ball_corner",
        "the orange ball at the box's near-left corner",
        {"orange_ball": {"xy": [-0.18, 0.23]}, "blue_ball": {"xy": [0.1, 0.15]}},
    ),
    Layout(
        "take_blue", "take the blue ball (back-left on the box) instead of the orange one", ball="blue_ball"
    ),
    Layout(
        "table_turned",
        "the table turned 1.9 rad (its short side towards the box)",
        {"yellow_table": {"yaw": 1.9}},
    ),
    Layout(
        "table_left",
        "the table on the left, the box ahead-right: turn left after the grasp",
        {
            "green_box": {"xy": [3.4, -0.6]},
            "yellow_table": {"xy": [2.0, 2.7], "yaw": -0.4},
            "chair": {"xy": [1.4, 1.4]},
        },
        turn_deg=120,
    ),
    Layout(
        "table_behind",
        "the table behind the start, the usual turn right does not face it",
        {"yellow_table": {"xy": [-1.6, -1.2], "yaw": 0.9}, "chair": {"xy": [0.8, -2.0]}},
    ),
    Layout(
        "chair_in_way", "the chair between the start and the box", {"chair": {"xy": [1.8, 0.5], "yaw": 2.8}}
    ),
    Layout(
        "table_to_box",
        "the orange ball on the table, put on the box (beside the other balls)",
        {"orange_ball": {"on_top_of": "yellow_table", "xy": [0.1, 0.0]}, "yellow_table": {"xy": [2.4, -1.8]}},
        support="yellow_table",
        surface="green_box",
        turn_deg=120,
    ),
    Layout(
        "ball_on_floor",
        "the orange ball on the floor 4.3 m away (below any reach from standing)",
        {"orange_ball": {"on_top_of": None, "xy": [4.3, -0.7]}},
        support="",
    ),
)


def _supports_first(objects: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The objects ordered so that each comes after the one it rests on (``on_top_of`` names an
    object declared earlier in a scene file)."""
    placed: list[dict[str, Any]] = []
    names: set[str] = set()
    pending = list(objects)
    while pending:
        ready = [o for o in pending if o.get("on_top_of") in (None, *names)]
        if not ready:
            raise SystemExit(f"layout objects rest on missing supports: {[o['name'] for o in pending]}")
        for obj in ready:
            placed.append(obj)
            names.add(obj["name"])
            pending.remove(obj)
    return placed


def by_name(names: str) -> list[Layout]:
    """The layouts named in ``names`` (comma-separated, or ``all``); SystemExit listing them if unknown."""
    known = {layout.name: layout for layout in LAYOUTS}
    if names == "all":
        return list(LAYOUTS)
    chosen = []
    for name in names.split(","):
        if name not in known:
            raise SystemExit(f"unknown layout {name!r}; known: {', '.join(known)}, or all")
        chosen.append(known[name])
    return chosen


def write_scenes(layouts: list[Layout], folder: Path) -> Path:
    """Write each layout's scene file ``<scene_name>.yaml`` into ``folder``; the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    for layout in layouts:
        (folder / f"{layout.scene_name}.yaml").write_text(yaml.safe_dump(layout.scene(), sort_keys=False))
    return folder
