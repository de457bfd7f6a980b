"""What the schemas say about each message field: type, default, units, limits, description.

The schema modules document a field with a trailing comment (``x: float = 0.5  # forward [m]``) and
may constrain it with ``Annotated[float, msgspec.Meta(ge=0)]``. This module reads both, for
``humanoid interface`` and ``humanoid list``: the comments from the class's source (tokenize), the
constraints from :func:`msgspec.inspect.type_info`. Nested structs are expanded once.
"""

from __future__ import annotations

import inspect
import io
import re
import tokenize
from dataclasses import dataclass
from functools import cache
from typing import Any

import msgspec

from services.bus.spec import EndpointSpec, TopicSpec

#: ``[m]``, ``[rad/s]``, ``[m, m, rad]``: units in brackets inside a field comment.
_BRACKETS = re.compile(r"\[([^\[\]]{1,24})\]")
_UNIT_WORDS = {"m", "s", "rad", "n", "px", "kg", "hz", "deg", "b", "nm", "%", "mm", "cm", "ms", "-", "1"}
#: Field-name suffixes that carry the unit (CONVENTIONS: units in names).
_SUFFIX_UNITS = {
    "_s": "s",
    "_m": "m",
    "_rad": "rad",
    "_deg": "deg",
    "_n": "N",
    "_kg": "kg",
    "_px": "px",
    "_hz": "Hz",
    "_mm": "mm",
    "_ms": "ms",
    "_b": "B",
    "_nm": "N m",
}


def _is_unit(text: str) -> bool:
    """``m``, ``rad/s``, ``m, m, rad``, ``m/s^2``: every comma-separated part made of known units."""
    for part in text.split(","):
        tokens = re.split(r"[/*·^ ]+", part.strip().lower())
        if not all(t in _UNIT_WORDS or t.isdigit() for t in tokens if t) or not any(
            t in _UNIT_WORDS for t in tokens
        ):
            return False
    return True


def units_of(name: str, comment: str) -> str:
    """The units of a field: the last bracket of its comment that holds units, else its name's suffix."""
    found = list(dict.fromkeys(m.group(1) for m in _BRACKETS.finditer(comment) if _is_unit(m.group(1))))
    if found:
        return " or ".join(found)  # "[m] reach/gaze, [rad] posture": m or rad
    for suffix, unit in _SUFFIX_UNITS.items():
        if name.endswith(suffix):
            return unit
    return ""


_LIMIT_NAMES = (
    ("ge", ">="),
    ("gt", ">"),
    ("le", "<="),
    ("lt", "<"),
    ("min_length", "len >="),
    ("max_length", "len <="),
)


@dataclass(frozen=True)
class FieldInfo:
    """One field of a message, as ``humanoid interface`` prints it.

    ``path`` is dotted for nested structs (``collisions[].robot_link``); ``default`` is the JSON text of
    the default, or ``"required"``.
    """

    path: str
    type: str
    default: str
    units: str
    limits: str
    doc: str
    depth: int


def type_text(t: Any) -> str:
    """A short type name: ``float``, ``list[float]``, ``array``, ``Contact``, ``int | None``."""
    text = getattr(t, "__name__", None) if not hasattr(t, "__args__") else None
    text = text or str(t).replace("typing.", "")
    text = re.sub(r"\b[a-z_]+\.(?:[a-z_]+\.)*([A-Z]\w*)", r"\1", text)
    text = re.sub(r"Annotated\[([^,\]]+), [^\]]*\]", r"\1", text)
    return text.replace("numpy.ndarray", "array").replace("NoneType", "None").replace("ndarray", "array")


