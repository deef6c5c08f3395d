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
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from ethical_planner.harm import HarmModel
from ethical_planner.impulse import DeltaVModel, RestitutionLaw
from ethical_planner.records import errors_in, from_mapping, read_toml
from ethical_planner.registry import Registry
from ethical_planner.validation import (
    check,
    check_finite,
    check_non_negative,
    check_numeric_fields_finite,
    check_positive,
    parse_enum,
)

#: Bounds of the candidate grid: end speeds or offsets per horizon, planning step [s],
#: horizon [s], and candidates x steps per cycle (each point costs ~1 kB of arrays).
MAX_GRID_SIDE = 200
MIN_DT, MAX_DT = 0.001, 1.0
MAX_HORIZON = 20.0
MAX_GRID_POINTS = 2_000_000


@dataclass(frozen=True, slots=True)
class SamplingConfig:
    """Candidate families of one planning cycle (paper Fig. 1 step 1).

    Three families share one time grid, that of the longest horizon:

    - the paper's grid: end speeds x end offsets x horizons (quartic s(t), quintic
      d(t)); shorter horizons continue at constant speed and offset;
    - braking candidates: brake at each of ``brake_decelerations`` and at the vehicle's
      emergency deceleration (reached at ``vehicle.max_jerk``) to a stop, and stay
      stopped, each combined with every end offset; the lateral shift is a quintic in
      arc length completed over a fraction ``brake_lateral_fractions`` of the braking
      distance (a vehicle cannot move sideways while it stands);
    - the continuation of the previous cycle's plan (``CommitmentConfig``).

    Below ``low_speed`` the grid's lateral motion is also a quintic in arc length,
    over the distance each candidate travels in its horizon (Werling et al. 2010's
    low-speed mode): a quintic in time would ask a crawling car to move sideways
    faster than it moves forward.

    Attributes:
        n_speeds: number of end speeds per horizon.
        n_offsets: number of end lateral offsets per horizon.
        d_min, d_max: range of end lateral offsets from the reference path [m].
        horizons: planning horizons T [s]. Several: a 1 s lateral move covers 0.5 m in
            its first 0.5 s where a 2 s move covers 0.13 m (too slow to evade); 3 s
            plans see far enough to stop from urban speeds.
        dt: time step [s].
        max_end_acceleration: end speeds reach up to v0 + this times T [m/s^2].
        max_end_deceleration: end speeds reach down to v0 - this times T (and 0) [m/s^2].
        brake_candidates: sample the braking family.
        brake_decelerations: decelerations of braking candidates besides the
            emergency deceleration [m/s^2] (values above it are dropped).
        brake_lateral_fractions: fractions of the braking distance over which a
            braking candidate completes its lateral shift.
        low_speed: below this speed the grid's lateral motion follows arc length [m/s].
    """

    n_speeds: int = 15
    n_offsets: int = 15
    d_min: float = -3.5
    d_max: float = 3.5
    horizons: tuple[float, ...] = (1.0, 1.5, 2.0, 3.0)
    dt: float = 0.1
    max_end_acceleration: float = 3.0
    max_end_deceleration: float = 5.0
    brake_candidates: bool = True
    brake_decelerations: tuple[float, ...] = (2.0, 4.0, 6.0)
    brake_lateral_fractions: tuple[float, ...] = (0.5, 1.0)
    low_speed: float = 3.0

    def __post_init__(self) -> None:
        check_numeric_fields_finite("sampling", self)
        for name in ("n_speeds", "n_offsets"):
            value = getattr(self, name)
            check(
                isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= MAX_GRID_SIDE,
                f"sampling.{name} must be an integer in 1..{MAX_GRID_SIDE}, got {value!r}",
            )
        check(self.d_min <= self.d_max, "sampling.d_min must be <= sampling.d_max")
        for name in ("horizons", "brake_decelerations", "brake_lateral_fractions"):
            object.__setattr__(self, name, tuple(float(h) for h in getattr(self, name)))
        check(len(self.horizons) >= 1, "sampling.horizons must name at least one horizon")
        check(MIN_DT <= self.dt <= MAX_DT, f"sampling.dt must lie in [{MIN_DT}, {MAX_DT}] s, got {self.dt}")
        for horizon in self.horizons:
            check(
                math.isfinite(horizon) and self.dt <= horizon <= MAX_HORIZON,
                f"sampling.horizons must lie in [dt ({self.dt} s), {MAX_HORIZON} s], got {horizon}",
            )
        steps = int(round(max(self.horizons) / self.dt)) + 1
        points = self.n_trajectories * steps
        check(
            points <= MAX_GRID_POINTS,
            f"sampling.n_speeds x n_offsets x steps = {self.n_trajectories} x {steps} = {points} points per "
            f"cycle; at most {MAX_GRID_POINTS} (fewer end speeds or offsets, or a larger dt)",
        )
        check(
            self.max_end_acceleration > 0 and self.max_end_deceleration > 0,
            "sampling.max_end_acceleration and max_end_deceleration must be > 0 m/s^2",
        )
        check(
            all(math.isfinite(b) and b > 0 for b in self.brake_decelerations),
            f"sampling.brake_decelerations must be finite and > 0 m/s^2, got {self.brake_decelerations}",
        )
        check(
            len(self.brake_lateral_fractions) >= 1
            and all(math.isfinite(f) and 0 < f <= 1 for f in self.brake_lateral_fractions),
            "sampling.brake_lateral_fractions must name at least one fraction in (0, 1], "
            f"got {self.brake_lateral_fractions}",
        )
        check(self.low_speed >= 0, f"sampling.low_speed must be >= 0 m/s, got {self.low_speed}")

    @property
    def n_trajectories(self) -> int:
        """Number of grid candidates per planning cycle (without braking and continuation)."""
        return self.n_speeds * self.n_offsets * len(self.horizons)


