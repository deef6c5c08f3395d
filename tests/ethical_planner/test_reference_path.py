import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ethical_planner.reference_path import ReferencePath


def test_arc_length_and_curvature_of_a_circle():
    theta = np.linspace(0, np.pi / 2, 40)
    radius = 30.0
    path = ReferencePath.from_polyline(np.c_[radius * np.cos(theta), radius * np.sin(theta)])
    assert path.length == pytest.approx(np.pi / 2 * radius, rel=1e-4)
    inner = slice(len(path.s) // 10, -len(path.s) // 10)
    np.testing.assert_allclose(path.kappa[inner], 1 / radius, rtol=6e-3)  # spline ripple


@settings(max_examples=50, deadline=None)
@given(s=st.floats(-10, 110), d=st.floats(-5, 5))
def test_frenet_round_trip_on_gentle_curve(s, d):
    x = np.linspace(0, 100, 30)
    path = ReferencePath.from_polyline(np.c_[x, 3 * np.sin(x / 30)])
    xs, ys = path.to_cartesian(np.array([s]), np.array([d]))
    s2, d2 = path.to_frenet(xs, ys)
    assert s2[0] == pytest.approx(s, abs=1e-2)
    assert d2[0] == pytest.approx(d, abs=1e-2)


def test_projection_of_one_point_equals_that_of_many_and_a_brute_force_foot_point():
    # One point finds its nearest sample by comparing every sample, many points by the
    # k-d tree: the same foot points to the bit. Near the path both equal the foot
    # point on the nearest segment found by numpy over every segment.
    theta = np.linspace(0.0, 2.5 * np.pi, 90)
    path = ReferencePath.from_polyline(np.c_[40 * np.cos(theta) + 12 * theta, 25 * np.sin(theta)])
    rng = np.random.default_rng(7)
    s_true = rng.uniform(-5.0, path.length + 5.0, 400)
    d_true = rng.uniform(-4.0, 4.0, 400)
    x, y = path.to_cartesian(s_true, d_true)
    many = path.to_frenet(x, y)
    one = np.array([path.to_frenet(np.array(a), np.array(b)) for a, b in zip(x, y, strict=True)])
    np.testing.assert_array_equal(one[:, 0], many[0])
    np.testing.assert_array_equal(one[:, 1], many[1])
    ax, ay, bx, by = path.x[:-1], path.y[:-1], path.x[1:], path.y[1:]
    ex, ey = bx - ax, by - ay
    u = ((x[:, None] - ax) * ex + (y[:, None] - ay) * ey) / (ex**2 + ey**2)
    u = np.clip(u, 0.0, 1.0)  # points beyond the ends are not compared
    fx, fy = ax + u * ex - x[:, None], ay + u * ey - y[:, None]
    distance = np.hypot(fx, fy)
    nearest = distance.argmin(axis=1)
    inner = (s_true > 0.5) & (s_true < path.length - 0.5)
    np.testing.assert_allclose(np.abs(many[1][inner]), distance[np.arange(400), nearest][inner], atol=1e-9)
    np.testing.assert_allclose(many[1][inner], d_true[inner], atol=0.05)  # the polyline vs the spline


def test_straight_extension_beyond_the_ends():
    path = ReferencePath.from_polyline([[0, 0], [10, 0]])
    x, y = path.to_cartesian(np.array([15.0, -5.0]), np.array([1.0, -1.0]))
    np.testing.assert_allclose(x, [15, -5])
    np.testing.assert_allclose(y, [1, -1])


@pytest.mark.parametrize(
    "points,match",
    [([[0, 0]], "shape"), ([[0, 0], [np.nan, 1]], "finite"), ([[0, 0], [0, 0], [1, 1]], "repeat")],
)
def test_bad_polylines_are_rejected(points, match):
    with pytest.raises(ValueError, match=match):
        ReferencePath.from_polyline(points)


def test_evaluate_is_linear_interpolation_of_the_samples_as_numpy_does_it():
    # The compiled lookup must give numpy.interp's numbers to the bit (the sampling's
    # standing-heading rule reads rounding residues), at the samples, between them and
    # at both ends; beyond the ends the path goes on straight with zero curvature.
    x = np.linspace(0, 100, 30)
    path = ReferencePath.from_polyline(np.c_[x, 3 * np.sin(x / 30)])
    rng = np.random.default_rng(3)
    s = np.concatenate(
        [rng.uniform(0, path.length, 5000), path.s, path.s[1:] - 1e-12, [-4.0, path.length + 7.0]]
    )
    px, py, theta, kappa, dkappa = path.evaluate(s)
    clipped = np.clip(s, 0.0, path.length)
    beyond = s - clipped
    expected_theta = np.interp(clipped, path.s, path.theta)
    np.testing.assert_array_equal(theta, expected_theta)
    np.testing.assert_array_equal(px, np.interp(clipped, path.s, path.x) + beyond * np.cos(expected_theta))
    np.testing.assert_array_equal(py, np.interp(clipped, path.s, path.y) + beyond * np.sin(expected_theta))
    inside = beyond == 0.0
    np.testing.assert_array_equal(kappa, np.where(inside, np.interp(clipped, path.s, path.kappa), 0.0))
    np.testing.assert_array_equal(dkappa, np.where(inside, np.interp(clipped, path.s, path.dkappa), 0.0))
    assert path.evaluate(np.array([[1.0, 2.0]]))[0].shape == (1, 2)  # any shape in, same shape out


@pytest.mark.parametrize("bad", [np.nan, np.inf])
@pytest.mark.parametrize("many", [False, True])
def test_to_frenet_refuses_non_finite_positions(bad, many):
    # One point takes the compiled nearest-sample search, many the k-d tree; neither may
    # return a foot point for a position that is not a number.
    path = ReferencePath.from_polyline(np.c_[np.linspace(0.0, 100.0, 50), np.zeros(50)])
    x = np.full(5000 if many else 1, 10.0)
    x[-1] = bad
    with pytest.raises(ValueError, match="finite"):
        path.to_frenet(x, np.ones_like(x))
