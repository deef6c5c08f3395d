"""Recorded trajectories as references: the Hermite spline against independent checks."""

import math

import numpy as np
import pytest

from mujoco_world.scenario.imported import RecordedTrajectory
from mujoco_world.scenario.recorded_tracks import RecordedTracks


def _track(start=1.0, dt=0.2, n=12, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    x = 5.0 * t + 0.8 * t**2 + rng.normal(0, 0.05, n)
    y = 2.0 * np.sin(0.7 * t) + rng.normal(0, 0.05, n)
    yaw = np.arctan2(np.gradient(y), np.gradient(x))
    return RecordedTrajectory(start, dt, tuple(x), tuple(y), tuple(yaw))


def test_the_spline_passes_through_the_recorded_states_with_central_difference_velocities():
    tr = _track()
    tracks = RecordedTracks([tr, _track(start=0.0, dt=0.1, n=5, seed=1)])
    for k in range(1, tr.states - 1):
        p, v, _, yaw, _ = tracks.sample(tr.start + k * tr.dt)
        assert p[0] == pytest.approx((tr.x[k], tr.y[k]), abs=1e-9)
        central = ((tr.x[k + 1] - tr.x[k - 1]) / (2 * tr.dt), (tr.y[k + 1] - tr.y[k - 1]) / (2 * tr.dt))
        assert v[0] == pytest.approx(central, abs=1e-9)
        assert yaw[0] == pytest.approx(tr.yaw[k], abs=1e-9)


def test_velocity_and_acceleration_are_the_derivatives_of_the_position():
    tracks = RecordedTracks([_track()])
    h = 1e-5
    for t in np.linspace(1.01, 3.1, 17):
        p0, v, a, _, _ = tracks.sample(t)
        pm, vm, _, _, _ = tracks.sample(t - h)
        pp, vp, _, _, _ = tracks.sample(t + h)
        assert v[0] == pytest.approx((pp[0] - pm[0]) / (2 * h), abs=1e-4)
        assert a[0] == pytest.approx((vp[0] - vm[0]) / (2 * h), abs=1e-3)


def test_presence_and_standing_outside_the_recording():
    tr = _track(start=1.0, dt=0.2, n=12)
    tracks = RecordedTracks([tr])
    assert not tracks.present(0.9)[0] and tracks.present(1.0)[0] and tracks.present(tr.end)[0]
    assert not tracks.present(tr.end + 0.01)[0]
    p, v, a, _, rate = tracks.sample(tr.end + 1.0)
    assert p[0] == pytest.approx((tr.x[-1], tr.y[-1])) and not v.any() and not a.any() and rate[0] == 0.0


def test_peak_acceleration_matches_dense_sampling():
    tr = _track(n=15, seed=3)
    tracks = RecordedTracks([tr])
    peak = tracks.peak_accelerations()[0]
    times = np.linspace(tr.start, tr.end, 4001)
    dense = max(float(np.hypot(*tracks.sample(t)[2][0])) for t in times)
    assert peak.value == pytest.approx(dense, rel=2e-3)
    at = np.hypot(*tracks.sample(peak.time - 1e-9)[2][0]), np.hypot(*tracks.sample(peak.time + 1e-9)[2][0])
    assert max(at) == pytest.approx(peak.value, rel=1e-6)


def test_a_recording_needs_two_consistent_states():
    with pytest.raises(ValueError, match="at least two states"):
        RecordedTrajectory(0.0, 0.1, (1.0,), (1.0,), (0.0,))
    with pytest.raises(ValueError, match="one value per state"):
        RecordedTrajectory(0.0, 0.1, (1.0, 2.0), (1.0,), (0.0, 0.0))
    with pytest.raises(ValueError, match="trajectory.dt must be > 0"):
        RecordedTrajectory(0.0, 0.0, (1.0, 2.0), (1.0, 1.0), (0.0, 0.0))
    with pytest.raises(ValueError, match="trajectory.x must hold finite numbers"):
        RecordedTrajectory(0.0, 0.1, (1.0, math.nan), (1.0, 1.0), (0.0, 0.0))
