import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from ethical_planner.dv_correction import DeltaVCorrection
from ethical_planner.geometry import impact_offset_fraction, velocity_angle
from ethical_planner.harm import collision_harm

EGO = (4.0, 2.0)  # length, width [m]


def offset(ego_pos, ego_vel, ego_yaw, obs_pos, obs_vel, obs_yaw, ego=EGO, obs=EGO):
    return impact_offset_fraction(ego_pos, ego_vel, ego_yaw, *ego, obs_pos, obs_vel, obs_yaw, *obs)


def scalar_offset(ep, ev, eyaw, el, ew, op, ov, oyaw, ol, ow):
    """Plain per-impact version: distance to the approach line over the sum of half-extents."""
    w = (ov[0] - ev[0], ov[1] - ev[1])
    speed = math.hypot(*w)
    if speed <= 1e-9:
        return 0.0
    n = (-w[1] / speed, w[0] / speed)
    dist = abs((op[0] - ep[0]) * n[0] + (op[1] - ep[1]) * n[1])

    def half(yaw, length, width):
        corners = [(sx * length / 2, sy * width / 2) for sx in (-1, 1) for sy in (-1, 1)]
        c, s = math.cos(yaw), math.sin(yaw)
        return max((c * x - s * y) * n[0] + (s * x + c * y) * n[1] for x, y in corners)

    return min(1.0, dist / (half(eyaw, el, ew) + half(oyaw, ol, ow)))


# ------------------------------------------------------------------ offset fraction by hand


def test_central_impact_is_zero():
    # ego drives at the parked car dead ahead; and a T-bone aimed at the ego's centre
    assert offset([0, 0], [10, 0], 0.0, [8, 0], [0, 0], 0.0) == pytest.approx(0.0)
    assert offset([0, 0], [0, 0], 0.0, [0, 5], [0, -8], -math.pi / 2) == pytest.approx(0.0)


def test_grazing_impact_is_one_and_beyond_is_clipped():
    # same headings, lateral distance = half width + half width = 2 m: the sides just touch
    assert offset([0, 0], [10, 0], 0.0, [8, 2.0], [0, 0], 0.0) == pytest.approx(1.0)
    assert offset([0, 0], [10, 0], 0.0, [8, 3.5], [0, 0], 0.0) == 1.0
    # partner turned by 90 deg: its half-length (2 m) faces the approach line, reach 1 + 2 m
    assert offset([0, 0], [10, 0], 0.0, [8, 1.5], [0, 0], math.pi / 2) == pytest.approx(0.5)


def test_rotated_square_by_hand():
    # 2 x 2 squares, partner rotated 45 deg: half-extents 1 and sqrt(2)
    out = offset([0, 0], [5, 0], 0.0, [6, 1.0], [0, 0], math.pi / 4, ego=(2, 2), obs=(2, 2))
    assert out == pytest.approx(1.0 / (1.0 + math.sqrt(2)))


def test_offset_is_symmetric():
    args = ([0.3, -0.2], [9.0, 1.0], 0.1, [7.0, 1.1], [-2.0, 4.0], 2.0)
    base = offset(*args)
    assert 0.0 < base < 1.0
    # swapping ego and partner (their shapes too), and mirroring the scene left-right
    ep, ev, ey, op, ov, oy = args
    assert offset(op, ov, oy, ep, ev, ey) == pytest.approx(base)
    mirror = np.array([1.0, -1.0])
    assert offset(np.multiply(ep, mirror), np.multiply(ev, mirror), -ey, np.multiply(op, mirror),
                  np.multiply(ov, mirror), -oy) == pytest.approx(base)  # fmt: skip
    # a partner on the other side of the approach line at the same distance
    assert offset([0, 0], [10, 0], 0.0, [8, -0.7], [0, 0], 0.0) == pytest.approx(
        offset([0, 0], [10, 0], 0.0, [8, 0.7], [0, 0], 0.0)
    )


def test_invariant_along_the_approach():
    ev, ov = np.array([10.0, 0.0]), np.array([-3.0, 5.0])
    op = np.array([12.0, -6.0])
    shifted = op + 0.37 * (ov - ev)
    assert offset([0, 0], ev, 0.0, shifted, ov, 2.1) == pytest.approx(offset([0, 0], ev, 0.0, op, ov, 2.1))


