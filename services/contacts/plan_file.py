"""A contact plan saved to disk and read back: the sets of contacts, their witness postures and the
changes between them, so that its execution can be played again without searching again (a search
costs minutes of CPU).

The file is a NumPy ``.npz``: ``witnesses`` (k x nq, pinocchio layout), ``changes`` (k strings),
``contact_set`` (the index of the set each contact belongs to), ``contact_pair`` (spot, surface),
``contact_xyt`` (x [m], y [m], theta [rad] in the surface's frame, §2.5) and ``meta`` (a JSON object:
the search's counters, the scene). No pickled objects.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from services.contacts.sets import Contact, ContactSet
from services.errors import InvalidRequestError


@dataclass(frozen=True)
class SavedPlan:
    """A plan read from disk: ``sets`` and their ``witnesses`` (k x nq), the ``changes`` (k strings,
    "start" first) and ``meta`` (JSON values)."""

    sets: list[ContactSet]
    witnesses: np.ndarray
    changes: list[str]
    meta: dict = field(default_factory=dict)


def save_plan(
    path: str | Path,
    sets: Sequence[ContactSet],
    witnesses: Sequence[np.ndarray],
    changes: Sequence[str],
    meta: dict | None = None,
) -> Path:
    """Write the plan to ``path`` (``.npz``; parent folders made); returns the path."""
    if not (len(sets) == len(witnesses) == len(changes)) or not sets:
        raise InvalidRequestError(
            f"a plan needs as many sets, witnesses and changes (>= 1): {len(sets)}, {len(witnesses)}, "
            f"{len(changes)}"
        )
    rows = [(k, c) for k, s in enumerate(sets) for c in s]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path,
        witnesses=np.array([np.asarray(q, float) for q in witnesses]),
        changes=np.array([str(c) for c in changes]),
        contact_set=np.array([k for k, _ in rows], dtype=np.int64),
        contact_pair=np.array([[c.spot, c.surface] for _, c in rows], dtype=str).reshape(-1, 2),
        contact_xyt=np.array([[c.x, c.y, c.theta] for _, c in rows], dtype=float).reshape(-1, 3),
        meta=np.array(json.dumps(meta or {})),
    )
    return path


def load_plan(path: str | Path) -> SavedPlan:
    """Read a plan written by :func:`save_plan`. Raises InvalidRequestError when the file lacks the
    plan's arrays (e.g. the figures' ``out/contacts_chair_plan.npz`` of an earlier version)."""
    with np.load(Path(path), allow_pickle=False) as data:
        missing = {"witnesses", "changes", "contact_set", "contact_pair", "contact_xyt"} - set(data.files)
        if missing:
            raise InvalidRequestError(f"{path} is not a saved contact plan: no {sorted(missing)}")
        witnesses = np.asarray(data["witnesses"], float)
        changes = [str(c) for c in data["changes"]]
        index, pairs, xyt = data["contact_set"], data["contact_pair"], data["contact_xyt"]
        meta = json.loads(str(data["meta"])) if "meta" in data.files else {}
    sets: list[list[Contact]] = [[] for _ in range(len(witnesses))]
    for k, (spot, surface), (x, y, theta) in zip(index, pairs, xyt, strict=True):
        sets[int(k)].append(Contact(str(spot), str(surface), float(x), float(y), float(theta)))
    return SavedPlan([tuple(s) for s in sets], witnesses, changes, meta)
