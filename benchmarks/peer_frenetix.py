"""Time the planning cycle of the peer planner ``frenetix`` (SPEC section 9).

``frenetix`` (TUM-AVS, PyPI 0.4.0) is the C++ core of the Frenetix motion planner of the
same lab as the paper. This module times its per-cycle work on the same candidate grid as
ours, the way Frenetix-Motion-Planner's ``ReactivePlannerCpp.plan()`` drives it:

setup, once and untimed (the real planner also keeps its handler across cycles):
    ``CoordinateSystemWrapper`` of the reference path, a ``TrajectoryHandler`` with
    ``FillCoordinates`` (Frenet -> Cartesian), the four cheap kinematic feasibility checks
    Frenetix-Motion-Planner registers, cheap comfort/mobility costs mirroring ours, and,
    if there are obstacles, ``CalculateCollisionProbabilityFast`` fed with the obstacles'
    predicted means, headings, covariances and shapes (``PredictedObject`` map).

timed, per repetition:
    ``ComputeInitialState`` (ego -> Frenet), the sampling matrix (end speeds x end lateral
    offsets, one horizon), ``reset_Trajectories`` + ``generate_trajectories`` (quartic s(t),
    quintic d(t)), ``evaluate_all_current_functions(True)`` (coordinates, feasibility,
    all costs for every valid candidate, as Frenetix-Motion-Planner calls it) and ``sort``.

``frenetix`` is an optional peer, never a dependency of the planner: it is imported
only when a peer timing is asked for. ``python -m benchmarks.peer_frenetix``
prints a self-check table.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

# Ego vehicle: BMW 320i (SPEC section 3; CommonRoad vehicle type 2 for the axle data).
EGO_LENGTH = 4.508  # [m]
EGO_WIDTH = 1.610  # [m]
WHEELBASE = 2.578  # [m]
WB_REAR_AXLE = 1.4227  # rear axle -> vehicle centre [m]
DELTA_MAX = 1.066  # max steering angle [rad]
V_DELTA_MAX = 0.4  # max steering rate [rad/s]
A_MAX = 11.5  # max acceleration [m/s^2]
V_SWITCH = 7.319  # switching velocity of the acceleration limit [m/s]
LOW_VEL_MODE_THRESHOLD = 4.0  # [m/s] below this frenetix samples d over s instead of t

# Cheap costs that mirror our comfort + mobility terms (SPEC section 5).
_CHEAP_COSTS = {
    "lateral_jerk": 1.0,
    "longitudinal_jerk": 1.0,
    "distance_to_reference_path": 10.0,
    "velocity_offset": 1.0,
}
RISK_COST_NAME = "prediction"
RISK_COST_WEIGHT = 1.0


def _import_frenetix() -> Any:
    try:
        import frenetix
        import frenetix.trajectory_functions  # noqa: F401
        import frenetix.trajectory_functions.cost_functions  # noqa: F401
        import frenetix.trajectory_functions.feasability_functions  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "frenetix is not installed: `pip install frenetix==0.4.0` "
            "(or `pip install .[peer]`) to time the peer planner"
        ) from exc
    return frenetix


def _predictions(frenetix: Any, obstacles: list[dict], n_points: int) -> dict[int, Any]:
    """Convert our obstacle predictions into frenetix's ``{id: PredictedObject}`` map.

    Our arrays are sampled at t_k = k * dt, k = 0..n_t-1 (index 0 = now). Frenetix pairs
    trajectory point i (t = i * dt) with ``predictedPath[i - 1]`` and stops at the end of
    the path, so ``predictedPath[j]`` holds our step j + 1, for j = 0..n_points-1 (the last
    predicted state is held if our arrays are shorter). Position z and the covariance
    beyond its x-y block are zero, as Frenetix-Motion-Planner's ``set_predictions`` does.
    """
    out: dict[int, Any] = {}
    for key, obs in enumerate(obstacles):
        mean = np.asarray(obs["mean"], dtype=np.float64)
        cov = np.asarray(obs["cov"], dtype=np.float64)
        n_t = mean.shape[0]
        heading = np.broadcast_to(np.asarray(obs["heading"], dtype=np.float64), (n_t,))
        path = []
        for j in range(n_points):
            k = min(j + 1, n_t - 1)
            position = np.array([mean[k, 0], mean[k, 1], 0.0])
            half = 0.5 * float(heading[k])
            orientation = np.array([0.0, 0.0, math.sin(half), math.cos(half)])  # x, y, z, w
            cov6 = np.zeros((6, 6), dtype=np.float64, order="F")
            cov6[:2, :2] = 0.5 * (cov[k] + cov[k].T)
            path.append(frenetix.PoseWithCovariance(position, orientation, cov6))
        out[key] = frenetix.PredictedObject(key, path, float(obs["length"]), float(obs["width"]))
    return out


class FrenetixCycle:
    """One frenetix planner set up for a fixed scene; ``run()`` is one planning cycle."""

    def __init__(
        self,
        reference_path: np.ndarray,
        ego_state: dict,
        n_speeds: int,
        n_offsets: int,
        d_min: float,
        d_max: float,
        horizon: float,
        dt: float,
        obstacles: list[dict],
        *,
        v_end_range: tuple[float, float] | None = None,
        concurrent: bool = False,
    ) -> None:
        frenetix = _import_frenetix()
        tfun = frenetix.trajectory_functions
        cf = tfun.cost_functions
        ff = tfun.feasability_functions
        self._frenetix = frenetix
        self.n_points = int(round(horizon / dt)) + 1
        # Frenetix sizes a trajectory as int(1 + T / dt); T = 3.0, dt = 0.1 gives 30.99..
        # -> 30 points. A 1e-9 s longer end time keeps all n_points samples of ours.
        self._t_end = horizon + 1e-9
        self._concurrent = concurrent

        ref = np.ascontiguousarray(reference_path, dtype=np.float64)
        self.coordinate_system = frenetix.CoordinateSystemWrapper(ref)

        yaw = float(ego_state["yaw"])
        v0 = float(ego_state["v"])
        # Frenetix plans the rear axle; our ego state is the vehicle centre.
        self._rear_x = float(ego_state["x"]) - WB_REAR_AXLE * math.cos(yaw)
        self._rear_y = float(ego_state["y"]) - WB_REAR_AXLE * math.sin(yaw)
        self._yaw, self._v0, self._a0 = yaw, v0, float(ego_state.get("a", 0.0))
        self.low_velocity_mode = v0 < LOW_VEL_MODE_THRESHOLD
        self._initial_state_fn = tfun.ComputeInitialState(
            coordinateSystem=self.coordinate_system,
            wheelBase=WHEELBASE,
            steeringAngle=0.0,
            lowVelocityMode=self.low_velocity_mode,
        )

        if v_end_range is None:  # Frenetix-Motion-Planner's velocity sampling interval
            v_end_range = (
                max(0.01, v0 - 0.75 * A_MAX * horizon),
                v0 + A_MAX / 7.0 * horizon,
            )
        self.v_end = np.linspace(v_end_range[0], v_end_range[1], n_speeds)
        self.d_end = np.linspace(d_min, d_max, n_offsets)
        self.n_trajectories = n_speeds * n_offsets

        handler = frenetix.TrajectoryHandler(dt=dt)
        handler.add_function(
            tfun.FillCoordinates(
                lowVelocityMode=self.low_velocity_mode,
                initialOrientation=yaw,
                coordinateSystem=self.coordinate_system,
                horizon=horizon,
            )
        )
        handler.add_feasability_function(
            ff.CheckYawRateConstraint(deltaMax=DELTA_MAX, wheelbase=WHEELBASE, wholeTrajectory=False)
        )
        handler.add_feasability_function(
            ff.CheckAccelerationConstraint(
                switchingVelocity=V_SWITCH, maxAcceleration=A_MAX, wholeTrajectory=False
            )
        )
        handler.add_feasability_function(
            ff.CheckCurvatureConstraint(deltaMax=DELTA_MAX, wheelbase=WHEELBASE, wholeTrajectory=False)
        )
        handler.add_feasability_function(
            ff.CheckCurvatureRateConstraint(
                wheelbase=WHEELBASE, velocityDeltaMax=V_DELTA_MAX, wholeTrajectory=False
            )
        )
        handler.add_cost_function(cf.CalculateLateralJerkCost("lateral_jerk", _CHEAP_COSTS["lateral_jerk"]))
        handler.add_cost_function(
            cf.CalculateLongitudinalJerkCost("longitudinal_jerk", _CHEAP_COSTS["longitudinal_jerk"])
        )
        handler.add_cost_function(
            cf.CalculateDistanceToReferencePathCost(
                "distance_to_reference_path", _CHEAP_COSTS["distance_to_reference_path"]
            )
        )
        handler.add_cost_function(
            cf.CalculateVelocityOffsetCost(
                "velocity_offset", _CHEAP_COSTS["velocity_offset"], v0, dt, 0.0, False, 2
            )
        )
        self.with_risk = bool(obstacles)
        if self.with_risk:
            self.predictions = _predictions(frenetix, obstacles, self.n_points)
            handler.add_cost_function(
                cf.CalculateCollisionProbabilityFast(
                    RISK_COST_NAME,
                    RISK_COST_WEIGHT,
                    self.predictions,
                    EGO_LENGTH,
                    EGO_WIDTH,
                    WB_REAR_AXLE,
                )
            )
        self.handler = handler

    def _sampling_matrix(self) -> np.ndarray:
        init = self._frenetix.TrajectorySample(
            x0=self._rear_x,
            y0=self._rear_y,
            orientation0=self._yaw,
            acceleration0=self._a0,
            velocity0=self._v0,
        )
        self._initial_state_fn.evaluate_trajectory(init)
        c = init.curvilinear
        # Columns (frenetix TrajectoryHandler::generateTrajectories): t0, t1, s0, s0', s0'',
        # s1', s1'', d0, d0', d0'', d1, d1', d1''.
        m = np.zeros((self.n_trajectories, 13))
        m[:, 1] = self._t_end
        m[:, 2] = c.s[0]
        m[:, 3] = c.s_dot[0]
        m[:, 4] = c.s_ddot[0]
        m[:, 5] = np.repeat(self.v_end, self.d_end.size)
        m[:, 7] = c.d[0]
        m[:, 8] = c.d_dot[0]
        m[:, 9] = c.d_ddot[0]
        m[:, 10] = np.tile(self.d_end, self.v_end.size)
        return m

    def run(self) -> None:
        """One planning cycle: sample, convert, check, cost and sort all candidates."""
        matrix = self._sampling_matrix()
        handler = self.handler
        handler.reset_Trajectories()
        handler.generate_trajectories(matrix, self.low_velocity_mode)
        if self._concurrent:
            handler.evaluate_all_current_functions_concurrent(True)
        else:
            handler.evaluate_all_current_functions(True)
        handler.sort()

    def trajectories(self) -> list:
        """Candidates of the last cycle, cheapest (feasible) first."""
        return list(self.handler.get_sorted_trajectories())

    def risk_costs(self) -> tuple[np.ndarray, np.ndarray]:
        """End lateral offsets and unweighted collision probability cost of the last cycle."""
        d_end, cost = [], []
        for traj in self.trajectories():
            d_end.append(traj.sampling_parameters[10])
            cost.append(traj.costMap.get(RISK_COST_NAME, (0.0, 0.0))[0])
        return np.asarray(d_end), np.asarray(cost)


def time_frenetix_cycle(
    reference_path: np.ndarray,
    ego_state: dict,
    n_speeds: int,
    n_offsets: int,
    d_min: float,
    d_max: float,
    horizon: float,
    dt: float,
    obstacles: list[dict],
    repetitions: int = 20,
    *,
    v_end_range: tuple[float, float] | None = None,
    concurrent: bool = False,
) -> dict:
    """Median and 90th percentile wall time of one frenetix planning cycle.

    Args:
        reference_path: (n, 2) polyline [m].
        ego_state: ``{"x", "y", "yaw", "v", "a"}`` of the ego centre at the path start.
        n_speeds, n_offsets: candidate grid, end speeds x end lateral offsets.
        d_min, d_max: end lateral offset range [m].
        horizon, dt: planning horizon and step [s].
        obstacles: per obstacle ``"mean"`` (n_t, 2), ``"cov"`` (n_t, 2, 2), ``"heading"``
            (n_t,), ``"length"``, ``"width"``; step k is at t = k * dt. Empty: no risk cost.
        repetitions: timed cycles (after two untimed warm-up cycles).
        v_end_range: end speed range [m/s]; default Frenetix-Motion-Planner's
            [max(0.01, v - 0.75 a_max T), v + a_max T / 7].
        concurrent: use frenetix's taskflow-parallel evaluation instead of the serial one.

    Returns:
        ``{"median_ms", "p90_ms", "n_trajectories", "with_risk"}`` plus ``"min_ms"``,
        ``"cpu_median_ms"`` (process CPU time, all threads),
        ``"n_valid"`` and ``"n_feasible"`` of the last cycle.

    Raises:
        ImportError: frenetix is not installed.
    """
    cycle = FrenetixCycle(
        reference_path,
        ego_state,
        n_speeds,
        n_offsets,
        d_min,
        d_max,
        horizon,
        dt,
        obstacles,
        v_end_range=v_end_range,
        concurrent=concurrent,
    )
    for _ in range(2):
        cycle.run()
    times = np.empty(max(1, repetitions))
    cpu = np.empty(times.size)
    for i in range(times.size):
        t0, c0 = time.perf_counter(), time.process_time()
        cycle.run()
        times[i] = time.perf_counter() - t0
        cpu[i] = time.process_time() - c0
    trajs = cycle.trajectories()
    return {
        "median_ms": float(np.median(times) * 1e3),
        "cpu_median_ms": float(np.median(cpu) * 1e3),
        "p90_ms": float(np.percentile(times, 90) * 1e3),
        "min_ms": float(times.min() * 1e3),
        "n_trajectories": len(trajs),
        "n_valid": sum(t.valid for t in trajs),
        "n_feasible": sum(t.feasible for t in trajs),
        "with_risk": cycle.with_risk,
    }


# --------------------------------------------------------------------------- self-check


def demo_scene(
    n_obstacles: int,
    horizon: float,
    dt: float,
    ego_speed: float = 10.0,
    seed: int = 0,
) -> tuple[np.ndarray, dict, list[dict]]:
    """Straight 3-lane road (3.5 m lanes), ego in the middle lane at x = 0.

    Obstacles 5-60 m ahead, round-robin over the lanes, constant velocity 3-9 m/s along
    the road, covariance growing linearly over the horizon.
    """
    rng = np.random.default_rng(seed)
    reference_path = np.column_stack([np.linspace(-30.0, 250.0, 281), np.zeros(281)])
    ego = {"x": 0.0, "y": 0.0, "yaw": 0.0, "v": ego_speed, "a": 0.0}
    n_t = int(round(horizon / dt)) + 1
    t = np.arange(n_t) * dt
    lanes = (-3.5, 0.0, 3.5)
    obstacles = []
    for i, x0 in enumerate(np.linspace(5.0, 60.0, n_obstacles) if n_obstacles else []):
        speed = rng.uniform(3.0, 9.0)
        mean = np.column_stack([x0 + speed * t, np.full(n_t, lanes[i % 3])])
        sig_lon = 0.3 + 0.6 * t
        sig_lat = 0.2 + 0.2 * t
        cov = np.zeros((n_t, 2, 2))
        cov[:, 0, 0] = sig_lon**2
        cov[:, 1, 1] = sig_lat**2
        obstacles.append(
            {
                "mean": mean,
                "cov": cov,
                "heading": np.zeros(n_t),
                "length": 4.5,
                "width": 1.8,
            }
        )
    return reference_path, ego, obstacles


def _check_risk_cost_nonzero(horizon: float, dt: float) -> None:
    """Read back the collision cost: nonzero towards an obstacle, zero far from all."""
    ref, ego, _ = demo_scene(0, horizon, dt)
    n_t = int(round(horizon / dt)) + 1
    t = np.arange(n_t) * dt
    cov = np.zeros((n_t, 2, 2))
    cov[:, 0, 0] = (0.3 + 0.6 * t) ** 2
    cov[:, 1, 1] = (0.2 + 0.2 * t) ** 2
    # One car in the left lane, 12 m ahead at 5 m/s: the ego (10 m/s) reaches it.
    obs = {
        "mean": np.column_stack([12.0 + 5.0 * t, np.full(n_t, 3.5)]),
        "cov": cov,
        "heading": np.zeros(n_t),
        "length": 4.5,
        "width": 1.8,
    }
    cycle = FrenetixCycle(ref, ego, 15, 15, -3.5, 3.5, horizon, dt, [obs])
    cycle.run()
    trajs = cycle.trajectories()
    n_pts = {len(tr.cartesian.x) for tr in trajs if tr.valid}
    d_end, cost = cycle.risk_costs()
    left = cost[d_end > 2.5]
    right = cost[d_end < -2.5]
    print(
        f"risk read-back ({len(trajs)} candidates, {n_pts} points each): "
        f"{np.count_nonzero(cost)} with nonzero collision cost; "
        f"max cost towards the obstacle (d_end > 2.5) {left.max():.3g}, "
        f"away from it (d_end < -2.5) {right.max():.3g}"
    )
    assert n_pts == {cycle.n_points}, n_pts
    assert left.max() > 0.0, "collision probability cost is zero next to the obstacle"
    assert right.max() < left.max()


def _main() -> None:
    try:
        _import_frenetix()
    except ImportError as exc:
        print(exc)
        return
    import frenetix

    print(f"frenetix {getattr(frenetix, '__version__', '0.4.0')}: planning cycle medians")
    _check_risk_cost_nonzero(2.0, 0.1)
    ref, ego, obstacles = demo_scene(1, 2.0, 0.1)
    handler = FrenetixCycle(ref, ego, 15, 15, -3.5, 3.5, 2.0, 0.1, obstacles).handler
    for kind, funcs in (
        ("other", handler.get_other_functions()),
        ("feasibility", handler.get_feasability_functions()),
        ("cost", handler.get_cost_functions()),
    ):
        print(f"  {kind:>11}: " + ", ".join(type(f).__name__ for _, f in funcs))
    grids = [(15, 2.0, 20), (45, 3.0, 5)]
    print(
        f"{'trajectories':>13} {'T [s]':>6} {'obstacles':>9} {'median ms':>10} {'p90 ms':>8}"
        f" {'concurrent median ms':>21}"
    )
    for n, horizon, reps in grids:
        for n_obs in (0, 5, 20):
            ref, ego, obstacles = demo_scene(n_obs, horizon, 0.1)
            args = (ref, ego, n, n, -3.5, 3.5, horizon, 0.1, obstacles)
            r = time_frenetix_cycle(*args, repetitions=reps)
            rc = time_frenetix_cycle(*args, repetitions=reps, concurrent=True)
            print(
                f"{r['n_trajectories']:>13} {horizon:>6.1f} {n_obs:>9} "
                f"{r['median_ms']:>10.2f} {r['p90_ms']:>8.2f} {rc['median_ms']:>21.2f}"
            )


if __name__ == "__main__":
    _main()
