"""The package layering, read from the source's imports with :mod:`ast` (nothing is imported).

CONVENTIONS §1-2 and issue #15: the supervisor imports only the bus, its schemas, ``services.errors``
and its own modules (it calls the planners over the bus); the pure algorithm packages never import
zenoh, not even through another module (only each service's ``service.py`` adapter does, through
``services.bus.service``); no planner loads pybullet when imported (only the sim executes; a planner
that drives the sim for a command or a study imports it inside that function); the service packages
stand in a declared order, the robot model at the bottom, and no package imports one above it or
beside it. Every import counts, at module level or inside a function, except for the pybullet rule
(module level only).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("services", "supervisor", "sim", "vision")
"""Top-level folders whose modules are read."""

LAYERS: tuple[tuple[str, ...], ...] = (
    ("services.model",),
    ("services.ik", "services.collision", "sim", "vision"),
    ("services.walking", "services.perception"),
    ("services.navigation", "services.reaching"),
    ("services.footsteps",),
    ("services.contacts",),
    ("services.viz",),
)
"""The service packages, lowest first: a package imports only packages of lower rows. The robot model
at the bottom; the shared obstacles and 3D motion check (``services.collision``) below walking and
navigation; walking (the two-stage API) below navigation and reaching; footsteps above reaching (it
executes with reaching's spline); contacts above footsteps and the sim (the scenes it plans in)."""

FOUNDATION = ("services", "services.bus", "services.errors", "services.budget", "services.cli_common")
"""What any package may import: the root package (a docstring), the bus (schemas, limits, the service
base), errors, budgets and the command-line helpers. None of it imports a package of :data:`LAYERS` at
module level."""

EXCEPTIONS: dict[tuple[str, str], str] = {
    ("vision.cli", "services.perception"): (
        "`humanoid perception learn-sim` is registered by vision's command group; the command learns "
        "the colour models from sim renders (imported inside the function building the parser)"
    ),
}
"""Imports against the order, each with its reason: (importing module, imported package)."""

ALGORITHM_PACKAGES = (
    "services.model",
    "services.ik",
    "services.collision",
    "services.walking",
    "services.footsteps",
    "services.reaching",
    "services.navigation",
    "services.contacts",
    "services.perception",
    "vision",
)
"""Packages whose modules, except the ``service.py`` adapter, never reach zenoh."""

PYBULLET_ADAPTERS = ("services.model.pybullet_robot",)
"""The model's URDF loaded in pybullet, for the sim: the one algorithm-package module that imports it
(nothing else imports it at module level: the rule follows the chains through it)."""

SUPERVISOR_MAY_IMPORT = ("supervisor", "services", "services.bus", "services.errors")
"""The root package runs on the way to the bus; ``services.budget`` and the rest are not here."""


@dataclass(frozen=True)
class Import:
    """``module`` imports ``target`` (a module of the scanned tree, or ``zenoh``) at ``line``, inside a
    function when ``lazy``."""

    module: str
    target: str
    line: int
    lazy: bool


def module_name(path: Path) -> str:
    """``services/walking/sweep.py`` -> ``services.walking.sweep``; a package's ``__init__``: the package."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def package_of(module: str) -> str:
    """The package a module belongs to: ``services.X`` for ``services.X.*``, else the top-level name."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "services" and len(parts) > 1 else parts[0]


EXTERNAL = ("zenoh", "pybullet")
"""Outside packages whose imports are followed."""


def _resolve(name: str, modules: set[str]) -> str | None:
    """The longest prefix of the dotted ``name`` that is a scanned module (or one of :data:`EXTERNAL`)."""
    top = name.split(".")[0]
    if top in EXTERNAL:
        return top
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        candidate = ".".join(parts[:k])
        if candidate in modules:
            return candidate
    return None


def read_imports(root: Path = ROOT) -> dict[str, list[Import]]:
    """Every module of :data:`SCANNED` -> its imports of scanned modules and of :data:`EXTERNAL`.

    ``from a.b import c`` imports ``a.b.c`` when that is a module, else ``a.b``; importing ``a.b.c``
    also runs the packages ``a`` and ``a.b`` (their ``__init__``)."""
    files = {module_name(p): p for top in SCANNED for p in sorted((root / top).rglob("*.py"))}
    modules = set(files)
    graph: dict[str, list[Import]] = {}
    for module, path in files.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        lazy_lines = {
            n.lineno
            for f in ast.walk(tree)
            if isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef)
            for n in ast.walk(f)
            if isinstance(n, ast.Import | ast.ImportFrom)
        }
        found: list[Import] = []
        for node in ast.walk(tree):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [f"{node.module}.{a.name}" for a in node.names]
            for name in names:
                target = _resolve(name, modules)
                if target is None:
                    continue
                lazy = node.lineno in lazy_lines
                parents = target.split(".")
                for k in range(1, len(parents)):  # the packages the import runs on the way
                    if ".".join(parents[:k]) in modules:
                        found.append(Import(module, ".".join(parents[:k]), node.lineno, lazy))
                found.append(Import(module, target, node.lineno, lazy))
        graph[module] = found
    return graph


