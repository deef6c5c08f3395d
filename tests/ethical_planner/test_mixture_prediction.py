"""Gaussian-mixture predictions: validation, flooring, and their collision probability.

The collision probability of a mixture is checked against Monte Carlo: sample a
component by its weight, then the centre from that component, and test rectangle
overlap with a separating-axis test (the one of ``test_collision_probability``).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from ethical_planner.prediction.base import Prediction
from ethical_planner.risk import prediction_collision_probability
from ethical_planner.road_users import RoadUserType, Shape
from tests.ethical_planner.test_collision_probability import _cov, _sat_overlap

EGO = Shape(4.5, 1.8)


def _mixture(
    weights: np.ndarray, components: np.ndarray, mean: np.ndarray, heading: np.ndarray
) -> Prediction:
    """A mixture prediction of n_obs road users (cars and a pedestrian) at n_t steps."""
    n_obs, n_t = mean.shape[:2]
    cov = np.einsum("otk,otkij->otij", weights, components)
    types = tuple(RoadUserType.CAR if o % 2 == 0 else RoadUserType.PEDESTRIAN for o in range(n_obs))
    size = np.array([(4.5, 1.8) if o % 2 == 0 else (0.6, 0.6) for o in range(n_obs)])
    return Prediction(
        ids=np.arange(n_obs),
        types=types,
        mean=mean,
        cov=cov,
        heading=heading,
        speed=np.ones((n_obs, n_t)),
        length=size[:, 0],
        width=size[:, 1],
        mass=np.full(n_obs, 1000.0),
        component_weight=weights,
        component_cov=components,
    )


def _case() -> tuple[SimpleNamespace, Prediction]:
    """Three ego poses against two road users at two steps, a narrow and a wide component each."""
    rng = np.random.default_rng(3)
    ego = SimpleNamespace(
        x=np.array([[0.0, 1.0], [0.5, 2.0], [-1.0, 0.0]]),
        y=np.array([[0.0, 0.2], [1.0, -0.5], [0.0, 1.5]]),
        yaw=np.array([[0.0, 0.3], [0.8, -0.4], [1.6, 0.1]]),
    )
    mean = np.array([[[4.0, 1.0], [5.5, -1.0]], [[1.5, 2.5], [0.5, -2.0]]])
    heading = rng.uniform(-math.pi, math.pi, (2, 2))
    weights = np.array([[[0.7, 0.3], [0.55, 0.45]], [[0.8, 0.2], [0.35, 0.65]]])
    components = np.empty((2, 2, 2, 2, 2))
    for o in range(2):
        for t in range(2):
            angle = rng.uniform(0, math.pi)
            components[o, t, 0] = _cov(0.6, 0.3, angle)
            components[o, t, 1] = _cov(3.0, 1.5, angle)
    return ego, _mixture(weights, components, mean, heading)


def test_mixture_collision_probability_matches_monte_carlo():
    ego, prediction = _case()
    p = prediction_collision_probability(ego, prediction, EGO, gate_sigmas=6.0).probability
    rng = np.random.default_rng(11)
    n_samples = 400_000
    informative = 0
    for o in range(prediction.n_obs):
        size = (prediction.length[o], prediction.width[o])
        for t in range(2):
            weights = prediction.component_weight[o, t]
            component = rng.choice(len(weights), size=n_samples, p=weights)
            samples = np.empty((n_samples, 2))
            for c in range(len(weights)):
                rows = component == c
                samples[rows] = rng.multivariate_normal(
                    prediction.mean[o, t], prediction.component_cov[o, t, c], size=int(rows.sum())
                )
            for u in range(ego.x.shape[0]):
                pose = (ego.x[u, t], ego.y[u, t], ego.yaw[u, t])
                p_mc = float(
                    _sat_overlap(
                        pose, (EGO.length, EGO.width), samples, prediction.heading[o, t], size
                    ).mean()
                )
                assert abs(p[u, o, t] - p_mc) <= 0.004, (u, o, t, p[u, o, t], p_mc)
                informative += 0.05 < p_mc < 0.95
    # The check means something only if many probabilities are neither 0 nor 1.
    assert informative >= 6


def test_mixture_probability_differs_from_its_moment_matched_gaussian():
    # The mixture is not integrated as one Gaussian of its total covariance.
    ego, prediction = _case()
    mixed = prediction_collision_probability(ego, prediction, EGO, 6.0).probability
    single = Prediction(
        *(
            getattr(prediction, f)
            for f in ("ids", "types", "mean", "cov", "heading", "speed", "length", "width", "mass")
        )
    )
    assert single.n_components == 1 and prediction.n_components == 2
    moment = prediction_collision_probability(ego, single, EGO, 6.0).probability
    assert np.abs(mixed - moment).max() > 0.02


def test_single_component_mixture_equals_the_gaussian():
    ego, prediction = _case()
    one = _mixture(np.ones((2, 2, 1)), prediction.cov[:, :, None], prediction.mean, prediction.heading)
    single = Prediction(
        *(
            getattr(one, f)
            for f in ("ids", "types", "mean", "cov", "heading", "speed", "length", "width", "mass")
        )
    )
    a = prediction_collision_probability(ego, one, EGO, 6.0)
    b = prediction_collision_probability(ego, single, EGO, 6.0)
    np.testing.assert_allclose(a.probability, b.probability, atol=1e-12)
    np.testing.assert_array_equal(a.mean_overlap, b.mean_overlap)


def test_covariance_floor_applies_to_every_component():
    _, prediction = _case()
    tiny = prediction.component_cov.copy()
    tiny[:, :, 0] = 1e-4 * np.eye(2)
    floored = _mixture(
        prediction.component_weight, tiny, prediction.mean, prediction.heading
    ).with_covariance_floor(0.1)
    assert np.linalg.eigvalsh(floored.component_cov).min() >= 0.1 - 1e-12
    np.testing.assert_allclose(
        floored.component_cov[:, :, 0], np.broadcast_to(0.1 * np.eye(2), (2, 2, 2, 2)), atol=1e-12
    )
    expected = np.einsum("otk,otkij->otij", floored.component_weight, floored.component_cov)
    np.testing.assert_allclose(floored.cov, expected, atol=1e-12)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda w, c: (w * 1.1, c), "sum to 1"),
        (lambda w, c: (w, None), "together"),
        (lambda w, c: (w[..., :1], c), "component_cov must have shape"),
        (lambda w, c: (w, c - 20.0 * np.eye(2)), "positive semidefinite"),
        (lambda w, c: (np.where(w > 0.5, np.nan, w), c), "finite"),
    ],
)
def test_bad_mixture_is_refused(change, message):
    _, prediction = _case()
    weights, components = change(prediction.component_weight, prediction.component_cov)
    with pytest.raises(ValueError, match=message):
        Prediction(
            *(
                getattr(prediction, f)
                for f in ("ids", "types", "mean", "cov", "heading", "speed", "length", "width", "mass")
            ),
            component_weight=weights,
            component_cov=components,
        )
