"""The learned predictor: history windows, features, weights files, the shipped model."""

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from ethical_planner.config import PredictionConfig  # noqa: E402
from ethical_planner.prediction import make_predictor  # noqa: E402
from ethical_planner.prediction.learned import (  # noqa: E402
    LearnedModel,
    LearnedPredictor,
    ModelSpec,
    encode,
    gaussian_nll,
    gaussian_params,
    history_windows,
    pad_history,
    to_world,
    type_groups,
)
from ethical_planner.road_users import KinematicState, MotionHistory, RoadUser, Shape  # noqa: E402

SPEC = ModelSpec()


def moving_user(uid=1, kind="car", x0=0.0, y0=0.0, yaw=0.3, v=8.0, history_s=3.0, step=0.1, lag=0.0):
    """A road user at constant velocity with a history every ``step`` ending ``lag`` s ago."""
    times = np.arange(-history_s, 1e-9, step) - lag
    times = times[times <= 0]
    direction = np.array([math.cos(yaw), math.sin(yaw)])
    positions = np.array([x0, y0]) + times[:, None] * v * direction
    history = MotionHistory(times, positions, np.full(len(times), yaw), np.full(len(times), v))
    state = KinematicState(x0, y0, yaw, v)
    shape = Shape(4.5, 1.8) if kind == "car" else Shape(0.6, 0.6)
    return RoadUser(uid, kind, state, shape, history=history)


def test_pad_history_extrapolates_backwards_at_constant_velocity():
    positions = np.zeros((1, 4, 2))
    positions[0, 2:] = [[1.0, 0.0], [2.0, 0.0]]
    headings = np.zeros((1, 4))
    speeds = np.full((1, 4), 5.0)
    p, _, _ = pad_history(positions, headings, speeds, np.array([2]), 0.2)
    # 5 m/s along x, 0.2 s slots: one slot back is 1 m behind the oldest real sample.
    assert p[0, :, 0] == pytest.approx([-1.0, 0.0, 1.0, 2.0])
    assert positions[0, 0, 0] == 0.0  # argument unchanged
    with pytest.raises(ValueError, match="between 1 and 4 samples"):
        pad_history(positions, headings, speeds, np.array([0]), 0.2)


def test_history_windows_interpolate_any_step_and_pad_short_histories():
    full = moving_user(step=0.1, lag=0.05)
    short = moving_user(uid=2, history_s=0.6, step=0.1)
    bare = RoadUser(3, "pedestrian", KinematicState(1.0, 2.0, -1.0, 1.4), Shape(0.6, 0.6))
    positions, headings, speeds, available = history_windows([full, short, bare], SPEC)
    # Constant velocity: the grid positions are exactly on the line (independent formula).
    grid = SPEC.history_times
    for k, user in enumerate([full, short]):
        direction = np.array([math.cos(user.state.yaw), math.sin(user.state.yaw)])
        expected = np.array([user.state.x, user.state.y]) + grid[:, None] * user.state.v * direction
        assert positions[k] == pytest.approx(expected, abs=1e-9)
    assert list(available) == [11, 4, 1]
    assert positions[2, -1] == pytest.approx([1.0, 2.0]) and speeds[2] == pytest.approx(1.4)
    assert headings[2] == pytest.approx(-1.0)


def test_history_across_the_heading_wrap_is_interpolated_smoothly():
    times = np.array([-0.2, -0.1])
    yaw = np.array([math.pi - 0.05, -math.pi + 0.05])  # turning left across +-pi
    history = MotionHistory(times, np.zeros((2, 2)), yaw, np.zeros(2))
    user = RoadUser(1, "car", KinematicState(0, 0, -math.pi + 0.15, 0.0), Shape(4, 2), history=history)
    _, headings, _, _ = history_windows([user], SPEC)
    assert np.all(np.abs(np.diff(headings[0])) < 0.2)


