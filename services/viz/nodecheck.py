"""Run ``scripts/foxglove_check`` (Foxglove's own MCAP reader and decoders, in Node) over a log.

The Node script is set up from nothing on first use: ``npm ci`` of its lockfile into
``scripts/foxglove_check/node_modules`` with the npm cache in ``.cache/npm`` (both ignored by git).
:func:`unavailable` says why it cannot run here (no ``node`` or ``npm``), so a test can skip with
that reason.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

from services.errors import HumanoidError

REPO = Path(__file__).resolve().parents[2]
CHECK_DIR = REPO / "scripts" / "foxglove_check"
NPM_CACHE = REPO / ".cache" / "npm"
#: Oldest Node major version the script is written for (ES modules, top-level await not needed).
MIN_NODE_MAJOR = 18


class FoxgloveCheckError(HumanoidError):
    """The Node check could not be set up or did not produce a report."""

    code = "internal"


def unavailable() -> str:
    """Why the check cannot run on this machine ("" when it can)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        return "node and npm are needed for Foxglove's own reader (scripts/foxglove_check): not on PATH"
    try:
        version = subprocess.run([node, "--version"], capture_output=True, text=True, timeout=30).stdout
        major = int(version.strip().lstrip("v").split(".")[0])
    except (OSError, ValueError, subprocess.TimeoutExpired) as exc:
        return f"node --version failed: {exc}"
    if major < MIN_NODE_MAJOR:
        return f"node {version.strip()} is older than {MIN_NODE_MAJOR}"
    return ""


def ensure_installed(timeout_s: float = 600.0) -> None:
    """``npm ci`` the script's locked dependencies unless they are installed for this lockfile."""
    lock = CHECK_DIR / "package-lock.json"
    stamp = CHECK_DIR / "node_modules" / ".package-lock.json"  # npm's own copy of the installed tree
    if stamp.is_file() and stamp.stat().st_mtime >= lock.stat().st_mtime:
        return
    NPM_CACHE.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(
        ["npm", "ci", "--cache", str(NPM_CACHE), "--no-audit", "--no-fund", "--loglevel", "error"],
        cwd=CHECK_DIR, capture_output=True, text=True, timeout=timeout_s,
    )  # fmt: skip
    if done.returncode != 0:
        raise FoxgloveCheckError(f"npm ci in {CHECK_DIR} failed: {done.stderr.strip()[-2000:]}")


def check_log(path: str | Path, timeout_s: float = 600.0) -> dict[str, Any]:
    """The report of ``check.mjs`` for the log at ``path``: ``channels_total``, ``channels_ok``,
    ``messages``, ``summary_message_count`` and per channel ``ok``, ``decoded`` and ``errors``."""
    ensure_installed()
    done = subprocess.run(
        ["node", str(CHECK_DIR / "check.mjs"), str(Path(path).resolve())],
        cwd=CHECK_DIR, capture_output=True, text=True, timeout=timeout_s,
    )  # fmt: skip
    try:
        report = json.loads(done.stdout)
    except json.JSONDecodeError:
        raise FoxgloveCheckError(
            f"foxglove_check gave no report (exit {done.returncode}): {done.stderr[-2000:]}"
        ) from None
    report["exit_code"] = done.returncode
    return report
