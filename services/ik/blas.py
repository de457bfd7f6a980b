"""Keep OpenBLAS on one thread while the IK runs.

The IK's matrices have tens of rows. OpenBLAS may still split a LAPACK call over its thread pool;
on a loaded machine the call then waits for a descheduled worker, or the workers spin: measured
here, one 23 x 38 triangular solve went from 4 us to milliseconds. OpenBLAS >= 0.3.27 has a
*thread-local* setting, ``openblas_set_num_threads_local``: the solver sets it to 1 for the thread it
runs in, leaving every other thread of the process (and other libraries) alone. When no OpenBLAS
with that symbol is loaded (another BLAS, another platform) nothing is done: results are the same,
only slower on a busy machine.
"""

from __future__ import annotations

import ctypes
import importlib.util
import threading
from collections.abc import Callable
from pathlib import Path

_setters: list[Callable[[int], int]] | None = None
_thread_state = threading.local()


def _openblas_libraries() -> list[Path]:
    """OpenBLAS copies bundled with the numpy and scipy wheels (``numpy.libs``, ``scipy.libs``,
    ``.dylibs``)."""
    found: list[Path] = []
    for package in ("numpy", "scipy"):
        spec = importlib.util.find_spec(package)
        if spec is None or spec.origin is None:
            continue
        package_dir = Path(spec.origin).parent
        for directory in (package_dir.parent / f"{package}.libs", package_dir / ".dylibs"):
            if directory.is_dir():
                found.extend(sorted(directory.glob("*openblas*")))
    return found


def _local_setters() -> list[Callable[[int], int]]:
    global _setters
    if _setters is None:
        setters = []
        for path in _openblas_libraries():
            try:
                function = ctypes.CDLL(str(path)).openblas_set_num_threads_local
            except (OSError, AttributeError):
                continue  # not loadable, or an OpenBLAS without thread-local control
            function.argtypes = [ctypes.c_int]
            function.restype = ctypes.c_int
            setters.append(function)
        _setters = setters
    return _setters


def single_thread_blas_here() -> bool:
    """Make OpenBLAS single-threaded for the calling thread only (once per thread); True if some
    OpenBLAS was set."""
    done = getattr(_thread_state, "done", None)
    if done is None:
        setters = _local_setters()
        for setter in setters:
            setter(1)
        done = _thread_state.done = bool(setters)
    return done
