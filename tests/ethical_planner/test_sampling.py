import numpy as np
import pytest

from ethical_planner.config import SamplingConfig, VehicleConfig
from ethical_planner.reference_path import ReferencePath, curvature
from ethical_planner.road_users import KinematicState
from ethical_planner.sampling import (
    CandidateKind,
    PreviousPlan,
    braking_motion,
    continue_plan,
    emergency_braking,
    frenet_state,
    quartic_coefficients,
    quintic_coefficients,
    sample_candidates,
)

VEHICLE = VehicleConfig()
GRID_ONLY = {"brake_candidates": False}


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
    config = SamplingConfig(n_speeds=7, n_offsets=5, horizons=(2.0, 3.0), **GRID_ONLY)
    cands = sample_candidates(frenet_state(KinematicState(5, 0, 0, 10), path), path, config, VEHICLE)
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
    """On a straight path the positions are exact polynomials: finite differences are exact too.

    Braking candidates (lateral shift in arc length) are checked where they are
    physically possible: the violent ones change curvature too fast within one finite-
    difference step for the check to be exact.
    """
    from ethical_planner.validity import physically_invalid

    path = ReferencePath.from_polyline([[0, 0], [300, 0]])
    dt = 0.005
    config = SamplingConfig(n_speeds=4, n_offsets=5, dt=dt, horizons=(2.0,), brake_decelerations=(4.0,))
    cands = sample_candidates(frenet_state(KinematicState(0, 0.3, 0, 10), path), path, config, VEHICLE)
    assert set(cands.kind.tolist()) == {CandidateKind.GRID, CandidateKind.BRAKE}
    possible = ~np.any(list(physically_invalid(cands, VEHICLE).values()), axis=0)
    checked = np.flatnonzero((cands.kind == CandidateKind.GRID) | possible)
    assert (cands.kind[checked] == CandidateKind.BRAKE).sum() >= 3
    inner = slice(5, -5)
    for i in checked:  # test-side loop over an independent reference
        x, y = cands.x[i], cands.y[i]
        dx, dy = np.gradient(x, dt), np.gradient(y, dt)
        ddx, ddy = np.gradient(dx, dt), np.gradient(dy, dt)
        with np.errstate(invalid="ignore"):  # 0 / 0 where a braking candidate stands
            reference_curvature = curvature(dx, dy, ddx, ddy)
        # Away from the kinks of braking candidates (end of the jerk ramp, the stop, the
        # end of the lateral shift), where central differences are off by O(dt).
        jumps = np.flatnonzero(
            (np.abs(np.diff(cands.lon[3, i])) > 1.0)
            | (np.abs(np.diff(cands.lon[2, i])) > 0.5)
            | (np.abs(np.diff(cands.lat[3, i])) > 1.0)
        )
        near_stop = np.zeros(len(x), dtype=bool)
        for j in jumps:
            near_stop[max(j - 4, 0) : j + 5] = True
        smooth = ~near_stop[inner]
        np.testing.assert_allclose(np.hypot(dx, dy)[inner][smooth], cands.v[i, inner][smooth], atol=1e-3)
        moving = (cands.v[i] > 1.0)[inner] & ~near_stop[inner]
        np.testing.assert_allclose(
            reference_curvature[inner][moving], cands.kappa[i, inner][moving], atol=1e-3
        )
        np.testing.assert_allclose(
            np.gradient(cands.v[i], dt)[inner][smooth], cands.a[i, inner][smooth], atol=1e-2
        )
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
        **GRID_ONLY,
    )
    cands = sample_candidates(start, path, config, VEHICLE)
    np.testing.assert_allclose(cands.kappa[0], 1 / (radius - offset), rtol=1e-2)
    np.testing.assert_allclose(cands.v[0], speed_on_path * (1 - offset / radius), rtol=1e-3)


def test_end_speeds_respect_bounds_and_start_state():
    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    start = frenet_state(KinematicState(0, 1.0, 0.0, 3.0), path)
    cands = sample_candidates(start, path, SamplingConfig(), VEHICLE)
    assert cands.end_speed.min() == 0.0
    assert cands.end_speed.max() == pytest.approx(3.0 + 3.0 * 3.0)
    np.testing.assert_allclose(cands.d[:, 0], 1.0)
    np.testing.assert_allclose(cands.v[:, 0], 3.0)


def _integrate_braking(v0, a0, b, jerk, dt=1e-5):
    """Independent reference: explicit integration of the jerk-limited braking law."""
    s, v, a, t = 0.0, v0, a0, 0.0
    while v > 0:
        a = max(a - jerk * dt, -b) if a > -b else min(a + jerk * dt, -b)
        v += a * dt
        s += max(v, 0.0) * dt
        t += dt
    return s, t