def test_encode_rejects_bad_shapes_and_nan():
    positions, headings, speeds, available = history_windows([moving_user()], SPEC)
    groups = type_groups(["car"])
    features = encode(groups, np.array([4.5]), np.array([1.8]), positions, headings, speeds, available, SPEC)
    assert features.shape == (1, SPEC.n_features) and features.dtype == np.float32
    with pytest.raises(ValueError, match=r"history positions must have shape \(1, 11, 2\)"):
        encode(groups, np.array([4.5]), np.array([1.8]), positions[:, :5], headings, speeds, available, SPEC)
    bad = speeds.copy()
    bad[0, 3] = np.nan
    with pytest.raises(ValueError, match="history speeds must be finite"):
        encode(groups, np.array([4.5]), np.array([1.8]), positions, headings, bad, available, SPEC)


def test_unknown_types_are_named():
    with pytest.raises(ValueError, match="no model for road-user type 'train'"):
        type_groups(["train"])
    with pytest.raises(ValueError, match="unknown road-user type 'hovercraft'"):
        type_groups(["hovercraft"])


def test_history_with_nan_is_refused_where_it_is_built():
    with pytest.raises(ValueError, match="MotionHistory.positions must be finite"):
        MotionHistory(np.array([-0.1, 0.0]), np.array([[0.0, np.nan], [1.0, 0.0]]), np.zeros(2), np.zeros(2))


def test_gaussian_nll_matches_scipy():
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(0)
    out = torch.as_tensor(rng.normal(size=(3, 5 * SPEC.n_future)), dtype=torch.float64)
    mean, chol = gaussian_params(out, torch.tensor([1.0, 5.0, 0.0], dtype=torch.float64), SPEC)
    target = mean + torch.as_tensor(rng.normal(size=mean.shape))
    nll = gaussian_nll(mean, chol, target).numpy()
    cov = (chol @ chol.transpose(-1, -2)).numpy()
    k, t = 1, 7
    expected = -multivariate_normal(mean[k, t].numpy(), cov[k, t]).logpdf(target[k, t].numpy())
    assert nll[k, t] == pytest.approx(expected, rel=1e-9)


def test_to_world_rotates_means_and_covariances():
    mean = np.array([[[1.0, 0.0]]])
    cov = np.array([[[[4.0, 0.0], [0.0, 1.0]]]])
    m, c = to_world(mean, cov, np.array([[10.0, 5.0]]), np.array([math.pi / 2]))
    assert m[0, 0] == pytest.approx([10.0, 6.0])
    assert c[0, 0] == pytest.approx(np.array([[1.0, 0.0], [0.0, 4.0]]), abs=1e-12)


def test_weights_files_round_trip_and_bad_files_give_clear_errors(tmp_path):
    torch.manual_seed(0)
    calibration = np.zeros((5, 2, 20, 2, 2))
    calibration[..., 0] = [0.7, 0.3]
    calibration[..., 1] = [0.5, 4.0]
    model = LearnedModel(ModelSpec(hidden=(8,)), calibration=calibration, meta={"seed": 0})
    path = tmp_path / "model.pt"
    model.save(path)
    loaded = LearnedModel.load(path)
    assert loaded.spec == model.spec and loaded.meta == {"seed": 0}
    np.testing.assert_array_equal(loaded.calibration, calibration)
    assert loaded.n_components == 2
    for a, b in zip(model.network.parameters(), loaded.network.parameters(), strict=True):
        assert torch.equal(a, b)
    corrupted = tmp_path / "corrupted.pt"
    corrupted.write_bytes(path.read_bytes()[:200])
    with pytest.raises(ValueError, match="corrupted.pt: not a readable weights file"):
        LearnedModel.load(corrupted)
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(ValueError, match="not a etp-learned-predictor file"):
        LearnedModel.load(other)
    with pytest.raises(ValueError, match="no such file"):
        LearnedModel.load(tmp_path / "missing.pt")
    wrong = tmp_path / "wrong.pt"
    LearnedModel(ModelSpec(hidden=(4,))).save(wrong)
    payload = torch.load(wrong, weights_only=True)
    payload["spec"]["hidden"] = [16]
    torch.save(payload, wrong)
    with pytest.raises(ValueError, match="weights do not fit the model"):
        LearnedModel.load(wrong)
    config = PredictionConfig(model="learned", learned_weights=str(corrupted))
    with pytest.raises(ValueError, match="not a readable weights file"):
        make_predictor(config)
    # A version-1 file (one covariance factor per step) gives its network, uncalibrated.
    old = tmp_path / "v1.pt"
    payload = torch.load(path, weights_only=True)
    payload["version"], payload["calibration"] = 1, torch.full((5, 20, 2), 2.0, dtype=torch.float64)
    torch.save(payload, old)
    assert LearnedModel.load(old).n_components == 1
    payload["version"] = 7
    torch.save(payload, old)
    with pytest.raises(ValueError, match="format version 7"):
        LearnedModel.load(old)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda c: c[:, :1], "must have shape"),
        (lambda c: c * np.array([1.2, 1.0]), "sum to 1"),
        (lambda c: c * np.array([1.0, 0.0]), "variance factors must be > 0"),
        (lambda c: np.where(c > 3, np.inf, c), "finite"),
    ],
)
def test_bad_calibration_is_refused(change, message):
    calibration = np.zeros((5, 2, 20, 2, 2))
    calibration[..., 0] = [0.7, 0.3]
    calibration[..., 1] = [0.5, 4.0]
    with pytest.raises(ValueError, match=message):
        LearnedModel(ModelSpec(hidden=(4,)), calibration=change(calibration))


