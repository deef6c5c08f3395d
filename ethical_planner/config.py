"""Planner configuration: nested frozen dataclasses, TOML loading and presets.

One default configuration; the presets ``ethical``, ``selfish`` and ``standard``
are small overrides of it (SPEC section 5). Unknown keys in TOML or in overrides
are rejected with the key's dotted name.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ethical_planner.harm import HarmModel
from ethical_planner.records import errors_in, from_mapping, read_toml
from ethical_planner.registry import Registry
from ethical_planner.validation import check, check_numeric_fields_finite, parse_enum


@dataclass(frozen=True, slots=True)
class SamplingConfig:
    """Candidate grid (paper Fig. 1 step 1).

    Attributes:
        n_speeds: number of end speeds per horizon.
        n_offsets: number of end lateral offsets per horizon.
        d_min, d_max: range of end lateral offsets from the reference path [m].
        horizons: planning horizons T [s]; candidates of shorter horizons continue
            at constant speed and offset up to the longest.
        dt: time step [s].
        max_end_acceleration: end speeds reach up to v0 + this times T [m/s^2].
        max_end_deceleration: end speeds reach down to v0 - this times T (and 0) [m/s^2].
    """

    n_speeds: int = 15
    n_offsets: int = 15
    d_min: float = -3.5
    d_max: float = 3.5
    horizons: tuple[float, ...] = (2.0,)
    dt: float = 0.1
    max_end_acceleration: float = 4.0
    max_end_deceleration: float = 8.0

    def __post_init__(self) -> None:
        check_numeric_fields_finite("sampling", self)
        check(self.n_speeds >= 1, "sampling.n_speeds must be >= 1")
        check(self.n_offsets >= 1, "sampling.n_offsets must be >= 1")
        check(self.d_min <= self.d_max, "sampling.d_min must be <= sampling.d_max")
        object.__setattr__(self, "horizons", tuple(float(h) for h in self.horizons))
        check(len(self.horizons) >= 1, "sampling.horizons must name at least one horizon")
        check(self.dt > 0, f"sampling.dt must be > 0 s, got {self.dt}")
        for horizon in self.horizons:
            check(
                math.isfinite(horizon) and horizon >= self.dt,
                f"sampling.horizons must be finite and >= dt ({self.dt} s), got {horizon}",
            )
        check(
            self.max_end_acceleration > 0 and self.max_end_deceleration > 0,
            "sampling.max_end_acceleration and max_end_deceleration must be > 0 m/s^2",
        )

    @property
    def n_trajectories(self) -> int:
        """Number of candidates per planning cycle."""
        return self.n_speeds * self.n_offsets * len(self.horizons)


@dataclass(frozen=True, slots=True)
class VehicleLimits:
    """Physical limits of the ego used by validity level 0.

    Attributes:
        v_max: [m/s]. a_max: [m/s^2]. a_min: most negative acceleration [m/s^2].
        kappa_max: curvature [1/m], checked above ``kappa_check_speed`` [m/s] (curvature
            is ill-defined at standstill).
        emergency_deceleration: used by the emergency-braking fallback [m/s^2].
    """

    v_max: float = 50.0
    a_max: float = 5.0
    a_min: float = -9.0
    kappa_max: float = 0.2
    kappa_check_speed: float = 1.0
    emergency_deceleration: float = 8.0

    def __post_init__(self) -> None:
        check_numeric_fields_finite("vehicle", self)
        check(self.v_max > 0, "vehicle.v_max must be > 0 m/s")
        check(self.a_max > 0 > self.a_min, "vehicle.a_max must be > 0 and vehicle.a_min < 0")
        check(self.kappa_max > 0, "vehicle.kappa_max must be > 0 1/m")
        check(self.emergency_deceleration > 0, "vehicle.emergency_deceleration must be > 0")


@dataclass(frozen=True, slots=True)
class PredictionConfig:
    """Prediction of the other road users, with a covariance growing over the horizon.

    ``model`` names the predictor in ``ethical_planner.prediction.PREDICTORS``:
    ``"constant_acceleration"`` (the default) keeps each road user's observed
    acceleration until it stops (never reversing) and lets its observed turn rate
    decay; ``"constant_turn_rate"`` keeps speed and turn rate.

    Standard deviations in the road user's heading frame, with tau the time of motion
    (t, or the predicted stop time if earlier; the constant-turn-rate model uses t):
    sigma_long(t) = sigma0_long + (growth_long + growth_long_per_speed v) tau
    + 0.5 sigma_a tau^2, sigma_a = acceleration_sigma + acceleration_sigma_per_observed |a|
    (the constant-turn-rate model has no acceleration term);
    sigma_lat(t) = sigma0_lat + growth_lat t. Pedestrians use ``pedestrian_growth`` in
    both directions instead of the growth terms. Eigenvalues below ``covariance_floor``
    [m^2] are raised to it.

    ``learned_weights`` is the weights file of the ``"learned"`` predictor (empty: the
    shipped weights); ``torch_threads`` its torch intra-op threads (set explicitly so
    that a pool of planner processes does not oversubscribe the cores);
    ``learned_recalibration`` applies the weights file's coverage recalibration (off by
    default: on held-out locations it brings the 1-sigma coverage to nominal but
    under-covers the 2-sigma ellipse and raises the NLL; README, learned predictor).

    Attributes:
        model: predictor name.
        sigma0_long, sigma0_lat: standard deviations at t = 0 [m].
        growth_long, growth_lat: growth of the standard deviations [m/s].
        growth_long_per_speed: extra longitudinal growth per m/s of speed [1].
        pedestrian_growth: growth of both standard deviations of pedestrians [m/s].
        covariance_floor: smallest covariance eigenvalue [m^2].
        use_turn_rate: False predicts straight lines.
        turn_rate_time_constant: the observed turn rate decays as exp(-t / this) [s]
            (constant-acceleration model): a swerve is an episode, not a circle. With
            the default 0.8 s a turn rate keeps acting for 0.8 s in total.
        acceleration_time_constant: an observed positive acceleration decays as
            exp(-t / this) [s] (an acceleration phase ends; braking to a stop is held
            at its observed value).
        acceleration_sigma: uncertainty of the future acceleration [m/s^2].
        acceleration_sigma_per_observed: extra uncertainty per m/s^2 of observed
            acceleration [1] (a braking road user may brake harder or release).
        max_observed_acceleration: observed accelerations are clipped to +- this
            [m/s^2] (finite differences through a contact are not a driver's input).
    """

    model: str = "constant_acceleration"
    learned_weights: str = ""
    torch_threads: int = 1
    learned_recalibration: bool = False

    sigma0_long: float = 0.3
    sigma0_lat: float = 0.2
    growth_long: float = 0.3
    growth_long_per_speed: float = 0.05
    growth_lat: float = 0.25
    pedestrian_growth: float = 0.5
    covariance_floor: float = 0.1
    use_turn_rate: bool = True
    turn_rate_time_constant: float = 0.8
    acceleration_time_constant: float = 1.0
    acceleration_sigma: float = 0.5
    acceleration_sigma_per_observed: float = 0.2
    max_observed_acceleration: float = 10.0

    def __post_init__(self) -> None:
        check_numeric_fields_finite("prediction", self)
        check(isinstance(self.model, str) and bool(self.model), "prediction.model must name a predictor")
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, bool | str):
                check(value >= 0, f"prediction.{f.name} must be >= 0, got {value}")
        check(self.covariance_floor > 0, "prediction.covariance_floor must be > 0 m^2")
        for name in ("turn_rate_time_constant", "acceleration_time_constant"):
            check(getattr(self, name) > 0, f"prediction.{name} must be > 0 s")
        check(
            isinstance(self.torch_threads, int) and self.torch_threads >= 1,
            f"prediction.torch_threads must be an integer >= 1, got {self.torch_threads!r}",
        )


@dataclass(frozen=True, slots=True)
class RiskConfig:
    """Risk assessment (SPEC section 3).

    Attributes:
        harm_model: model for protected collision partners.
        pedestrian_model: model for unprotected partners (pedestrians, cyclists...).
        gate_sigmas: distance gate of the collision probability [standard deviations].
        max_acceptable_risk: R_max; a candidate with R_ego or any R_k above it is level 3.
        boundary_harm: add the harm of hitting a wall when a candidate leaves the road.
        delta_v_correction: path of a ``calibration.json`` written by ``etp impacts``
            (a ``DeltaVCorrection``); None plans with the plain Eq. 1 delta-v.
    """

    harm_model: HarmModel = HarmModel.REDUCED_SYM
    pedestrian_model: HarmModel = HarmModel.PEDESTRIAN_MAIS3
    gate_sigmas: float = 6.0
    max_acceptable_risk: float = 0.05
    boundary_harm: bool = True
    delta_v_correction: str | None = None

    def __post_init__(self) -> None:
        for name in ("harm_model", "pedestrian_model"):
            object.__setattr__(
                self, name, parse_enum(HarmModel, getattr(self, name), "harm model", f"risk.{name}")
            )
        check_numeric_fields_finite("risk", self)
        check(
            self.delta_v_correction is None or isinstance(self.delta_v_correction, str),
            "risk.delta_v_correction must be the path of a calibration JSON file or unset",
        )
        check(self.gate_sigmas > 0, "risk.gate_sigmas must be > 0")
        check(
            0.0 <= self.max_acceptable_risk <= 1.0,
            f"risk.max_acceptable_risk must lie in [0, 1], got {self.max_acceptable_risk}",
        )


@dataclass(frozen=True, slots=True)
class ResponsibilityConfig:
    """Sources of responsibility r_i (Eq. 11); their sum must stay below 1.

    Attributes:
        base_max: base responsibility of a motorised road user of infinite mass.
        base_mass_scale: r_base = base_max (1 - exp(-m / base_mass_scale)) [kg].
        rule_violation: added when the potential collision lies outside the road
            user's legal reachable set.
        rear_end: added to the follower of a rear-end collision.
    """

    base_max: float = 0.1
    base_mass_scale: float = 5000.0
    rule_violation: float = 0.5
    rear_end: float = 0.3

    def __post_init__(self) -> None:
        check_numeric_fields_finite("responsibility", self)
        check(
            min(self.base_max, self.rule_violation, self.rear_end) >= 0,
            "responsibility.base_max, rule_violation and rear_end must be >= 0",
        )
        check(self.base_mass_scale > 0, "responsibility.base_mass_scale must be > 0 kg")
        total = self.base_max + self.rule_violation + self.rear_end
        check(
            total < 1.0,
            "responsibility.base_max + rule_violation + rear_end must be < 1 so that no "
            f"road user's risk is ignored entirely (r_i = 1), got {total:g}",
        )


@dataclass(frozen=True, slots=True)
class CostWeights:
    """Weights of Eqs. 5-11 and of comfort and mobility.

    Attributes:
        risk: w_risk of Eq. 5.
        bayes, equality, maximin: w_B, w_E, w_M of Eq. 7.
        responsibility: fraction rho of w_B applied to J_R (Eq. 7 has rho = 1).
        ego_risk: weight of the ego's combined risk (the selfish planner's only term).
        maximin_gamma: discount exponent gamma >= 1 of Eq. 10.
        maximin_epsilon: collision probability above which a harm counts for maximin.
        jerk_lon, jerk_lat: weights of integrated squared jerk [per m^2/s^5].
        speed: weight of the mean |v - v_desired| [per m/s].
        path_distance: weight of the mean |d| from the reference path [per m].
    """

    risk: float = 250.0
    bayes: float = 33.3
    equality: float = 33.3
    maximin: float = 33.3
    responsibility: float = 0.0
    ego_risk: float = 0.0
    maximin_gamma: float = 10.0
    maximin_epsilon: float = 1e-3
    jerk_lon: float = 0.05
    jerk_lat: float = 0.05
    speed: float = 1.0
    path_distance: float = 10.0

    def __post_init__(self) -> None:
        check_numeric_fields_finite("weights", self)
        for f in dataclasses.fields(self):
            check(getattr(self, f.name) >= 0, f"weights.{f.name} must be >= 0")
        check(self.maximin_gamma >= 1, "weights.maximin_gamma must be >= 1 (Eq. 10)")
        check(self.responsibility <= 1, "weights.responsibility must lie in [0, 1]")


@dataclass(frozen=True, slots=True)
class PlannerConfig:
    """Everything a planning cycle needs besides the scene.

    Attributes:
        name: preset name shown in decision records.
        desired_speed: [m/s]; None uses the road's speed limit.
    """

    name: str = "ethical"
    desired_speed: float | None = None
    sampling: SamplingConfig = field(default_factory=SamplingConfig)
    vehicle: VehicleLimits = field(default_factory=VehicleLimits)
    prediction: PredictionConfig = field(default_factory=PredictionConfig)
    risk: RiskConfig = field(default_factory=RiskConfig)
    responsibility: ResponsibilityConfig = field(default_factory=ResponsibilityConfig)
    weights: CostWeights = field(default_factory=CostWeights)

    def __post_init__(self) -> None:
        if self.desired_speed is not None:
            check(
                math.isfinite(self.desired_speed) and self.desired_speed >= 0,
                f"desired_speed must be a finite speed >= 0 m/s, got {self.desired_speed}",
            )

    def with_overrides(self, overrides: Mapping[str, Any]) -> PlannerConfig:
        """Return a copy with nested ``overrides`` applied.

        Raises:
            ValueError: an unknown key (named with its dotted path) or an invalid value.
        """
        return from_mapping(PlannerConfig, overrides, base=self)


#: The presets as small overrides of the default (SPEC section 5).
PRESETS: Registry[Mapping[str, Any]] = Registry("planner preset")
PRESETS.register("ethical", {})
PRESETS.register(
    "selfish",
    {"name": "selfish", "weights": {"bayes": 0.0, "equality": 0.0, "maximin": 0.0, "ego_risk": 100.0}},
)
PRESETS.register(
    "standard",
    {"name": "standard", "weights": {"risk": 0.0, "bayes": 0.0, "equality": 0.0, "maximin": 0.0}},
)
PRESETS.register("ethical_responsible", {"name": "ethical_responsible", "weights": {"responsibility": 0.5}})


def preset(name: str) -> PlannerConfig:
    """Return the configuration of a named preset (``PRESETS``).

    Raises:
        ValueError: for an unknown name (the message lists the presets).
    """
    return PlannerConfig().with_overrides(PRESETS.get(name))


def load_config(path: str | Path, base: str = "ethical") -> PlannerConfig:
    """Load a TOML file of overrides on top of the preset ``base`` (key ``preset`` wins).

    A relative ``risk.delta_v_correction`` path is relative to the TOML file's folder.

    Raises:
        ValueError: unreadable file, unknown preset or key, invalid value; the message
            names the file and the dotted key.
    """
    data = read_toml(path, "planner configuration")
    with errors_in(path):
        config = preset(data.pop("preset", base)).with_overrides(data)
    correction = config.risk.delta_v_correction
    if correction is not None and not Path(correction).is_absolute():
        resolved = str(Path(path).parent / correction)
        config = dataclasses.replace(
            config, risk=dataclasses.replace(config.risk, delta_v_correction=resolved)
        )
    return config
