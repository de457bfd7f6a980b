"""Whole-body reaching with task-driven support polygon reshaping (section "Task-driven Support Polygon
Reshaping for Reaching" of the motion autonomy paper, ``001_771c0ce3779b0683.txt``: eqs. 1-5, Figs. 4-8).

Pure algorithm package (no bus; the ``reaching/reach`` endpoint is in ``service.py``); see README.md::

    from services.reaching import ReachRequest, plan_reach
    result = plan_reach("hrp2_like", ReachRequest("left", target_world_m, q_start))

The names below are imported on first use, so that ``python -m services.reaching.service`` can set up
the process (BLAS threads) before numpy loads.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "CRITERIA": "services.reaching.options",
    "ReachingOptions": "services.reaching.options",
    "MonitorSeries": "services.reaching.monitors",
    "Thresholds": "services.reaching.monitors",
    "Violation": "services.reaching.monitors",
    "ReachPlanner": "services.reaching.planner",
    "plan_reach": "services.reaching.planner",
    "ReachRequest": "services.reaching.request",
    "ReachTiming": "services.reaching.request",
    "Attempt": "services.reaching.result",
    "ReachResult": "services.reaching.result",
    "StepPlan": "services.reaching.support_polygon",
    "SupportPolygonPlanner": "services.reaching.support_polygon",
    "arm_length": "services.reaching.support_polygon",
    "ReachEnvelope": "services.reaching.envelope",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'services.reaching' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