def test_mixture_prediction_scales_the_network_gaussian_per_motion_state():
    """Calibrated components are v_k times the uncalibrated covariance; cov is their weighted sum."""
    calibration = np.zeros((5, 2, 20, 2, 2))
    calibration[:, 0, :, :, 0] = [0.9, 0.1]  # standing
    calibration[:, 1, :, :, 0] = [0.6, 0.4]  # moving
    calibration[..., 1] = [0.5, 4.0]
    torch.manual_seed(1)
    model = LearnedModel(ModelSpec(hidden=(8,)), calibration=calibration)
    users = [moving_user(v=8.0), moving_user(uid=2, kind="pedestrian", v=0.2, x0=5.0)]
    times = np.array([0.0, 0.5, 1.0, 2.0])
    plain = LearnedPredictor(PredictionConfig(model="learned", learned_recalibration=False), model)
    mixed = LearnedPredictor(PredictionConfig(model="learned", covariance_floor=1e-9), model)
    a = plain.predict(users, times)
    b = LearnedPredictor(
        PredictionConfig(model="learned", learned_recalibration=False, covariance_floor=1e-9), model
    )
    base = b.predict(users, times)
    m = mixed.predict(users, times)
    assert a.n_components == 1 and m.n_components == 2
    np.testing.assert_allclose(m.mean, base.mean)
    # Steps after t = 0 (t = 0 is the observation, the same for every component).
    np.testing.assert_allclose(m.component_weight[0, 1:], np.broadcast_to([0.6, 0.4], (3, 2)))
    np.testing.assert_allclose(m.component_weight[1, 1:], np.broadcast_to([0.9, 0.1], (3, 2)))
    for k, v in enumerate([0.5, 4.0]):
        np.testing.assert_allclose(m.component_cov[:, 2:, k], v * base.cov[:, 2:], rtol=1e-9)
    np.testing.assert_allclose(m.cov, np.einsum("ntk,ntkij->ntij", m.component_weight, m.component_cov))


