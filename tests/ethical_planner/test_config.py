import pytest

from ethical_planner.config import PlannerConfig, load_config, preset


def test_presets_are_small_overrides_of_one_default():
    ethical, selfish, standard = preset("ethical"), preset("selfish"), preset("standard")
    assert ethical == PlannerConfig()
    assert selfish.weights.ego_risk == 100 and selfish.weights.bayes == 0
    assert selfish.weights.risk == ethical.weights.risk
    assert standard.weights.risk == 0
    assert standard.sampling == ethical.sampling and standard.vehicle == ethical.vehicle


def test_reference_preset_runs_the_papers_weights():
    """The reference implementation's parameterisation: w_risk 250, equal principle
    weights 33.3, gamma 10, R_max 0.05, path weight 10 against the route's lane."""
    reference = preset("reference")
    w = reference.weights
    assert (w.risk, w.bayes, w.equality, w.maximin, w.maximin_gamma) == (250, 33.3, 33.3, 33.3, 10)
    assert (w.speed, w.path_distance, w.other_lane, w.jerk_lon, w.jerk_lat) == (1, 10, 0, 0.05, 0.05)
    assert w.path_reference == "route" and reference.risk.max_acceptable_risk == 0.05
    assert reference.sampling == preset("ethical").sampling


def test_unknown_key_is_named(tmp_path):
    path = tmp_path / "planner.toml"
    path.write_text('preset = "selfish"\n[weights]\nbayes = 2.0\nbogus = 1\n')
    with pytest.raises(ValueError, match="weights.bogus"):
        load_config(path)


def test_toml_overrides_apply(tmp_path):
    path = tmp_path / "planner.toml"
    path.write_text(
        'preset = "selfish"\n[risk]\nmax_acceptable_risk = 0.02\n[sampling]\nhorizons = [2.0, 3.0]\n'
    )
    config = load_config(path)
    assert config.name == "selfish"
    assert config.risk.max_acceptable_risk == 0.02
    assert config.sampling.horizons == (2.0, 3.0)
    assert config.sampling.n_trajectories == 15 * 15 * 2


@pytest.mark.parametrize(
    "overrides,match",
    [
        ({"responsibility": {"rule_violation": 0.7, "rear_end": 0.3}}, "r_i = 1"),
        ({"weights": {"maximin_gamma": 0.5}}, "gamma"),
        ({"risk": {"max_acceptable_risk": 1.5}}, "max_acceptable_risk"),
        ({"risk": {"harm_model": "nonsense"}}, "allowed"),
        ({"sampling": {"dt": 0.0}}, "dt"),
        ({"sampling": {"d_min": 2.0, "d_max": 1.0}}, "d_min"),
        ({"weights": {"bayes": float("nan")}}, "finite"),
        ({"vehicle": {"emergency_deceleration": -1.0}}, "vehicle.emergency_deceleration"),
        ({"vehicle": {"max_steering_angle": 1.6}}, "max_steering_angle"),
        ({"sampling": {"brake_lateral_fractions": [0.0]}}, "brake_lateral_fractions"),
        ({"sampling": {"brake_decelerations": [-2.0]}}, "brake_decelerations"),
        ({"commitment": {"relative_margin": -0.1}}, "commitment.relative_margin"),
        ({"commitment": {"switch_after_cycles": -1}}, "commitment.switch_after_cycles"),
        ({"commitment": {"switch_after_cycles": 2.5}}, "commitment.switch_after_cycles"),
        ({"weights": {"path_reference": "kerb"}}, "weights.path_reference"),
        ({"prediction": {"turn_rate_time_constant": 0.0}}, "turn_rate_time_constant"),
    ],
)
def test_bad_values_are_rejected_with_the_field(overrides, match):
    with pytest.raises(ValueError, match=match):
        PlannerConfig().with_overrides(overrides)


def test_unknown_preset():
    with pytest.raises(ValueError, match="allowed: ethical"):
        preset("utilitarian")


def test_curvature_limit_follows_the_kinematic_bicycle_and_the_tyres():
    """kappa_max(v) = min(tan(delta_max) / L, a_lat / v^2): by hand for the BMW 320i."""
    import math

    import numpy as np

    vehicle = preset("ethical").vehicle
    steering = math.tan(0.61) / 2.81  # 0.2487 1/m, a turning radius of 4.0 m
    assert vehicle.steering_curvature == pytest.approx(steering)
    limits = vehicle.max_curvature(np.array([0.0, 2.0, 14.0]))
    np.testing.assert_allclose(limits, [steering, steering, 8 / 196])
