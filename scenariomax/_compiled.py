"""Where the compiled kernels come from: `kernels()` gives `scenariomax._numba_kernels` (imported on first use: numba
takes ~0.5 s to import and the CLI's other commands never need it), or None where numba is not installed or cannot
cache its code, or `SCENARIOMAX_NO_NUMBA=1` is set. Callers fall back to their numpy code, which gives the same
bits, only slower.

A process pays ~1 s the first time it calls a kernel (numba's start and its cached code loaded); the very first
conversion after an install also compiles them (~10-15 s once), into `__pycache__` next to the module."""

from __future__ import annotations

import functools
import os
from types import ModuleType

DISABLE_ENV = "SCENARIOMAX_NO_NUMBA"


@functools.cache  # once per process
def kernels() -> ModuleType | None:
    if os.environ.get(DISABLE_ENV, "").strip() not in ("", "0"):
        return None
    try:
        from scenariomax import _numba_kernels
    except (ImportError, RuntimeError, OSError):
        # numba missing or built for another numpy; or no writable place for its cache (next to this file, else
        # ~/.cache or NUMBA_CACHE_DIR): numba refuses to compile a cached function then
        return None
    return _numba_kernels
