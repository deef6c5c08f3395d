"""Planning-cycle benchmark: the full ethical cycle on the default candidate set and the SPEC's grids.

Run as ``etp bench`` or ``python benchmarks/planning_cycle.py`` (same options). The scene is a straight
three-lane road (ego in the middle lane at 10 m/s) with road users of mixed types
spread 5-60 m ahead in the three lanes and a covariance growing over the horizon.

Candidate sets ("grids"): ``default`` is the ethical preset's own set (15 x 15 end speeds
x offsets for each of four horizons and the braking family; the continuation is off,
since every cycle replans the same scene); ``225`` and ``2025`` are the paper's single
grids. frenetix plans the grid part only: for ``default`` it plans each horizon's 225
candidates in a cycle of its own and the times are added.

``first_call_times`` measures the planner's first cycle in a new process, with the
compiled kernels compiled afresh (an empty numba cache) and loaded from the disk cache.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ethical_planner.config import PlannerConfig, preset
from ethical_planner.environment import RoadEnvironment
from ethical_planner.planner import Planner
from ethical_planner.prediction import make_predictor
from ethical_planner.road_users import DEFAULT_SHAPES, KinematicState, RoadUser, RoadUserType

#: (n_speeds, n_offsets, horizon [s]) of the two standard grids.
GRIDS = {"225": (15, 15, 2.0), "2025": (45, 45, 3.0)}
#: The ethical preset's own candidate set (see ``grid_config``).
DEFAULT_GRID = "default"
#: Every candidate set ``grid_config`` knows, in the benchmark's order.
GRID_NAMES = (DEFAULT_GRID, *GRIDS)
LANE_WIDTH = 3.5
EGO_SPEED = 10.0

_MIX = (
    RoadUserType.CAR,
    RoadUserType.TRUCK,
    RoadUserType.BICYCLE,
    RoadUserType.PEDESTRIAN,
    RoadUserType.CAR,
)
_SPEED = {
    RoadUserType.CAR: 9.0,
    RoadUserType.TRUCK: 8.0,
    RoadUserType.BICYCLE: 4.0,
    RoadUserType.PEDESTRIAN: 1.2,
}


@dataclass(frozen=True, slots=True)
class BenchScene:
    """A benchmark situation: road, ego state and road users."""

    environment: RoadEnvironment
    ego: KinematicState
    road_users: tuple[RoadUser, ...]


def bench_scene(n_road_users: int, seed: int = 0) -> BenchScene:
    """Road users of mixed types 5-60 m ahead in three lanes (seeded)."""
    rng = np.random.default_rng(seed)
    env = RoadEnvironment.along_path(
        [[-20.0, 0.0], [300.0, 0.0]],
        lanes_left=1,
        lanes_right=1,
        lane_width=LANE_WIDTH,
        speed_limit=13.9,
        margin=0.5,
    )
    ahead = np.sort(rng.uniform(5.0, 60.0, n_road_users))
    users = []
    for i, x in enumerate(ahead):
        kind = _MIX[i % len(_MIX)]
        lane = int(rng.integers(-1, 2))
        if kind is RoadUserType.PEDESTRIAN:
            # Pedestrians walk along the road edges, some drifting towards the road.
            y, yaw = (lane or 1) * 1.6 * LANE_WIDTH, float(rng.choice([0.0, np.pi / 2, -np.pi / 2]))
        else:
            y, yaw = lane * LANE_WIDTH, float(np.pi if lane == 1 else 0.0)
        users.append(
            RoadUser(
                id=i + 1,
                type=kind,
                state=KinematicState(float(x), float(y), yaw, _SPEED[kind] * rng.uniform(0.7, 1.1)),
                shape=DEFAULT_SHAPES[kind],
            )
        )
    return BenchScene(env, KinematicState(0.0, 0.0, 0.0, EGO_SPEED), tuple(users))


def grid_config(grid: str, base: PlannerConfig | None = None) -> PlannerConfig:
    """The ethical preset with the candidate set ``grid`` ('default', '225' or '2025').

    '225' and '2025' are the paper's grid only (one horizon, no braking family, no
    continuation), so that the peer's cycle plans exactly the same candidates. 'default'
    keeps the preset's candidates (several horizons, the braking family) without the
    continuation (every cycle replans the same scene, so there is no previous plan).
    """
    if grid not in GRID_NAMES:
        raise ValueError(f"unknown grid {grid!r}; allowed: {', '.join(GRID_NAMES)}")
    base = base or preset("ethical")
    if grid == DEFAULT_GRID:
        return base.with_overrides({"commitment": {"enabled": False}})
    n_speeds, n_offsets, horizon = GRIDS[grid]
    return base.with_overrides(
        {
            "sampling": {
                "n_speeds": n_speeds,
                "n_offsets": n_offsets,
                "horizons": [horizon],
                "brake_candidates": False,
            },
            "commitment": {"enabled": False},
        }
    )


def time_call(function: Callable[[], object], repetitions: int) -> dict[str, float]:
    """Median and 90th percentile wall time [ms] of ``function`` after one warm-up call.

    ``cpu_median_ms`` is the median process CPU time (all threads): on a shared machine
    wall time also counts other jobs' time slices, CPU time does not.
    """
    function()
    samples = []
    cpu = []
    for _ in range(repetitions):
        clock, cpu_clock = time.perf_counter(), time.process_time()
        function()
        samples.append((time.perf_counter() - clock) * 1e3)
        cpu.append((time.process_time() - cpu_clock) * 1e3)
    samples.sort()
    return {
        "median_ms": statistics.median(samples),
        "cpu_median_ms": statistics.median(cpu),
        "p90_ms": samples[min(len(samples) - 1, int(0.9 * len(samples)))],
    }


def time_planner(
    grid: str, n_road_users: int, repetitions: int = 20, delta_v_model: str = "eq1"
) -> dict[str, float]:
    """Time full ethical planning cycles on a standard grid with a delta-v model."""
    scene = bench_scene(n_road_users)
    config = grid_config(grid).with_overrides({"risk": {"delta_v_model": delta_v_model}})
    planner = Planner(config, scene.environment)
    result = time_call(lambda: planner.plan(scene.ego, scene.road_users), repetitions)
    decision = planner.plan(scene.ego, scene.road_users)
    result["n_trajectories"] = len(decision.candidate_levels)
    result["stage_ms"] = decision.timings_ms
    return result


#: Run in a new process by ``first_call_times``: the first and the second cycle, timed.
_FIRST_CALL = """
import json, sys, time
clock = time.perf_counter()
from benchmarks.planning_cycle import bench_scene, grid_config
from ethical_planner.planner import Planner
from ethical_planner.jit import cache_report
imported = time.perf_counter() - clock
grid, count = sys.argv[1], int(sys.argv[2])
scene = bench_scene(count)
planner = Planner(grid_config(grid), scene.environment)
times = []
for _ in range(2):
    clock = time.perf_counter()
    planner.plan(scene.ego, scene.road_users)
    times.append(time.perf_counter() - clock)
