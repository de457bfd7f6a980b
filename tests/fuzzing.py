"""Hostile payloads for every endpoint of the stack, and how a running stack answers them.

Used by ``tests/test_fuzz.py`` (about two minutes in the suite) and ``scripts/bench fuzz`` (the long
run). Payloads come from hypothesis strategies derived from each endpoint's request schema (its JSON
schema, so ranges and lengths of the ``Meta`` constraints are respected or deliberately broken), then
mutated the ways an attacker or a careless client would:

* ``valid``: drawn from the schema as it is (reaches the handlers' own checks and the planners);
* ``leaf``: one value replaced by an absurd one (1e308, -1, 2**64, a 1 MB string, a 3000-deep array,
  a 200 000-element list, a list of strings, null, ...);
* ``unknown``: an unknown field added to some object;
* ``bytes``: invalid UTF-8 inside a string, truncation, random bytes, non-JSON literals (NaN, 1e999);
* ``binary``: a binary frame (``services.bus.codec``) whose array references are corrupted: missing
  ``dtype``/``shape``, datetime/object/string dtypes, shapes that do not match, offsets outside the
  message, a header length beyond the frame, NaN and infinities in the array.

:func:`send` classifies the answer: ``ok``, a typed error (``invalid_request``, ``infeasible``, ...),
``internal`` (an unhandled exception in the service: a bug) or ``no_reply`` (nothing within the
timeout: a hung or dead service).
"""

from __future__ import annotations

import json
import struct
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import msgspec
from hypothesis import strategies as st

from services.bus import keys
from services.bus.codec import MAGIC
from services.bus.schemas.common import ErrorInfo
from services.bus.spec import EndpointSpec, json_schema

ND_DESCRIPTION = "numpy array"
#: Words that the services know, so that generated strings reach past the first name check.
WORDS = (
    "",
    "left",
    "right",
    "left",
    "right",
    "auto",
    "wide",
    "narrow",
    "box",
    "cylinder",
    "walk",
    "world",
    "reach",
    "gaze",
    "posture",
    "open",
    "close",
    "hrp2_like",
    "talos",
    "ball_fetch",
    "orange_ball",
    "yellow_table",
    "overview",
    "centroid",
    "bug",
    "internal",
    "-x",
    "+y",
    "../../etc/passwd.yaml",
    "/etc/hostname",
)
#: Array lengths drawn besides the robot's nq (hrp2_like: 37).
NQ_CHOICES = (0, 1, 7, 36, 37, 38, 46)
MUTATIONS = ("valid", "leaf", "unknown", "bytes", "binary")
#: Fields drawn from a narrower range than the schema allows, so that a fuzz run is not spent waiting
#: for valid long requests (a 60 s planning budget, a 100 000-frame stream); the schema's bounds
#: themselves are tested by the leaf mutations.
NARROWER = {
    "time_budget_s": st.floats(0.01, 2.0),
    "total_budget_s": st.floats(0.01, 5.0),
    "count": st.integers(1, 20),
    "hold_s": st.floats(0.0, 1.0),
    "max_iterations": st.integers(0, 300),
    "dt_s": st.sampled_from((0.005, 0.01, 0.001, 0.0015, 0.0)),
}


# ---------------------------------------------------------------------------------------------- schemas
def _is_array(node: dict[str, Any]) -> bool:
    return ND_DESCRIPTION in str(node.get("description", "")) and "type" not in node and "anyOf" not in node


def _number_bounds(node: dict[str, Any], lo: float, hi: float) -> tuple[float, float, bool, bool]:
    lo = node.get("minimum", node.get("exclusiveMinimum", lo))
    hi = node.get("maximum", node.get("exclusiveMaximum", hi))
    return float(lo), float(hi), "exclusiveMinimum" in node, "exclusiveMaximum" in node


