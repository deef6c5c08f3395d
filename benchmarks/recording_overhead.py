"""Wall time of closed-loop runs with and without the Rerun recorder (prints a table).

Usage: python benchmarks/recording_overhead.py [SCENARIO ...] [--repeat N] [--duration S]
Budget (issue): recording costs at most 25 % of a run's wall time.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

from mujoco_world.loop.runner import run_scenario
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.storage.recording import RecorderConfig, RerunRecorder

CONFIGS = {
    "no recorder": None,
    "recorder, all candidates": RecorderConfig(),
    "recorder, 50 candidates": RecorderConfig(candidates=50),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("scenarios", nargs="*", default=["tailgater_sudden_stop", "dense_urban"])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--duration", type=float, default=10.0, help="time limit per run [s]")
    args = parser.parse_args()
    run_scenario(dataclasses.replace(get_scenario(args.scenarios[0]), duration=0.5))  # warm up
    print(f"{'scenario':<24} {'config':<26} {'sim [s]':>7} {'wall [s]':>8} {'overhead':>8} {'rrd [KB]':>8}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenarios:
            scenario = dataclasses.replace(get_scenario(name), duration=args.duration)
            base = None
            for label, config in CONFIGS.items():
                walls, size, sim = [], 0, 0.0
                for k in range(args.repeat):
                    out = Path(tmp) / f"{name}-{k}-{len(walls)}-{label[:12].replace(' ', '_')}"
                    observer = RerunRecorder(out, config) if config is not None else None
                    t0 = time.perf_counter()
                    summary = run_scenario(scenario, "ethical", 0, observer=observer)
                    walls.append(time.perf_counter() - t0)
                    sim = summary.duration
                    if observer is not None:
                        size = observer.path.stat().st_size
                wall = min(walls)
                base = wall if base is None else base
                overhead = f"{100 * (wall / base - 1):+.1f} %" if config is not None else "-"
                print(f"{name:<24} {label:<26} {sim:7.1f} {wall:8.2f} {overhead:>8} {size / 1024:8.0f}")


if __name__ == "__main__":
    main()
