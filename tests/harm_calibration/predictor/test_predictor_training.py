"""Training windows, a tiny training run, the mixture calibration and the evaluation metrics."""

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from ethical_planner.prediction.learned import MOTION_STATES, TYPE_GROUPS, LearnedModel, ModelSpec  # noqa: E402
from ethical_planner.road_users import RoadUserType  # noqa: E402
from harm_calibration.predictor.data import Windows, split_of, track_windows  # noqa: E402
from harm_calibration.predictor.evaluate import (  # noqa: E402
    Scored,
    ctra_mean,
    evaluate,
    metrics,
    mixture_nll,
    report_markdown,
)
from harm_calibration.predictor.train import (  # noqa: E402
    NOMINAL,
    TrainConfig,
    fit_mixture,
    fit_scale_mixture,
    group_weights,
    mahalanobis_sq,
    mixture_cdf,
    train,
)
from mujoco_world.scenario.commonroad_tracks import Track  # noqa: E402

SPEC = ModelSpec(hidden=(32,))


def synthetic_windows(n_tracks, rng, recording="x"):
    """Tracks of cars and pedestrians turning at random constant rates, cut into windows."""
    parts = []
    for k in range(n_tracks):
        kind = RoadUserType.CAR if k % 2 == 0 else RoadUserType.PEDESTRIAN
        v = rng.uniform(8.0, 15.0) if kind is RoadUserType.CAR else rng.uniform(0.8, 1.8)
        rate = rng.uniform(-0.15, 0.15)
        t = np.arange(0.0, 12.0, 0.1)
        yaw = rng.uniform(-math.pi, math.pi) + rate * t
        step = v * 0.1 * np.stack([np.cos(yaw), np.sin(yaw)], -1)
        positions = np.cumsum(step, axis=0) + rng.normal(0.0, 0.02, step.shape)
        track = Track(k, kind, 4.5, 1.8, False, np.arange(len(t)), t, positions, yaw, np.full(len(t), v))
        parts.append(track_windows(track, SPEC, stride=3))
    cat = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    groups = np.array([0 if s == "car" else 4 for s in cat["types"]])
    return Windows(
        groups,
        cat["types"],
        cat["length"],
        cat["width"],
        cat["positions"],
        cat["headings"],
        cat["speeds"],
        cat["available"],
        cat["future"],
        np.full(len(groups), recording),
    )


def test_track_windows_cut_history_and_future_on_the_grid():
    t = np.arange(0.0, 8.0, 0.5)  # a SinD-like 0.5 s track, resampled at 0.2 s
    positions = np.stack([2.0 * t, np.zeros_like(t)], -1)
    track = Track(
        1,
        RoadUserType.PEDESTRIAN,
        0.6,
        0.6,
        True,
        np.arange(len(t)),
        t,
        positions,
        np.zeros_like(t),
        np.full_like(t, 2.0),
    )
    w = track_windows(track, SPEC, stride=1)
    # Grid 0 .. 7.4 s (38 points); anchors need 20 future points: 18 windows.
    assert len(w["future"]) == 18
    # The first anchor has one real sample, padded back at 2 m/s; its future is 0.4 m per step.
    assert w["available"][0] == 1 and w["positions"][0, :, 0] == pytest.approx(2.0 * SPEC.history_times)
    assert w["future"][0, :, 0] == pytest.approx(2.0 * SPEC.future_times)
    assert w["available"][12] == 11
    short = Track(
        2, RoadUserType.CAR, 4, 2, False, np.arange(5), t[:5], positions[:5], np.zeros(5), np.full(5, 2.0)
    )
    assert track_windows(short, SPEC, stride=1) is None  # leaves before 4 s of future


def test_split_is_by_location():
    assert split_of("highD-A") == "train" and split_of("highD-B") == "val" and split_of("highD-E") == "test"
    assert split_of("SinD-851") == "test" and split_of("NGSIM-Lanker") == "test"
    assert split_of("DEU_Muc") is None


def test_group_weights_balance_groups():
    groups = np.array([0, 0, 0, 4])
    w = group_weights(groups)
    assert w[:3].sum() == pytest.approx(w[3]) and w.mean() == pytest.approx(1.0)


def test_tiny_training_lowers_the_loss_and_is_reproducible():
    rng = np.random.default_rng(1)
    train_w = synthetic_windows(12, rng)
    val_w = synthetic_windows(4, rng)
    config = TrainConfig(epochs=6, batch=64, lr=3e-3, seed=3)
    model, log = train(train_w, val_w, SPEC, config)
    assert log.train_nll[-1] < log.train_nll[0] - 0.5
    assert log.val_nll[log.best_epoch] < log.val_nll[0]
    again, log2 = train(train_w, val_w, SPEC, config)
    assert log2.train_nll == log.train_nll
    for a, b in zip(model.network.parameters(), again.network.parameters(), strict=True):
        assert torch.equal(a, b)


