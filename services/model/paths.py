"""Where the robot description files are: the project's generated URDF and example-robot-data's share."""

from __future__ import annotations

import functools
import importlib.metadata
from pathlib import Path

from services.errors import NotFoundError

DATA_DIR = Path(__file__).resolve().parent / "data"


@functools.cache
def example_robot_data_share() -> Path:
    """The ``share`` directory holding ``example-robot-data/robots/...`` (the package:// root).

    example-robot-data 6.x is a cmeel wheel with data files only (no importable module): its files
    live under ``site-packages/cmeel.prefix/share/example-robot-data``. Located from the installed
    distribution's file list, so no environment variable is needed.
    """
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:
        raise NotFoundError(
            "example-robot-data is not installed; install it with `pip install example-robot-data` "
            "to use the talos robot"
        ) from exc
    for f in dist.files or ():
        parts = Path(str(f)).parts
        if "example-robot-data" in parts and parts[-1].endswith(".urdf"):
            idx = parts.index("example-robot-data")
            share = Path(str(dist.locate_file(Path(*parts[:idx])))).resolve()
            if (share / "example-robot-data" / "robots").is_dir():
                return share
    raise NotFoundError(
        "example-robot-data is installed but its share/example-robot-data/robots folder was not found"
    )


def talos_data_dir() -> Path:
    """``.../share/example-robot-data/robots/talos_data``."""
    path = example_robot_data_share() / "example-robot-data" / "robots" / "talos_data"
    if not path.is_dir():
        raise NotFoundError(f"talos_data not found under {path.parent}")
    return path