@dataclass(frozen=True, slots=True)
class VehicleConfig:
    """The ego vehicle's physical limits, in one place (validity level 0 and braking).

    Defaults describe the default ego, a BMW 320i (wheelbase 2.81 m, 35 degrees of
    steering at the front wheels: a kerb-to-kerb turning circle of about 11 m), on dry
    asphalt with the world's tyre friction (mu = 0.9, ``mujoco_world`` ControlConfig).

    A kinematic bicycle turns with curvature kappa = tan(delta) / wheelbase, so the
    steering limit bounds |kappa| <= tan(max_steering_angle) / wheelbase at every speed;
    the tyres bound the lateral acceleration v^2 |kappa| <= max_lateral_acceleration,
    which is the tighter bound above sqrt(max_lateral_acceleration / kappa_steer)
    (5.7 m/s with the defaults); together ``max_curvature(v)``. Longitudinal and
    lateral acceleration share the friction circle sqrt(a^2 + (v^2 kappa)^2) <=
    friction_acceleration.

    Attributes:
        v_max: top speed [m/s].
        a_max: largest forward acceleration [m/s^2] (drive-train limit).
        emergency_deceleration: largest deceleration [m/s^2]: the hardest braking
            candidates brake at it, and a plan braking harder is invalid.
        max_jerk: rate at which braking builds up in braking candidates [m/s^3].
        wheelbase: [m].
        max_steering_angle: front-wheel angle [rad].
        max_lateral_acceleration: [m/s^2].
        friction_acceleration: radius of the friction circle [m/s^2] (mu g).
        curvature_check_speed: curvature is checked where the speed exceeds this
            [m/s]; below it the heading is ill-defined (the plan stands).
    """

    v_max: float = 50.0
    a_max: float = 5.0
    emergency_deceleration: float = 8.0
    max_jerk: float = 30.0
    wheelbase: float = 2.81
    max_steering_angle: float = 0.61
    max_lateral_acceleration: float = 8.0
    friction_acceleration: float = 8.8
    curvature_check_speed: float = 0.1

    def __post_init__(self) -> None:
        check_positive("vehicle", **{f.name: getattr(self, f.name) for f in dataclasses.fields(self)})
        check(
            self.max_steering_angle < 0.5 * math.pi,
            f"vehicle.max_steering_angle must be below pi/2 rad, got {self.max_steering_angle}",
        )

    @property
    def steering_curvature(self) -> float:
        """Largest curvature the steering allows [1/m]: tan(max_steering_angle) / wheelbase."""
        return math.tan(self.max_steering_angle) / self.wheelbase

    def max_curvature(self, speed: np.ndarray) -> np.ndarray:
        """Largest curvature [1/m] at ``speed`` [m/s] (any shape): steering, then tyres."""
        speed = np.asarray(speed, dtype=float)
        with np.errstate(divide="ignore"):
            tyres = self.max_lateral_acceleration / np.square(speed)
        return np.minimum(self.steering_curvature, tyres)


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
    ``learned_recalibration`` applies the weights file's calibration, a Gaussian scale
    mixture per step (on by default: on held-out locations it brings the 1- and 2-sigma
    coverage of moving road users near nominal and lowers the NLL; README, learned
    predictor); off, the prediction is the network's own single Gaussian.

    Attributes:
        model: predictor name.
        sigma0_long, sigma0_lat: standard deviations at t = 0 [m].
        growth_long, growth_lat: growth of the standard deviations [m/s].
        growth_long_per_speed: extra longitudinal growth per m/s of speed [1].
        pedestrian_growth: growth of both standard deviations of pedestrians [m/s].
            0.3: with 0.5 the 1-sigma ellipse held 99.7 / 99.1 / 97.7 % of held-out
            SinD pedestrian positions at 1 / 2 / 3 s (nominal 39.3 %, ``etp predictor
            eval``), and a walker on the shoulder made passing it 4.5 m away cost more
            than crawling behind it for the rest of the run (curve_truck). With 0.3 the
            standard deviation at 3 s is 1.1 m per axis, still above the predictor's
            0.60 m mean final error at 4 s on those pedestrians (README).
        covariance_floor: smallest covariance eigenvalue [m^2].
        use_turn_rate: False predicts straight lines.
        turn_rate_time_constant: time constant of the critically damped return of the
            heading to the road user's sustained course [s] (constant-acceleration
            model): a swerve is an episode, not a circle. A turn rate omega without a
            deviation from the course turns the heading by at most omega T / e.
        sustained_turn_window: (start, end) [s before now] of the window of the road
            user's motion history whose headings give its sustained course and turn rate
            (a curve it follows); without a history that long the course is the current
            heading. The sustained rate is capped at the current rate and dropped if
            their signs differ (a curve ends, a swerve swings back).
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
    learned_recalibration: bool = True

    sigma0_long: float = 0.3
    sigma0_lat: float = 0.2
    growth_long: float = 0.3
    growth_long_per_speed: float = 0.05
    growth_lat: float = 0.25
    pedestrian_growth: float = 0.3
    covariance_floor: float = 0.1
    use_turn_rate: bool = True
    turn_rate_time_constant: float = 0.8
    sustained_turn_window: tuple[float, float] = (2.5, 1.0)
    acceleration_time_constant: float = 1.0
    acceleration_sigma: float = 0.2
    acceleration_sigma_per_observed: float = 0.1
    max_observed_acceleration: float = 10.0

    def __post_init__(self) -> None:
        check_numeric_fields_finite("prediction", self)
        check(isinstance(self.model, str) and bool(self.model), "prediction.model must name a predictor")
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, bool | str | tuple):
                check(value >= 0, f"prediction.{f.name} must be >= 0, got {value}")
        check(self.covariance_floor > 0, "prediction.covariance_floor must be > 0 m^2")
        for name in ("turn_rate_time_constant", "acceleration_time_constant"):
            check(getattr(self, name) > 0, f"prediction.{name} must be > 0 s")
        check(
            isinstance(self.torch_threads, int) and self.torch_threads >= 1,
            f"prediction.torch_threads must be an integer >= 1, got {self.torch_threads!r}",
        )
        window = tuple(float(w) for w in self.sustained_turn_window)
        check(
            len(window) == 2 and all(math.isfinite(w) for w in window) and window[0] > window[1] >= 0,
            "prediction.sustained_turn_window must be (start, end) seconds before now with "
            f"start > end >= 0, got {self.sustained_turn_window}",
        )
        object.__setattr__(self, "sustained_turn_window", window)


