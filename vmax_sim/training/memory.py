"""Handing freed heap memory back to the operating system.

XLA's compiler, TensorStore and the data loader free hundreds of MB at a time in blocks small enough for
glibc's malloc to keep for later instead of returning them; what it keeps still counts in the resident
set. `release_freed_memory` asks glibc to return it (a no-op elsewhere), after the phases that free a lot.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import sys


@functools.lru_cache(maxsize=1)
def _malloc_trim():
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc (musl has no malloc_trim)
        return None


def release_freed_memory() -> None:
    """Returns the C heap's free pages to the operating system (glibc `malloc_trim`; a few ms)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
