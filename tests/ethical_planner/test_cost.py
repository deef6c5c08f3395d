import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from ethical_planner.config import CostWeights
from ethical_planner.cost import bayes, equality, maximin, responsibility, risk_set, total_cost
from ethical_planner.validity import Validity

risk_rows = arrays(np.float64, st.tuples(st.integers(1, 4), st.integers(0, 9)), elements=st.floats(0, 1))


def _equality_scalar(row):
    pairs = list(itertools.combinations(row, 2))
    return sum(abs(a - b) for a, b in pairs) / len(pairs) if pairs else 0.0


@settings(max_examples=100, deadline=None)
@given(risk_rows)
def test_equality_matches_all_pairs(risks):
    expected = [_equality_scalar(list(row)) for row in risks]
    np.testing.assert_allclose(equality(risks), expected, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(risk_rows)
def test_bayes_is_the_mean_and_responsibility_never_exceeds_it(risks):
    expected = [float(np.mean(row)) if len(row) else 0.0 for row in risks]
    np.testing.assert_allclose(bayes(risks), expected)
    r = np.full_like(risks, 0.9)
    assert np.all(responsibility(risks, r) <= bayes(risks) + 1e-15)


def test_hand_computed_principles():
    risks = np.array([[0.1, 0.3, 0.0]])
    assert bayes(risks)[0] == pytest.approx(0.4 / 3)
    # pairs: |0.1-0.3| + |0.1-0| + |0.3-0| = 0.6, three pairs
    assert equality(risks)[0] == pytest.approx(0.2)
    harms = np.array([[0.5, 0.8, 0.9]])
    counted = np.array([[True, True, False]])  # 0.9 has negligible probability
    assert maximin(harms, counted, gamma=2.0)[0] == pytest.approx(0.64)
    assert responsibility(risks, np.array([[0.5, 0.0, 0.2]]))[0] == pytest.approx(0.05 / 3)


def test_total_cost_uses_eq5_for_valid_and_eq6_otherwise():
    weights = CostWeights(
        risk=10.0,
        bayes=1.0,
        equality=0.0,
        maximin=0.0,
        jerk_lon=1.0,
        jerk_lat=0.0,
        speed=2.0,
        path_distance=0.0,
    )
    risks = np.array([[0.2], [0.2]])
    zeros = np.zeros((2, 1))
    costs = total_cost(
        risks,
        np.ones((2, 1), dtype=bool),
        zeros,
        zeros,
        zeros.astype(bool),
        np.zeros(2),
        np.array([3.0, 3.0]),
        np.zeros(2),
        np.array([1.5, 1.5]),
        np.zeros(2),
        np.zeros(2),
        np.array([Validity.VALID, Validity.COLLISION]),
        weights,
    )
    assert costs.total[0] == pytest.approx(10 * 0.2 + 3.0 + 2 * 1.5)
    assert costs.total[1] == pytest.approx(0.2)
    assert costs.row(0)["comfort"] == pytest.approx(3.0)


def test_empty_risk_set_costs_nothing():
    empty = np.zeros((3, 0))
    assert np.all(bayes(empty) == 0) and np.all(equality(empty) == 0)
    assert np.all(maximin(empty, empty.astype(bool), 10.0) == 0)


@settings(max_examples=100, deadline=None)
@given(risk_rows, st.data())
def test_masked_principles_use_only_the_entries_present(risks, data):
    present = data.draw(arrays(np.bool_, risks.shape))
    rows = list(zip(risks, present, strict=True))
    expected_e = [_equality_scalar(list(row[keep])) for row, keep in rows]
    expected_b = [float(np.mean(row[keep])) if keep.any() else 0.0 for row, keep in rows]
    np.testing.assert_allclose(equality(risks, present), expected_e, atol=1e-12)
    np.testing.assert_allclose(bayes(risks, present), expected_b, atol=1e-15)


def test_risk_set_is_the_papers_2k_entries_on_the_road():
    """Issue 9's example: one road user, candidates A (R_1, R_ego,1) = (0.010, 0.010) and
    B = (0.009, 0.000), both on the road, w_B = w_E = 1.

    By hand (Eqs. 8, 9 with |S_R| = 2): A: J_B = 0.010, J_E = 0 -> 0.010;
    B: J_B = 0.0045, J_E = 0.009 -> 0.0135. The paper prefers A. With an extra entry of
    0 for the road edge (|S_R| = 3) J_B + J_E would be A: 0.0133, B: 0.0090, the other
    way round.
    """
    risk_obs = np.array([[0.010], [0.009]])
    risk_ego = np.array([[0.010], [0.000]])
    on_road = np.zeros(2, dtype=bool)
    risks, present = risk_set(risk_obs, risk_ego, np.zeros(2), on_road)
    assert present.sum(axis=1).tolist() == [2, 2]
    np.testing.assert_allclose(bayes(risks, present), [0.010, 0.0045])
    np.testing.assert_allclose(equality(risks, present), [0.0, 0.009])
    weights = CostWeights(risk=1.0, bayes=1.0, equality=1.0, maximin=0.0, jerk_lon=0, jerk_lat=0, speed=0)
    costs = total_cost(
        risks,
        present,
        np.zeros_like(risks),
        np.zeros_like(risks),
        np.zeros(risks.shape, dtype=bool),
        np.zeros(2),
        np.zeros(2),
        np.zeros(2),
        np.zeros(2),
        np.zeros(2),
        np.zeros(2),
        np.full(2, int(Validity.VALID)),
        weights,
    )
    np.testing.assert_allclose(costs.risk, [0.010, 0.0135])
    assert costs.total[0] < costs.total[1]
    # The old set, every entry present (a road-edge risk of 0 counted): the preference flips.
    flipped = bayes(risks) + equality(risks)
    np.testing.assert_allclose(flipped, [0.02 / 3 + 0.02 / 3, 0.009 / 3 + 0.018 / 3])
    assert flipped[0] > flipped[1]


def test_leaving_the_road_adds_the_egos_road_edge_risk_to_its_set():
    risks, present = risk_set(np.array([[0.0]]), np.array([[0.0]]), np.array([0.06]), np.array([True]))
    assert present.sum() == 3
    assert bayes(risks, present)[0] == pytest.approx(0.02)
    assert equality(risks, present)[0] == pytest.approx((0.0 + 0.06 + 0.06) / 3)


@pytest.mark.parametrize(
    ("weights", "j_risk"),
    [
        # S_R = (0.1, 0.3): J_B = 0.2, J_E = |0.1 - 0.3| = 0.2, J_M = max harm 0.5 (gamma 1),
        # J_R = (0.5 * 0.1 + 0 * 0.3) / 2 = 0.025, R_ego = 0.2
        ({"bayes": 1.0}, 0.2),
        ({"equality": 1.0}, 0.2),
        ({"maximin": 1.0}, 0.5),
        ({"bayes": 1.0, "responsibility": 1.0}, 0.2 - 0.025),
        ({"bayes": 2.0, "responsibility": 0.5}, 2 * 0.2 - 0.5 * 2 * 0.025),
        ({"ego_risk": 1.0}, 0.2),
    ],
)
def test_each_principle_enters_eq7_with_its_sign(weights, j_risk):
    zero = {"bayes": 0.0, "equality": 0.0, "maximin": 0.0, "responsibility": 0.0, "ego_risk": 0.0}
    w = CostWeights(**(zero | weights | {"risk": 2.0, "maximin_gamma": 1.0, "jerk_lon": 1.0, "speed": 2.0}))
    costs = total_cost(
        np.array([[0.1, 0.3], [0.1, 0.3]]),
        np.ones((2, 2), dtype=bool),
        np.array([[0.5, 0.0], [0.5, 0.0]]),
        np.array([[0.5, 0.2], [0.5, 0.2]]),
        np.ones((2, 2), dtype=bool),
        np.array([0.2, 0.2]),
        np.array([3.0, 3.0]),
        np.zeros(2),
        np.array([1.5, 1.5]),
        np.zeros(2),
        np.zeros(2),
        np.array([Validity.VALID, Validity.LEAVES_ROAD]),
        w,
    )
    assert costs.risk[0] == pytest.approx(j_risk)
    assert costs.total[0] == pytest.approx(2.0 * j_risk + 3.0 + 2.0 * 1.5)  # Eq. 5
    assert costs.total[1] == pytest.approx(j_risk)  # Eq. 6: risk only below the valid level


def test_mobility_by_hand_lane_centres_and_the_lane_preference():
    """Path term against the nearest lane centre at every step, lane term per lane away.

    Lanes at d = 0 (the route's) and 3.5. A candidate at d = 0.5 throughout: 0.5 m off,
    0 lanes away; at 3.5 throughout: 0 m off, 1 lane away; one that crosses from 0 to 3.5
    in the middle of four steps (0, 1.5, 2.0, 3.5): off by (0, 1.5, 1.5, 0) / 4 = 0.75,
    in the other lane half the time. Against the route (the reference) all offsets count.
    """
    from ethical_planner.config import PathReference
    from ethical_planner.cost import path_deviation

    d = np.array([[0.5, 0.5, 0.5, 0.5], [3.5, 3.5, 3.5, 3.5], [0.0, 1.5, 2.0, 3.5]])
    deviation, lanes = path_deviation(d, (0.0, 3.5), 3.5, PathReference.LANES)
    np.testing.assert_allclose(deviation, [0.5, 0.0, 0.75])
    np.testing.assert_allclose(lanes, [0.0, 1.0, 0.5])
    deviation, lanes = path_deviation(d, (0.0, 3.5), 3.5, PathReference.ROUTE)
    np.testing.assert_allclose(deviation, [0.5, 3.5, 7.0 / 4])
    np.testing.assert_allclose(lanes, 0.0)
    # Beyond the road's lanes the grid goes on: a parking strip at d = -3.2 is a lane away
    # (0.3 m from its centre at -3.5), not 3.2 m from the route's lane.
    deviation, lanes = path_deviation(np.full((1, 4), -3.2), (0.0, 3.5), 3.5, PathReference.LANES)
    np.testing.assert_allclose(deviation, [0.3])
    np.testing.assert_allclose(lanes, [1.0])
    w = CostWeights(speed=2.0, path_distance=1.0, other_lane=10.0, jerk_lon=0.0, jerk_lat=0.0)
    costs = total_cost(
        np.zeros((3, 0)),
        np.zeros((3, 0), dtype=bool),
        np.zeros((3, 0)),
        np.zeros((3, 0)),
        np.zeros((3, 0), dtype=bool),
        np.zeros(3),
        np.zeros(3),
        np.zeros(3),
        np.array([1.0, 0.0, 0.0]),
        np.array([0.5, 0.0, 0.75]),
        np.array([0.0, 1.0, 0.5]),
        np.full(3, int(Validity.VALID)),
        w,
    )
    np.testing.assert_allclose(costs.mobility, [2.0 + 0.5, 10.0, 0.75 + 5.0])


def test_oncoming_lanes_count_the_lanes_across_the_centre_line():
    """The wrong side of the road: lanes across the centre line, by hand.

    Two lanes (0 the ego's, 3.5 the oncoming; centre line 1.75): at 3.3 m throughout one
    oncoming lane, half the time there (0, 0, 3.5, 3.5) 0.5; at 7.0 m (beyond the road,
    the grid goes on) two. Four lanes, two per direction (centre line 5.25): the own
    direction's left lane (3.5) is none, the first oncoming (7.0) one, the next (10.5) two.
    """
    from ethical_planner.config import PathReference
    from ethical_planner.cost import comfort_and_mobility, oncoming_lanes, path_deviation

    lanes = PathReference.LANES
    d = np.array([[0.3] * 4, [3.3] * 4, [0.0, 0.0, 3.5, 3.5], [7.0] * 4, [-3.5] * 4])
    np.testing.assert_allclose(oncoming_lanes(d, (0.0, 3.5), 3.5, 1.75, lanes), [0.0, 1.0, 0.5, 2.0, 0.0])
    four = (0.0, 3.5, 7.0, 10.5)
    d4 = np.array([[3.5] * 4, [7.0] * 4, [10.5] * 4])
    np.testing.assert_allclose(oncoming_lanes(d4, four, 3.5, 5.25, lanes), [0.0, 1.0, 2.0])
    # No centre line (one way), or the route as the reference: nothing counted.
    np.testing.assert_allclose(oncoming_lanes(d, (0.0, 3.5), 3.5, None, lanes), 0.0)
    np.testing.assert_allclose(oncoming_lanes(d, (0.0, 3.5), 3.5, 1.75, PathReference.ROUTE), 0.0)
    # Mobility: a lane of oncoming traffic costs other_lane + oncoming_lane (10 + 10), the
    # own direction's left lane of a one-way road other_lane alone (10).
    w = CostWeights(
        speed=0.0, path_distance=0.0, other_lane=10.0, oncoming_lane=10.0, jerk_lon=0.0, jerk_lat=0.0
    )
    one_way = np.array([[3.5] * 4])
    _, away = path_deviation(one_way, (0.0, 3.5), 3.5, lanes)
    _, mobility = comfort_and_mobility(
        np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), away, w,
        oncoming_lanes(one_way, (0.0, 3.5), 3.5, None, lanes),
    )  # fmt: skip
    np.testing.assert_allclose(mobility, [10.0])
    _, mobility = comfort_and_mobility(
        np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), away, w,
        oncoming_lanes(one_way, (0.0, 3.5), 3.5, 1.75, lanes),
    )  # fmt: skip
    np.testing.assert_allclose(mobility, [20.0])
