"""What Foxglove can read of the bus's messages: JSON Schemas its reader accepts, and the reader's rules.

Foxglove decodes a JSON channel of an MCAP log with the channel's JSON Schema, parsed by its
``parseJsonSchema`` (foxglove/studio ``packages/mcap-support/src/parseJsonSchema.ts``; the same rules in
its successors). Those rules, which :func:`schema_problems` checks and :func:`message_schema` obeys:

* every object schema has ``"type": "object"`` and a ``properties`` mapping (the root too);
* every property has a ``type`` among ``boolean``, ``string`` (no ``contentEncoding`` or ``base64``),
  ``number``, ``integer``, ``object`` (recursively) and ``array``; ``null``, a list of types, ``anyOf``
  and a missing type are rejected; ``oneOf`` only as numeric constants (an enum);
* an array's ``items`` is one schema whose ``type`` is ``boolean``, ``string`` (no contentEncoding),
  ``number``, ``integer`` or ``object``: an array of arrays is rejected.

So a message type becomes a schema with: ``Optional[T]`` as ``T`` (the value may be null, which
Foxglove shows as empty), a ``dict`` as an object without declared properties (its keys still show in
the raw message), a numpy array as :data:`ARRAY_SCHEMA` (the form :mod:`services.bus.mcaplog` writes
arrays in), and a list of lists as an array of ``{"values": [...]}`` objects (:data:`NESTED_KEY`, the
form the log writes nested lists in; :func:`nested_list_paths` says where).
"""

from __future__ import annotations

import functools
from typing import Any

import msgspec
import numpy as np

#: A numpy array in a log (:mod:`services.bus.logform`): dtype (numpy ``str``, e.g. ``<f8``), shape,
#: and either its bytes in base64 (``data``, in the byte ``layout`` named, none = C order) or its
#: values as numbers (``values``, flattened in C order; floats rounded to the channel's
#: ``hrp.decimals``).
ARRAY_SCHEMA: dict[str, Any] = {
    "type": "object",
    "description": "numpy array: base64 bytes (data, in the given layout) or numbers (values, C order)",
    "properties": {
        "dtype": {"type": "string"},
        "shape": {"type": "array", "items": {"type": "integer"}},
        "layout": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"},
        "values": {"type": "array", "items": {"type": "number"}},
    },
}
#: The key under which each inner list of a list of lists is kept in a log (``[[1, 2]]`` ->
#: ``[{"values": [1, 2]}]``): Foxglove's reader has no arrays of arrays.
NESTED_KEY = "values"

_SCALARS = ("boolean", "string", "number", "integer")
_ITEM_TYPES = (*_SCALARS, "object")


def _hook(type_: Any) -> dict[str, Any]:
    if type_ is np.ndarray:
        return {"x-hrp-ndarray": True}
    raise NotImplementedError(f"no JSON schema for {type_!r}")


@functools.lru_cache(maxsize=512)
def message_schema(type_: Any) -> dict[str, Any]:
    """The JSON Schema of message type ``type_`` that Foxglove's reader accepts (see the module doc)."""
    schema = msgspec.json.schema(type_, schema_hook=_hook)
    defs = schema.pop("$defs", {})
    out = _convert(schema, defs, ())
    if out.get("type") != "object":  # a message is an object; anything else is wrapped
        out = {"type": "object", "properties": {"value": out}}
    title = getattr(type_, "__name__", "")
    return {"title": title, **out} if title else out