def strategy_for(
    node: dict[str, Any], depth: int = 0, q_ref: tuple[float, ...] = ()
) -> st.SearchStrategy[Any]:
    """JSON values that satisfy (mostly) the JSON schema ``node``; arrays as nested lists, near the
    configuration ``q_ref`` (the robot's, so that requests reach past the planners' first checks)."""
    if _is_array(node):
        return array_lists(q_ref)
    if "anyOf" in node:
        return st.one_of([strategy_for(n, depth, q_ref) for n in node["anyOf"]])
    kind = node.get("type")
    if isinstance(kind, list):
        return st.one_of([strategy_for({**node, "type": k}, depth, q_ref) for k in kind])
    if kind == "null":
        return st.none()
    if kind == "boolean":
        return st.booleans()
    if kind == "integer":
        lo, hi, _, _ = _number_bounds(node, -3, 60)
        lo, hi = max(lo, -(2**31)), min(hi, 2**31)
        near = st.integers(int(max(lo, -3)), int(min(hi, max(lo, -3) + 60)))
        return st.one_of(near, st.integers(int(lo), int(hi)))
    if kind == "number":
        lo, hi, ex_lo, ex_hi = _number_bounds(node, -5.0, 5.0)
        lo, hi = max(lo, -1e6), min(hi, 1e6)
        room = st.floats(max(lo, -3.0), min(hi, 3.0), exclude_min=ex_lo, exclude_max=ex_hi, allow_nan=False)
        anywhere = st.floats(lo, hi, exclude_min=ex_lo, exclude_max=ex_hi, allow_nan=False)
        return st.one_of(room, room, anywhere) if max(lo, -3.0) < min(hi, 3.0) else anywhere
    if kind == "string":
        if "enum" in node:
            return st.sampled_from(node["enum"])
        n = int(node.get("maxLength", 40))
        return st.one_of(st.sampled_from(WORDS), st.text(max_size=min(n, 20))).filter(lambda s: len(s) <= n)
    if kind == "array":
        lo = int(node.get("minItems", 0))
        hi = int(node.get("maxItems", lo + 4))
        hi = min(hi, lo + 4)
        items = node.get("items", {})
        if depth > 4:
            return st.just([])
        return st.lists(strategy_for(items, depth + 1, q_ref), min_size=lo, max_size=hi)
    if kind == "object":
        props = node.get("properties")
        if props is None:  # a dict
            values = node.get("additionalProperties", {})
            value_strategy = strategy_for(values, depth + 1, q_ref) if isinstance(values, dict) else st.none()
            return st.dictionaries(st.sampled_from(WORDS), value_strategy, max_size=3)
        required = set(node.get("required", []))
        fields = {
            k: NARROWER[k] if k in NARROWER else strategy_for(v, depth + 1, q_ref) for k, v in props.items()
        }
        return st.fixed_dictionaries(
            {k: v for k, v in fields.items() if k in required},
            optional={k: v for k, v in fields.items() if k not in required},
        )
    return st.one_of(st.none(), st.integers(-3, 3), st.sampled_from(WORDS))