report = cache_report()
print(json.dumps({
    "import_s": imported, "first_cycle_s": times[0], "second_cycle_s": times[1],
    "compiled": sum(r["compiled"] for r in report.values()),
    "loaded": sum(r["loaded"] for r in report.values()),
}))
"""


def first_call_times(grid: str = DEFAULT_GRID, n_road_users: int = 20) -> list[dict]:
    """The first planning cycle of a new process: kernels compiled, then loaded from disk.

    Two new processes share an empty numba cache folder: the first compiles every kernel
    (and writes the cache), the second loads them. Each times the import of the planner,
    its first and its second cycle.

    Returns:
        Two rows (``"cache": "empty"`` and ``"warm"``) with ``import_s``,
        ``first_cycle_s``, ``second_cycle_s`` [s] and the kernel signatures
        ``compiled`` and ``loaded``.
    """
    import json
    import os
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    root = str(Path(__file__).resolve().parent.parent)
    rows = []
    with tempfile.TemporaryDirectory(prefix="etp-numba-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": root}
        for label in ("empty", "warm"):
            command = [sys.executable, "-c", _FIRST_CALL, grid, str(n_road_users)]
            done = subprocess.run(command, env=env, cwd=root, capture_output=True, text=True, check=True)
            rows.append({"cache": label, "grid": grid, "road_users": n_road_users, **json.loads(done.stdout)})
    return rows


def format_first_call_table(rows: list[dict]) -> str:
    """Plain-text table of ``first_call_times`` rows."""
    lines = [
        f"{'numba cache':>12} {'import':>8} {'1st cycle':>10} {'2nd cycle':>10} {'compiled':>9} {'loaded':>7}"
    ]
    for r in rows:
        lines.append(
            f"{r['cache']:>12} {r['import_s']:>6.2f} s {r['first_cycle_s']:>8.2f} s "
            f"{r['second_cycle_s'] * 1e3:>7.1f} ms {r['compiled']:>9} {r['loaded']:>7}"
        )
    first = rows[0]
    lines.append(
        f"a new process, {first['grid']} candidates, {first['road_users']} road users: kernels compiled "
        "on the first call (empty cache) or loaded from the disk cache (warm)"
    )
    return "\n".join(lines)


def peer_obstacles(grid: str, n_road_users: int) -> list[dict]:
    """The same road users as predicted by our predictor, in the peer's format."""
    scene = bench_scene(n_road_users)
    config = grid_config(grid)
    dt = config.sampling.dt
    times = np.arange(int(round(max(config.sampling.horizons) / dt)) + 1) * dt
    pred = make_predictor(config.prediction).predict(scene.road_users, times)
    pred = pred.with_covariance_floor(config.prediction.covariance_floor)  # as the planner does
    return [
        {
            "mean": pred.mean[k],
            "cov": pred.cov[k],
            "heading": pred.heading[k],
            "length": float(pred.length[k]),
            "width": float(pred.width[k]),
        }
        for k in range(pred.n_obs)
    ]