def _convert(node: Any, defs: dict[str, Any], seen: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(node, dict):
        return {"type": "object", "properties": {}}
    ref = node.get("$ref")
    if isinstance(ref, str):
        name = ref.rsplit("/", 1)[-1]
        if name in seen or name not in defs:  # a recursive type: an open object
            return {"type": "object", "properties": {}, "title": name}
        return _convert(defs[name], defs, (*seen, name))
    doc = {k: node[k] for k in ("title", "description") if isinstance(node.get(k), str)}
    if node.get("x-hrp-ndarray"):
        return dict(ARRAY_SCHEMA)
    for union in ("anyOf", "oneOf"):
        if isinstance(node.get(union), list):
            options = [o for o in node[union] if not (isinstance(o, dict) and o.get("type") == "null")]
            return {**doc, **_convert(options[0] if options else {}, defs, seen)}
    kind = node.get("type")
    if isinstance(kind, list):  # ["number", "null"]
        kinds = [k for k in kind if k != "null"]
        return _convert({**node, "type": kinds[0] if kinds else "string"}, defs, seen)
    if "enum" in node and kind is None:
        values = node["enum"]
        kind = (
            "integer" if all(isinstance(v, int) for v in values)
            else "number" if all(isinstance(v, int | float) for v in values)
            else "string"
        )  # fmt: skip
    if kind in _SCALARS:
        return {**doc, "type": kind}
    if kind == "array":
        items = node.get("items")
        if items is None and isinstance(node.get("prefixItems"), list) and node["prefixItems"]:
            items = node["prefixItems"][0]  # a tuple: typed by its first element
        item = _convert(items if items is not None else {"type": "string"}, defs, seen)
        if item.get("type") == "array":  # a list of lists: lists of {"values": [...]}
            item = {"type": "object", "properties": {NESTED_KEY: item}}
        return {**doc, "type": "array", "items": item}
    if kind == "object" or "properties" in node or "additionalProperties" in node or not node:
        props = node.get("properties", {}) if isinstance(node.get("properties"), dict) else {}
        return {
            **doc,
            "type": "object",
            "properties": {name: _convert(sub, defs, seen) for name, sub in props.items()},
        }
    return {**doc, "type": "string"}


@functools.lru_cache(maxsize=512)
def nested_list_paths(type_: Any) -> tuple[tuple[str, ...], ...]:
    """Where ``type_``'s messages hold lists of lists, as field paths (``"[]"`` steps into a list's
    items): the log writes each inner list there as ``{"values": [...]}``. Empty for most types."""
    found: list[tuple[str, ...]] = []

    def walk(node: dict[str, Any], path: tuple[str, ...]) -> None:
        kind = node.get("type")
        if kind == "object":
            for name, sub in node.get("properties", {}).items():
                walk(sub, (*path, name))
        elif kind == "array":
            item = node["items"]
            props = item.get("properties", {})
            if (
                item.get("type") == "object"
                and list(props) == [NESTED_KEY]
                and props[NESTED_KEY].get("type") == "array"
            ):
                found.append(path)
            walk(item, (*path, "[]"))

    walk(message_schema(type_), ())
    return tuple(found)


def schema_problems(schema: Any, name: str = "") -> list[str]:
    """Why Foxglove's JSON-schema reader would reject ``schema`` (the rules of the module doc); [] if
    it accepts it. Each problem names the field path."""
    problems: list[str] = []

    def obj(node: Any, path: str) -> None:
        if not isinstance(node, dict) or node.get("type") != "object":
            problems.append(f'{path or "(root)"}: expected "type": "object"')
            return
        props = node.get("properties")
        if not isinstance(props, dict):
            problems.append(f'{path or "(root)"}: an object needs a "properties" mapping')
            return
        for field, sub in props.items():
            where = f"{path}.{field}" if path else field
            if not isinstance(sub, dict):
                problems.append(f"{where}: not a schema")
                continue
            if isinstance(sub.get("oneOf"), list):
                options = sub["oneOf"]
                numbers = [isinstance(o, dict) and isinstance(o.get("const"), int | float) for o in options]
                if not all(numbers):
                    problems.append(f"{where}: oneOf alternatives must have number values")
                continue
            kind = sub.get("type")
            if kind == "string":
                if sub.get("contentEncoding") not in (None, "base64"):
                    problems.append(f"{where}: unsupported contentEncoding {sub.get('contentEncoding')!r}")
            elif kind in ("boolean", "number", "integer"):
                pass
            elif kind == "object":
                obj(sub, where)
            elif kind == "array":
                item = sub.get("items")
                item_kind = item.get("type") if isinstance(item, dict) else None
                if item_kind not in _ITEM_TYPES:
                    problems.append(f"{where}: unsupported type {item_kind!r} for array items")
                elif item_kind == "string" and item.get("contentEncoding") is not None:
                    problems.append(f"{where}: unsupported contentEncoding for array items")
                elif item_kind == "object":
                    obj(item, f"{where}[]")
            else:
                problems.append(f"{where}: unsupported type {kind!r}")

    obj(schema, "")
    return [f"{name}: {p}" for p in problems] if name else problems
