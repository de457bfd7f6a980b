"""Looking inside frames without knowing their type: for ``humanoid echo`` and the recorder's views.

A frame is one of (see :mod:`services.bus.codec`):

* ``json``: a plain JSON document;
* ``hrpb``: a binary frame, a JSON header whose arrays point into a blob section;
* ``octets``: anything else (a malformed request, an empty payload).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np

from services.bus.codec import MAGIC, split

_ND_KEY = "__nd__"
#: JSON documents up to this size are parsed to decide their kind; larger ones are judged by their ends.
_VALIDATE_LIMIT = 1 << 16


def frame_kind(data: bytes | memoryview) -> str:
    """``json``, ``hrpb`` or ``octets``."""
    view = memoryview(data)
    if len(view) >= 8 and bytes(view[:4]) == MAGIC:
        return "hrpb"
    if len(view) == 0:
        return "octets"
    if len(view) <= _VALIDATE_LIMIT:
        try:
            msgspec.json.decode(view)
            return "json"
        except (msgspec.DecodeError, UnicodeDecodeError):  # a string with bytes that are not UTF-8
            return "octets"
    first, last = bytes(view[:1]), bytes(view[-1:])
    return "json" if (first, last) in ((b"{", b"}"), (b"[", b"]")) else "octets"


@dataclass(frozen=True)
class ArrayRef:
    """An array inside a binary frame: where its bytes are and what they hold."""

    path: str  # field path in the message, e.g. "left" or "images/0"
    dtype: np.dtype
    shape: tuple[int, ...]
    data: memoryview  # the raw bytes, C order

    def array(self) -> np.ndarray:
        return np.frombuffer(self.data, dtype=self.dtype).reshape(self.shape)


def parse_frame(data: bytes | memoryview) -> tuple[Any, list[ArrayRef]]:
    """The JSON header of a frame (arrays still as references) and the arrays it points to."""
    header, blob = split(data)
    doc = msgspec.json.decode(header)
    refs: list[ArrayRef] = []
    if blob is not None:
        _collect(doc, "", blob, refs)
    return doc, refs


def _is_ref(node: Any) -> bool:
    return isinstance(node, dict) and _ND_KEY in node and "dtype" in node and "shape" in node


def _collect(node: Any, path: str, blob: memoryview, refs: list[ArrayRef]) -> None:
    if _is_ref(node):
        offset, nbytes = node[_ND_KEY]
        if offset < 0 or offset + nbytes > len(blob):
            raise ValueError(f"array {path or '/'} points outside the frame")
        refs.append(
            ArrayRef(path, np.dtype(node["dtype"]), tuple(node["shape"]), blob[offset : offset + nbytes])
        )
    elif isinstance(node, dict):
        for key, value in node.items():
            _collect(value, f"{path}/{key}" if path else str(key), blob, refs)
    elif isinstance(node, list):
        for i, value in enumerate(node):
            _collect(value, f"{path}/{i}" if path else str(i), blob, refs)


def replace_arrays(doc: Any, replace: Callable[[str, dict[str, Any]], Any], path: str = "") -> Any:
    """A copy of a parsed header where every array reference is replaced by ``replace(path, ref)``."""
    if _is_ref(doc):
        return replace(path, doc)
    if isinstance(doc, dict):
        return {k: replace_arrays(v, replace, f"{path}/{k}" if path else str(k)) for k, v in doc.items()}
    if isinstance(doc, list):
        return [replace_arrays(v, replace, f"{path}/{i}" if path else str(i)) for i, v in enumerate(doc)]
    return doc


def summarize(data: bytes | memoryview, max_octets: int = 32) -> Any:
    """A printable view: JSON as is, arrays as ``<ndarray uint8 (480, 640, 3)>``, other bytes as hex."""
    kind = frame_kind(data)
    if kind == "octets":
        raw = bytes(memoryview(data)[:max_octets])
        more = "..." if len(data) > max_octets else ""
        return f"<{len(data)} bytes: {raw.hex()}{more}>"
    try:
        doc, _ = parse_frame(data)
    except (msgspec.DecodeError, ValueError) as exc:
        return f"<{len(data)} bytes of malformed {kind}: {exc}>"
    return replace_arrays(doc, lambda _path, ref: f"<ndarray {np.dtype(ref['dtype'])} {tuple(ref['shape'])}>")