def time_peer(grid: str, n_road_users: int, repetitions: int = 20) -> dict | None:
    """Time frenetix's C++ cycle on the same grid and road users; None if not installed.

    With several horizons (the 'default' set) frenetix plans each horizon's grid in a
    cycle of its own; the medians and 90th percentiles are added.
    """
    try:
        from benchmarks.peer_frenetix import time_frenetix_cycle
    except ImportError:
        return None
    scene = bench_scene(n_road_users)
    config = grid_config(grid)
    sampling = config.sampling
    v0 = scene.ego.v
    path = scene.environment.reference_path
    obstacles = peer_obstacles(grid, n_road_users) if n_road_users else []
    total = {"median_ms": 0.0, "p90_ms": 0.0, "cpu_median_ms": 0.0, "n_trajectories": 0}
    for horizon in sampling.horizons:
        try:
            timing = time_frenetix_cycle(
                np.column_stack([path.x, path.y])[::8],
                {"x": scene.ego.x, "y": scene.ego.y, "yaw": scene.ego.yaw, "v": v0, "a": 0.0},
                sampling.n_speeds,
                sampling.n_offsets,
                sampling.d_min,
                sampling.d_max,
                horizon,
                sampling.dt,
                obstacles,
                repetitions,
                v_end_range=(
                    max(0.0, v0 - sampling.max_end_deceleration * horizon),
                    min(config.vehicle.v_max, v0 + sampling.max_end_acceleration * horizon),
                ),
            )
        except ImportError:
            return None
        total["median_ms"] += timing["median_ms"]
        total["p90_ms"] += timing["p90_ms"]
        total["cpu_median_ms"] += timing["cpu_median_ms"]
        total["n_trajectories"] += sampling.n_speeds * sampling.n_offsets
    return total


def run_benchmark(
    repetitions: int = 20,
    grids: tuple[str, ...] = GRID_NAMES,
    road_user_counts: tuple[int, ...] = (0, 5, 20),
    peer: bool = True,
) -> list[dict]:
    """Time our cycle (and frenetix's, if installed) on every grid and road-user count."""
    rows = []
    for grid in grids:
        for count in road_user_counts:
            ours = time_planner(grid, count, repetitions)
            planar = time_planner(grid, count, repetitions, "planar_impulse")
            theirs = time_peer(grid, count, repetitions) if peer else None
            row = {
                "grid": grid,
                "n_trajectories": ours["n_trajectories"],
                "road_users": count,
                "ours_median_ms": round(ours["median_ms"], 2),
                "ours_p90_ms": round(ours["p90_ms"], 2),
                "ours_cpu_ms": round(ours["cpu_median_ms"], 2),
                "stages_ms": ours["stage_ms"],
                "planar_median_ms": round(planar["median_ms"], 2),
                "planar_stages_ms": planar["stage_ms"],
                "frenetix_median_ms": None if theirs is None else round(theirs["median_ms"], 2),
                "frenetix_cpu_ms": None if theirs is None else round(theirs["cpu_median_ms"], 2),
                "frenetix_n_trajectories": None if theirs is None else theirs.get("n_trajectories"),
                "speedup": None if theirs is None else round(theirs["median_ms"] / ours["median_ms"], 2),
                "cpu_speedup": None
                if theirs is None or not ours["cpu_median_ms"]
                else round(theirs["cpu_median_ms"] / ours["cpu_median_ms"], 2),
            }
            rows.append(row)
    return rows


def with_history(users: tuple[RoadUser, ...], seconds: float = 3.0, step: float = 0.1) -> list[RoadUser]:
    """The road users with a constant-velocity history (as the world observes them)."""
    from dataclasses import replace

    from ethical_planner.road_users import MotionHistory

    times = np.arange(-seconds, 1e-9, step)
    out = []
    for user in users:
        s = user.state
        direction = np.array([np.cos(s.yaw), np.sin(s.yaw)])
        positions = np.array([s.x, s.y]) + times[:, None] * s.v * direction
        history = MotionHistory(times, positions, np.full(len(times), s.yaw), np.full(len(times), s.v))
        out.append(replace(user, history=history))
    return out