def order_violations(
    graph: dict[str, list[Import]],
    layers: tuple[tuple[str, ...], ...] = LAYERS,
    exceptions: dict[tuple[str, str], str] | None = None,
) -> list[str]:
    """Imports of a package of ``layers`` by one in the same row or a lower one, as readable lines."""
    exceptions = EXCEPTIONS if exceptions is None else exceptions
    rank = {package: row for row, packages in enumerate(layers) for package in packages}
    out = []
    for module, imports in graph.items():
        source = package_of(module)
        if source not in rank:
            continue
        for imp in imports:
            target = package_of(imp.target)
            if target == source or target not in rank or (module, target) in exceptions:
                continue
            if rank[target] >= rank[source]:
                out.append(f"{module}:{imp.line} imports {imp.target} ({target} is not below {source})")
    return out


def reaching(
    graph: dict[str, list[Import]], external: str, module_level: bool = False
) -> dict[str, list[str]]:
    """Every module that imports ``external``, directly or through other modules (``module_level``: by
    imports at module level only, what importing the module loads) -> one such chain."""
    chains: dict[str, list[str]] = {}
    counted = {m: [i for i in imports if not (module_level and i.lazy)] for m, imports in graph.items()}
    frontier = [m for m, imports in counted.items() if any(i.target == external for i in imports)]
    for m in frontier:
        chains[m] = [m, external]
    importers: dict[str, set[str]] = {}
    for m, imports in counted.items():
        for i in imports:
            importers.setdefault(i.target, set()).add(m)
    while frontier:
        nxt = []
        for m in frontier:
            for user in sorted(importers.get(m, ())):
                if user not in chains:
                    chains[user] = [user, *chains[m]]
                    nxt.append(user)
        frontier = nxt
    return chains


@pytest.fixture(scope="module")
def graph() -> dict[str, list[Import]]:
    return read_imports()


def test_the_scan_reads_the_tree(graph):
    """The scan sees the packages and a known import (walking's legs sweep uses the shared checker)."""
    packages = {package_of(m) for m in graph}
    for row in LAYERS:
        assert set(row) <= packages
    assert "services.collision.motion" in {i.target for i in graph["services.walking.sweep"]}
    assert "zenoh" in {i.target for i in graph["services.bus.service"]}


def test_every_service_package_is_placed():
    """A new package under services/ must be given its row (or be foundation)."""
    placed = {p for row in LAYERS for p in row} | set(FOUNDATION)
    folders = {f"services.{d.name}" for d in (ROOT / "services").iterdir() if (d / "__init__.py").exists()}
    assert folders - placed == set()


def test_service_packages_import_only_lower_ones(graph):
    assert order_violations(graph) == []


def test_the_exceptions_are_still_needed(graph):
    """An exception whose import is gone is removed from :data:`EXCEPTIONS`."""
    present = {(m, package_of(i.target)) for m, imports in graph.items() for i in imports}
    assert set(EXCEPTIONS) <= present


def test_an_import_upwards_is_found():
    """The rule on a made-up graph: walking importing navigation (what sweep.py did) is reported, the
    reverse is not."""
    sweep, stage2 = "services.walking.sweep", "services.navigation.stage2"
    made_up = {
        sweep: [Import(sweep, "services.navigation.collision3d", 22, False)],
        stage2: [Import(stage2, "services.walking.pattern", 60, False)],
    }
    assert order_violations(made_up, exceptions={}) == [
        "services.walking.sweep:22 imports services.navigation.collision3d "
        "(services.navigation is not below services.walking)"
    ]


def test_the_foundation_imports_no_service_package_at_import_time(graph):
    ranked = {p for row in LAYERS for p in row}
    bad = [
        f"{m}:{i.line} imports {i.target}"
        for m, imports in graph.items()
        if package_of(m) in FOUNDATION
        for i in imports
        if not i.lazy and package_of(i.target) in ranked
    ]
    assert bad == []


def test_the_supervisor_imports_no_algorithm_package(graph):
    """Issue #15 item 3: only the bus, its schemas, services.errors and its own modules."""
    bad = [
        f"{m}:{i.line} imports {i.target}"
        for m, imports in graph.items()
        if package_of(m) == "supervisor"
        for i in imports
        if i.target != "zenoh" and package_of(i.target) not in SUPERVISOR_MAY_IMPORT
    ]
    assert bad == []


def test_algorithm_modules_never_reach_zenoh(graph):
    """Only the ``service.py`` adapters reach zenoh (through ``services.bus.service``)."""
    chains = reaching(graph, "zenoh")
    bad = [
        " -> ".join(chains[m])
        for m in sorted(chains)
        if package_of(m) in ALGORITHM_PACKAGES and m.rsplit(".", 1)[-1] != "service"
    ]
    assert bad == []
    assert "services.walking.service" in chains  # the adapters do: the rule sees the path


def test_no_planner_loads_pybullet_when_imported(graph):
    """Only the sim executes: importing a planner, its service or vision loads no pybullet (the contact
    planner reads the scene's primitives from ``sim.parts``, not from ``sim.objects``)."""
    chains = reaching(graph, "pybullet", module_level=True)
    bad = [
        " -> ".join(chains[m])
        for m in sorted(chains)
        if package_of(m) in ALGORITHM_PACKAGES and m not in PYBULLET_ADAPTERS
    ]
    assert bad == []
    assert "sim.world" in chains  # the sim does: the rule sees the path
