"""Compiled kernels: the one decorator for the planner's numba kernels, cached on disk.

Why numba: the planning cycle's hot loops (Frenet to Cartesian states, the Gaussian
mass of the Minkowski octagon per (candidate, road user, step), bounds that skip
integrals) are per-element arithmetic with branches, which numpy can only express as
many passes over temporaries. numba compiles the same Python source to machine code,
installs from wheels on CPython 3.10-3.14 (Linux, macOS, Windows; no compiler on the
user's machine) and keeps each kernel readable beside the numpy code that prepares its
inputs: one implementation per kernel, tested like any other function. (Cython or a C++
extension would need a compiler or wheels built by us for every platform; pythran needs
a compiler; jax's dispatch costs more than these kernels take.)

Every kernel is compiled on its first call and cached on disk (``cache=True``): in the
package's ``__pycache__`` folder, or, where that is not writable (a read-only install),
in the user's cache directory; ``NUMBA_CACHE_DIR`` overrides both. Later processes (a
CI run's subprocesses, the workers of a batch, the next ``etp demo``) load the machine
code instead of compiling it. Where no cache location is writable at all, kernels are
compiled in memory per process, with one warning. A cache entry is keyed by the
kernel's source file: a kernel and every kernel it calls live in the same module, so
that an edit always invalidates what depends on it.

Kernels run without the GIL (``nogil``), so a ``Workers`` helper thread runs a second
one in parallel; without fast-math, so the arithmetic is the written one, in order.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numba

#: Options of every kernel: machine code only, GIL released, numpy's division semantics
#: (no ZeroDivisionError checks in the loops).
_OPTIONS: dict[str, Any] = {"nogil": True, "error_model": "numpy"}

#: Every kernel made by ``kernel``, by qualified name (for ``cache_report``).
KERNELS: dict[str, Any] = {}
_warned = False


def kernel(function: Callable) -> Any:
    """Compile ``function`` with numba on its first call, cached on disk where possible.

    Args:
        function: a function numba can compile in nopython mode.

    Returns:
        The numba dispatcher (callable from Python and from other kernels).
    """
    global _warned
    try:
        compiled = numba.njit(cache=True, **_OPTIONS)(function)
    except RuntimeError as error:  # numba found no writable cache location
        if not _warned:
            _warned = True
            warnings.warn(
                f"ethical_planner: compiled kernels cannot be cached on disk ({error}); they are "
                "compiled once per process. Set NUMBA_CACHE_DIR to a writable folder to cache them.",
                RuntimeWarning,
                stacklevel=2,
            )
        compiled = numba.njit(cache=False, **_OPTIONS)(function)
    KERNELS[f"{function.__module__}.{function.__qualname__}"] = compiled
    return compiled


def cache_report() -> dict[str, dict[str, int]]:
    """Per kernel used in this process: signatures loaded from the disk cache and compiled.

    Returns:
        ``{kernel name: {"loaded": n, "compiled": m}}`` for every kernel called so far.
    """
    report = {}
    for name, dispatcher in KERNELS.items():
        if not dispatcher.signatures:
            continue
        stats = getattr(dispatcher, "stats", None)
        loaded = sum(stats.cache_hits.values()) if stats is not None else 0
        report[name] = {"loaded": loaded, "compiled": len(dispatcher.signatures) - loaded}
    return report


__all__ = ["KERNELS", "cache_report", "kernel"]