@pytest.mark.parametrize("v0,a0,b", [(12.0, 0.0, 8.0), (14.0, 1.0, 4.0), (2.0, 0.0, 8.0), (9.0, -9.0, 6.0)])
def test_braking_motion_stops_where_integration_stops_and_stays(v0, a0, b):
    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    start = frenet_state(KinematicState(0, 0, 0, v0, a=a0), path)
    t = np.arange(41) * 0.1
    lon, stop_distance, stop_time = braking_motion(start, np.array([b]), t, 30.0)
    s_ref, t_ref = _integrate_braking(v0, a0, b, 30.0)
    assert stop_distance[0] == pytest.approx(s_ref, abs=2e-3)
    assert stop_time[0] == pytest.approx(t_ref, abs=2e-3)
    stopped = t >= stop_time[0]
    np.testing.assert_allclose(lon[1, 0, stopped], 0.0)  # stands ...
    np.testing.assert_allclose(lon[0, 0, stopped], stop_distance[0])  # ... where it stopped
    assert np.all(lon[1, 0] >= 0) and np.all(np.diff(lon[0, 0]) >= -1e-12)  # never reverses
    assert lon[2, 0].min() >= min(a0, -b) - 1e-9


def test_braking_by_hand():
    """From 12 m/s at a0 = 0, b = 8, jerk 30: ramp 4/15 s to v 12 - 16/15, then v^2 / 2b."""
    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    start = frenet_state(KinematicState(0, 0, 0, 12.0), path)
    _, stop_distance, stop_time = braking_motion(start, np.array([8.0]), np.arange(31) * 0.1, 30.0)
    t_j = 8.0 / 30.0
    v_j = 12.0 - 0.5 * 30.0 * t_j**2
    s_j = 12.0 * t_j - 30.0 * t_j**3 / 6.0
    assert stop_time[0] == pytest.approx(t_j + v_j / 8.0)
    assert stop_distance[0] == pytest.approx(s_j + v_j**2 / 16.0)


def test_braking_candidates_stop_with_their_lateral_shift_done_and_never_slide():
    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    start = frenet_state(KinematicState(0, 0.0, 0, 12.0), path)
    config = SamplingConfig(n_offsets=3, d_min=-1.0, d_max=1.0, brake_lateral_fractions=(0.5, 1.0))
    cands = sample_candidates(start, path, config, VEHICLE)
    brake = np.flatnonzero(cands.kind == CandidateKind.BRAKE)
    assert sorted(set(cands.deceleration[brake].tolist())) == [2.0, 4.0, 6.0, 8.0]
    hard = brake[(cands.deceleration[brake] == 8.0) & (cands.end_offset[brake] == 1.0)]
    for i in hard:  # stopped within the grid: at rest on its end offset, not moving sideways
        at_rest = cands.v[i] < 1e-9
        assert at_rest[-1]
        np.testing.assert_allclose(cands.d[i, at_rest], 1.0, atol=1e-9)
    # The lateral shift is done at half / all of the braking distance: d(s) in arc length.
    half, full = hard
    s_half = cands.s[half] - start.s
    stop = s_half[-1]
    np.testing.assert_allclose(cands.d[half, s_half >= 0.5 * stop + 1e-6], 1.0, atol=1e-9)
    assert abs(cands.d[full, np.argmin(np.abs(s_half - 0.5 * stop))]) < 0.9


def test_walking_pace_leaves_candidates_that_can_move_sideways():
    """Cause 5: at 1.3 m/s the old 0.2 1/m limit left 12 of 225 candidates valid.

    With the speed-dependent limits and Werling's low-speed mode (lateral shift in arc
    length) a fifth of the grid is physically valid and over a hundred of those end at
    least 1 m to the side; in time-parametrised lateral motion only 18 would.
    """
    from ethical_planner.validity import physically_invalid

    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    start = frenet_state(KinematicState(0, 0, 0, 1.3), path)

    def valid(config):
        cands = sample_candidates(start, path, config, VEHICLE)
        broken = np.any(list(physically_invalid(cands, VEHICLE).values()), axis=0)
        return ~broken, cands

    arc_ok, arc = valid(SamplingConfig(**GRID_ONLY))
    timed_ok, timed = valid(SamplingConfig(low_speed=0.0, **GRID_ONLY))
    sideways = np.abs(arc.end_offset) >= 1.0
    assert arc_ok.mean() > 0.2
    assert (arc_ok & sideways).sum() > 100
    assert (arc_ok & sideways).sum() > 4 * (timed_ok & (np.abs(timed.end_offset) >= 1.0)).sum()
    assert np.abs(arc.yaw[arc_ok]).max() < 0.8  # a valid plan never turns across the road