@dataclass(frozen=True, slots=True)
class RiskConfig:
    """Risk assessment (SPEC section 3).

    Attributes:
        harm_model: model for protected collision partners.
        pedestrian_model: model for unprotected partners (pedestrians, cyclists...).
        gate_sigmas: distance gate of the collision probability [standard deviations].
        max_acceptable_risk: R_max; a candidate with R_ego or any R_k above it is level 3.
        boundary_harm: add the harm of hitting a wall when a candidate leaves the road.
        road_edge_margin: a candidate leaves the road (level 2) when its footprint
            comes closer than this to the edge of the drivable area [m]: kerbs and walls
            stand right at the edge, and a plan that skims them at an angle hits them
            with a few centimetres of tracking error (measured in overtake_cyclist).
        delta_v_model: ``eq1`` (paper Eq. 1, the default) or ``planar_impulse`` (an impulse
            at the first contact of the predicted footprints, ``ethical_planner.impulse``).
        restitution_law: restitution against the normal closing speed (planar model).
        impulse_ratio: largest tangential / normal impulse of the planar model (Coulomb
            friction between bodies; the world's contact friction is 0.3); ``inf`` is
            full stick, a common tangential velocity at the contact point.
    """

    harm_model: HarmModel = HarmModel.REDUCED_SYM
    pedestrian_model: HarmModel = HarmModel.PEDESTRIAN_MAIS3
    gate_sigmas: float = 6.0
    max_acceptable_risk: float = 0.002
    boundary_harm: bool = True
    road_edge_margin: float = 0.25
    delta_v_model: DeltaVModel = DeltaVModel.EQ1
    restitution_law: RestitutionLaw = field(default_factory=RestitutionLaw)
    impulse_ratio: float = 0.3

    def __post_init__(self) -> None:
        for name in ("harm_model", "pedestrian_model"):
            object.__setattr__(
                self, name, parse_enum(HarmModel, getattr(self, name), "harm model", f"risk.{name}")
            )
        model = parse_enum(DeltaVModel, self.delta_v_model, "delta-v model", "risk.delta_v_model")
        object.__setattr__(self, "delta_v_model", model)
        check(
            isinstance(self.restitution_law, RestitutionLaw),
            "risk.restitution_law must be a table with e_high, e_low, speed_scale",
        )
        check_finite("risk", gate_sigmas=self.gate_sigmas, max_acceptable_risk=self.max_acceptable_risk)
        check(
            isinstance(self.impulse_ratio, int | float)
            and not isinstance(self.impulse_ratio, bool)
            and self.impulse_ratio >= 0,
            f"risk.impulse_ratio must be >= 0 (inf: full stick), got {self.impulse_ratio!r}",
        )
        check(self.gate_sigmas > 0, "risk.gate_sigmas must be > 0")
        check_non_negative("risk", road_edge_margin=self.road_edge_margin)
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


