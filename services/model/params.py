"""Load and validate the per-robot parameter YAML (``services/model/data/<robot>.yaml``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

from services.errors import InvalidRequestError
from services.model.ground import FootstepBounds
from services.model.specs import GripperSpec, RobotParams

_TOP_KEYS = {
    "footstep_bounds",
    "step_height_m",
    "com_height_m",
    "step_duration_s",
    "double_support_s",
    "manipulability_threshold",
    "ee_error_threshold_m",
    "fall_base_height_m",
    "fall_tilt_rad",
    "gripper",
    "extra",
}
_BOUND_KEYS = ("dx_min_m", "dx_max_m", "dy_min_m", "dy_max_m", "dtheta_min_rad", "dtheta_max_rad")
_POSITIVE = (
    "step_height_m",
    "com_height_m",
    "step_duration_s",
    "manipulability_threshold",
    "ee_error_threshold_m",
    "fall_base_height_m",
    "fall_tilt_rad",
)


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InvalidRequestError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _mapping(where: str, value: Any, keys: set[str] | tuple[str, ...], required: bool = True) -> dict:
    if not isinstance(value, dict):
        raise InvalidRequestError(f"{where}: expected a mapping, got {type(value).__name__}")
    unknown = sorted(set(value) - set(keys))
    if unknown:
        raise InvalidRequestError(f"{where}: unknown keys {unknown}; valid keys are {sorted(keys)}")
    missing = sorted(set(keys) - set(value) - {"extra"}) if required else []
    if missing:
        raise InvalidRequestError(f"{where}: missing keys {missing}")
    return value


def params_from_dict(raw: Any, source: str = "<dict>") -> RobotParams:
    """Validate a parsed YAML document into :class:`RobotParams` (raises InvalidRequestError)."""
    doc = _mapping(source, raw, _TOP_KEYS)
    fb = _mapping(f"{source}: footstep_bounds", doc["footstep_bounds"], _BOUND_KEYS)
    bounds = FootstepBounds(**{k: _number(f"{source}: footstep_bounds.{k}", fb[k]) for k in _BOUND_KEYS})
    for lo, hi in (("dx_min_m", "dx_max_m"), ("dy_min_m", "dy_max_m"), ("dtheta_min_rad", "dtheta_max_rad")):
        if getattr(bounds, lo) >= getattr(bounds, hi):
            raise InvalidRequestError(f"{source}: footstep_bounds.{lo} must be below {hi}")
    values = {k: _number(f"{source}: {k}", doc[k]) for k in _POSITIVE}
    for k, v in values.items():
        if v <= 0.0:
            raise InvalidRequestError(f"{source}: {k} must be positive, got {v}")
    double_support_s = _number(f"{source}: double_support_s", doc["double_support_s"])
    if not 0.0 <= double_support_s < values["step_duration_s"]:
        raise InvalidRequestError(f"{source}: double_support_s must be in [0, step_duration_s)")
    gr = _mapping(f"{source}: gripper", doc["gripper"], ("open_q", "closed_q"))
    gripper = GripperSpec(
        _number(f"{source}: gripper.open_q", gr["open_q"]),
        _number(f"{source}: gripper.closed_q", gr["closed_q"]),
    )
    extra_raw = doc.get("extra") or {}
    if not isinstance(extra_raw, dict):
        raise InvalidRequestError(f"{source}: extra must be a mapping of name -> number")
    extra = {str(k): _number(f"{source}: extra.{k}", v) for k, v in extra_raw.items()}
    return RobotParams(
        footstep_bounds=bounds,
        double_support_s=double_support_s,
        gripper=gripper,
        extra=extra,
        **values,
    )


def load_params(path: Path) -> RobotParams:
    """Read and validate a robot parameter YAML file."""
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InvalidRequestError(f"robot parameter file {path} does not exist") from exc
    except yaml.YAMLError as exc:
        raise InvalidRequestError(f"robot parameter file {path} is not valid YAML: {exc}") from exc
    return params_from_dict(raw, str(path))
