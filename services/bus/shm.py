"""Removing the shared-memory segments zenoh leaves in ``/dev/shm``.

zenoh (1.10) creates ``/dev/shm/<id>.zenoh`` segments in every process that opens a session (a small
one at open, a pool when large messages go through shared memory) and does not unlink them when the
process exits; it only sweeps orphans when the next session starts. The pool belongs to the process,
not to a session: every session of the process sends through it for as long as the process lives, and
a process that receives a large message maps the sender's segment by its name at that moment. Every
process holding a segment keeps a shared ``flock`` on it, and ``/proc/locks`` names the holders' pids.
So a segment is safe to unlink only when no living process, this one included, holds a lock on it:
that is what :func:`cleanup_segments` does after a session is closed (a service at exit, the launcher
once its children are gone). Unlinking this process's own segments while it lives made every large
message to a service started afterwards vanish (no reply, no error).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

SHM_DIR = Path("/dev/shm")
PATTERN = "*.zenoh"
#: A segment nobody locks yet may be one another process is creating right now: spare fresh ones.
_FRESH_S = 0.5


def segments(shm_dir: Path = SHM_DIR) -> list[Path]:
    """The zenoh segments present now."""
    try:
        return sorted(shm_dir.glob(PATTERN))
    except OSError:
        return []


def lock_holders() -> dict[tuple[int, int, int], set[int]]:
    """``(major, minor, inode) -> {pid}`` of every file lock in the system (``/proc/locks``)."""
    holders: dict[tuple[int, int, int], set[int]] = {}
    try:
        lines = Path("/proc/locks").read_text().splitlines()
    except OSError:
        return holders
    for line in lines:
        parts = line.split()
        # "1: FLOCK  ADVISORY  READ 8070 00:1b:18 0 EOF" (blocked waiters have a "->" field first)
        if len(parts) < 6 or parts[1] == "->":
            continue
        try:
            pid = int(parts[4])
            major, minor, inode = parts[5].split(":")
            holders.setdefault((int(major, 16), int(minor, 16), int(inode)), set()).add(pid)
        except ValueError:
            continue
    return holders


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def orphaned(shm_dir: Path = SHM_DIR) -> list[Path]:
    """Segments that no living process holds (a fresh one nobody locks yet is spared)."""
    holders = lock_holders()
    found = []
    now = time.time()
    for path in segments(shm_dir):
        try:
            st = path.stat()
        except FileNotFoundError:
            continue
        dev = (os.major(st.st_dev), os.minor(st.st_dev), st.st_ino)
        pids = holders.get(dev, set())
        if any(_alive(pid) for pid in pids):
            continue
        if not pids and now - st.st_mtime < _FRESH_S:
            continue
        found.append(path)
    return found


def cleanup_segments(shm_dir: Path = SHM_DIR) -> list[Path]:
    """Unlink the orphaned zenoh segments (call after closing this process's session)."""
    removed = []
    for path in orphaned(shm_dir):
        try:
            path.unlink()
            removed.append(path)
        except FileNotFoundError:
            continue
        except OSError:
            continue
    return removed