def test_prediction_is_equivariant_under_rotation_and_translation():
    """Rotating and shifting the whole scene rotates and shifts the prediction (independent check)."""
    model = LearnedModel.load()
    predictor = LearnedPredictor(PredictionConfig(model="learned"), model)
    times = np.arange(0.0, 3.01, 0.1)
    users = [moving_user(yaw=0.3), moving_user(uid=2, kind="pedestrian", x0=3.0, y0=-2.0, yaw=2.0, v=1.3)]
    angle, shift = 1.1, np.array([20.0, -7.0])
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])

    def moved(user):
        h = user.history
        p = (rot @ np.array([user.state.x, user.state.y])) + shift
        state = KinematicState(p[0], p[1], user.state.yaw + angle, user.state.v)
        history = MotionHistory(h.times, h.positions @ rot.T + shift, h.headings + angle, h.speeds)
        return RoadUser(user.id, user.type, state, user.shape, history=history)

    a = predictor.predict(users, times)
    b = predictor.predict([moved(u) for u in users], times)
    assert b.mean == pytest.approx(a.mean @ rot.T + shift, abs=1e-4)
    assert b.cov == pytest.approx(rot @ a.cov @ rot.T, abs=1e-4)
    assert b.component_cov == pytest.approx(rot @ a.component_cov @ rot.T, abs=1e-4)
    assert a.mean[:, 0] == pytest.approx(np.array([[0.0, 0.0], [3.0, -2.0]]))


def test_shipped_model_predicts_a_known_input_to_stored_values():
    """Shipped weights: a car at 10 m/s along x with 3 s of straight history (values stored at release)."""
    predictor = make_predictor(PredictionConfig(model="learned"))
    assert predictor.name == "learned"
    user = moving_user(yaw=0.0, v=10.0)
    times = np.array([0.0, 1.0, 2.0, 3.0])
    prediction = predictor.predict([user], times)
    assert prediction.mean[0, :, 0] == pytest.approx(SHIPPED_MEAN_X, abs=1e-3)
    # A car keeps roughly its speed for 3 s (a plausibility band, not the stored value).
    assert 25.0 < prediction.mean[0, 3, 0] < 35.0
    # The calibrated mixture (default): a confident core and a wide tail per step.
    assert prediction.component_weight[0] == pytest.approx(np.array(SHIPPED_WEIGHTS), abs=1e-3)
    assert np.sqrt(prediction.component_cov[0, :, :, 0, 0]) == pytest.approx(
        np.array(SHIPPED_SIGMA_X), abs=1e-3
    )
    # The network's own Gaussian (calibration off): unchanged since the network was trained.
    single = make_predictor(PredictionConfig(model="learned", learned_recalibration=False))
    prediction = single.predict([user], times)
    assert prediction.n_components == 1
    assert np.sqrt(prediction.cov[0, :, 0, 0]) == pytest.approx(SHIPPED_SIGMA_X_NETWORK, abs=1e-3)


def test_prediction_times_beyond_the_model_horizon_continue_smoothly():
    # Without the planner's floor, which raises each mixture component on its own.
    config = PredictionConfig(model="learned", covariance_floor=1e-9)
    predictor = LearnedPredictor(config, LearnedModel.load())
    times = np.arange(0.0, 6.01, 0.1)
    prediction = predictor.predict([moving_user(yaw=0.0, v=10.0)], times)
    step = np.diff(prediction.mean[0, :, 0])
    assert np.all(step > 0.5) and np.all(step < 1.5)
    # The size of the mixture (trace of its covariance) never shrinks from one model step
    # (every 0.2 s) to the next, inside the model's 4 s or beyond; t = 0 is the observation.
    # (Between steps, weights and components are interpolated apart, so their product may dip.)
    steps = slice(2, None, 2)
    assert np.all(np.diff(np.trace(prediction.cov[0, steps], axis1=-2, axis2=-1)) >= -1e-9)
    assert np.all(np.diff(np.trace(prediction.cov[0, 41:], axis1=-2, axis2=-1)) >= -1e-9)


SHIPPED_MEAN_X = [0.0, 10.0543, 20.082, 30.2114]
SHIPPED_SIGMA_X_NETWORK = [0.3162, 0.3162, 1.2236, 2.6275]
SHIPPED_WEIGHTS = [[0.5, 0.5], [0.9183, 0.0817], [0.7927, 0.2073], [0.7852, 0.2148]]
SHIPPED_SIGMA_X = [[0.3162, 0.3162], [0.3162, 0.595], [0.8144, 2.1762], [1.6865, 4.8888]]