class PathReference(StrEnum):
    """What the mobility's path term measures the lateral offset against."""

    #: The centre of the lane the candidate is in at each step (lane centres of the
    #: environment), with a preference for the route's lane.
    LANES = "lanes"
    #: The reference path, the route's own lane (the reference implementation).
    ROUTE = "route"


@dataclass(frozen=True, slots=True)
class CostWeights:
    """Weights of Eqs. 5-11 and of comfort and mobility.

    Units: the mobility and comfort terms are costs per m/s of speed deficit and the
    like; Eq. 5 multiplies the risk cost J_risk (Eq. 7, in units of risk, i.e. of the
    probability of an MAIS3+ injury) by ``risk``. The defaults are chosen so that risk
    decides whenever it is not negligible (issue 9, cause 4); ``preset("reference")``
    runs the paper's (reference implementation's) weights. Reasons, default by default:

    - risk = 1000: a risk of 1e-3 to one of three road users costs ~11 in Eq. 5, as
      much as a lane change; below 1e-4 it is noise next to comfort and mobility. The
      reference's 250 made risks below ~1e-2 irrelevant (at most 0.7 in the catalog).
    - bayes, equality, maximin = 33.3 each: the paper's equal weighting of the
      principles (it leaves their balance to society); kept.
    - responsibility = 0: the paper's experiment (non-interactive agents);
      ``ethical_responsible`` sets 0.5.
    - maximin_gamma = 4: the paper's discount of the worst harm regardless of
      probability. A vulnerable road user's harm of 0.4 counts (0.4^4 = 0.026), a car's
      0.05 does not (6e-6); gamma = 10 made maximin ~1e-10 for car harms (never deciding).
    - maximin_epsilon = 0.01: a collision counts as possible for maximin above a 1 %
      probability; the reference's 1e-3 would also count collisions that the
      deliberately wide covariances put only in their far tails.
    - jerk_lon, jerk_lat = 0.02: comfort is subordinate to safety: an evasive 1 m swerve
      in 1 s costs 14, not the 36 of the reference's 0.05.
    - speed = 2: one m/s of mean speed deficit over the horizon costs 2, so that
      staying behind a cyclist at 5 m/s on a 16.7 m/s road (23) costs more than a
      clear overtake (a lane, its transition and comfort: ~10).
    - path_distance = 1: one m of mean offset from the centre of the lane the ego is in
      costs as much as 0.5 m/s: lanes are where a car belongs, but a swerve around a
      walker is cheap. Measured against lane centres (``path_reference``), an
      overtake is not a permanent path deviation.
    - other_lane = 10: per lane between the lane the ego is in and the route's lane
      (time mean): keep to the own lane and return to it after an overtake.
    - oncoming_lane = 0: per lane across the centre line, in the oncoming traffic's
      lanes (time mean, ``cost.oncoming_lanes``), on top of other_lane; off by default.
      SPEC's mobility term knows no lanes, and pricing the wrong side more than a lane of
      the ego's own direction cost the catalog outcomes (measured against main 9ad1e39,
      seed 0): at 10, overtake_cyclist ethical and selfish timed out behind the cyclist;
      at 2, curve_truck selfish (goal -> timeout) and turning_truck_cyclist standard
      (goal -> no_progress) stayed behind the truck, while dense_urban standard reached
      its goal 9.5 s sooner. Set it together with ``speed`` (what staying behind costs).

    Attributes:
        risk: w_risk of Eq. 5.
        bayes, equality, maximin: w_B, w_E, w_M of Eq. 7.
        responsibility: fraction rho of w_B applied to J_R (Eq. 7 has rho = 1).
        ego_risk: weight of the ego's combined risk (the selfish planner's only term).
        maximin_gamma: discount exponent gamma >= 1 of Eq. 10.
        maximin_epsilon: collision probability above which a harm counts for maximin.
        jerk_lon, jerk_lat: weights of integrated squared jerk [per m^2/s^5].
        speed: weight of the mean |v - v_desired| [per m/s].
        path_distance: weight of the mean lateral offset from the path reference [per m].
        other_lane: weight per lane between the end lane and the route's lane.
        oncoming_lane: weight per lane across the centre line (oncoming traffic's lanes).
        path_reference: what the path term measures against (``PathReference``).
    """

    risk: float = 1000.0
    bayes: float = 33.3
    equality: float = 33.3
    maximin: float = 33.3
    responsibility: float = 0.0
    ego_risk: float = 0.0
    maximin_gamma: float = 4.0
    maximin_epsilon: float = 0.01
    jerk_lon: float = 0.02
    jerk_lat: float = 0.02
    speed: float = 2.0
    path_distance: float = 1.0
    other_lane: float = 10.0
    oncoming_lane: float = 0.0
    path_reference: PathReference = PathReference.LANES

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "path_reference",
            parse_enum(PathReference, self.path_reference, "path reference", "weights.path_reference"),
        )
        check_numeric_fields_finite("weights", self)
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, str):
                check(value >= 0, f"weights.{f.name} must be >= 0")
        check(self.maximin_gamma >= 1, "weights.maximin_gamma must be >= 1 (Eq. 10)")
        check(self.responsibility <= 1, "weights.responsibility must lie in [0, 1]")


