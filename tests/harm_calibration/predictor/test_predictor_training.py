"""Training windows, a tiny training run, recalibration and the evaluation metrics."""

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from ethical_planner.prediction.learned import TYPE_GROUPS, LearnedModel, ModelSpec, recalibrate  # noqa: E402
from ethical_planner.road_users import RoadUserType  # noqa: E402
from harm_calibration.predictor.data import Windows, split_of, track_windows  # noqa: E402
from harm_calibration.predictor.evaluate import (  # noqa: E402
    Scored,
    ctra_mean,
    evaluate,
    gaussian_nll_np,
    metrics,
    report_markdown,
)
from harm_calibration.predictor.train import (  # noqa: E402
    NOMINAL,
    TrainConfig,
    fit_calibration,
    group_weights,
    mahalanobis_sq,
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


def test_calibration_recovers_a_known_variance_factor():
    rng = np.random.default_rng(0)
    n, steps = 20000, 3
    # Claimed variances vary over rows; true errors have twice the claimed variance.
    var = rng.uniform(0.5, 4.0, size=(n, steps))
    cov = np.zeros((n, steps, 2, 2))
    cov[..., 0, 0] = cov[..., 1, 1] = var
    error = rng.normal(size=(n, steps, 2)) * np.sqrt(2.0 * var)[..., None]
    groups = np.zeros(n, dtype=int)
    # A plain scale (b fixed at 1) recovers the factor 2.
    scale = fit_calibration(cov, error, groups, floor=1e-6, b_grid=np.array([1.0]))
    assert scale[0, :, 0] == pytest.approx(2.0, rel=0.05) and np.all(scale[0, :, 1] == 1.0)
    assert np.all(scale[1:] == 1.0)  # groups without rows keep (1, 1)
    # With the power free, the coverage objective has a ridge of (a, b); coverage is what it fits.
    params = fit_calibration(cov, error, groups, floor=1e-6)
    for step in range(steps):
        d2 = mahalanobis_sq(np.zeros(2), recalibrate(cov[:, step], params[0, step][None]), error[:, step])
        assert (d2 <= 1).mean() == pytest.approx(NOMINAL[1], abs=0.02)
        assert (d2 <= 4).mean() == pytest.approx(NOMINAL[2], abs=0.02)
    assert NOMINAL[1] == pytest.approx(0.3935, abs=1e-4) and NOMINAL[2] == pytest.approx(0.8647, abs=1e-4)


def test_recalibration_power_spreads_sizes():
    cov = np.zeros((2, 2, 2))
    cov[0] = np.eye(2) * 0.25
    cov[1] = np.eye(2) * 4.0
    out = recalibrate(cov, np.array([2.0, 1.5]))
    # a * s2^(b - 1) with s2 = 0.25 and 4: factors 2 * 0.5 = 1 and 2 * 2 = 4.
    assert out[0, 0, 0] == pytest.approx(0.25) and out[1, 0, 0] == pytest.approx(16.0)


def test_metrics_on_exact_gaussian_samples():
    """Targets drawn from the predicted Gaussians: coverage near nominal, NLL near its expectation."""
    rng = np.random.default_rng(2)
    n, k = 4000, SPEC.n_future
    cov = np.broadcast_to(np.array([[2.0, 0.6], [0.6, 1.0]]), (n, k, 2, 2)).copy()
    mean = np.zeros((n, k, 2))
    future = rng.multivariate_normal(np.zeros(2), cov[0, 0], size=(n, k))
    windows = synthetic_windows(2, rng)
    windows = windows.subset(np.arange(len(windows)) % len(windows) < len(windows))
    idx = np.arange(n) % len(windows)
    w = windows.subset(idx)
    w = Windows(*(getattr(w, f) for f in Windows.__slots__[:-2]), future, w.recording)
    m = metrics(Scored(mean, cov), w, SPEC.future_times)
    for category in m.values():
        for value in category["coverage_1sigma"].values():
            assert value == pytest.approx(NOMINAL[1], abs=0.04)
        for value in category["coverage_2sigma"].values():
            assert value == pytest.approx(NOMINAL[2], abs=0.03)
    # E[NLL] = 1 + log(2 pi) + log(det)/2 for a 2-D Gaussian.
    expected = 1.0 + math.log(2 * math.pi) + 0.5 * math.log(np.linalg.det(cov[0, 0]))
    assert m["car"]["nll"] == pytest.approx(expected, abs=0.05)
    assert mahalanobis_sq(np.zeros(2), np.eye(2) * 4.0, np.array([2.0, 0.0])) == pytest.approx(1.0)
    assert gaussian_nll_np(np.zeros(2), np.eye(2), np.zeros(2)) == pytest.approx(math.log(2 * math.pi))


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
        "learned",
        "learned_recalibrated",
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
    }
    text = report_markdown(result)
    assert "| car | constant_velocity |" in text and "Nominal coverage" in text
    assert len(TYPE_GROUPS) == 5