def test_no_relative_motion_gives_zero():
    assert offset([0, 0], [5, 0], 0.0, [0, 1.0], [5, 0], 0.0) == 0.0


def test_vectorised_matches_scalar_and_broadcasts():
    rng = np.random.default_rng(3)
    ep = rng.normal(0, 3, (5, 1, 2))
    ev = rng.normal(0, 8, (5, 1, 2))
    ey = rng.uniform(-math.pi, math.pi, (5, 1))
    op = rng.normal(0, 3, (1, 4, 2))
    ov = rng.normal(0, 8, (1, 4, 2))
    oy = rng.uniform(-math.pi, math.pi, (1, 4))
    ol, ow = np.array([[4.5, 0.5, 12.0, 2.0]]), np.array([[1.8, 0.5, 2.5, 0.8]])
    out = impact_offset_fraction(ep, ev, ey, 4.508, 1.61, op, ov, oy, ol, ow)
    assert out.shape == (5, 4)
    for i in range(5):
        for k in range(4):
            expected = scalar_offset(ep[i, 0], ev[i, 0], ey[i, 0], 4.508, 1.61, op[0, k], ov[0, k], oy[0, k],
                                     ol[0, k], ow[0, k])  # fmt: skip
            assert out[i, k] == pytest.approx(expected, abs=1e-12)


coord = st.floats(-50, 50, allow_nan=False)
speed = st.floats(-30, 30, allow_nan=False)
yaw = st.floats(-7, 7, allow_nan=False)
size = st.floats(0.3, 15, allow_nan=False)


@given(coord, coord, speed, speed, yaw, coord, coord, speed, speed, yaw, size, size)
def test_offset_in_unit_interval_and_swap_symmetric(ex, ey, evx, evy, eyaw, ox, oy, ovx, ovy, oyaw, ln, wd):
    a = impact_offset_fraction([ex, ey], [evx, evy], eyaw, 4.5, 1.8, [ox, oy], [ovx, ovy], oyaw, ln, wd)
    b = impact_offset_fraction([ox, oy], [ovx, ovy], oyaw, ln, wd, [ex, ey], [evx, evy], eyaw, 4.5, 1.8)
    assert 0.0 <= float(a) <= 1.0
    assert float(a) == pytest.approx(float(b), abs=1e-9)


def test_offset_rejects_bad_shapes():
    with pytest.raises(ValueError, match="obs_width"):
        impact_offset_fraction([0, 0], [1, 0], 0.0, 4.0, 2.0, [5, 0], [0, 0], 0.0, 4.0, 0.0)
    with pytest.raises(ValueError, match="ego_vel"):
        impact_offset_fraction([0, 0], [1, 0, 0], 0.0, 4.0, 2.0, [5, 0], [0, 0], 0.0, 4.0, 2.0)


def test_velocity_angle():
    out = velocity_angle([[10, 0], [10, 0], [10, 0], [0, 0]], [[5, 0], [0, 3], [-2, 0], [0, 0]], 0.0,
                         [0.0, 0.0, 0.0, -math.pi / 2])  # fmt: skip
    np.testing.assert_allclose(out, [0.0, math.pi / 2, math.pi, math.pi / 2], atol=1e-12)


# ------------------------------------------------------------------ the correction table


def table():
    return DeltaVCorrection((0.0, 90.0, 180.0), (0.0, 0.5, 1.0), ((1.0, 0.5), (1.2, 0.8)), ((3, 4), (5, 6)))


def test_factor_lookup_folds_angles_and_clips_offsets():
    corr = table()
    angle = np.array([0.1, -0.1, math.pi - 0.1, 2 * math.pi + 0.1])[:, None]
    off = np.array([0.0, 0.7, 1.0, 1.5, -0.2])
    out = corr.factor(angle, off)
    assert out.shape == (4, 5)
    np.testing.assert_allclose(out[0], [1.0, 0.5, 0.5, 0.5, 1.0])
    np.testing.assert_allclose(out[2], [1.2, 0.8, 0.8, 0.8, 1.2])
    np.testing.assert_allclose(out[3], out[0])
    assert float(corr(10.0, math.pi, 0.9)) == pytest.approx(8.0)
    assert math.isnan(float(corr.factor(1.0, math.nan)))


def test_identity_is_one():
    assert float(DeltaVCorrection.identity()(7.0, 2.0, 0.3)) == 7.0