@dataclass(frozen=True, slots=True)
class CommitmentConfig:
    """Commitment to a manoeuvre: the previous plan is kept unless a better one is clearly better.

    The previous cycle's plan, continued from where the ego is on it, is one more
    candidate. It is chosen over the cheapest candidate of the same validity level if
    its cost is within ``relative_margin`` |J_best| + ``absolute_margin`` of it (the
    absolute part only on the valid level, where Eq. 5's comfort and mobility set the
    scale; Eq. 6's risk costs have no fixed scale). A cost difference below the margin
    is within what one grid step of offset or speed and one cycle of re-prediction
    change, and swapping between equivalent manoeuvres is how the planner lost a
    working swerve (issue 9, cause 1). Across levels there is no hysteresis: a plan that
    became invalid, riskier than R_max or colliding is dropped at once.

    Persistence: the margin absorbs cycle-to-cycle noise, but a kept plan that costs
    more than the cheapest candidate of its level on ``switch_after_cycles``
    consecutive cycles is not kept on noise: on that cycle the cheapest is taken
    (``keep_previous_plan``). In curve_truck (seed 0) the ego crawled behind a walker
    at 1.5 m/s for 15 s although from 9.2 s a pass through the free oncoming lane was
    the cheapest plan on every cycle for 1.4 s, 0.2-1.2 below the crawl (1-4 %, margin
    2.0): within a 3 s horizon from 2 m/s the pass's speed gain (mean deficit 11.2
    instead of 14.9 m/s, 7.4 cost units) barely exceeds its lane change and lateral
    jerk (6.5). A cheaper plan must win again on every one of those cycles, so
    equivalent manoeuvres whose order flips from cycle to cycle are still not swapped.

    Attributes:
        enabled: add the continuation and apply the hysteresis.
        relative_margin: [1].
        absolute_margin: [cost units of Eq. 5].
        max_deviation: the continuation is dropped if the ego is further than this from
            it (position [m]) or its speed differs by more than this [m/s].
        switch_after_cycles: [planning cycles] (10: 1 s at the closed loop's 10 Hz
            replanning, ``RunConfig.replan_rate``); 0 keeps a plan within the margin
            for as long as it stays there (no persistence rule).
    """

    enabled: bool = True
    relative_margin: float = 0.05
    absolute_margin: float = 0.5
    max_deviation: float = 0.5
    switch_after_cycles: int = 10

    def __post_init__(self) -> None:
        check_non_negative(
            "commitment",
            relative_margin=self.relative_margin,
            absolute_margin=self.absolute_margin,
            max_deviation=self.max_deviation,
        )
        check(
            isinstance(self.switch_after_cycles, int)
            and not isinstance(self.switch_after_cycles, bool)
            and self.switch_after_cycles >= 0,
            f"commitment.switch_after_cycles must be a whole number of cycles >= 0, "
            f"got {self.switch_after_cycles!r}",
        )


