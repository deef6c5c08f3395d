"""Compiled kernels: the disk cache serves later processes; no writable cache still works."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings

import numba
import pytest

from ethical_planner import jit

_PROBE = (
    "import json; from ethical_planner.collision_probability import _upper_tail; "
    "from ethical_planner.jit import cache_report; "
    "assert abs(_upper_tail(1.0) - 0.15865525393145707) < 2e-9; "
    "print(json.dumps(cache_report()))"
)


def _probe(cache_dir) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    command = [sys.executable, "-c", _PROBE]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)["ethical_planner.collision_probability._upper_tail"]


def test_a_second_process_loads_the_kernel_from_the_disk_cache(tmp_path):
    assert _probe(tmp_path) == {"loaded": 0, "compiled": 1}
    assert any(path.suffix == ".nbi" for path in tmp_path.rglob("*"))  # the cache index
    assert _probe(tmp_path) == {"loaded": 1, "compiled": 0}


def test_without_a_writable_cache_kernels_compile_in_memory_with_one_warning(monkeypatch):
    real_njit = numba.njit

    def no_cache_location(*args, cache=False, **kwargs):
        if cache:
            raise RuntimeError("cannot cache function: no locator available")
        return real_njit(*args, **kwargs)

    monkeypatch.setattr(jit.numba, "njit", no_cache_location)
    monkeypatch.setattr(jit, "_warned", False)
    monkeypatch.setattr(jit, "KERNELS", {})

    def double(x):
        return 2.0 * x

    def triple(x):
        return 3.0 * x

    with pytest.warns(RuntimeWarning, match="NUMBA_CACHE_DIR"):
        double = jit.kernel(double)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the second kernel does not warn again
        triple = jit.kernel(triple)
    assert double(2.0) == 4.0 and triple(2.0) == 6.0
    assert sorted(jit.cache_report().values(), key=str) == [{"loaded": 0, "compiled": 1}] * 2
