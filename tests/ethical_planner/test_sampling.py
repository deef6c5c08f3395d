import numpy as np
import pytest

from ethical_planner.config import SamplingConfig
from ethical_planner.reference_path import ReferencePath, curvature
from ethical_planner.road_users import KinematicState
from ethical_planner.sampling import (
    emergency_braking,
    frenet_state,
    quartic_coefficients,
    quintic_coefficients,
    sample_candidates,
)


def _poly(coeffs, t, order=0):
    c = np.polynomial.polynomial.Polynomial(coeffs)
    return c.deriv(order)(t) if order else c(t)


@pytest.mark.parametrize("v0,a0,v_end,horizon", [(10, 0, 5, 2), (3, 1.5, 12, 3), (0, 0, 8, 1)])
def test_quartic_meets_boundary_conditions(v0, a0, v_end, horizon):
    c = quartic_coefficients(2.0, v0, a0, np.array(v_end, float), np.array(horizon, float))
    assert _poly(c, 0) == pytest.approx(2.0)
    assert _poly(c, 0, 1) == pytest.approx(v0)
    assert _poly(c, 0, 2) == pytest.approx(a0)
    assert _poly(c, horizon, 1) == pytest.approx(v_end, abs=1e-9)
    assert _poly(c, horizon, 2) == pytest.approx(0.0, abs=1e-9)


def test_quintic_matches_linear_solve():
    d0, d1, d2, d_end, horizon = 0.4, -0.3, 0.2, 3.5, 2.5
    c = quintic_coefficients(d0, d1, d2, np.array(d_end), np.array(horizon))
    T = horizon
    matrix = np.array([[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4], [6 * T, 12 * T**2, 20 * T**3]])
    rhs = np.array([d_end - d0 - d1 * T - d2 / 2 * T**2, -d1 - d2 * T, -d2])
    np.testing.assert_allclose(c[3:], np.linalg.solve(matrix, rhs), rtol=1e-12)
    np.testing.assert_allclose(c[:3], [d0, d1, d2 / 2])


def test_curvature_formula_on_circle_and_operator_precedence():
    theta = np.linspace(0, 1, 5)
    radius = 7.0
    dx, dy = -radius * np.sin(theta), radius * np.cos(theta)
    ddx, ddy = -radius * np.cos(theta), -radius * np.sin(theta)
    np.testing.assert_allclose(curvature(dx, dy, ddx, ddy), 1 / radius)
    # Non-unit parameter speed: x = t, y = t^2 at t = 1 -> kappa = 2 / 5^(3/2).
    assert curvature(np.array(1.0), np.array(2.0), np.array(0.0), np.array(2.0)) == pytest.approx(2 / 5**1.5)


def test_grid_shape_and_struct_of_arrays():
    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    config = SamplingConfig(n_speeds=7, n_offsets=5, horizons=(2.0, 3.0))
    cands = sample_candidates(frenet_state(KinematicState(5, 0, 0, 10), path), path, config, 40)
    assert cands.x.shape == (70, 31)
    assert cands.t[-1] == pytest.approx(3.0)
    # The 2 s candidates continue at constant speed and offset after their horizon.
    short = cands.horizon == 2.0
    np.testing.assert_allclose(
        cands.v[short, 20:], np.repeat(cands.end_speed[short, None], 11, axis=1), atol=1e-9
    )
    np.testing.assert_allclose(
        cands.d[short, 20:], np.repeat(cands.end_offset[short, None], 11, axis=1), atol=1e-9
    )


def test_cartesian_states_agree_with_finite_differences():
    """On a straight path the positions are exact polynomials: finite differences are exact too."""
    path = ReferencePath.from_polyline([[0, 0], [300, 0]])
    dt = 0.005
    config = SamplingConfig(n_speeds=4, n_offsets=5, dt=dt, horizons=(2.0,))
    cands = sample_candidates(frenet_state(KinematicState(0, 0.3, 0, 10), path), path, config, 30)
    inner = slice(5, -5)
    for i in range(cands.n_traj):  # test-side loop over an independent reference
        x, y = cands.x[i], cands.y[i]
        dx, dy = np.gradient(x, dt), np.gradient(y, dt)
        ddx, ddy = np.gradient(dx, dt), np.gradient(dy, dt)
        np.testing.assert_allclose(np.hypot(dx, dy)[inner], cands.v[i, inner], atol=1e-3)
        moving = cands.v[i, inner] > 1.0
        np.testing.assert_allclose(
            curvature(dx, dy, ddx, ddy)[inner][moving], cands.kappa[i, inner][moving], atol=1e-3
        )
        np.testing.assert_allclose(np.gradient(cands.v[i], dt)[inner], cands.a[i, inner], atol=1e-2)
        heading = np.arctan2(dy, dx)
        np.testing.assert_allclose(
            np.angle(np.exp(1j * (heading - cands.yaw[i])))[inner][moving], 0, atol=1e-4
        )


@pytest.mark.parametrize("offset", [-3.0, 0.0, 2.0])
def test_constant_offset_on_a_circle_has_the_offset_curvature(offset):
    """Driving parallel to a circle of radius R at offset d: kappa = 1 / (R - d), v = s' (1 - d / R)."""
    radius = 60.0
    theta = np.linspace(0, np.pi, 120)
    path = ReferencePath.from_polyline(np.c_[radius * np.sin(theta), radius - radius * np.cos(theta)])
    speed_on_path = 8.0
    x0, y0 = path.to_cartesian(np.array(20.0), np.array(offset))
    yaw0 = float(path.heading(20.0))
    state = KinematicState(float(x0), float(y0), yaw0, speed_on_path * (1 - offset / radius))
    start = frenet_state(state, path)
    config = SamplingConfig(
        n_speeds=1,
        n_offsets=1,
        d_min=offset,
        d_max=offset,
        max_end_acceleration=1e-9,
        max_end_deceleration=1e-9,
    )
    cands = sample_candidates(start, path, config, 30)
    np.testing.assert_allclose(cands.kappa[0], 1 / (radius - offset), rtol=1e-2)
    np.testing.assert_allclose(cands.v[0], speed_on_path * (1 - offset / radius), rtol=1e-3)


def test_end_speeds_respect_bounds_and_start_state():
    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    start = frenet_state(KinematicState(0, 1.0, 0.0, 3.0), path)
    cands = sample_candidates(start, path, SamplingConfig(), 50)
    assert cands.end_speed.min() == 0.0
    assert cands.end_speed.max() == pytest.approx(3.0 + 4.0 * 2.0)
    np.testing.assert_allclose(cands.d[:, 0], 1.0)
    np.testing.assert_allclose(cands.v[:, 0], 3.0)


def test_emergency_braking_stops_and_holds_lane_offset():
    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    start = frenet_state(KinematicState(0, 0.5, 0, 12.0), path)
    t = np.arange(31) * 0.1
    brake = emergency_braking(start, path, t, 8.0)
    assert brake.v[0, -1] == pytest.approx(0.0, abs=1e-9)
    assert brake.x[0, -1] == pytest.approx(12.0**2 / 16.0)
    np.testing.assert_allclose(brake.y[0], 0.5, atol=1e-9)