@cache
def field_comments(struct: type) -> dict[str, str]:
    """``{field: trailing comment}`` from the struct's source (empty when the source is not there)."""
    try:
        source = inspect.getsource(struct)
    except (OSError, TypeError):
        return {}
    comments: dict[str, str] = {}
    pending: list[str] = []  # comment lines above a field document it too
    names = set(struct.__struct_fields__)
    line_field: dict[int, str] = {}
    for line_no, line in enumerate(source.splitlines(), start=1):
        match = re.match(r"\s+([a-z_][a-z0-9_]*)\s*:", line)
        if match and match.group(1) in names:
            line_field[line_no] = match.group(1)
    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(source).readline))
    except (tokenize.TokenError, SyntaxError):
        return {}
    last_field = ""  # the field whose trailing comment a "#   ..." line continues
    for tok in tokens:
        if tok.type == tokenize.NAME and line_field.get(tok.start[0]) == tok.string:
            last_field = ""  # a field without a trailing comment ends any continuation
        if tok.type != tokenize.COMMENT:
            continue
        text = tok.string.lstrip("#").strip()
        row = tok.start[0]
        if row in line_field:
            comments[line_field[row]] = " ".join([*pending, text]).strip()
            last_field = line_field[row]
            pending = []
        elif tok.line.strip().startswith("#") and re.match(r"#\s{2,}", tok.string) and last_field:
            comments[last_field] = f"{comments.get(last_field, '')} {text}".strip()  # a continuation
        elif tok.line.strip().startswith("#"):
            pending.append(text)
            if row + 1 in line_field and line_field[row + 1] not in comments:
                comments[line_field[row + 1]] = " ".join(pending)
                pending = []
        else:
            pending = []
    return comments


def _unwrap(info: Any) -> tuple[Any, str]:
    """The type inside ``Annotated[..., Meta(...)]`` wrappers, and the first description they give."""
    description = ""
    while isinstance(info, msgspec.inspect.Metadata):
        description = description or (info.extra_json_schema or {}).get("description", "")
        info = info.type
    return info, description


def info_text(info: Any) -> str:
    """A short type name from msgspec's type info: ``float``, ``list[float]``, ``Contact | None``."""
    import numpy as np

    info, _ = _unwrap(info)
    ins = msgspec.inspect
    simple = {
        ins.FloatType: "float",
        ins.IntType: "int",
        ins.StrType: "str",
        ins.BoolType: "bool",
        ins.NoneType: "None",
        ins.AnyType: "any",
        ins.BytesType: "bytes",
    }
    for kind, text in simple.items():
        if isinstance(info, kind):
            return text
    if isinstance(info, ins.ListType | ins.SetType | ins.FrozenSetType):
        return f"{type(info).__name__.removesuffix('Type').lower()}[{info_text(info.item_type)}]"
    if isinstance(info, ins.VarTupleType):
        return f"tuple[{info_text(info.item_type)}, ...]"
    if isinstance(info, ins.TupleType):
        return f"tuple[{', '.join(info_text(t) for t in info.item_types)}]"
    if isinstance(info, ins.DictType):
        return f"dict[{info_text(info.key_type)}, {info_text(info.value_type)}]"
    if isinstance(info, ins.UnionType):
        return " | ".join(info_text(t) for t in info.types)
    if isinstance(info, ins.LiteralType):
        return " | ".join(repr(v) for v in info.values)
    if isinstance(info, ins.StructType | ins.EnumType | ins.DataclassType):
        return info.cls.__name__
    if isinstance(info, ins.CustomType):
        return "array" if info.cls is np.ndarray else info.cls.__name__
    return type(info).__name__.removesuffix("Type").lower()


def _limits(info: Any) -> str:
    """``>= 0, <= 2.5``, ``len == 3``, ``each >= -100, <= 100`` from msgspec constraints."""
    info, _ = _unwrap(info)
    parts = []
    low, high = getattr(info, "min_length", None), getattr(info, "max_length", None)
    if low is not None and low == high:
        parts.append(f"len == {low}")
    for attr, sign in _LIMIT_NAMES:
        if attr in ("min_length", "max_length") and low is not None and low == high:
            continue
        value = getattr(info, attr, None)
        if value is not None:
            parts.append(f"{sign} {value:g}" if isinstance(value, float) else f"{sign} {value}")
    if isinstance(info, msgspec.inspect.UnionType):
        for member in info.types:
            text = _limits(member)
            if text:
                parts.append(text)
    item = getattr(info, "item_type", None)
    if item is not None:
        text = _limits(item)
        if text:
            parts.append(f"each {text}")
    return ", ".join(parts)


