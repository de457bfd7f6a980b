"""Finding the services of the stack without importing them.

A service is a class deriving from :class:`~services.bus.service.Service` with a literal ``name``
in one of :data:`SERVICE_FILES` (relative to the repository root), plus the bus's own ``diag``.
The files are read with :mod:`ast`, so the launcher does not import pinocchio or pybullet to learn
what to start; each service then runs as ``python -m <module>``.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import services

#: Where services live, as globs under the repository root.
SERVICE_FILES = ("services/*/service.py", "sim/service.py", "supervisor/service.py", "services/bus/diag.py")
#: Not started by ``humanoid up`` unless asked for (``--record``).
RECORDER = "record"
#: The live Foxglove view (services/viz): started by ``humanoid up --foxglove [PORT]`` only.
VIZ = "viz"
#: Services that ``humanoid up`` starts only when named in ``--services``: tools for tests and
#: benchmarks (``diag/raise``, ``diag/stream``) that a deployed robot does not expose.
OPT_IN = ("diag",)


@dataclass(frozen=True)
class ServiceEntry:
    """A service that can be started: ``python -m {module}``."""

    name: str
    module: str
    path: Path


def repo_root() -> Path:
    return Path(services.__file__).resolve().parent.parent


def discover(root: Path | None = None) -> tuple[dict[str, ServiceEntry], list[str]]:
    """``(services by name, problems)``; a problem says why a file that looks like a service is not one."""
    root = repo_root() if root is None else root
    found: dict[str, ServiceEntry] = {}
    problems: list[str] = []
    for pattern in SERVICE_FILES:
        for path in sorted(root.glob(pattern)):
            module = ".".join(path.relative_to(root).with_suffix("").parts)
            try:
                tree = ast.parse(path.read_text(), filename=str(path))
            except SyntaxError as exc:
                problems.append(f"{path.relative_to(root)}: syntax error line {exc.lineno}: {exc.msg}")
                continue
            names = _service_names(tree)
            if not names:
                continue
            if len(names) > 1:
                problems.append(
                    f"{path.relative_to(root)} defines several services ({', '.join(names)}): one per module"
                )
                continue
            if not _has_main(tree):
                problems.append(
                    f"{path.relative_to(root)} defines service {names[0]!r} but no "
                    "`if __name__ == '__main__': raise SystemExit(run_service(...))`"
                )
                continue
            name = names[0]
            if name in found:
                problems.append(f"service name {name!r} is used by both {found[name].module} and {module}")
                continue
            found[name] = ServiceEntry(name=name, module=module, path=path)
    recorder = root / "services/bus/recorder.py"
    found.setdefault(RECORDER, ServiceEntry(RECORDER, "services.bus.recorder", recorder))
    return found, problems


def default_services(found: dict[str, ServiceEntry]) -> list[str]:
    """What ``humanoid up`` starts without ``--services``: every service found but the recorder, the
    live view and the :data:`OPT_IN` ones."""
    return sorted(name for name in found if name not in (RECORDER, VIZ) and name not in OPT_IN)


def _service_names(tree: ast.Module) -> list[str]:
    names = []
    for node in tree.body:
        if not isinstance(node, ast.ClassDef) or not any(_is_service_base(b) for b in node.bases):
            continue
        for item in node.body:
            target, value = None, None
            if isinstance(item, ast.Assign) and len(item.targets) == 1:
                target, value = item.targets[0], item.value
            elif isinstance(item, ast.AnnAssign):
                target, value = item.target, item.value
            is_name = isinstance(target, ast.Name) and target.id == "name"
            if is_name and isinstance(value, ast.Constant) and isinstance(value.value, str):
                names.append(value.value)
    return names


def _is_service_base(node: ast.expr) -> bool:
    return (isinstance(node, ast.Name) and node.id == "Service") or (
        isinstance(node, ast.Attribute) and node.attr == "Service"
    )


def _has_main(tree: ast.Module) -> bool:
    for node in tree.body:
        if (
            isinstance(node, ast.If)
            and "__main__" in ast.unparse(node.test)
            and "__name__" in ast.unparse(node.test)
        ):
            return True
    return False