@dataclass(frozen=True, slots=True)
class TrafficRulesConfig:
    """How the planner treats the road's stop lines (``ethical_planner.traffic_rules``).

    A candidate that crosses a binding stop line (a red light at its predicted crossing
    time, or a stop sign the ego has not stood still at) gets validity level 4
    (``Validity.BREAKS_TRAFFIC_RULE``): invalid, not costed. A line binds unless the ego
    can no longer stop before it (the dilemma zone): a light that turns red later binds
    while the ego can stop before the line at ``comfortable_deceleration``; a light that
    is red now, and a stop sign, bind while it can stop at the vehicle's emergency
    deceleration.

    Attributes:
        enabled: apply the stop lines (False: the planner ignores them, as before).
        comfortable_deceleration: [m/s^2]. 3.0 m/s^2 (10 ft/s^2) is the deceleration
            behind the ITE yellow-interval formula, which sizes the amber phase so that
            a driver who cannot stop at it can clear the line. It also judges a
            candidate's end state: if it cannot stop before a line at this deceleration,
            the candidate is taken to cross it at its end speed.
        stop_gap: the front stops this far before the line [m] (stop-line candidates).
        min_deceleration: stop-line candidates brake at least this hard [m/s^2]; a line
            further away than that stop gets none (the grid reaches it later).
        red_margin: each red window is widened by this much on both sides when a plan
            is judged [s]: the world's ego does not cross exactly when planned (a
            random red_light_for_ego variant planned to cross 0.0 s after the green
            and crossed 13 ms before it, a violation). 0.5 s at 8 m/s is 4 m.
        no_overtaking: keep the road's no-overtaking zones (``RoadEnvironment.
            no_overtaking``): a candidate whose footprint moves further across the
            centre line in a zone is level 4, unless something slower than the zone's
            ``pass_below`` blocks the ego's lane within ``pass_lookahead``.
        shoulder: keep off the shoulders (``RoadEnvironment.lane_edges``): a candidate
            whose footprint moves further beyond an outer lane edge is level 4. The
            validity hierarchy lets a shoulder plan win when every plan in the lanes is
            invalid or above R_max (to avoid a crash). Off by default: switched on, it
            changed plans across the catalog and turned curve_truck (ethical and
            selfish) from goal into no_progress (an ego stopped on the shoulder had no
            move that kept the rule; fixed, ``breaks_lane_rules``; the catalog with it
            on is not compared yet); the world still reports every shoulder entry
            (``RuleViolations``).
        pass_lookahead: how far ahead of the ego's front a slow obstacle releases a
            no-overtaking zone [m].
        marking_margin: the planner keeps this far inside the centre line and the
            outer lane edges [m] (the world's judge tolerates 0.1 m; the executed path
            strays from the plan by a few centimetres).
        zone_margin: each no-overtaking zone is lengthened by this much at both ends
            [m] (the plan is judged at its samples; the executed path lags it).
    """

    enabled: bool = True
    comfortable_deceleration: float = 3.0
    stop_gap: float = 1.0
    min_deceleration: float = 0.5
    red_margin: float = 0.5
    no_overtaking: bool = True
    shoulder: bool = False
    pass_lookahead: float = 40.0
    marking_margin: float = 0.05
    zone_margin: float = 2.0

    def __post_init__(self) -> None:
        enabled = self.enabled
        check(isinstance(enabled, bool), f"traffic_rules.enabled must be true or false, got {enabled!r}")
        for name in ("no_overtaking", "shoulder"):
            value = getattr(self, name)
            check(isinstance(value, bool), f"traffic_rules.{name} must be true or false, got {value!r}")
        check_positive("traffic_rules", pass_lookahead=self.pass_lookahead)
        check_non_negative("traffic_rules", marking_margin=self.marking_margin, zone_margin=self.zone_margin)
        check_positive(
            "traffic_rules",
            comfortable_deceleration=self.comfortable_deceleration,
            min_deceleration=self.min_deceleration,
        )
        check_non_negative("traffic_rules", stop_gap=self.stop_gap, red_margin=self.red_margin)


