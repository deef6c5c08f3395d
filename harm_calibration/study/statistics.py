"""The statistics a reviewer asks of a planner comparison.

* ``cluster_bootstrap``: a percentile confidence interval of any summary of runs, with
  scenarios resampled as units (the values of one scenario are not independent).
* ``paired_test``: Wilcoxon signed-rank test of two planners over the same scenarios,
  with the matched-pairs rank-biserial correlation as effect size (Kerby 2014: the
  share of favourable minus unfavourable rank sums, in [-1, 1]) and the median
  difference.
* ``holm``: Holm's step-down adjustment of a family of p-values.
* ``poisson_rate_ci``: exact (Garwood) interval of a count per exposure (crashes per
  1000 km).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

#: Confidence level of every interval.
CONFIDENCE = 0.95
#: Bootstrap resamples.
BOOTSTRAP_RESAMPLES = 2000


@dataclass(frozen=True, slots=True)
class Interval:
    """An estimate with its confidence interval.

    Attributes:
        value: the estimate on the data. low, high: interval bounds (nan if undefined).
    """

    value: float
    low: float
    high: float

    def text(self, digits: int = 4) -> str:
        """``value [low, high]``."""
        if not math.isfinite(self.value):
            return "-"
        if not (math.isfinite(self.low) and math.isfinite(self.high)):
            return f"{self.value:.{digits}g}"
        return f"{self.value:.{digits}g} [{self.low:.{digits}g}, {self.high:.{digits}g}]"


def cluster_bootstrap(
    clusters: Sequence[object],
    summary: Callable[[Sequence[object]], float],
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = 0,
) -> Interval:
    """Percentile bootstrap interval of ``summary`` over resampled clusters.

    Args:
        clusters: one item per scenario (whatever ``summary`` needs of it).
        summary: the statistic of a list of clusters (drawn with replacement).
        resamples: number of bootstrap resamples.
        seed: seed of the resampling (results are reproducible).

    Returns:
        The statistic on the data and its ``CONFIDENCE`` percentile interval (nan
        bounds with fewer than two clusters).
    """
    value = float(summary(clusters))
    n = len(clusters)
    if n < 2:
        return Interval(value, math.nan, math.nan)
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, n, size=(resamples, n))
    values = np.array([summary([clusters[i] for i in row]) for row in draws], dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return Interval(value, math.nan, math.nan)
    alpha = 1.0 - CONFIDENCE
    low, high = np.quantile(values, [alpha / 2, 1 - alpha / 2])
    return Interval(value, float(low), float(high))


@dataclass(frozen=True, slots=True)
class PairedTest:
    """Two planners compared over the same scenarios (a minus b).

    Attributes:
        a, b: planner names. n: scenarios with a value for both. n_nonzero: pairs that
            differ (the test's sample size).
        statistic: Wilcoxon's W (smaller of the signed-rank sums).
        p: two-sided p-value (nan if no pair differs). p_holm: Holm-adjusted (set by
            ``holm``).
        rank_biserial: matched-pairs rank-biserial correlation: (R+ - R-) / (R+ + R-)
            of the differences a - b; negative means a is lower.
        median_difference: median of a - b over the n pairs.
        mean_a, mean_b: means of a and b over the n pairs.
    """

    a: str
    b: str
    n: int
    n_nonzero: int
    statistic: float
    p: float
    p_holm: float
    rank_biserial: float
    median_difference: float
    mean_a: float
    mean_b: float


def rank_biserial(differences: np.ndarray) -> float:
    """Matched-pairs rank-biserial correlation of paired differences (zeros dropped).

    (sum of ranks of positive differences - sum of negative ones) / total rank sum,
    with ranks of |d| (average ranks for ties); nan without a non-zero difference.
    """
    d = np.asarray(differences, dtype=float)
    d = d[d != 0]
    if d.size == 0:
        return math.nan
    ranks = stats.rankdata(np.abs(d))
    return float((ranks[d > 0].sum() - ranks[d < 0].sum()) / ranks.sum())


def paired_test(a_name: str, b_name: str, a: Sequence[float], b: Sequence[float]) -> PairedTest:
    """Wilcoxon signed-rank test of paired values (same scenario order), two-sided.

    Pairs with a zero difference are dropped (Wilcoxon's original treatment); the
    p-value is exact for fewer than 50 non-zero pairs without ties, else from the
    normal approximation with tie correction (SciPy's ``method="auto"``).
    """
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    keep = np.isfinite(x) & np.isfinite(y)
    x, y = x[keep], y[keep]
    d = x - y
    nonzero = int(np.count_nonzero(d))
    if nonzero == 0:
        statistic, p = math.nan, math.nan
    else:
        result = stats.wilcoxon(x, y, zero_method="wilcox", alternative="two-sided")
        statistic, p = float(result.statistic), float(result.pvalue)
    return PairedTest(
        a=a_name,
        b=b_name,
        n=int(d.size),
        n_nonzero=nonzero,
        statistic=statistic,
        p=p,
        p_holm=math.nan,
        rank_biserial=rank_biserial(d),
        median_difference=float(np.median(d)) if d.size else math.nan,
        mean_a=float(np.mean(x)) if x.size else math.nan,
        mean_b=float(np.mean(y)) if y.size else math.nan,
    )


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values (nan stays nan and is not counted).

    The k-th smallest of m p-values becomes max over j <= k of (m - j + 1) p_(j),
    capped at 1.
    """
    p = np.asarray(p_values, dtype=float)
    out = np.full(p.shape, math.nan)
    valid = np.flatnonzero(np.isfinite(p))
    m = valid.size
    order = valid[np.argsort(p[valid], kind="stable")]
    running = 0.0
    for k, index in enumerate(order):
        running = max(running, min(1.0, (m - k) * p[index]))
        out[index] = running
    return out.tolist()


def poisson_rate_ci(count: int, exposure: float, per: float = 1.0) -> Interval:
    """Rate ``count / exposure * per`` with its exact (Garwood) ``CONFIDENCE`` interval.

    Args:
        count: events (>= 0). exposure: e.g. km driven (> 0). per: scale (1000 for
            "per 1000 km").
    """
    if exposure <= 0:
        return Interval(math.nan, math.nan, math.nan)
    alpha = 1.0 - CONFIDENCE
    low = stats.chi2.ppf(alpha / 2, 2 * count) / 2 if count > 0 else 0.0
    high = stats.chi2.ppf(1 - alpha / 2, 2 * count + 2) / 2
    scale = per / exposure
    return Interval(count * scale, float(low) * scale, float(high) * scale)


__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "CONFIDENCE",
    "Interval",
    "PairedTest",
    "cluster_bootstrap",
    "holm",
    "paired_test",
    "poisson_rate_ci",
    "rank_biserial",
]
