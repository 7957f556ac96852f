"""Conversion workers keep freed memory for the next scenario instead of handing it back to the system.

A scenario's conversion allocates and frees arrays and records of 0.1-3 MB by the hundred. glibc serves blocks of
that size with fresh mmap'd pages (or trims the heap top once 128 KB lie free), so every scenario pays the page
faults of zero-filling its memory again: 3-7% of a fresh worker's WOMD conversion on the 2-core VM (session 56).
With the mmap threshold raised to its ceiling and trimming from 64 MB on, the heap keeps those blocks (a worker holds
at most 64 MB more between scenarios). Linux with glibc only; elsewhere (musl, macOS, Windows) nothing changes.
"""

from __future__ import annotations

import ctypes
import functools
import sys

M_TRIM_THRESHOLD = -1  # malloc.h
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 32 << 20  # glibc's ceiling for the threshold on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX)
TRIM_THRESHOLD_BYTES = 64 << 20


@functools.cache  # once per process: every unit a worker converts asks again
def keep_freed_memory() -> bool:
    """Tunes this process's allocator as above. Returns whether it was (False where there is no glibc)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # a libc without mallopt (musl)
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    # Both or neither: a fixed mmap threshold alone turns off glibc's own adaptation and trims at 128 KB (slower).
    if not mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES):
        return False
    return bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
