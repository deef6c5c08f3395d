"""Study statistics against hand-computed values and independent methods."""

import math

import numpy as np
import pytest
from scipy import stats

from harm_calibration.study.statistics import (
    cluster_bootstrap,
    holm,
    paired_test,
    poisson_rate_ci,
    rank_biserial,
)


def test_rank_biserial_by_hand():
    # Differences 1, -2, 3, 4: ranks of |d| 1, 2, 3, 4; R+ = 1 + 3 + 4 = 8, R- = 2: (8 - 2) / 10.
    assert rank_biserial(np.array([1.0, -2.0, 3.0, 4.0, 0.0])) == pytest.approx(0.6)
    assert rank_biserial(np.array([-1.0, -2.0])) == pytest.approx(-1.0)
    assert math.isnan(rank_biserial(np.zeros(3)))


def test_paired_test_small_sample_exact_p_by_enumeration():
    a = np.array([0.30, 0.10, 0.52, 0.70, 0.25, 0.90])
    b = np.array([0.20, 0.15, 0.40, 0.50, 0.05, 0.60])
    result = paired_test("a", "b", a, b)
    d = a - b
    # Exact two-sided p by enumerating all 2^6 sign patterns of the ranks (no ties here).
    ranks = stats.rankdata(np.abs(d))
    w_plus = ranks[d > 0].sum()
    signs = np.array(np.meshgrid(*[[0, 1]] * 6)).reshape(6, -1).T
    sums = signs @ ranks
    centre = ranks.sum() / 2
    p_exact = np.mean(np.abs(sums - centre) >= abs(w_plus - centre) - 1e-12)
    assert result.p == pytest.approx(p_exact)
    assert result.n == 6 and result.n_nonzero == 6
    assert result.rank_biserial == pytest.approx((w_plus - (ranks.sum() - w_plus)) / ranks.sum())
    assert result.median_difference == pytest.approx(np.median(d))


def test_paired_test_without_differences_has_no_p():
    result = paired_test("a", "b", [0.1, 0.2], [0.1, 0.2])
    assert math.isnan(result.p) and result.n_nonzero == 0


def test_holm_by_hand():
    # m = 4: sorted 0.01, 0.02, 0.03, 0.5 -> 0.04, 0.06, 0.06 (monotone), 0.5.
    assert holm([0.03, 0.01, 0.5, 0.02]) == pytest.approx([0.06, 0.04, 0.5, 0.06])
    out = holm([0.2, math.nan, 0.9])
    assert out[0] == pytest.approx(0.4) and math.isnan(out[1]) and out[2] == pytest.approx(0.9)


def test_poisson_interval_matches_published_values():
    # Garwood 95 % limits for 0 and 3 events: [0, 3.689] and [0.6187, 8.767].
    zero = poisson_rate_ci(0, 1.0)
    assert (zero.value, zero.low) == (0.0, 0.0) and zero.high == pytest.approx(3.6889, abs=1e-3)
    three = poisson_rate_ci(3, 2000.0, per=1000.0)
    assert three.value == pytest.approx(1.5)
    assert (three.low, three.high) == pytest.approx((0.6187 / 2, 8.7673 / 2), abs=1e-3)


def test_cluster_bootstrap_of_a_mean_matches_the_normal_interval():
    rng = np.random.default_rng(5)
    values = list(rng.normal(3.0, 2.0, 400))
    ci = cluster_bootstrap(values, lambda xs: float(np.mean(xs)), resamples=3000, seed=1)
    half = 1.96 * np.std(values, ddof=1) / math.sqrt(len(values))
    assert ci.value == pytest.approx(np.mean(values))
    assert ci.low == pytest.approx(ci.value - half, abs=0.03)
    assert ci.high == pytest.approx(ci.value + half, abs=0.03)
    # Reproducible, and undefined for a single cluster.
    assert cluster_bootstrap(values, np.mean, resamples=200, seed=1) == cluster_bootstrap(
        values, np.mean, resamples=200, seed=1
    )
    assert math.isnan(cluster_bootstrap([1.0], np.mean).low)
