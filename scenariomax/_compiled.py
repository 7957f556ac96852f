"""Where the compiled kernels come from: `kernels()` gives `scenariomax._numba_kernels` (imported on first use: numba
takes ~0.5 s to import and the CLI's other commands never need it), or None where numba is not installed or
`SCENARIOMAX_NO_NUMBA=1` is set. Callers fall back to their numpy code, which gives the same bits, only slower."""

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
    except ImportError:  # numba missing, or a Python it has no build for yet
        return None
    return _numba_kernels
