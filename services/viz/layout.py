"""The Foxglove layout of the stack (``services/viz/layout.json``), built with foxglove-sdk's layout types.

Left: the 3D panel following the robot's base (the robot, what is there, what it believes, the plans).
Right, top to bottom: the two wide head cameras, the planned CoM and ZMP (x over time, of the latest
plan), and the log lines (supervisor, launcher, error replies). Regenerate the file with
``python -m services.viz.layout``; a test checks that the committed file is this one.
"""

from __future__ import annotations

import json
from pathlib import Path

import foxglove.layouts as fl

from services.viz import common as c

LAYOUT_PATH = Path(__file__).resolve().parent / "layout.json"
SCENE_TOPICS = (
    c.ROBOT, c.WORLD_OBJECTS, c.MAP_OBSTACLES, c.MAP_SIGHTINGS, c.PLAN_PATH, c.PLAN_FOOTSTEPS,
    c.PLAN_SUPPORT, c.PLAN_COM_ZMP, c.PLAN_REACH, c.PLAN_FOOTSTEP_PLANNER,
)  # fmt: skip


def layout() -> fl.Layout:
    three_d = fl.ThreeDeePanel(
        title="robot",
        config=fl.ThreeDeeConfig(
            follow_tf="base_link",
            fixed_frame=c.WORLD,
            follow_mode="follow-position",
            camera_state=fl.ThreeDeeCameraState(distance=6.0, phi=55.0, theta_offset=30.0, perspective=True),
            topics={t: fl.BaseRendererSceneUpdateTopicSettings(visible=True) for t in SCENE_TOPICS},
        ),
    )

    def camera(name: str) -> fl.ImagePanel:
        return fl.ImagePanel(
            title=name,
            config=fl.ImageConfig(
                image_mode=fl.ImageModeConfig(
                    image_topic=c.camera_image_topic(name), calibration_topic=c.camera_calibration_topic(name)
                )
            ),
        )

    series = c.PLAN_SERIES
    plot = fl.PlotPanel(
        title="planned CoM and ZMP (x, latest plan)",
        config=fl.PlotConfig(
            x_axis_val="currentCustom",
            x_axis_path=fl.PlotXAxisPath(value=f"{series}.t_s", enabled=True),
            x_axis_label="t [s]",
            y_axis_label="x [m]",
            paths=[
                fl.PlotSeries(value=f"{series}.com_x_m", id="com_x"),
                fl.PlotSeries(value=f"{series}.zmp_x_m", id="zmp_x"),
            ],
            show_legend=True,
        ),
    )
    log = fl.LogPanel(title="log", config=fl.LogConfig(topic_to_render=c.LOG, show_name=True))
    right = fl.SplitContainer(
        direction="column",
        items=[
            fl.SplitItem(
                proportion=1.0,
                content=fl.SplitContainer(
                    direction="row",
                    items=[
                        fl.SplitItem(content=camera("wide_left")),
                        fl.SplitItem(content=camera("wide_right")),
                    ],
                ),
            ),
            fl.SplitItem(proportion=1.0, content=plot),
            fl.SplitItem(proportion=1.0, content=log),
        ],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[fl.SplitItem(proportion=1.6, content=three_d), fl.SplitItem(content=right)],
        )
    )


def layout_json() -> str:
    return json.dumps(json.loads(layout().to_json()), indent=2) + "\n"


if __name__ == "__main__":
    LAYOUT_PATH.write_text(layout_json())
    print(f"wrote {LAYOUT_PATH}")
