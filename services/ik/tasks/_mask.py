"""Axis selection masks shared by the Cartesian tasks."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from services.errors import InvalidRequestError


def axis_rows(mask: Sequence[bool] | np.ndarray, size: int, task_name: str) -> np.ndarray:
    """Row indices selected by a boolean mask of length ``size``."""
    array = np.asarray(mask, dtype=bool).reshape(-1)
    if array.shape[0] != size:
        raise InvalidRequestError(
            f"task {task_name!r}: axis mask needs {size} booleans, got {array.shape[0]}"
        )
    if not array.any():
        raise InvalidRequestError(f"task {task_name!r}: axis mask selects no axis")
    return np.flatnonzero(array)


def vector3(value: Sequence[float] | np.ndarray, what: str) -> np.ndarray:
    """A finite 3-vector or InvalidRequestError naming ``what``."""
    array = np.asarray(value, dtype=float).reshape(-1)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise InvalidRequestError(f"{what} must be 3 finite numbers, got {value!r}")
    return array
