"""Keep freed memory in the process so that numpy temporaries do not page-fault.

glibc returns freed blocks above its mmap threshold (and the top of the heap) to the
kernel; each new temporary of a few hundred kB then page-faults on every planning
cycle. The command line and the batch workers call ``keep_freed_memory`` once: it
changes a process-wide allocator setting, so the library itself never does.
"""

from __future__ import annotations

import ctypes
import ctypes.util

_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3


def keep_freed_memory(mmap_threshold: int = 64 << 20, top_pad: int = 256 << 20) -> bool:
    """Ask glibc's malloc to keep up to ``top_pad`` bytes of freed memory [B].

    Returns:
        True if the settings took effect (glibc), False elsewhere (nothing changed).
    """
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    ok = mallopt(_M_MMAP_THRESHOLD, mmap_threshold) == 1
    ok &= mallopt(_M_TOP_PAD, top_pad) == 1
    ok &= mallopt(_M_TRIM_THRESHOLD, 2 * top_pad) == 1
    return bool(ok)
