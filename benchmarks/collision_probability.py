"""Time ``collision_probability`` on planner-sized problems and print a table.

Scene: a three-lane road (lanes at y = -3.5, 0, 3.5 m), the ego in the middle lane
at 12 m/s, candidates fanning out over end lateral offsets and end speeds, 20 road
users (pedestrians to trucks) 5-60 m ahead on the three lanes, driving 0-15 m/s,
their covariance growing over the 3 s horizon.

Columns: survivors of the distance gate, Owen's T evaluations of the fast kernel
(two per edge that can matter), median wall time on one and on two threads
(ETHICAL_PLANNER_THREADS), time per survivor on one thread.

Run: python benchmarks/collision_probability.py
"""

from __future__ import annotations

import math
import os
import statistics
import time

import numpy as np

import ethical_planner.collision_probability as cp

HORIZON = 3.0  # [s]
LANES = (-3.5, 0.0, 3.5)  # [m]
SHAPES = [(0.5, 0.5), (1.8, 0.7), (4.5, 1.8), (4.5, 1.8), (10.0, 2.5)]  # [m]


def candidates(n_lat: int, n_speed: int, n_t: int):
    t = np.linspace(0.0, HORIZON, n_t)
    y_end = np.repeat(np.linspace(-4.5, 4.5, n_lat), n_speed)[:, None]
    v_end = np.tile(np.linspace(0.0, 20.0, n_speed), n_lat)[:, None]
    v0 = 12.0
    s = t / HORIZON
    x = v0 * t + (v_end - v0) * t**2 / (2 * HORIZON)
    y = y_end * (3 * s**2 - 2 * s**3)
    dx = v0 + (v_end - v0) * t / HORIZON
    dy = y_end * (6 * s - 6 * s**2) / HORIZON
    return x, y, np.arctan2(dy, np.maximum(dx, 1e-3))


def road_users(n_obs: int, n_t: int, rng: np.random.Generator):
    t = np.linspace(0.0, HORIZON, n_t)
    x0 = rng.uniform(5.0, 60.0, n_obs)
    lane = rng.choice(LANES, n_obs)
    speed = rng.uniform(0.0, 15.0, n_obs)
    heading = rng.normal(0.0, 0.05, n_obs)
    mean = np.stack(
        [
            x0[:, None] + speed[:, None] * np.cos(heading)[:, None] * t,
            lane[:, None] + speed[:, None] * np.sin(heading)[:, None] * t,
        ],
        axis=-1,
    )
    sig_long = 0.3 + 0.6 * t  # [m]
    sig_lat = 0.2 + 0.2 * t  # [m]
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    cov = np.empty((n_obs, n_t, 2, 2))
    cov[..., 0, 0] = (c * sig_long) ** 2 + (s * sig_lat) ** 2
    cov[..., 1, 1] = (s * sig_long) ** 2 + (c * sig_lat) ** 2
    cov[..., 0, 1] = cov[..., 1, 0] = c * s * (sig_long**2 - sig_lat**2)
    shapes = np.array([SHAPES[i] for i in rng.integers(len(SHAPES), size=n_obs)])
    return mean, cov, np.repeat(heading[:, None], n_t, axis=1), shapes[:, 0], shapes[:, 1]


def count_owens_t(args, gate_sigmas):
    """Return (result, survivors, Owen's T evaluations) of one call, by wrapping the kernel."""
    calls = 0
    real = cp._owens_t_unit

    def counting(h, a):
        nonlocal calls
        calls += np.size(h)
        return real(h, a)

    cp._owens_t_unit = counting
    try:
        result = cp.collision_probability(*args, gate_sigmas=gate_sigmas)
    finally:
        cp._owens_t_unit = real
    ex, ey = args[0], args[1]
    mean, cov, length, width = args[5], args[6], args[8], args[9]
    sigma = np.sqrt(np.linalg.eigvalsh(cov)[..., -1])
    reach = 0.5 * math.hypot(args[3], args[4]) + 0.5 * np.hypot(length, width)[:, None]
    reach = reach + gate_sigmas * sigma
    dist = np.hypot(ex[:, None] - mean[None, ..., 0], ey[:, None] - mean[None, ..., 1])
    survivors = int(np.count_nonzero(dist <= reach))
    return result, survivors, calls


def median_ms(args, gate, reps, threads):
    """Median wall time [ms] of ``reps`` calls with ``threads`` threads, after a warm-up."""
    previous = os.environ.get("ETHICAL_PLANNER_THREADS")
    os.environ["ETHICAL_PLANNER_THREADS"] = str(threads)
    try:
        cp.collision_probability(*args, gate_sigmas=gate)
        times = []
        for _ in range(reps):
            start = time.perf_counter()
            cp.collision_probability(*args, gate_sigmas=gate)
            times.append(time.perf_counter() - start)
    finally:
        if previous is None:
            del os.environ["ETHICAL_PLANNER_THREADS"]
        else:
            os.environ["ETHICAL_PLANNER_THREADS"] = previous
    return statistics.median(times) * 1e3


def main() -> None:
    rows = []
    for n_lat, n_speed, n_obs, n_t, gate, reps in [
        (15, 15, 20, 21, 6.0, 15),
        (45, 45, 20, 31, 6.0, 7),
        (15, 15, 20, 21, math.inf, 3),
    ]:
        x, y, yaw = candidates(n_lat, n_speed, n_t)
        # The same road users for the same sizes, so gated and ungated rows compare.
        mean, cov, heading, length, width = road_users(n_obs, n_t, np.random.default_rng(0))
        args = (x, y, yaw, 4.508, 1.610, mean, cov, heading, length, width)
        result, survivors, calls = count_owens_t(args, gate)
        one = median_ms(args, gate, reps, threads=1)
        two = median_ms(args, gate, reps, threads=2)
        triples = x.shape[0] * n_obs * n_t
        rows.append(
            (
                f"{x.shape[0]} x {n_obs} x {n_t}",
                gate,
                triples,
                survivors / triples,
                calls,
                one,
                two,
                one / max(survivors, 1) * 1e3,
                float(result.probability.max()),
            )
        )
    header = (
        f"{'n_traj x n_obs x n_t':>22} {'gate':>5} {'triples':>9} {'survive':>8} "
        f"{'owens_t':>9} {'1 thread ms':>12} {'2 threads ms':>13} {'us/surv':>8} {'max p':>6}"
    )
    print(header)
    print("-" * len(header))
    for shape, gate, triples, frac, calls, one, two, us, pmax in rows:
        print(
            f"{shape:>22} {gate:>5} {triples:>9d} {frac:>8.1%} {calls:>9d} {one:>12.1f} "
            f"{two:>13.1f} {us:>8.2f} {pmax:>6.3f}"
        )


if __name__ == "__main__":
    main()
