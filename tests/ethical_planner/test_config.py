import pytest

from ethical_planner.config import PlannerConfig, load_config, preset


def test_presets_are_small_overrides_of_one_default():
    ethical, selfish, standard = preset("ethical"), preset("selfish"), preset("standard")
    assert ethical == PlannerConfig()
    assert selfish.weights.ego_risk == 100 and selfish.weights.bayes == 0 and selfish.weights.risk == 250
    assert standard.weights.risk == 0
    assert standard.sampling == ethical.sampling and standard.vehicle == ethical.vehicle


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
    assert config.sampling.n_trajectories == 450


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
        ({"vehicle": {"a_min": 1.0}}, "a_min"),
    ],
)
def test_bad_values_are_rejected_with_the_field(overrides, match):
    with pytest.raises(ValueError, match=match):
        PlannerConfig().with_overrides(overrides)


def test_unknown_preset():
    with pytest.raises(ValueError, match="allowed: ethical"):
        preset("utilitarian")
