"""Freed memory kept in the process (``ethical_planner.memory``): fewer page faults, same plans."""

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

_CYCLES = """
import json, resource
from benchmarks.planning_cycle import bench_scene, grid_config
from ethical_planner.memory import keep_freed_memory
from ethical_planner.planner import Planner
scene = bench_scene(0)
planner = Planner(grid_config("2025"), scene.environment)
faults, chosen, total = 0, [], []
for cycle in range(6):  # the first two fill the heap; the decisions are not kept
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    decision = planner.plan(scene.ego, scene.road_users)
    faults += (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) if cycle >= 2 else 0
    chosen.append(decision.chosen_index)
    total.append(decision.costs["total"])
    del decision
print(json.dumps({"kept": keep_freed_memory(), "faults": faults, "chosen": chosen, "total": total}))
"""


def _run(keep: str) -> dict:
    env = {
        **os.environ,
        "ETHICAL_PLANNER_KEEP_MEMORY": keep,
        "ETHICAL_PLANNER_THREADS": "1",
        "PYTHONPATH": str(ROOT),
    }
    done = subprocess.run(
        [sys.executable, "-c", _CYCLES], env=env, cwd=ROOT, capture_output=True, text=True, check=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="the thresholds are glibc's")
def test_kept_memory_removes_the_cycles_page_faults_and_changes_no_plan():
    kept, released = _run("1"), _run("0")
    assert kept["kept"] is True and released["kept"] is False
    # 2025 candidates without road users: ~2,700 faults a cycle with glibc's defaults.
    assert released["faults"] > 1000
    assert kept["faults"] < released["faults"] / 10
    assert kept["chosen"] == released["chosen"]
    assert kept["total"] == released["total"]