def _mixture_samples(rng, n, weights, factors, cov):
    """n draws from sum_k w_k N(0, v_k cov): the component by its weight, then the Gaussian."""
    component = rng.choice(len(weights), size=n, p=weights)
    unit = rng.multivariate_normal(np.zeros(2), cov, size=n)
    return unit * np.sqrt(np.asarray(factors))[component][:, None]


def test_scale_mixture_fit_recovers_known_weights_and_factors():
    rng = np.random.default_rng(0)
    cov = np.array([[2.0, 0.6], [0.6, 1.0]])
    error = _mixture_samples(rng, 40000, [0.7, 0.3], [0.25, 6.0], cov)
    d2 = mahalanobis_sq(np.zeros(2), cov, error)
    fit = fit_scale_mixture(d2, 2)
    assert fit[:, 0] == pytest.approx([0.7, 0.3], abs=0.02)
    assert fit[:, 1] == pytest.approx([0.25, 6.0], rel=0.06)
    # One component: the maximum-likelihood factor of a 2-D Gaussian is mean(d2) / 2.
    assert fit_scale_mixture(d2, 1)[0] == pytest.approx([1.0, d2.mean() / 2])
    with pytest.raises(ValueError, match="d2 must be"):
        fit_scale_mixture(np.array([1.0, np.nan]), 2)


def test_mixture_cdf_matches_monte_carlo():
    rng = np.random.default_rng(1)
    cov = np.array([[1.0, -0.3], [-0.3, 0.5]])
    weights, factors = np.array([0.6, 0.4]), np.array([0.5, 4.0])
    d2 = mahalanobis_sq(np.zeros(2), cov, _mixture_samples(rng, 200000, weights, factors, cov))
    for radius_sq in (0.3, 1.0, 4.0, 9.0):
        assert mixture_cdf(np.array(radius_sq), weights, factors) == pytest.approx(
            (d2 <= radius_sq).mean(), abs=0.004
        )


def test_mixture_calibration_cells_and_fallbacks():
    rng = np.random.default_rng(2)
    n, steps = 3000, 2
    groups = np.where(np.arange(n) < 2960, 0, 4)  # 40 pedestrians: too few for a cell of their own
    states = np.where(np.arange(n) % 2 == 0, 0, 1)
    factors = np.where(states == 0, 0.2, 3.0)[:, None] * np.ones((1, steps))
    error = rng.normal(size=(n, steps, 2)) * np.sqrt(factors)[..., None]
    d2 = (error**2).sum(-1)
    params = fit_mixture(d2, np.ones((n, steps)), groups, states, n_components=2)
    assert params.shape == (len(TYPE_GROUPS), len(MOTION_STATES), steps, 2, 2)
    # Each car cell is one Gaussian of its own size: the mixture's moment is its factor.
    for state, factor in ((0, 0.2), (1, 3.0)):
        moment = (params[0, state, :, :, 0] * params[0, state, :, :, 1]).sum(-1)
        assert moment == pytest.approx(factor, rel=0.1)
    # Pedestrians pool both states; absent groups keep the network's Gaussian.
    np.testing.assert_array_equal(params[4, 0], params[4, 1])
    assert np.all(params[1, :, :, 0] == [1.0, 1.0]) and np.all(params[1, :, :, 1, 0] == 0.0)
    assert np.allclose(params[..., 0].sum(-1), 1.0)
    # Windows whose covariance is at the resolution floor get no component narrower than it.
    bounded = fit_mixture(d2, np.full((n, steps), 0.5), groups, states, n_components=2, resolution=0.5)
    assert bounded[0, 0, :, :, 1].min() == pytest.approx(1.0) and params[0, 0, :, :, 1].min() < 0.5


def _windows_with_future(rng, future):
    """Synthetic windows (cars and pedestrians) with ``future`` as their true positions."""
    windows = synthetic_windows(2, rng)
    w = windows.subset(np.arange(len(future)) % len(windows))
    return Windows(*(getattr(w, f) for f in Windows.__slots__[:-2]), future, w.recording)