def _nested_struct(info: Any) -> tuple[type | None, str]:
    """The struct type inside a field (itself, list items, dict values, optional) and the path suffix."""
    info, _ = _unwrap(info)
    if isinstance(info, msgspec.inspect.StructType):
        return info.cls, ""
    if isinstance(info, msgspec.inspect.ListType | msgspec.inspect.TupleType | msgspec.inspect.VarTupleType):
        item, _ = _unwrap(getattr(info, "item_type", None))
        if isinstance(item, msgspec.inspect.StructType):
            return item.cls, "[]"
    if isinstance(info, msgspec.inspect.DictType):
        value, _ = _unwrap(info.value_type)
        if isinstance(value, msgspec.inspect.StructType):
            return value.cls, "{}"
    if isinstance(info, msgspec.inspect.UnionType):
        for member in info.types:
            cls, suffix = _nested_struct(member)
            if cls is not None:
                return cls, suffix
    return None, ""


def _default_text(field: Any) -> str:
    import json

    if field.required:
        return "required"
    default = field.default if field.default is not msgspec.NODEFAULT else field.default_factory()
    try:
        return json.dumps(default)
    except TypeError:
        return repr(default)


def struct_fields(
    struct: type, prefix: str = "", depth: int = 0, seen: tuple[type, ...] = ()
) -> list[FieldInfo]:
    """Every field of ``struct``, nested structs expanded below their field (recursion cut)."""
    try:
        info = msgspec.inspect.type_info(struct)
    except TypeError:
        info = None
    inspected = {f.name: f for f in info.fields} if isinstance(info, msgspec.inspect.StructType) else {}
    comments = field_comments(struct)
    hints = msgspec.structs.fields(struct)
    out: list[FieldInfo] = []
    for field in hints:
        f_info = inspected.get(field.name)
        described = _unwrap(f_info.type)[1] if f_info is not None else ""
        comment = comments.get(field.name, "") or described
        limits = _limits(f_info.type) if f_info is not None else ""
        out.append(
            FieldInfo(
                path=prefix + field.name,
                type=info_text(f_info.type) if f_info is not None else type_text(field.type),
                default=_default_text(field),
                units=units_of(field.name, comment),
                limits=limits,
                doc=comment,
                depth=depth,
            )
        )
        if f_info is not None:
            nested, suffix = _nested_struct(f_info.type)
            if nested is not None and nested not in seen and nested is not struct:
                out += struct_fields(nested, f"{prefix}{field.name}{suffix}.", depth + 1, (*seen, struct))
    return out


def struct_doc(struct: type) -> str:
    """The first paragraph of a struct's docstring, on one line."""
    own = struct.__dict__.get("__doc__")  # not the docstring msgspec.Struct would lend it
    doc = inspect.cleandoc(own) if isinstance(own, str) else ""
    return " ".join(doc.split("\n\n")[0].split())


def describe(spec: EndpointSpec | TopicSpec) -> dict[str, Any]:
    """A JSON-ready description of an endpoint (request, reply) or a topic (message)."""
    import dataclasses

    def part(struct: type) -> dict[str, Any]:
        return {
            "type": struct.__name__,
            "doc": struct_doc(struct),
            "fields": [dataclasses.asdict(f) for f in struct_fields(struct)],
        }

    if isinstance(spec, EndpointSpec):
        return {
            "name": spec.path,
            "kind": "endpoint",
            "service": spec.service,
            "doc": spec.doc,
            "request": part(spec.request),
            "reply": part(spec.reply),
        }
    return {
        "name": spec.path,
        "kind": "topic",
        "service": spec.service,
        "doc": spec.doc,
        "message": part(spec.message),
    }


def message_types() -> dict[str, type]:
    """Every message type of the schemas by ``<service>.<Type>`` (request, reply, topic message)."""
    from services.bus import schemas

    found: dict[str, type] = {}
    for spec in schemas.endpoints().values():
        found[f"{spec.service}.{spec.request.__name__}"] = spec.request
        found[f"{spec.service}.{spec.reply.__name__}"] = spec.reply
    for spec in schemas.topics().values():
        found[f"{spec.service}.{spec.message.__name__}"] = spec.message
    return found


def describe_type(qualified: str, struct: type) -> dict[str, Any]:
    """A JSON-ready description of one message type (``humanoid interface walking.PlanRequest``)."""
    import dataclasses

    return {
        "name": qualified,
        "kind": "message type",
        "service": qualified.split(".", 1)[0],
        "doc": struct_doc(struct),
        "message": {
            "type": struct.__name__,
            "doc": struct_doc(struct),
            "fields": [dataclasses.asdict(f) for f in struct_fields(struct)],
        },
    }