def test_continuation_is_the_previous_plan_shifted_and_held():
    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    config = SamplingConfig(n_speeds=3, n_offsets=3, horizons=(1.0, 2.0), **GRID_ONLY)
    first = sample_candidates(frenet_state(KinematicState(0, 0, 0, 10), path), path, config, VEHICLE)
    index = int(np.flatnonzero((first.horizon == 1.0) & (first.end_offset == 3.5))[-1])
    previous = PreviousPlan.of(first, index)
    # The ego 0.3 s later, exactly on the plan.
    k = 3
    state = KinematicState(first.x[index, k], first.y[index, k], first.yaw[index, k], first.v[index, k])
    start = frenet_state(state, path)
    part = continue_plan(previous, start, first.t, max_deviation=0.5)
    assert part is not None and part.kind is CandidateKind.CONTINUATION
    lon, lat = part.candidate_lon[:, 0], part.lat[:, 0]
    np.testing.assert_allclose(lon[:, : len(first.t) - k], first.lon[:, index, k:], atol=1e-6)
    np.testing.assert_allclose(lat[:, : len(first.t) - k], first.lat[:, index, k:], atol=1e-6)
    np.testing.assert_allclose(lat[0, -k:], 3.5, atol=1e-9)  # held at its end offset
    assert part.horizon[0] == pytest.approx(0.7)  # remaining horizon
    # An ego far from the plan gets no continuation.
    off = frenet_state(KinematicState(state.x, state.y - 1.0, state.yaw, state.v), path)
    assert continue_plan(previous, off, first.t, max_deviation=0.5) is None


def test_emergency_braking_stops_and_holds_lane_offset():
    path = ReferencePath.from_polyline([[0, 0], [200, 0]])
    start = frenet_state(KinematicState(0, 0.5, 0, 12.0), path)
    t = np.arange(31) * 0.1
    brake = emergency_braking(start, path, t, VEHICLE)
    assert brake.v[0, -1] == pytest.approx(0.0, abs=1e-9)
    s_ref, _ = _integrate_braking(12.0, 0.0, 8.0, 30.0)
    assert brake.x[0, -1] == pytest.approx(s_ref, abs=2e-3)
    np.testing.assert_allclose(brake.y[0], 0.5, atol=1e-9)
    assert brake.kind[0] == CandidateKind.EMERGENCY


def test_shared_longitudinal_motions_give_the_states_of_the_expanded_ones():
    # cartesian_states evaluates the path once per distinct longitudinal motion; indexing
    # them must give exactly the states of the motions written out per candidate.
    from ethical_planner.reference_path import cartesian_states

    path = ReferencePath.from_polyline([[0, 0], [30, 4], [60, 20], [80, 45]])
    start = frenet_state(KinematicState(2.0, 0.3, 0.1, 9.0, a=0.5), path)
    candidates = sample_candidates(start, path, SamplingConfig(), VEHICLE)
    lon = candidates.lon
    assert len(np.unique(lon[0], axis=0)) < lon.shape[1] / 5  # the grid shares its s(t)
    expanded = cartesian_states(lon, np.arange(lon.shape[1]), candidates.lat, path)
    for name, value in zip(("x", "y", "yaw", "v", "a", "kappa"), expanded, strict=True):
        np.testing.assert_array_equal(getattr(candidates, name), value)
    with pytest.raises(ValueError, match="lon_row"):
        cartesian_states(lon, np.full(lon.shape[1], lon.shape[1]), candidates.lat, path)


def test_a_creeping_ego_that_rolls_back_a_little_keeps_its_nose_forward():
    # Regression (curve_truck, 8.2 s): the ego at 2 cm/s braking at 4.5 m/s^2; every
    # quartic starts by rolling back a few mm/s (within the validity check's reversing
    # tolerance), and atan2 of the reversed velocity turned the planned heading by
    # 180 degrees: the tracking controller then spun the standing car into a wall.
    path = ReferencePath.from_polyline([[0.0, 0.0], [200.0, 0.0]])
    start = frenet_state(KinematicState(50.0, -1.0, 0.0, 0.02, a=-4.5), path)
    candidates = sample_candidates(start, path, SamplingConfig(), VEHICLE)
    rolls_back = np.any(candidates.s_dot < 0.0, axis=1)
    assert rolls_back.any()  # the situation of the regression
    lateral_move = np.abs(candidates.d - candidates.d[:, :1]).max(axis=1) < 0.01
    # A motion that stays in its lane keeps the path's heading, forwards or backwards.
    assert np.abs(candidates.yaw[rolls_back & lateral_move]).max() < 0.05


@pytest.mark.parametrize("yaw", [np.pi - 0.3, -np.pi + 0.3])
def test_frenet_heading_across_pi_is_the_wrapped_angle(yaw):
    # A straight path heading west (theta = pi) and an ego 0.3 rad off it, its yaw on
    # either side of +-pi. By hand (kappa = 0): d' = tan(+-0.3), d_dot = v sin(+-0.3).
    # Unwrapped, -pi + 0.3 - pi = -5.98 rad was clipped to -1.2 rad: d' = -2.57, a wild
    # lateral start that diverged in closed loop (SinD 8021_1804: "ego_x must be finite").
    path = ReferencePath.from_polyline(np.column_stack([-np.linspace(0.0, 100.0, 101), np.zeros(101)]))
    start = frenet_state(KinematicState(-50.0, 0.5, yaw, 6.0), path)
    sign = 1.0 if yaw < 0 else -1.0  # -pi + 0.3 lies 0.3 rad counter-clockwise of pi
    assert start.d_prime == pytest.approx(sign * np.tan(0.3), abs=1e-6)
    assert start.d_dot == pytest.approx(sign * 6.0 * np.sin(0.3), abs=1e-6)
    assert start.s_dot == pytest.approx(6.0 * np.cos(0.3), abs=1e-6)