def test_json_round_trip(tmp_path):
    corr = table()
    path = tmp_path / "dv.json"
    corr.save(path)
    loaded = DeltaVCorrection.load(path)
    assert loaded == corr
    assert loaded.shape == (2, 2)
    assert DeltaVCorrection.from_dict(json.loads(json.dumps(corr.to_dict()))) == corr
    # n_train may be left out
    data = corr.to_dict()
    del data["n_train"]
    assert DeltaVCorrection.from_dict(data).factors == corr.factors


def test_from_dict_names_unknown_and_missing_keys(tmp_path):
    data = table().to_dict()
    with pytest.raises(ValueError, match=r"unknown keys \['scale'\]"):
        DeltaVCorrection.from_dict(data | {"scale": 2.0})
    without = {k: v for k, v in data.items() if k != "offset_edges"}
    with pytest.raises(ValueError, match=r"missing keys \['offset_edges'\]"):
        DeltaVCorrection.from_dict(without)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(without))
    with pytest.raises(ValueError, match="bad.json.*offset_edges"):
        DeltaVCorrection.load(path)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"angle_edges_deg": (0.0, 90.0)}, "180"),
        ({"offset_edges": (0.0, 0.6, 0.5, 1.0)}, "increase"),
        ({"factors": ((1.0, 0.5),)}, r"shape \(2, 2\)"),
        ({"factors": ((1.0, 0.5), (1.0, 0.0))}, "> 0"),
        ({"n_train": ((1,), (2,))}, "n_train"),
    ],
)
def test_invalid_correction(kwargs, match):
    args = {
        "angle_edges_deg": (0.0, 90.0, 180.0),
        "offset_edges": (0.0, 0.5, 1.0),
        "factors": ((1.0, 0.5), (1.2, 0.8)),
    }
    with pytest.raises(ValueError, match=match):
        DeltaVCorrection(**(args | kwargs))


# ------------------------------------------------------------------ collision_harm


def crash(**extra):
    """Ego at 15 m/s hits a parked car side-on, its centre either on the approach line or 1.5 m off."""
    return collision_harm(
        ego_mass=1500.0,
        ego_vel=[15.0, 0.0],
        ego_pos=[0.0, 0.0],
        ego_yaw=0.0,
        obs_mass=1500.0,
        obs_vel=[0.0, 0.0],
        obs_pos=[[3.5, 0.0], [3.5, 1.5]],
        obs_yaw=math.pi / 2,
        obs_unprotected=np.array([False, False]),
        **extra,
    )


def test_correction_changes_dv_and_harm():
    plain = crash()
    corr = DeltaVCorrection((0.0, 180.0), (0.0, 0.25, 1.0), ((1.0, 0.5),))
    fixed = crash(dv_correction=corr, ego_shape=(4.5, 1.8), obs_shape=([4.5, 4.5], [1.8, 1.8]))
    # offsets: 0 (factor 1) and 1.5 / (0.9 + 2.25) = 0.48 (factor 0.5); both bodies alike
    np.testing.assert_allclose(fixed.dv_ego, plain.dv_ego * [1.0, 0.5])
    np.testing.assert_allclose(fixed.dv_obs, plain.dv_obs * [1.0, 0.5])
    assert fixed.harm_ego[0] == pytest.approx(plain.harm_ego[0])
    assert fixed.harm_obs[0] == pytest.approx(plain.harm_obs[0])
    assert fixed.harm_ego[1] < plain.harm_ego[1] and fixed.harm_obs[1] < plain.harm_obs[1]
    np.testing.assert_array_equal(fixed.ego_angle, plain.ego_angle)


def test_without_correction_shapes_are_ignored():
    plain = crash()
    with_shapes = crash(ego_shape=(4.5, 1.8), obs_shape=(4.5, 1.8))
    identity = crash(dv_correction=DeltaVCorrection.identity(), ego_shape=(4.5, 1.8), obs_shape=(4.5, 1.8))
    for result in (with_shapes, identity):
        np.testing.assert_array_equal(result.harm_ego, plain.harm_ego)
        np.testing.assert_array_equal(result.harm_obs, plain.harm_obs)
        np.testing.assert_array_equal(result.dv_ego, plain.dv_ego)


def test_correction_needs_shapes():
    with pytest.raises(ValueError, match="ego_shape"):
        crash(dv_correction=DeltaVCorrection.identity(), obs_shape=(4.5, 1.8))