def time_predictors(n_road_users: int = 20, repetitions: int = 20, horizon: float = 3.0) -> list[dict]:
    """Time one prediction of ``n_road_users`` (3 s of history each) per registered predictor.

    The learned predictor runs on one torch thread (``PredictionConfig.torch_threads``);
    it is skipped where torch or its weights are missing.
    """
    from ethical_planner.config import PredictionConfig
    from ethical_planner.prediction import PREDICTORS, make_predictor

    users = with_history(bench_scene(n_road_users).road_users)
    times = np.arange(0.0, horizon + 1e-9, 0.1)
    rows = []
    for name in PREDICTORS.names():
        try:
            predictor = make_predictor(PredictionConfig(model=name, torch_threads=1))
        except (ImportError, ValueError) as error:
            rows.append(
                {"kind": "prediction", "predictor": name, "road_users": n_road_users, "skipped": str(error)}
            )
            continue
        timing = time_call(lambda p=predictor: p.predict(users, times), repetitions)
        rows.append(
            {
                "kind": "prediction",
                "predictor": name,
                "road_users": n_road_users,
                "median_ms": round(timing["median_ms"], 3),
                "p90_ms": round(timing["p90_ms"], 3),
            }
        )
    return rows


def format_prediction_table(rows: list[dict]) -> str:
    """Plain-text table of ``time_predictors`` rows."""
    lines = [f"{'predictor':>20} {'road users':>10} {'median':>10} {'p90':>10}"]
    for r in rows:
        if "skipped" in r:
            lines.append(f"{r['predictor']:>20} {r['road_users']:>10}   skipped: {r['skipped']}")
        else:
            lines.append(
                f"{r['predictor']:>20} {r['road_users']:>10} {r['median_ms']:>7.2f} ms {r['p90_ms']:>7.2f} ms"
            )
    lines.append("one prediction over 3 s at 0.1 s, one thread; 10 Hz planning allows 100 ms per cycle")
    return "\n".join(lines)


def format_table(rows: list[dict]) -> str:
    """Plain-text table of ``run_benchmark`` rows."""
    header = (
        f"{'candidates':>10} {'road users':>10} {'ours median':>12} {'ours p90':>9} "
        f"{'planar dv':>10} {'planar/eq1':>10} {'frenetix':>9} {'frenetix/ours':>13} "
        f"{'ours CPU':>9} {'frenetix CPU':>12} {'CPU ratio':>9}"
    )
    lines = [header, "-" * len(header)]
    for r in rows:
        peer = "n/a" if r["frenetix_median_ms"] is None else f"{r['frenetix_median_ms']:.2f}"
        ratio = "n/a" if r["speedup"] is None else f"{r['speedup']:.2f}x"
        overhead = r["planar_median_ms"] / r["ours_median_ms"] if r["ours_median_ms"] else float("nan")
        peer_cpu = "n/a" if r.get("frenetix_cpu_ms") is None else f"{r['frenetix_cpu_ms']:.2f}"
        cpu_ratio = "n/a" if r.get("cpu_speedup") is None else f"{r['cpu_speedup']:.2f}x"
        lines.append(
            f"{r['n_trajectories']:>10} {r['road_users']:>10} {r['ours_median_ms']:>9.2f} ms "
            f"{r['ours_p90_ms']:>6.2f} ms {r['planar_median_ms']:>7.2f} ms {overhead:>9.2f}x "
            f"{peer:>9} {ratio:>13} {r['ours_cpu_ms']:>9.2f} {peer_cpu:>12} {cpu_ratio:>9}"
        )
    lines.append(
        "times in ms, medians over the repetitions; ours = the cycle with Eq. 1 delta-v, planar dv = "
        "the same with [risk] delta_v_model = planar_impulse; frenetix = its C++ cycle with "
        "CalculateCollisionProbabilityFast (no harm, principles or R_max); CPU = median process CPU "
        "time per cycle [ms], all threads (on a shared machine wall time counts other jobs too)"
    )
    for r in rows:
        peer_n = r.get("frenetix_n_trajectories")
        if peer_n is not None and peer_n != r["n_trajectories"]:
            lines.append(
                f"{r['grid']}: frenetix plans its {peer_n} grid candidates (one cycle per horizon, "
                f"times added), ours all {r['n_trajectories']} (grid and braking family)"
            )
            break
    lines.append(
        "ours per stage, CPU ms of one more cycle (Decision.timings_ms: process time, all threads; "
        "the stages add up to total):"
    )
    for r in rows:
        stages = r.get("stages_ms") or {}
        parts = ", ".join(f"{k} {v:.2f}" for k, v in stages.items() if k != "wall")
        lines.append(f"  {r['n_trajectories']} candidates, {r['road_users']} road users: {parts}")
    return "\n".join(lines)


def main() -> int:
    """``python benchmarks/planning_cycle.py [etp bench options]``."""
    import sys

    from harm_calibration.cli import main as etp

    return etp(["bench", *sys.argv[1:]])


if __name__ == "__main__":
    raise SystemExit(main())
