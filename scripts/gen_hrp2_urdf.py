#!/usr/bin/env python3
"""Regenerate the hrp2_like URDF (services/model/data/hrp2_like.urdf) from services/model/generate_urdf.py.

Usage: scripts/gen_hrp2_urdf.py [--output PATH] [--check]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from services.model.generate_urdf import DEFAULT_URDF_PATH, urdf_text, write_urdf


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path, default=DEFAULT_URDF_PATH, help="where to write the URDF")
    parser.add_argument(
        "--check",
        action="store_true",
        help="do not write; exit 1 if the file differs from the generator output",
    )
    args = parser.parse_args(argv)
    if args.check:
        current = args.output.read_text(encoding="utf-8") if args.output.exists() else ""
        if current != urdf_text():
            print(f"{args.output} is out of date: run scripts/gen_hrp2_urdf.py", file=sys.stderr)
            return 1
        print(f"{args.output} is up to date")
        return 0
    path = write_urdf(args.output)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
