"""Dispatch to the benchmark modules in scripts/bench.d/ (each exposes ``main(argv) -> int``)."""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

BENCH_DIR = Path(__file__).resolve().parent / "bench.d"


def available() -> list[str]:
    return sorted(p.stem for p in BENCH_DIR.glob("*.py") if not p.stem.startswith("_"))


def run(name: str, argv: list[str]) -> int:
    spec = importlib.util.spec_from_file_location(f"bench_{name}", BENCH_DIR / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return int(module.main(argv) or 0)


def main() -> int:
    names = available()
    parser = argparse.ArgumentParser(
        prog="scripts/bench",
        description="Run the stack's benchmarks; each prints a table and writes bench/out/NAME.json.",
    )
    parser.add_argument("name", nargs="?", choices=names, help="one benchmark (default: all of them)")
    parser.add_argument("args", nargs=argparse.REMAINDER, help="arguments passed to the benchmark")
    args = parser.parse_args()
    if args.name:
        return run(args.name, args.args)
    failed = [name for name in names if run(name, []) != 0]
    if failed:
        print(f"benchmarks that failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
