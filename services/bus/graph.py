"""Who serves, publishes, calls and subscribes to what: the graph of ``humanoid graph``.

What a service serves and publishes is in the schemas (each spec names its service). What it calls
and subscribes to is read from its package's source with :mod:`ast`: a reference to another
service's endpoint spec is a call, to another service's topic spec a subscription (the specs are the
only way the stack addresses the bus, so this finds every use without running anything). Nothing
here imports a service package.
"""

from __future__ import annotations

import ast
import importlib
from dataclasses import dataclass, field
from pathlib import Path

from services.bus import schemas
from services.bus.discovery import RECORDER, discover, repo_root
from services.bus.spec import EndpointSpec, TopicSpec

#: Packages that use the bus without being started by ``humanoid up``: name -> folder.
CLIENT_PACKAGES = {"supervisor": "supervisor"}
_SCHEMA_PACKAGE = "services.bus.schemas"
#: What a subscriber to every key (``keys.everything``) subscribes to, in the graph.
EVERYTHING = "**"


@dataclass
class Node:
    """One service (or client package) and its edges, each a ``service/name`` path."""

    name: str
    module: str = ""
    serves: list[str] = field(default_factory=list)
    publishes: list[str] = field(default_factory=list)
    calls: list[str] = field(default_factory=list)
    subscribes: list[str] = field(default_factory=list)
    alive: bool | None = None  # None: not asked


def _package_files(path: Path, root: Path) -> list[Path]:
    """The files of the package a service file belongs to (diag is one file of services/bus)."""
    if path.parent == root / "services" / "bus":
        return [path]
    return sorted(path.parent.rglob("*.py"))


def _spec_references(files: list[Path]) -> set[str]:
    """``service/name`` of every spec the files refer to (``msg.LOCATE``, ``from ... import LOCATE``)."""
    found: set[str] = set()
    for path in files:
        try:
            tree = ast.parse(path.read_text(), filename=str(path))
        except (SyntaxError, UnicodeDecodeError):
            continue
        aliases: dict[str, str] = {}  # local name -> schema module
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                if node.module == _SCHEMA_PACKAGE:
                    for a in node.names:
                        aliases[a.asname or a.name] = f"{_SCHEMA_PACKAGE}.{a.name}"
                elif node.module.startswith(_SCHEMA_PACKAGE + "."):
                    module = importlib.import_module(node.module)
                    for a in node.names:
                        value = getattr(module, a.name, None)
                        if isinstance(value, EndpointSpec | TopicSpec):
                            found.add(value.path)
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.startswith(_SCHEMA_PACKAGE + ".") and a.asname:
                        aliases[a.asname] = a.name
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):  # keys.everything(robot): a subscriber to all of hrp/**
                func = node.func
                name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
                if name == "everything":
                    found.add(EVERYTHING)
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
                module_name = aliases.get(node.value.id)
                if module_name is None:
                    continue
                try:
                    module = importlib.import_module(module_name)
                except ImportError:
                    continue
                value = getattr(module, node.attr, None)
                if isinstance(value, EndpointSpec | TopicSpec):
                    found.add(value.path)
    return found


def build_graph(alive: set[str] | None = None) -> dict[str, Node]:
    """Every service found by discovery plus the client packages; ``alive`` marks the live ones."""
    root = repo_root()
    endpoints, topics = schemas.endpoints(), schemas.topics()
    entries, _problems = discover(root)
    nodes: dict[str, Node] = {}
    sources: dict[str, list[Path]] = {}
    for name, entry in sorted(entries.items()):
        nodes[name] = Node(name, entry.module)
        sources[name] = _package_files(entry.path, root)
    for name, folder in CLIENT_PACKAGES.items():
        nodes.setdefault(name, Node(name, folder))
        sources[name] = sorted((root / folder).rglob("*.py"))
    owners = {spec.service for spec in [*endpoints.values(), *topics.values()]}
    for owner in sorted(owners - set(nodes)):  # e.g. the launcher: publishes only
        nodes[owner] = Node(owner)
    for spec in endpoints.values():
        nodes[spec.service].serves.append(spec.path)
    for spec in topics.values():
        nodes[spec.service].publishes.append(spec.path)
    for name, files in sources.items():
        references = _spec_references(files)
        if name == RECORDER or EVERYTHING in references:  # the recorder's key comes from its config
            nodes[name].subscribes.append(EVERYTHING)
        for path in sorted(references - {EVERYTHING}):
            if path in endpoints and endpoints[path].service != name:
                nodes[name].calls.append(path)
            elif path in topics and topics[path].service != name:
                nodes[name].subscribes.append(path)
    for node in nodes.values():
        for items in (node.serves, node.publishes, node.calls, node.subscribes):
            items.sort()
        if alive is not None and node.name in entries:  # the others declare no liveliness token
            node.alive = node.name in alive
    return nodes


def to_text(nodes: dict[str, Node]) -> str:
    lines = []
    for node in nodes.values():
        state = "" if node.alive is None else ("  (alive)" if node.alive else "  (not running)")
        lines.append(f"{node.name}{state}")
        for label, items in (
            ("serves", node.serves),
            ("publishes", node.publishes),
            ("calls", node.calls),
            ("subscribes", node.subscribes),
        ):
            if items:
                lines.append(f"  {label:<11}{', '.join(items)}")
    return "\n".join(lines)


def _edges(nodes: dict[str, Node]) -> list[tuple[str, str, str, str]]:
    """``(from, to, label, kind)``: calls go caller -> server, topics publisher -> subscriber."""
    topics = schemas.topics()
    edges = []
    for node in nodes.values():
        for path in node.calls:
            edges.append((node.name, path.split("/", 1)[0], path.split("/", 1)[1], "call"))
        for path in node.subscribes:
            if path == EVERYTHING:
                continue
            edges.append((topics[path].service, node.name, path.split("/", 1)[1], "topic"))
    return edges


def to_mermaid(nodes: dict[str, Node]) -> str:
    """A Mermaid flowchart: solid arrows are calls (caller -> server), dotted ones topics."""
    lines = ["flowchart LR"]
    for node in nodes.values():
        served = "<br/>".join(p.split("/", 1)[1] for p in node.serves)
        label = f"{node.name}<br/><small>{served}</small>" if served else node.name
        lines.append(f'  {node.name}["{label}"]')
    for a, b, label, kind in _edges(nodes):
        lines.append(f"  {a} -->|{label}| {b}" if kind == "call" else f"  {a} -.->|{label}| {b}")
    for node in nodes.values():
        if EVERYTHING in node.subscribes:
            lines.append(f"  bus((hrp/**)) -.-> {node.name}")
    return "\n".join(lines) + "\n"


def to_dot(nodes: dict[str, Node]) -> str:
    """A Graphviz digraph: solid edges are calls, dashed ones topics."""
    lines = ["digraph humanoid {", "  rankdir=LR;", "  node [shape=box, fontname=Helvetica];"]
    for node in nodes.values():
        served = "\\n".join(p.split("/", 1)[1] for p in node.serves)
        label = f"{node.name}\\n{served}" if served else node.name
        lines.append(f'  "{node.name}" [label="{label}"];')
    for a, b, label, kind in _edges(nodes):
        style = "solid" if kind == "call" else "dashed"
        lines.append(f'  "{a}" -> "{b}" [label="{label}", style={style}];')
    lines.append("}")
    return "\n".join(lines) + "\n"
