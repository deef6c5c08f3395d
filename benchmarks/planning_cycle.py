"""Planning-cycle benchmark: the full ethical cycle on the SPEC's standard grids.

Run as ``etp bench`` or ``python benchmarks/planning_cycle.py`` (same options). The scene is a straight
three-lane road (ego in the middle lane at 10 m/s) with road users of mixed types
spread 5-60 m ahead in the three lanes and a covariance growing over the horizon.
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
    """The ethical preset with the sampling grid ``grid`` ('225' or '2025') and nothing else.

    Only the paper's grid (one horizon, no braking family, no continuation), so that the
    peer's cycle plans exactly the same candidates.
    """
    if grid not in GRIDS:
        raise ValueError(f"unknown grid {grid!r}; allowed: {', '.join(GRIDS)}")
    n_speeds, n_offsets, horizon = GRIDS[grid]
    base = base or preset("ethical")
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
    """Median and 90th percentile wall time [ms] of ``function`` after one warm-up call."""
    function()
    samples = []
    for _ in range(repetitions):
        clock = time.perf_counter()
        function()
        samples.append((time.perf_counter() - clock) * 1e3)
    samples.sort()
    return {
        "median_ms": statistics.median(samples),
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
    """Time frenetix's C++ cycle on the same grid and road users; None if not installed."""
    try:
        from benchmarks.peer_frenetix import time_frenetix_cycle
    except ImportError:
        return None
    scene = bench_scene(n_road_users)
    config = grid_config(grid)
    sampling = config.sampling
    horizon = max(sampling.horizons)
    v0 = scene.ego.v
    path = scene.environment.reference_path
    try:
        return time_frenetix_cycle(
            np.column_stack([path.x, path.y])[::8],
            {"x": scene.ego.x, "y": scene.ego.y, "yaw": scene.ego.yaw, "v": v0, "a": 0.0},
            sampling.n_speeds,
            sampling.n_offsets,
            sampling.d_min,
            sampling.d_max,
            horizon,
            sampling.dt,
            peer_obstacles(grid, n_road_users) if n_road_users else [],
            repetitions,
            v_end_range=(
                max(0.0, v0 - sampling.max_end_deceleration * horizon),
                min(config.vehicle.v_max, v0 + sampling.max_end_acceleration * horizon),
            ),
        )
    except ImportError:
        return None


def run_benchmark(
    repetitions: int = 20,
    grids: tuple[str, ...] = ("225", "2025"),
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
                "stages_ms": ours["stage_ms"],
                "planar_median_ms": round(planar["median_ms"], 2),
                "planar_stages_ms": planar["stage_ms"],
                "frenetix_median_ms": None if theirs is None else round(theirs["median_ms"], 2),
                "speedup": None if theirs is None else round(theirs["median_ms"] / ours["median_ms"], 2),
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
        f"{'planar dv':>10} {'planar/eq1':>10} {'frenetix':>9} {'frenetix/ours':>13}"
    )
    lines = [header, "-" * len(header)]
    for r in rows:
        peer = "n/a" if r["frenetix_median_ms"] is None else f"{r['frenetix_median_ms']:.2f}"
        ratio = "n/a" if r["speedup"] is None else f"{r['speedup']:.2f}x"
        overhead = r["planar_median_ms"] / r["ours_median_ms"] if r["ours_median_ms"] else float("nan")
        lines.append(
            f"{r['n_trajectories']:>10} {r['road_users']:>10} {r['ours_median_ms']:>9.2f} ms "
            f"{r['ours_p90_ms']:>6.2f} ms {r['planar_median_ms']:>7.2f} ms {overhead:>9.2f}x "
            f"{peer:>9} {ratio:>13}"
        )
    lines.append(
        "times in ms, medians over the repetitions; ours = the cycle with Eq. 1 delta-v, planar dv = "
        "the same with [risk] delta_v_model = planar_impulse; frenetix = its C++ cycle with "
        "CalculateCollisionProbabilityFast (no harm, principles or R_max)"
    )
    return "\n".join(lines)


def main() -> int:
    """``python benchmarks/planning_cycle.py [etp bench options]``."""
    import sys

    from harm_calibration.cli import main as etp

    return etp(["bench", *sys.argv[1:]])


if __name__ == "__main__":
    raise SystemExit(main())