def test_metrics_on_exact_gaussian_samples():
    """Targets drawn from the predicted Gaussians: coverage near nominal, NLL near its expectation."""
    rng = np.random.default_rng(2)
    n, k = 4000, SPEC.n_future
    cov = np.broadcast_to(np.array([[2.0, 0.6], [0.6, 1.0]]), (n, k, 2, 2)).copy()
    mean = np.zeros((n, k, 2))
    future = rng.multivariate_normal(np.zeros(2), cov[0, 0], size=(n, k))
    m = metrics(Scored.gaussian(mean, cov), _windows_with_future(rng, future), SPEC.future_times)
    for category in m.values():
        for value in category["coverage_1sigma"].values():
            assert value == pytest.approx(NOMINAL[1], abs=0.04)
        for value in category["coverage_2sigma"].values():
            assert value == pytest.approx(NOMINAL[2], abs=0.03)
    # E[NLL] = 1 + log(2 pi) + log(det)/2 for a 2-D Gaussian.
    expected = 1.0 + math.log(2 * math.pi) + 0.5 * math.log(np.linalg.det(cov[0, 0]))
    assert m["car"]["nll"] == pytest.approx(expected, abs=0.05)
    assert mahalanobis_sq(np.zeros(2), np.eye(2) * 4.0, np.array([2.0, 0.0])) == pytest.approx(1.0)
    assert NOMINAL[1] == pytest.approx(0.3935, abs=1e-4) and NOMINAL[2] == pytest.approx(0.8647, abs=1e-4)


def test_metrics_on_exact_mixture_samples_and_a_single_gaussian_fails_them():
    """Targets from a scale mixture: it covers at nominal, its moment-matched Gaussian does not."""
    rng = np.random.default_rng(4)
    n, k = 6000, SPEC.n_future
    base = np.array([[1.5, 0.4], [0.4, 0.8]])
    weights, factors = np.array([0.75, 0.25]), np.array([0.3, 5.0])
    future = _mixture_samples(rng, n * k, weights, factors, base).reshape(n, k, 2)
    mean = np.zeros((n, k, 2))
    comp = np.broadcast_to(factors[:, None, None] * base, (n, k, 2, 2, 2)).copy()
    mixture = Scored(mean, np.broadcast_to(weights, (n, k, 2)).copy(), comp)
    windows = _windows_with_future(rng, future)
    m = metrics(mixture, windows, SPEC.future_times)["car"]
    assert list(m["coverage_1sigma"].values()) == pytest.approx([NOMINAL[1]] * 3, abs=0.04)
    assert list(m["coverage_2sigma"].values()) == pytest.approx([NOMINAL[2]] * 3, abs=0.03)
    single = Scored.gaussian(mean, np.broadcast_to((weights * factors).sum() * base, (n, k, 2, 2)).copy())
    s = metrics(single, windows, SPEC.future_times)["car"]
    assert min(s["coverage_1sigma"].values()) > NOMINAL[1] + 0.1
    assert s["nll"] > m["nll"] + 0.1
    # The mixture NLL is that of its density (independent: a sum of scipy densities).
    from scipy.stats import multivariate_normal

    x = future[7, 3]
    density = sum(
        w * multivariate_normal(np.zeros(2), v * base).pdf(x) for w, v in zip(weights, factors, strict=True)
    )
    assert mixture_nll(mixture, future)[7, 3] == pytest.approx(-math.log(density), rel=1e-9)


def test_ctra_follows_a_circle_without_acceleration():
    rng = np.random.default_rng(0)
    w = synthetic_windows(2, rng).subset(np.array([5]))
    rate = (w.headings[0, -1] - w.headings[0, -2]) / SPEC.history_step
    v, yaw0, p0 = w.speeds[0, -1], w.headings[0, -1], w.positions[0, -1]
    t = SPEC.future_times
    expected = p0 + (v / rate) * np.stack(
        [np.sin(yaw0 + rate * t) - np.sin(yaw0), -np.cos(yaw0 + rate * t) + np.cos(yaw0)], -1
    )
    assert ctra_mean(w, t, SPEC.history_step, substeps=50)[0] == pytest.approx(expected, abs=1e-3)


def test_evaluate_reports_every_predictor_and_category():
    rng = np.random.default_rng(3)
    torch.manual_seed(0)
    result = evaluate(LearnedModel(SPEC), synthetic_windows(4, rng))
    assert set(result["metrics"]) == {
        "learned (1-Gaussian mixture)",
        "learned, one Gaussian",
        "constant_velocity",
        "ctra",
        "default (constant_acceleration)",
    }
    assert set(result["metrics"]["ctra"]) == {
        "car",
        "pedestrian",
        "pedestrians+cyclists",
        "car (moving)",
        "pedestrians+cyclists (moving)",
    }  # the synthetic road users all move: no "(standing)" rows
    text = report_markdown(result)
    assert "| car | constant_velocity |" in text and "Nominal coverage" in text
    assert len(TYPE_GROUPS) == 5
