"""The ``--model`` start-up option of the services that serve one robot model (sim, navigation, reaching).

argparse only: no bus here, so the services stay thin adapters and the model package stays pure.
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import TypeVar

from services.model.robot_model import load_robot, robot_names

C = TypeVar("C")


def add_model_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--model NAME`` (default: the service config's ``model``)."""
    parser.add_argument("--model", help=f"robot model: {' or '.join(robot_names())} (default: hrp2_like)")


def with_model(config: C, model: str | None) -> C:
    """``config`` (a frozen dataclass with a ``model`` field) with ``model`` when given, checked by loading
    it now: a wrong name fails at start-up with the known names, not at the first request."""
    if model is not None:
        config = dataclasses.replace(config, model=model)  # type: ignore[type-var]
    load_robot(config.model)  # type: ignore[attr-defined]
    return config