def array_lists(q_ref: tuple[float, ...] = ()) -> st.SearchStrategy[Any]:
    """A configuration (nq,), a trajectory (n, nq) or a small matrix, as nested lists of floats;
    with ``q_ref``, often ``q_ref`` itself or a trajectory that stays near it."""
    value = st.floats(-2.0, 2.0, allow_nan=False)
    near: list[st.SearchStrategy[Any]] = []
    if q_ref:
        ref = list(q_ref)
        noise = st.floats(-0.05, 0.05, allow_nan=False)
        near_q = st.lists(noise, min_size=len(ref), max_size=len(ref)).map(
            lambda d: [a + b for a, b in zip(ref, d, strict=True)]
        )
        near = [st.just(ref), near_q, st.tuples(near_q, st.integers(1, 400)).map(lambda t: [t[0]] * t[1])]
    vector = st.sampled_from(NQ_CHOICES).flatmap(lambda n: st.lists(value, min_size=n, max_size=n))
    matrix = st.tuples(st.integers(1, 6), st.sampled_from(NQ_CHOICES)).flatmap(
        lambda rc: st.lists(st.lists(value, min_size=rc[1], max_size=rc[1]), min_size=rc[0], max_size=rc[0])
    )
    return st.one_of(*near, vector, matrix, st.just([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))


#: Realistic requests of the endpoints known here (``"$q"``: the robot's configuration, ``"$traj"``: a
#: short trajectory holding it): hostile mutations of one of their fields reach the planners' code.
EXAMPLES: dict[str, list[dict[str, Any]]] = {
    "walking/plan": [
        {"steps": [{"pose": [0.2, -0.095, 0.0]}, {"pose": [0.2, 0.095, 0.0]}], "first_side": "right"},
        {"q_start": "$q", "steps": [{"pose": [0.15, -0.095, 0.1], "side": "right"}], "hands": []},
    ],
    "walking/goal": [
        {"q_start": "$q", "pose": [0.3, 0.1, 0.2]},
        {"q_start": "$q", "kind": "turn", "angle_rad": 0.5, "obstacles": []},
        {  # the supervisor's step back and turn beside the box it took the ball from
            "q_start": "$q",
            "kind": "turn",
            "angle_rad": -2.0,
            "back_m": 0.2,
            "obstacles": [{"name": "box", "center": [0.7, 0.0, 0.35], "size": [0.5, 0.6, 0.7], "yaw": 0.3}],
        },
    ],
    "footsteps/plan": [
        {
            "tasks": [{"kind": "reach", "target": [1.0, -0.2, 0.8]}, {"kind": "posture"}],
            "disks": [{"x": 0.6, "y": 0.0, "radius": 0.1}],
            "time_budget_s": 2.0,
        },
        {"q_start": "$q", "tasks": [{"kind": "gaze", "target": [2.0, 0.0, 0.5]}], "max_steps": 4},
        {  # the grasp's last steps: fingers down, the jaws' yaw free, a neighbouring ball kept clear
            "q_start": "$q",
            "tasks": [
                {"kind": "reach", "target": [0.8, -0.2, 0.85], "hand": "right"},
                {"kind": "orient", "orientation": [0.0, 0.7071, 0.0, 0.7071], "free_yaw": True},
                {"kind": "posture"},
            ],
            "hand_obstacles": [{"center": [0.85, -0.05, 0.8], "radius": 0.05}],
            "time_budget_s": 2.0,
        },
    ],
    "navigation/goto": [
        {"q_start": "$q", "goal_pose": [1.0, 0.5, 0.3], "time_budget_s": 1.0},
        {
            "q_start": "$q",
            "obstacles": [{"name": "b", "center": [1.2, 0.8, 0.3], "size": [0.3, 0.3, 0.6]}],
            "goal_object": "b",
        },
    ],
    "reaching/reach": [
        {"hand": "right", "target": [0.35, -0.2, 0.8], "q_start": "$q"},
        {"hand": "left", "target": [0.6, 0.3, 0.4], "q_start": "$q", "allow_stepping": True},
        {  # a timed reach keeping the arm clear of a ball beside the target, with a final posture
            "hand": "right",
            "target": [0.45, -0.2, 0.85],
            "q_start": "$q",
            "orientation": [0.0, 0.7071, 0.0, 0.7071],
            "hand_obstacles": [{"center": [0.5, -0.08, 0.8], "radius": 0.05}],
            "hand_speed_m_s": 0.3,
            "posture": "$q",
            "time_budget_s": 2.0,
        },
    ],
    "sim/execute": [
        {"q": "$traj"},
        {"q": "$traj", "dt_s": 0.01, "hold_s": 0.1},
        {"q": "$traj", "allowed_contacts": ["orange_ball"], "effort_scale": {"RARM_JOINT0": 0.5}},
    ],
    "sim/kinematics": [{"q": "$q", "place_at": [0.5, 0.2, 0.3]}, {"q": "$traj"}],
    "sim/render": [{"camera": "wide", "width_px": 160, "height_px": 120, "depth": True}],
    "sim/snapshot": [{"viewpoint": "top", "width_px": 160, "height_px": 120}],
    "sim/gripper": [{"side": "right", "action": "close"}, {"side": "left", "action": "open"}],
    "sim/reset": [{"scene": "ball_fetch", "seed": 3}, {"scene": "empty"}],
    "perception/locate": [
        {"object": "orange_ball"},
        {"object": "green_box", "camera": "narrow", "width_px": 320, "height_px": 240},
        {"object": "orange_ball", "others": False, "method": "edges", "width_px": 320, "height_px": 240},
    ],
    "perception/look_around": [{"camera": "wide"}, {"model": "hrp2_like", "camera": "narrow"}],
    "contacts/plan": [
        {
            "scene": "chair_egress",
            "q_start": "$q",
            "start_contacts": [["left_sole", "floor"], ["right_sole", "floor"]],
            "goal_axis": "x",
            "goal_value_m": 0.3,
            "max_nodes": 20,
            "n_interpolation": 2,
            "time_budget_s": 2.0,
        }
    ],
    "contacts/transition": [
        {
            "scene": "chair_egress",
            "q_measured": "$q",
            "from_set": [
                {"spot": "left_sole", "surface": "floor", "x": 0.0, "y": 0.1, "theta": 0.0},
                {"spot": "right_sole", "surface": "floor", "x": 0.0, "y": -0.1, "theta": 0.0},
            ],
            "to_set": [{"spot": "left_sole", "surface": "floor", "x": 0.0, "y": 0.1, "theta": 0.0}],
            "witness": "$q",
            "n_interpolation": 2,
            "time_budget_s": 2.0,
        }
    ],
    "diag/stream": [{"count": 3, "width": 64, "height": 48}],
    "diag/echo": [{"text": "hi", "blob": [1, 2, 3]}],
    "diag/echo_worker": [{"text": "hi", "blob": [[0.5, 1.5]]}],
    "diag/raise": [{"code": "bug", "message": "x"}, {"code": "infeasible", "message": "x"}],
}


def _fill(doc: Any, q_ref: tuple[float, ...]) -> Any:
    if doc == "$q":
        return list(q_ref) or [0.0]
    if doc == "$traj":
        return [list(q_ref) or [0.0]] * 20
    if isinstance(doc, dict):
        return {k: _fill(v, q_ref) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_fill(v, q_ref) for v in doc]
    return doc


# ---------------------------------------------------------------------------------------------- hostility
HUGE_STRING = "x" * 1_000_000


#: Values too deep for the json module: a placeholder string in the document, the raw JSON in the bytes.
_RAW = {
    "\x01deep_list\x01": b"[" * 3000 + b"0" + b"]" * 3000,
    "\x01deep_dict\x01": b'{"a":' * 3000 + b"0" + b"}" * 3000,
}


HOSTILE_VALUES: tuple[Any, ...] = (
    1e308,
    -1e308,
    5e-324,
    0,
    -1,
    -(2**63) - 1,
    2**64 + 5,
    2**31,
    "",
    "\x00",
    HUGE_STRING,
    None,
    True,
    [],
    {},
    ["a", "b"],
    [[1.0, "x"]],
    [1e308] * 39,
    [0.0] * 200_000,
    [[0.0] * 39] * 20_000,
    *_RAW,
    {"__nd__": [0, 8], "dtype": "<f8", "shape": [1]},
)


def _paths(doc: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path (keys and indices) into ``doc``, the root included."""
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.extend(_paths(v, (*prefix, k)))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:8]):
            out.extend(_paths(v, (*prefix, i)))
    return out


def _replace(doc: Any, path: tuple[Any, ...], value: Any) -> Any:
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(doc, dict):
        return {**doc, head: _replace(doc[head], rest, value)}
    copy = list(doc)
    copy[head] = _replace(doc[head], rest, value)
    return copy


def _dump(doc: Any) -> bytes:
    raw = json.dumps(doc, allow_nan=False, separators=(",", ":")).encode()
    for placeholder, deep in _RAW.items():
        quoted = json.dumps(placeholder).encode()
        if quoted in raw:
            raw = raw.replace(quoted, deep)
    return raw


@st.composite
def leaf_mutation(draw: st.DrawFn, doc: Any) -> bytes:
    paths = _paths(doc)
    path = draw(st.sampled_from(paths[1:] or paths))
    value = draw(st.sampled_from(HOSTILE_VALUES))
    return _dump(_replace(doc, path, value))


@st.composite
def unknown_field(draw: st.DrawFn, doc: Any) -> bytes:
    objects = [p for p in _paths(doc) if isinstance(_get(doc, p), dict)]
    if not objects:
        return _dump({"unexpected_field": 1, "value": doc})
    path = draw(st.sampled_from(objects))
    name = draw(st.sampled_from(("unexpected_field", "__nd__", "q_start_", "Tasks", "x" * 300)))
    target = dict(_get(doc, path))
    target[name] = draw(st.sampled_from((1, "a", None, [1, 2])))
    return _dump(_replace(doc, path, target))


def _get(doc: Any, path: tuple[Any, ...]) -> Any:
    for p in path:
        doc = doc[p]
    return doc


@st.composite
def byte_mutation(draw: st.DrawFn, doc: Any) -> bytes:
    raw = _dump(doc)
    how = draw(st.sampled_from(("utf8", "truncate", "random", "literal", "empty", "bom", "long_number")))
    if how == "utf8":
        quote = raw.find(b'":"')
        bad = draw(st.sampled_from((b"\xff\xfe", b"\xc3", b"\xed\xa0\x80", b"\x80abc")))
        if quote < 0:
            return b'{"' + bad + b'": 1}'
        return raw[: quote + 3] + bad + raw[quote + 3 :]
    if how == "truncate":
        return raw[: draw(st.integers(0, max(0, len(raw) - 1)))]
    if how == "random":
        return draw(st.binary(min_size=1, max_size=200))
    if how == "literal":
        key = draw(st.sampled_from(list(doc) if isinstance(doc, dict) and doc else ["x"]))
        lit = draw(st.sampled_from((b"NaN", b"Infinity", b"-Infinity", b"1e999", b"-1e999", b"0x10")))
        return b'{"' + key.encode("utf-8", "replace") + b'":' + lit + b"}"
    if how == "empty":
        return draw(st.sampled_from((b"", b" ", b"null", b"[]", b"0", b'""', b"HRPB")))
    if how == "bom":
        return b"\xef\xbb\xbf" + raw
    key = draw(st.sampled_from(list(doc) if isinstance(doc, dict) and doc else ["x"]))
    return b'{"' + key.encode("utf-8", "replace") + b'":' + b"1" * 5000 + b"}"


@st.composite
def binary_mutation(draw: st.DrawFn, doc: Any, array_fields: tuple[str, ...]) -> bytes:
    """A binary frame: one field (an array field if any) replaced by a reference into the blob."""
    blob_values = draw(st.sampled_from(("ok", "nan", "inf")))
    n = draw(st.sampled_from((1, 3, 39)))
    floats = [0.1] * n
    if blob_values == "nan":
        floats[-1] = float("nan")
    elif blob_values == "inf":
        floats[0] = float("-inf")
    blob = struct.pack(f"<{n}d", *floats)
    ref: dict[str, Any] = {"__nd__": [0, len(blob)], "dtype": "<f8", "shape": [n]}
    how = draw(
        st.sampled_from(
            ("none", "no_dtype", "no_shape", "dtype", "shape", "offset", "extra_key", "header_len", "nd")
        )
    )
    if how == "no_dtype":
        del ref["dtype"]
    elif how == "no_shape":
        del ref["shape"]
    elif how == "dtype":
        ref["dtype"] = draw(st.sampled_from(("<M8[s]", "O", "<U4", "|V8", "<c16", ">f8", "bogus", 5, "<f2")))
    elif how == "shape":
        ref["shape"] = draw(st.sampled_from(([-1], [10**12], [n, 2], "3", [1.5], [1] * 40, [n, 0])))
    elif how == "offset":
        ref["__nd__"] = draw(st.sampled_from(([len(blob), 8], [-8, 8], [0, 2**62], [0], "0", [0.5, 8])))
    elif how == "extra_key":
        ref["why"] = 1
    elif how == "nd":
        ref = {"__nd__": None}
    target = array_fields[0] if array_fields else None
    if isinstance(doc, dict):
        name = draw(st.sampled_from(array_fields or tuple(doc) or ("x",))) if target else "x"
        header = _dump({**doc, name: ref})
    else:
        header = _dump(ref)
    length = len(header)
    if how == "header_len":
        length = draw(st.sampled_from((len(header) + len(blob) + 1, 2**32 - 1, 0)))
    return MAGIC + struct.pack("<I", length) + header + blob


def array_fields_of(schema: dict[str, Any]) -> tuple[str, ...]:
    props = schema.get("properties", {})
    out = []
    for name, node in props.items():
        options = node.get("anyOf", [node])
        if any(_is_array(n) for n in options):
            out.append(name)
    return tuple(out)


def payloads(spec: EndpointSpec, q_ref: tuple[float, ...] = ()) -> st.SearchStrategy[tuple[str, bytes]]:
    """``(mutation kind, payload bytes)`` for ``spec``'s request (arrays near ``q_ref``, see
    :func:`array_lists`)."""
    schema = json_schema(spec.request)
    arrays = array_fields_of(schema)
    docs = strategy_for(schema, q_ref=q_ref)
    examples = [_fill(doc, q_ref) for doc in EXAMPLES.get(spec.path, [])]
    if examples:  # two draws in three from a realistic request, so that mutations reach the planners
        realistic = st.sampled_from(examples)
        docs = st.sampled_from((0, 1, 2)).flatmap(lambda i: docs if i == 0 else realistic)

    def mutate(kind: str) -> st.SearchStrategy[tuple[str, bytes]]:
        if kind == "valid":
            strategy = docs.map(_dump)
        elif kind == "leaf":
            strategy = docs.flatmap(leaf_mutation)
        elif kind == "unknown":
            strategy = docs.flatmap(unknown_field)
        elif kind == "bytes":
            strategy = docs.flatmap(byte_mutation)
        else:
            strategy = docs.flatmap(lambda d: binary_mutation(d, arrays))
        return strategy.map(lambda raw: (kind, raw))

    return st.sampled_from(MUTATIONS).flatmap(mutate)


# ---------------------------------------------------------------------------------------------- sending
#: Endpoints whose job includes answering ``internal`` on request (diag/raise with code "bug").
ASKED_FOR_INTERNAL = frozenset({"diag/raise"})

def reference_q(session: Any, robot: str) -> tuple[float, ...]:
    """The sim's current configuration (``()`` without a sim): arrays of valid payloads stay near it."""
    from services.bus.codec import decode
    from services.bus.schemas.sim import STATE, StateReply

    for reply in session.get(keys.key(robot, STATE.service, STATE.name), payload=b"{}", timeout=30.0):
        if reply.ok is not None:
            return tuple(float(x) for x in decode(reply.ok.payload.to_bytes(), StateReply).q)
    return ()


@dataclass
class Tally:
    """Counts of the answers, per endpoint, and the worst offenders (for the report)."""

    payloads: int = 0
    outcomes: Counter[str] = field(default_factory=Counter)
    by_endpoint: dict[str, Counter[str]] = field(default_factory=dict)
    by_mutation: Counter[str] = field(default_factory=Counter)
    failures: list[dict[str, Any]] = field(default_factory=list)
    #: The first few messages of each (endpoint, mutation, outcome): what the typed errors said.
    samples: dict[str, list[str]] = field(default_factory=dict)

    def add(self, spec: EndpointSpec, kind: str, raw: bytes, outcome: str, message: str) -> None:
        if outcome == "internal" and spec.path in ASKED_FOR_INTERNAL:
            outcome = "internal_asked"  # diag/raise {"code": "bug"}: the documented answer, not a bug
        self.payloads += 1
        self.outcomes[outcome] += 1
        self.by_mutation[kind] += 1
        self.by_endpoint.setdefault(spec.path, Counter())[outcome] += 1
        said = self.samples.setdefault(f"{spec.path} {kind} {outcome}", [])
        if len(said) < 3:
            said.append(message[:300])
        if outcome in ("internal", "no_reply", "bad_error") and len(self.failures) < 200:
            self.failures.append(
                {
                    "endpoint": spec.path,
                    "mutation": kind,
                    "outcome": outcome,
                    "message": message[:400],
                    "payload_head": raw[:300].decode("utf-8", "replace"),
                    "payload_bytes": len(raw),
                }
            )

    @property
    def typed_errors(self) -> int:
        untyped = ("ok", "internal", "no_reply", "bad_error")
        return sum(n for k, n in self.outcomes.items() if k not in untyped)


def send(session: Any, robot: str, spec: EndpointSpec, raw: bytes, timeout_s: float) -> tuple[str, str]:
    """Send ``raw`` to ``spec``; ``(outcome, message)``: ``ok``, an error code, ``no_reply`` or
    ``bad_error`` (an error reply that is not an ErrorInfo)."""
    key = keys.key(robot, spec.service, spec.name)
    for reply in session.get(key, payload=raw, timeout=timeout_s):
        if reply.ok is not None:
            return "ok", ""
        body = reply.err.payload.to_bytes()
        if body == b"Timeout":
            break
        try:
            info = msgspec.json.decode(body, type=ErrorInfo)
        except (msgspec.DecodeError, msgspec.ValidationError, UnicodeDecodeError):
            return "bad_error", body[:200].decode("utf-8", "replace")
        return info.code, info.message
    return "no_reply", f"no reply within {timeout_s:.0f} s"