@dataclass(frozen=True, slots=True)
class TerminalConfig:
    """Terminal safety: a plan must not end in oncoming traffic's way too late to get out.

    ``ethical_planner.terminal`` states the rule. A plan that ends with the ego's
    footprint in an oncoming road user's lane is a predicted collision (level 1) unless
    the ego can return to its side of the lane boundary, with a quintic lateral move at
    ``return_lateral_acceleration``, ``time_buffer`` before the road user arrives.

    Attributes:
        enabled: apply the condition (False: plans are judged over their horizon only).
        return_lateral_acceleration: peak lateral acceleration of the return [m/s^2].
            3.0 m/s^2 is a brisk but ordinary lane change (drivers' lane changes peak at
            1-3 m/s^2), well inside the tyres' 8 m/s^2: the condition must not rest on
            an emergency manoeuvre.
        time_buffer: margin between the end of the return and the road user's arrival
            [s]. 1.0 s is the order of a driver's reaction time and of one replanning
            interval plus the controller's tracking lag.
        min_speed: road users slower than this along the path are not oncoming [m/s].
        oncoming_angle: a road user is oncoming if its heading is within this angle of
            the path's opposite direction [rad] (60 degrees).
        standstill_distance: a plan must end able to stop this far before a static
            obstacle of the road (debris) [m]. 9.0 m is the arc length a quintic
            lateral move of one lane width (3.5 m) needs at the steering limit
            (0.249 1/m): from there the ego can still steer around it
            (``terminal.standstill_distance``). debris_on_lane: stopped 0.6 m before the
            debris, the ego could not pass it without reversing.
        stopping_deceleration: the braking assumed for that stop [m/s^2]; 3.0 m/s^2 is
            a firm, ordinary stop (the ITE amber-interval deceleration).
    """

    enabled: bool = True
    return_lateral_acceleration: float = 3.0
    time_buffer: float = 1.0
    min_speed: float = 0.5
    oncoming_angle: float = math.pi / 3.0
    standstill_distance: float = 9.0
    stopping_deceleration: float = 3.0

    def __post_init__(self) -> None:
        check(isinstance(self.enabled, bool), f"terminal.enabled must be true or false, got {self.enabled!r}")
        check_positive("terminal", return_lateral_acceleration=self.return_lateral_acceleration)
        check_positive("terminal", stopping_deceleration=self.stopping_deceleration)
        check_non_negative(
            "terminal",
            time_buffer=self.time_buffer,
            min_speed=self.min_speed,
            standstill_distance=self.standstill_distance,
        )
        check(
            0.0 < self.oncoming_angle < 0.5 * math.pi,
            f"terminal.oncoming_angle must lie in (0, pi/2) rad, got {self.oncoming_angle}",
        )


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
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    prediction: PredictionConfig = field(default_factory=PredictionConfig)
    risk: RiskConfig = field(default_factory=RiskConfig)
    responsibility: ResponsibilityConfig = field(default_factory=ResponsibilityConfig)
    weights: CostWeights = field(default_factory=CostWeights)
    commitment: CommitmentConfig = field(default_factory=CommitmentConfig)
    traffic_rules: TrafficRulesConfig = field(default_factory=TrafficRulesConfig)
    terminal: TerminalConfig = field(default_factory=TerminalConfig)

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
#: The paper's parameterisation (reference implementation): its weights, gamma, R_max
#: and a path term against the route's lane. The sampling is the default one.
PRESETS.register(
    "reference",
    {
        "name": "reference",
        "risk": {"max_acceptable_risk": 0.05},
        "weights": {
            "risk": 250.0,
            "maximin_gamma": 10.0,
            "maximin_epsilon": 1e-3,
            "jerk_lon": 0.05,
            "jerk_lat": 0.05,
            "speed": 1.0,
            "path_distance": 10.0,
            "other_lane": 0.0,
            "oncoming_lane": 0.0,
            "path_reference": "route",
        },
    },
)


def preset(name: str) -> PlannerConfig:
    """Return the configuration of a named preset (``PRESETS``).

    Raises:
        ValueError: for an unknown name (the message lists the presets).
    """
    return PlannerConfig().with_overrides(PRESETS.get(name))


def load_config(path: str | Path, base: str = "ethical") -> PlannerConfig:
    """Load a TOML file of overrides on top of the preset ``base`` (key ``preset`` wins).

    Raises:
        ValueError: unreadable file, unknown preset or key, invalid value; the message
            names the file and the dotted key.
    """
    data = read_toml(path, "planner configuration")
    with errors_in(path):
        return preset(data.pop("preset", base)).with_overrides(data)
