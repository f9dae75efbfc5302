"""Freed arrays handed back to the system (issue 22, memory).

glibc's allocator serves an array from ``mmap`` (returned to the system when freed) only
above its threshold, and the threshold rises to the size of each mmapped block that is
freed, up to 32 MiB. After the first freed (N, 3) array of a long recording, every array
up to that size (a (3N) vector is 24 MB at 1 M readings) is served from the heap, and the
heap keeps the pages of the freed ones: they stay resident between the long-lived arrays
and are reused only by arrays that fit in them. Building the base problem frees dozens
of such vectors (the noise model's terms, the residuals, the weights of each refit): at
1 M readings 0.1–0.3 GB of freed memory stayed resident under everything that follows
(docs/benchmarks.md, *the base problem's floor*).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _malloc_trim():  # -> the C function, or None where the C library has none
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        return ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError):  # not glibc (musl, macOS, Windows)
        return None


def release_freed_memory() -> None:
    """Return the free pages of the C heap to the system (glibc's ``malloc_trim(0)``).

    No effect on any value: only pages no array occupies are released. A no-op where the
    C library has no ``malloc_trim``.
    """
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
