"""Keep the planning cycle's freed memory in the process (glibc only), so cycles do not page-fault.

A cycle allocates and frees arrays of 0.2-3 MB each (candidates, tables, triples). With
glibc's defaults, arrays above its dynamic mmap threshold are mapped and unmapped on every
allocation, and the heap top is returned to the system when more than the trim threshold
lies free: the next cycle touches fresh pages again, and the kernel faults and zeroes each.
Measured (``etp bench`` scenes, one thread): 2,000-3,000 minor faults and 7-8 ms of
system time per cycle on the 2025 grid (a third of the cycle without road users), ~2,000
faults on the default set with 20 road users, none at 225 candidates.

``keep_freed_memory`` sets a fixed mmap threshold (32 MiB, glibc's largest dynamic one)
and a trim threshold of 128 MiB: freed arrays stay in the heap for the next cycle. The
price is memory: the process keeps up to 128 MiB of freed heap instead of returning it.
It changes how memory is obtained, never a value. The planner calls it once per process
(``Planner``); ``ETHICAL_PLANNER_KEEP_MEMORY=0`` leaves the allocator alone. Elsewhere
than glibc (macOS, Windows, musl) it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import platform

#: Environment variable: "0" leaves the allocator's settings alone.
KEEP_MEMORY_VARIABLE = "ETHICAL_PLANNER_KEEP_MEMORY"
#: glibc's ``mallopt`` parameters (malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: Allocations above this many bytes are still mapped (returned at once when freed).
MMAP_THRESHOLD = 32 << 20
#: Freed memory at the heap top kept before any is returned to the system [bytes].
TRIM_THRESHOLD = 128 << 20

_done: bool | None = None


def keep_freed_memory() -> bool:
    """Set glibc's mmap and trim thresholds once per process (see the module docstring).

    Returns:
        True if the thresholds are set (now or by an earlier call), False where this is
        not glibc or ``ETHICAL_PLANNER_KEEP_MEMORY`` is "0".
    """
    global _done
    if _done is not None:
        return _done
    _done = False
    if os.environ.get(KEEP_MEMORY_VARIABLE, "1") == "0" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    _done = bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    )
    return _done


__all__ = ["KEEP_MEMORY_VARIABLE", "MMAP_THRESHOLD", "TRIM_THRESHOLD", "keep_freed_memory"]
