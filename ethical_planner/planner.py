"""One planning cycle (paper Fig. 1) and its decision record.

sample -> predict -> assess risk -> responsibility -> validity levels -> cost ->
choose the cheapest candidate of the highest available level. Every cycle returns a
``Decision`` that says what was chosen and why, in numbers a person can check.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ethical_planner.boundary import edge_impact_speed, physical_view
from ethical_planner.collision_probability import collides
from ethical_planner.config import CommitmentConfig, CostWeights, PlannerConfig
from ethical_planner.cost import (
    CostBreakdown,
    comfort_and_mobility,
    eq5_cost,
    oncoming_lanes,
    path_deviation,
    responsibility,
    risk_set,
    total_cost,
)
from ethical_planner.environment import RoadEnvironment
from ethical_planner.prediction import Prediction, Predictor, make_predictor
from ethical_planner.responsibility import LegalCorridors, collision_onset, responsibilities
from ethical_planner.risk import (
    RiskAssessment,
    assess_risk,
    gated_triples,
    outside_drivable_area,
    prediction_tables,
    risk_detail,
    subset_triples,
)
from ethical_planner.road_users import EGO_MASS_KG, EGO_SHAPE, KinematicState, RoadUser, RoadUserType, Shape
from ethical_planner.sampling import (
    CandidateKind,
    CandidateParameters,
    Candidates,
    FrenetState,
    PreviousPlan,
    emergency_braking,
    every_row,
    frenet_state,
    sample_candidates,
)
from ethical_planner.terminal import crowds_static_obstacle, terminally_unsafe
from ethical_planner.traffic_rules import (
    LaneRules,
    StopLines,
    breaks_lane_rules,
    breaks_stop_lines,
    stood_at,
    stop_targets,
)
from ethical_planner.validity import UNASSESSED, Validity, physically_invalid, validity_levels
from ethical_planner.workers import Workers


@dataclass(frozen=True, slots=True, eq=False)
class Trajectory:
    """The executed plan: arrays of shape (n_t,), t[0] = 0 at the planning state.

    Attributes:
        t: [s]. x, y: ego centre [m]. yaw: [rad]. v: [m/s]. a: [m/s^2]. kappa: [1/m].
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    v: np.ndarray
    a: np.ndarray
    kappa: np.ndarray

    @classmethod
    def from_candidates(cls, candidates: Candidates, index: int) -> Trajectory:
        """Copy candidate ``index`` out of the struct of arrays."""
        return cls(
            candidates.t.copy(),
            *(getattr(candidates, name)[index].copy() for name in ("x", "y", "yaw", "v", "a", "kappa")),
        )


@dataclass(frozen=True, slots=True)
class RoadUserAssessment:
    """What the chosen plan means for one road user.

    Attributes:
        id, type: the road user.
        risk: R_k of the chosen plan (max over the horizon of p H).
        ego_risk: R_ego,k, the ego's risk in a collision with it.
        collision_probability: highest p_k(t) along the plan.
        harm: its harm at the step of the highest collision probability.
        ego_harm: the ego's harm at that step.
        responsibility: r_k.
        ego_responsibility: the ego's responsibility for R_ego,k.
    """

    id: int
    type: RoadUserType
    risk: float
    ego_risk: float
    collision_probability: float
    harm: float
    ego_harm: float
    responsibility: float
    ego_responsibility: float


@dataclass(frozen=True, slots=True)
class LevelBest:
    """The cheapest candidate of one validity level.

    Attributes:
        index: its index among the cycle's sampled candidates.
        cost: its total cost: Eq. 5 on the valid level, the risk cost (Eq. 6) on the others.
        candidate: its family and parameters.
    """

    index: int
    cost: float
    candidate: CandidateParameters

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form."""
        return {"index": self.index, "cost": self.cost, "candidate": self.candidate.to_dict()}


@dataclass(frozen=True, slots=True, eq=False)
class Decision:
    """Readable record of one planning cycle.

    Attributes:
        planner: preset name.
        trajectory: the chosen plan.
        chosen_index: index of the chosen candidate, -1 for emergency braking.
        candidate: the chosen candidate's family and parameters.
        continued: the plan is the continuation of the previous cycle's.
        max_risk_refused: candidates above R_max (level 3) that Eq. 5 would have
            preferred to the chosen valid plan: R_max decided this cycle if > 0.
        level: validity level of the chosen plan.
        level_counts: candidates per validity level; key ``UNASSESSED`` (-1): candidates
            whose risk was not evaluated because their Eq. 5 cost at zero risk is above
            the chosen plan's (valid, above R_max or breaks a traffic rule: unknown, never counted as any),
            or, at a fallback level (a predicted collision, leaving the road), because a
            lower bound of their Eq. 6 cost is (they are at that level; never counted there).
        invalid_counts: physically invalid candidates per broken limit (a candidate
            may break several).
        terminal_unsafe: candidates within the physical limits that end in oncoming
            traffic's way too late to get out (``ethical_planner.terminal``); they count
            as level 1 (collision beyond the horizon).
        best_by_level: the cheapest sampled candidate of each level whose candidates
            were costed, by level (ties broken by comfort plus mobility, as the choice
            does). Costs need risk, which is evaluated only for the candidates of the
            highest level the integral-free tests leave possible (``_Evaluation``):
            levels below it (physically invalid, collision, leaves the road when a
            better one exists) have no entry. When candidates were left unassessed
            (``level_counts[UNASSESSED]``), the levels they may be at have no entry
            (above R_max, and breaks a traffic rule if one of them does), except the
            valid level, whose cheapest candidate is exact.
        reason: why this candidate.
        emergency: True if the emergency-braking fallback was taken.
        ego_combined_risk: R_ego of the plan (Eq. 4).
        boundary_risk: the ego's risk of leaving the road on the plan.
        max_acceptable_risk: R_max in force.
        costs: every cost term of the plan (Eqs. 5-11).
        road_users: per road user, in the order given.
        timings_ms: process CPU time per stage [ms]: ``sampling``, ``prediction``,
            ``validity``, ``risk``, ``responsibility``, ``cost``, ``selection`` and
            ``record`` (this record), which add up to ``total`` (less the clock reads);
            ``wall``: the cycle's wall time [ms]. Process time counts every thread of the
            process: the collision-probability pool's workers (what the cycle costs), but
            also any other thread the caller runs meanwhile. On a shared machine wall
            time also counts other jobs' time slices.
        candidate_x, candidate_y: all candidates [m], shape (n, n_t), for display.
        candidate_levels: their validity levels, shape (n,).
        prediction: the prediction used.
    """

    planner: str
    trajectory: Trajectory
    chosen_index: int
    candidate: CandidateParameters
    continued: bool
    max_risk_refused: int
    level: int
    level_counts: dict[int, int]
    invalid_counts: dict[str, int]
    terminal_unsafe: int
    best_by_level: dict[int, LevelBest]
    reason: str
    emergency: bool
    ego_combined_risk: float
    boundary_risk: float
    max_acceptable_risk: float
    costs: dict[str, float]
    road_users: tuple[RoadUserAssessment, ...]
    timings_ms: dict[str, float]
    candidate_x: np.ndarray = field(repr=False)
    candidate_y: np.ndarray = field(repr=False)
    candidate_levels: np.ndarray = field(repr=False)
    prediction: Prediction = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (no candidate arrays)."""
        return {
            "planner": self.planner,
            "chosen_index": self.chosen_index,
            "candidate": self.candidate.to_dict(),
            "continued": self.continued,
            "max_risk_refused": self.max_risk_refused,
            "level": self.level,
            "level_counts": {str(k): v for k, v in self.level_counts.items()},
            "invalid_counts": dict(self.invalid_counts),
            "terminal_unsafe": self.terminal_unsafe,
            "best_by_level": {str(k): v.to_dict() for k, v in self.best_by_level.items()},
            "reason": self.reason,
            "emergency": self.emergency,
            "ego_combined_risk": self.ego_combined_risk,
            "boundary_risk": self.boundary_risk,
            "max_acceptable_risk": self.max_acceptable_risk,
            "costs": dict(self.costs),
            "road_users": [
                {
                    name: (getattr(u, name).value if name == "type" else getattr(u, name))
                    for name in RoadUserAssessment.__slots__
                }
                for u in self.road_users
            ],
            "timings_ms": dict(self.timings_ms),
            "end_speed": float(self.trajectory.v[-1]),
        }

    def summary(self) -> str:
        """Multi-line text a person reads: choice, reason, costs, per-road-user risk."""
        counts = ", ".join(
            f"L{k}: {v}" if k != UNASSESSED else f"not risk-assessed (cost bound above the chosen): {v}"
            for k, v in sorted(self.level_counts.items(), reverse=True)
        )
        if self.terminal_unsafe:
            counts += f" (L1 includes {self.terminal_unsafe} ending in oncoming traffic's way)"
        lines = [
            f"[{self.planner}] level {self.level} ({Validity(self.level).name.lower()}), "
            f"candidate {self.chosen_index} ({self.candidate.describe()}); {counts}",
            f"  why: {self.reason}",
            f"  ego risk {self.ego_combined_risk:.4f} (R_max {self.max_acceptable_risk:g}), "
            f"boundary {self.boundary_risk:.4f}",
            "  costs: " + ", ".join(f"{k} {v:.4g}" for k, v in self.costs.items()),
        ]
        for level, best in sorted(self.best_by_level.items(), reverse=True):
            lines.append(f"  best L{level}: {best.candidate.describe()}, cost {best.cost:.4g}")
        for u in self.road_users:
            lines.append(
                f"  #{u.id} {u.type.value:<10} p {u.collision_probability:.4f} "
                f"harm {u.harm:.3f} risk {u.risk:.5f} | ego harm {u.ego_harm:.3f} "
                f"ego risk {u.ego_risk:.5f} | r {u.responsibility:.2f}/{u.ego_responsibility:.2f}"
            )
        stages = ", ".join(f"{k} {v:.2f}" for k, v in self.timings_ms.items() if k != "wall")
        wall = self.timings_ms.get("wall", math.nan)
        lines.append(f"  CPU time [ms]: {stages}; wall {wall:.2f} ms")
        return "\n".join(lines)


#: The branch and bound's first batch: the cheapest of the assessed candidates at zero
#: risk, at least _BATCH_MIN and one in _BATCH_FRACTION of them; each next batch doubles.
_BATCH_MIN = 32
_BATCH_FRACTION = 16
#: Levels below the valid one whose candidates' levels risk cannot change (a predicted
#: collision, leaving the road): the choice among them is by Eq. 6 alone, which
#: ``Planner._fallback_branch_and_bound`` bounds from below.
_FALLBACK_LEVELS = (int(Validity.COLLISION), int(Validity.LEAVES_ROAD))
#: Fewest candidates at a fallback level for its branch and bound: its lower bounds cost
#: about half of a full evaluation (the visiting order of every triple and one integral
#: per pair), which pays off only where most candidates are then left out (measured on
#: ``etp bench``'s scenes with 20 road users: the default set's risk stage ~15 % less,
#: the 225 grid's ~7 % more).
_FALLBACK_MIN = 512


@dataclass(frozen=True, slots=True, eq=False)
class _Assessed:
    """Risk, responsibility, levels and cost of some candidates (``risk.rows``).

    Attributes:
        risk: their risk; rows ascending when built by ``concatenate``.
        r_obs, r_ego: their responsibilities, shape (m, k), or None (weight 0).
        levels: their validity levels, shape (m,).
        costs: their cost terms, shape (m,) each.
    """

    risk: RiskAssessment
    r_obs: np.ndarray | None
    r_ego: np.ndarray | None
    levels: np.ndarray
    costs: CostBreakdown

    @classmethod
    def concatenate(cls, parts: Sequence[_Assessed]) -> _Assessed:
        """One assessment of the parts' candidates (disjoint), rows in ascending order."""
        if len(parts) == 1:
            return parts[0]
        order = np.argsort(np.concatenate([part.risk.rows for part in parts]), kind="stable")

        def join(records: Sequence[Any], kind: type) -> Any:
            fields = {}
            for name in kind.__slots__:
                values = [getattr(record, name) for record in records]
                if isinstance(values[0], np.ndarray):
                    fields[name] = np.concatenate(values)[order]
                else:
                    fields[name] = sum(values)  # counts: triples, integrals
            return kind(**fields)

        r_obs = r_ego = None
        if parts[0].r_obs is not None:
            r_obs = np.concatenate([part.r_obs for part in parts])[order]
            r_ego = np.concatenate([part.r_ego for part in parts])[order]
        return cls(
            join([part.risk for part in parts], RiskAssessment),
            r_obs,
            r_ego,
            np.concatenate([part.levels for part in parts])[order],
            join([part.costs for part in parts], CostBreakdown),
        )


@dataclass(frozen=True, slots=True, eq=False)
class _Evaluation:
    """One cycle's candidates evaluated: levels of all, risk and cost of the assessed.

    Risk, responsibility and cost are evaluated for the assessed candidates only: those
    of the highest level that the integral-free tests (physical limits, predicted mean
    occupancies, the road edge) leave possible, and among those, when the valid level
    is possible, only the candidates whose Eq. 5 cost at zero risk is not above the
    chosen plan's (``Planner._branch_and_bound``). The others cannot be chosen; their
    costs are NaN.

    Attributes:
        candidates: the cycle's n candidates.
        physical: the same candidates pressed against the road edge where they cross it
            (``boundary.physical_view``): what the road users' risks are judged on.
        risk: risk of the m assessed candidates (``risk.rows`` are their indices).
        r_obs, r_ego: their responsibilities, shape (m, k); None if the responsibility
            weight is 0 (then only the chosen plan's are computed, for the record).
        levels: validity level of every candidate, shape (n,); ``UNASSESSED`` for a
            candidate the branch and bound left out (valid, above R_max or breaks a traffic rule: unknown).
        invalid: physically invalid candidates per broken limit, shape (n,) each.
        costs: cost terms of every candidate, shape (n,) each, NaN where not assessed.
        risk_obs: R_k of every candidate, shape (n, k), 0 where not assessed.
        ego_combined: R_ego of every candidate, shape (n,), 0 where not assessed.
        terminal: candidates that end in oncoming traffic's way too late to get out
            (``ethical_planner.terminal``), shape (n,); they are level 1 unless invalid.
        possible: every candidate's level by the integral-free tests (risk 0), shape (n,).
    """

    candidates: Candidates
    physical: Candidates
    risk: RiskAssessment
    r_obs: np.ndarray | None
    r_ego: np.ndarray | None
    levels: np.ndarray
    invalid: dict[str, np.ndarray]
    costs: CostBreakdown
    risk_obs: np.ndarray
    ego_combined: np.ndarray
    terminal: np.ndarray
    possible: np.ndarray

    def position(self, index: int) -> int:
        """Row of candidate ``index`` in the assessed arrays."""
        return int(np.searchsorted(self.risk.rows, index))


class Planner:
    """Ethical Frenet sampling planner.

    Args:
        config: weights, limits and grid (see ``preset``).
        environment: the road.
        ego_shape: footprint of the ego [m].
        ego_mass: [kg].
        predictor: predicts the other road users every cycle (any ``Predictor``);
            None builds the one named by ``config.prediction.model``.
        workers: threads of the risk kernels; None makes one with
            ``ETHICAL_PLANNER_THREADS`` threads.
    """

    def __init__(
        self,
        config: PlannerConfig,
        environment: RoadEnvironment,
        ego_shape: Shape = EGO_SHAPE,
        ego_mass: float = EGO_MASS_KG,
        predictor: Predictor | None = None,
        workers: Workers | None = None,
    ) -> None:
        if not isinstance(config, PlannerConfig):
            raise ValueError("config must be a PlannerConfig (see ethical_planner.config.preset)")
        if not isinstance(environment, RoadEnvironment):
            raise ValueError("environment must be a RoadEnvironment")
        if not isinstance(ego_shape, Shape):
            raise ValueError("ego_shape must be a Shape")
        if not (math.isfinite(ego_mass) and ego_mass > 0):
            raise ValueError(f"ego_mass must be a finite mass > 0 kg, got {ego_mass}")
        if predictor is None:
            predictor = make_predictor(config.prediction)
        elif not isinstance(predictor, Predictor):
            raise ValueError(
                f"predictor must follow the Predictor protocol (a name and predict(road_users, times)), "
                f"got {type(predictor).__name__}"
            )
        self.config = config
        self.environment = environment
        self.ego_shape = ego_shape
        self.ego_mass = float(ego_mass)
        self.predictor = predictor
        self.workers = Workers() if workers is None else workers
        self._previous: PreviousPlan | None = None
        #: Consecutive cycles on which the kept previous plan cost more than the cheapest.
        self._outvoted = 0
        self._stood = np.zeros(len(environment.stop_lines), dtype=bool)
        self.desired_speed = (
            config.desired_speed if config.desired_speed is not None else environment.speed_limit
        )

    def _evaluate(
        self,
        candidates: Candidates,
        prediction: Prediction,
        corridors: LegalCorridors,
        timings: dict[str, float],
        lines: StopLines | None = None,
        lane_rules: LaneRules | None = None,
    ) -> _Evaluation:
        config = self.config
        clock = _clock()
        n, n_t = candidates.x.shape
        k = prediction.n_obs
        # Levels 0, 1 and 2 need no integral: physical limits, then (for the candidates
        # within them) a predicted mean occupancy, then (for the rest) the road edge.
        # None of them judges the present sample (t = 0), which every candidate shares
        # and none can change: an ego already within the edge margin, or touching a
        # road user, would otherwise find every candidate at level 2 or 1. An ego
        # within the edge margin needs a few steps to leave it: the margin is judged
        # from the first step at which a plan is clear of it.
        invalid = physically_invalid(candidates, config.vehicle)
        broken = np.logical_or.reduce(list(invalid.values()))
        considered = np.flatnonzero(~broken) if not broken.all() else np.arange(n)
        # A plan's positions beyond the road edge are not where the car would be: the
        # road users' risks, predicted collisions and responsibilities are judged on the
        # plan pressed against the edge (``ethical_planner.boundary``). Only a plan within
        # the edge margin after the present step can cross the edge itself.
        margin = config.risk.road_edge_margin
        near_edge = outside_drivable_area(candidates, self.ego_shape, self.environment, margin, considered)
        leaving = considered[near_edge[:, 1:].any(axis=1)]
        physical, _ = physical_view(candidates, leaving, self.ego_shape, self.environment)
        tables = prediction_tables(physical, considered, prediction, self.ego_shape, config.risk.gate_sigmas)
        collision = np.zeros(n, dtype=bool)
        collision[considered] = collides(tables, np.arange(considered.size), first_step=1)
        # A plan ending in oncoming traffic's way too late to get out is a predicted
        # collision beyond the horizon (``ethical_planner.terminal``).
        terminal = terminally_unsafe(
            candidates, prediction, self.environment, self.ego_shape, config.terminal
        )
        collision[considered] |= terminal[considered]
        outside = np.zeros((n, n_t), dtype=bool)
        on_road = considered[~collision[considered]]
        outside[on_road] = near_edge[~collision[considered]]
        if outside[on_road, 0].any():
            # The ego is within the edge margin now: the margin is not judged until the
            # plan has cleared it (the road edge itself is, from the first step on).
            inherited = np.logical_and.accumulate(outside[on_road], axis=1)
            edge = outside_drivable_area(candidates, self.ego_shape, self.environment, 0.0, on_road)
            outside[on_road] = (outside[on_road] & ~inherited) | edge
        outside[:, 0] = False
        # A plan that ends unable to stop short of debris with room to steer around it
        # comes too close to the drivable area's edge (``ethical_planner.terminal``).
        outside[on_road, -1] |= crowds_static_obstacle(
            candidates, on_road, self.environment, self.ego_shape, config.terminal
        )
        max_risk = config.risk.max_acceptable_risk
        breaks = self._breaks_rules(candidates, lines, lane_rules)
        zero_risk = np.zeros((n, k)), np.zeros(n)
        possible = _rule_levels(
            validity_levels(invalid, collision[:, None, None], outside, *zero_risk, max_risk), breaks
        )
        # Risk decides between a valid plan and one that breaks a rule (levels 10 and 4):
        # a plan may fall to level 3, below a rule breaker within R_max. Both are assessed.
        best = int(possible.max())
        assessed = np.flatnonzero(possible >= min(best, Validity.BREAKS_TRAFFIC_RULE))
        timings["validity"] = timings.get("validity", 0.0) + _since(clock)

        clock = _clock()
        position = np.full(n, -1)
        position[considered] = np.arange(considered.size)
        with_onset = config.weights.responsibility != 0.0
        # Comfort's and mobility's inputs need no risk: once for every assessed candidate
        # (row by row, so a subset's values are those of the subset computed alone).
        free = self._risk_free_terms(candidates, assessed)
        slot = np.full(n, -1)
        slot[assessed] = np.arange(assessed.size)

        # The gated triples and harms of every assessed candidate, once (fallback only).
        known: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

        def risk_of(rows: np.ndarray, cap: int = 0) -> RiskAssessment:
            """Risk of candidates ``rows``; with ``cap`` > 0 lower bounds (``assess_risk``)."""
            triples = None
            if known:
                per_row = tables.n_obs * tables.n_t
                triples = subset_triples(known[0], slot[rows], assessed.size, per_row)
            impact = edge_impact_speed(
                candidates,
                rows,
                outside[rows],
                self.ego_shape,
                self.environment,
                config.risk.road_edge_margin,
            )
            return assess_risk(
                physical,
                rows,
                tables,
                position[rows],
                prediction,
                self.ego_shape,
                self.ego_mass,
                outside[rows],
                config.risk,
                config.weights.maximin_epsilon,
                with_onset and not cap,
                self.workers,
                impact,
                cap,
                triples,
            )

        def evaluate(rows: np.ndarray) -> _Assessed:
            """Risk, responsibility and cost of candidates ``rows`` (the stage timers run)."""
            clock = _clock()
            risk = risk_of(rows)
            row_levels = _rule_levels(
                validity_levels(
                    {name: broken[rows] for name, broken in invalid.items()},
                    collision[rows, None, None],
                    outside[rows],
                    risk.risk_obs,
                    risk.ego_combined,
                    max_risk,
                ),
                breaks[rows],
            )
            timings["risk"] = timings.get("risk", 0.0) + _since(clock)
            clock = _clock()
            r_obs = r_ego = None
            if with_onset:
                r_obs, r_ego = responsibilities(
                    physical,
                    rows,
                    risk.peak_probability,
                    risk.onset_step,
                    prediction,
                    corridors,
                    self.ego_mass,
                    config.responsibility,
                )
            timings["responsibility"] = timings.get("responsibility", 0.0) + _since(clock)
            clock = _clock()
            costs = self._costs(
                candidates, risk, r_obs, r_ego, row_levels, [term[slot[rows]] for term in free]
            )
            timings["cost"] = timings.get("cost", 0.0) + _since(clock)
            return _Assessed(risk, r_obs, r_ego, row_levels, costs)

        def lower_bound(rows: np.ndarray) -> np.ndarray:
            """A lower bound of the Eq. 6 cost of candidates ``rows`` at a fallback level, (m,).

            One integral per (candidate, road user) pair, the one of highest bound x harm
            (``assess_risk`` with cap 1): R_k, R_ego,k, maximin's harms and R_ego are then
            lower bounds, and so are J_B, J_M and the ego term, each a sum, mean, maximum
            or product of them that rounds monotonically; J_E, which is not monotone in
            the risks, is bounded by 0 (its weight set to 0 in the same expression). Only
            without responsibility (w_R = 0): J_R lowers the cost.
            """
            clock = _clock()
            risk = risk_of(rows, cap=1)
            weights = replace(config.weights, equality=0.0)
            free_rows = [term[slot[rows]] for term in free]
            costs = self._costs(candidates, risk, None, None, possible[rows], free_rows, weights)
            timings["risk"] = timings.get("risk", 0.0) + _since(clock)
            return costs.total

        if best == Validity.VALID:
            assessed_part = self._branch_and_bound(candidates, assessed, free, evaluate)
        elif (
            best in _FALLBACK_LEVELS
            and k
            and _risk_bounded(config.weights)
            and assessed.size >= _FALLBACK_MIN
        ):
            clock = _clock()
            known.append(
                gated_triples(
                    physical,
                    assessed,
                    tables,
                    position[assessed],
                    prediction,
                    self.ego_shape,
                    self.ego_mass,
                    config.risk,
                    self.workers,
                )
            )
            timings["risk"] = timings.get("risk", 0.0) + _since(clock)
            assessed_part = self._fallback_branch_and_bound(candidates, assessed, lower_bound, evaluate)
        else:
            # Eq. 6 (risk alone) decides below the valid level: no risk-free part bounds it.
            assessed_part = evaluate(assessed)
        risk = assessed_part.risk
        rows = risk.rows
        levels = possible.copy()
        levels[assessed] = UNASSESSED
        levels[rows] = assessed_part.levels
        risk_obs = np.zeros((n, k))
        risk_obs[rows] = risk.risk_obs
        ego_combined = np.zeros(n)
        ego_combined[rows] = risk.ego_combined
        costs = _full_costs(assessed_part.costs, rows, n)
        return _Evaluation(
            candidates,
            physical,
            risk,
            assessed_part.r_obs,
            assessed_part.r_ego,
            levels,
            invalid,
            costs,
            risk_obs,
            ego_combined,
            terminal,
            possible,
        )

    def _branch_and_bound(
        self,
        candidates: Candidates,
        assessed: np.ndarray,
        free: Sequence[np.ndarray],
        evaluate: Callable[[np.ndarray], _Assessed],
    ) -> _Assessed:
        """Risk of the candidates ``assessed`` that can be chosen or refused by R_max (Eq. 5).

        The valid level is possible: the choice is the valid candidate of least Eq. 5
        cost, w_risk J_risk + comfort + mobility. J_risk is a weighted sum of terms >= 0
        (weights >= 0, ``CostWeights``; J_B - rho J_R >= 0 since r < 1 and rho <= 1), so
        comfort + mobility, computed as Eq. 5 with J_risk = 0, bounds a candidate's
        cost from below, in floating point too (each operation rounds monotonically).
        Candidates are evaluated in batches in ascending order of that bound until the
        next bound exceeds the cheapest valid total found (the incumbent: its level is
        final once its risk is known; a candidate whose risk puts it above R_max is
        not one). Every candidate not evaluated then costs more than the chosen one
        (ties are evaluated, so the tie-break by comfort plus mobility is that of full
        evaluation), and so does its Eq. 5 cost if R_max refuses it: the refused count
        and ``Decision.best_by_level[VALID]`` are exact. The continuation of the
        previous plan is always evaluated (the commitment compares its cost); if it is
        valid, the search also goes on up to its cost, because the commitment may keep it
        at a cost above the cheapest and R_max's refusals are counted against the plan
        chosen.

        If an evaluated candidate's total ever falls below its bound (a cost term that
        can be negative), the rest is evaluated too: the result stays that of full
        evaluation.

        Args:
            candidates: the cycle's candidates.
            assessed: the candidates that may be chosen (integral-free level valid or
                breaks a traffic rule), indices, shape (m,).
            free: their ``_risk_free_terms``, shape (m,) each.
            evaluate: risk, responsibility and cost of some of them.

        Returns:
            The evaluated candidates' assessment, rows ascending.
        """
        weights = self.config.weights
        rows = assessed
        comfort, mobility = comfort_and_mobility(*free, weights, self._oncoming(candidates, rows))
        bound = eq5_cost(np.zeros(rows.size), comfort, mobility, weights)
        order = np.argsort(bound, kind="stable")
        first = np.flatnonzero(candidates.kind[rows] == CandidateKind.CONTINUATION)
        batch = max(_BATCH_MIN, -(-rows.size // _BATCH_FRACTION))
        done = np.zeros(rows.size, dtype=bool)
        parts: list[_Assessed] = []
        incumbent = math.inf
        kept_cost = -math.inf
        take = np.union1d(first, order[:batch])
        while take.size:
            part = evaluate(rows[take])
            parts.append(part)
            done[take] = True
            costs = part.costs
            if np.any(eq5_cost(costs.risk, costs.comfort, costs.mobility, weights) < bound[take]):
                take = np.flatnonzero(~done)
                continue
            valid = part.levels == Validity.VALID
            if valid.any():
                incumbent = min(incumbent, float(costs.total[valid].min()))
            # A valid continuation may be kept at a cost above the cheapest (commitment),
            # and R_max's refusals are counted against the plan chosen: every candidate
            # whose Eq. 5 cost could lie below the kept plan's must be evaluated as well.
            continued = valid & (candidates.kind[part.risk.rows] == CandidateKind.CONTINUATION)
            if continued.any():
                kept_cost = max(kept_cost, float(costs.total[continued].max()))
            batch *= 2
            waiting = order[~done[order]]
            threshold = max(incumbent, kept_cost) if math.isfinite(incumbent) else incumbent
            take = np.sort(waiting[bound[waiting] <= threshold][:batch])
        return _Assessed.concatenate(parts)

    def _fallback_branch_and_bound(
        self,
        candidates: Candidates,
        assessed: np.ndarray,
        lower_bound: Callable[[np.ndarray], np.ndarray],
        evaluate: Callable[[np.ndarray], _Assessed],
    ) -> _Assessed:
        """Risk of the candidates ``assessed`` that can be chosen at a fallback level (Eq. 6).

        Every candidate ``assessed`` is at the same level, a predicted collision or leaving
        the road, which its risk cannot change: the choice is the candidate of least
        Eq. 6 cost (J_risk). ``lower_bound`` bounds that cost from below (one integral
        per pair, ``Planner._evaluate``). Candidates are evaluated in batches in ascending
        order of the bound, as in ``_branch_and_bound``, until the next bound exceeds the
        cheapest total found. Always evaluated: the continuation of the previous plan
        (the commitment compares its cost) and the braking candidates (the fallback's
        reason names the best hard stop and its J_risk). Ties are evaluated, so the
        tie-break is that of full evaluation; if an evaluated total ever falls below its
        bound, every candidate is evaluated.

        Args:
            candidates: the cycle's candidates.
            assessed: the candidates of the fallback level, indices, shape (m,).
            lower_bound: lower bounds of the Eq. 6 cost of some of them.
            evaluate: risk, responsibility and cost of some of them.

        Returns:
            The evaluated candidates' assessment, rows ascending.
        """
        rows = assessed
        bound = lower_bound(rows)
        order = np.argsort(bound, kind="stable")
        kind = candidates.kind[rows]
        first = np.flatnonzero((kind == CandidateKind.CONTINUATION) | (kind == CandidateKind.BRAKE))
        batch = max(_BATCH_MIN, -(-rows.size // _BATCH_FRACTION))
        done = np.zeros(rows.size, dtype=bool)
        parts: list[_Assessed] = []
        incumbent = math.inf
        take = np.union1d(first, order[:batch])
        while take.size:
            part = evaluate(rows[take])
            parts.append(part)
            done[take] = True
            if np.any(part.costs.total < bound[take]):
                take = np.flatnonzero(~done)
                continue
            incumbent = min(incumbent, float(part.costs.total.min()))
            batch *= 2
            waiting = order[~done[order]]
            take = np.sort(waiting[bound[waiting] <= incumbent][:batch])
        return _Assessed.concatenate(parts)

    def _breaks_rules(
        self, candidates: Candidates, lines: StopLines | None, lane_rules: LaneRules | None = None
    ) -> np.ndarray:
        """Candidates that cross a binding stop line or marking, shape (n,) (``traffic_rules``)."""
        breaks = np.zeros(candidates.n_traj, dtype=bool)
        if lines is not None:
            breaks |= breaks_stop_lines(
                candidates.s + 0.5 * self.ego_shape.length,
                candidates.s_dot[:, -1],
                candidates.t,
                lines,
                self.config.traffic_rules.comfortable_deceleration,
                candidates.deceleration,
            )
        if lane_rules is not None:
            breaks |= breaks_lane_rules(
                candidates, self.environment.reference_path, self.ego_shape, lane_rules
            )
        return breaks

    def _stop_lines(self, start: FrenetState, speed: float, now: float) -> StopLines | None:
        """This cycle's stop lines, after noting a standstill at a stop sign; None without any."""
        lines = self.environment.stop_lines
        rules = self.config.traffic_rules
        if not lines or not rules.enabled:
            return None
        front_offset = 0.5 * self.ego_shape.length
        self._stood |= stood_at(lines, start.s + front_offset, speed)
        return StopLines.of(lines, start, front_offset, now, self._stood, self.config.vehicle, rules)

    def _costs(
        self,
        candidates: Candidates,
        risk: RiskAssessment,
        r_obs: np.ndarray | None,
        r_ego: np.ndarray | None,
        levels: np.ndarray,
        free: Sequence[np.ndarray],
        weights: CostWeights | None = None,
    ) -> CostBreakdown:
        """Eqs. 5-11 of the assessed candidates ``risk.rows``, whose levels are ``levels`` (m,).

        ``free`` holds their ``_risk_free_terms``, shape (m,) each; ``weights`` replaces
        the configuration's (the fallback's lower bound).

        Without responsibilities (weight 0) J_R is left 0: it does not enter the total.
        """
        config = self.config
        m, k = risk.risk_obs.shape
        leaves = risk.leaves_road
        risks, present = risk_set(risk.risk_obs, risk.risk_ego, risk.boundary_risk, leaves)
        if r_obs is None:
            r = np.zeros((m, 2 * k + 1))
        else:
            r = np.concatenate([r_obs, r_ego, np.zeros((m, 1))], axis=1)
        # Maximin's harms are those at steps above epsilon already (0 where none is).
        harms = np.concatenate(
            [risk.maximin_harm_obs, risk.maximin_harm_ego, risk.boundary_risk[:, None]], axis=1
        )
        counted = np.concatenate([np.ones((m, 2 * k), dtype=bool), leaves[:, None]], axis=1)
        oncoming = self._oncoming(candidates, risk.rows)
        return total_cost(
            risks,
            present,
            r,
            harms,
            counted,
            risk.ego_combined,
            *free,
            levels,
            config.weights if weights is None else weights,
            **({} if oncoming is None else {"lanes_oncoming": oncoming}),
        )

    def _risk_free_terms(self, candidates: Candidates, rows: np.ndarray) -> tuple[np.ndarray, ...]:
        """Inputs of comfort and mobility of candidates ``rows`` (``comfort_and_mobility``), (m,) each.

        Returns:
            (jerk_lon, jerk_lat, speed deviation, lateral deviation, lanes away).
        """
        # Row by row: for most of the candidates, every row's values and then those of
        # ``rows`` are the same numbers, without gathering (n, n_t) arrays first.
        whole = 2 * rows.size >= candidates.n_traj
        v, d = (candidates.v, candidates.d) if whole else (candidates.v[rows], candidates.d[rows])
        terms = (
            np.abs(v - self.desired_speed).mean(axis=1),
            *path_deviation(
                d,
                self.environment.lane_offsets,
                self.environment.lane_width,
                self.config.weights.path_reference,
            ),
        )
        if whole and not every_row(rows, candidates.n_traj):
            terms = tuple(term[rows] for term in terms)
        return (candidates.jerk_lon[rows], candidates.jerk_lat[rows], *terms)

    def _oncoming(self, candidates: Candidates, rows: np.ndarray) -> np.ndarray | None:
        """Mean lanes across the centre line of candidates ``rows`` (``cost.oncoming_lanes``), (m,).

        None when ``weights.oncoming_lane`` is 0 (the default): the term is left out.
        """
        weights, env = self.config.weights, self.environment
        if not weights.oncoming_lane:
            return None
        d = candidates.d[rows]
        return oncoming_lanes(d, env.lane_offsets, env.lane_width, env.centre_line, weights.path_reference)

    def plan(
        self,
        ego_state: KinematicState,
        road_users: Sequence[RoadUser],
        prediction: Prediction | None = None,
        now: float = 0.0,
    ) -> Decision:
        """Run one planning cycle.

        Args:
            ego_state: current state of the ego's centre.
            road_users: every other road user the ego perceives (may be empty).
            prediction: a prediction on the planner's time grid; by default the
                planner's predictor makes one. Either way its covariances are floored
                at ``config.prediction.covariance_floor``.
            now: the cycle's time on the clock of the stop lines' red windows [s]
                (the run's time).

        Returns:
            The decision; never None. If every candidate is physically invalid, the
            plan is emergency braking.
        """
        if not isinstance(ego_state, KinematicState):
            raise ValueError("ego_state must be a KinematicState")
        config = self.config
        timings: dict[str, float] = {}
        start_clock = clock = _clock()
        wall_clock = time.perf_counter()
        path = self.environment.reference_path
        start = frenet_state(ego_state, path)
        previous = self._previous if config.commitment.enabled else None
        lines = self._stop_lines(start, ego_state.v, now)
        rules = config.traffic_rules
        front_offset = 0.5 * self.ego_shape.length
        candidates = sample_candidates(
            start,
            path,
            config.sampling,
            config.vehicle,
            previous,
            config.commitment.max_deviation,
            None if lines is None else stop_targets(lines, start, front_offset, rules.stop_gap),
            rules.min_deceleration,
        )
        timings["sampling"] = _since(clock)
        clock = _clock()
        if prediction is None:
            prediction = self.predictor.predict(road_users, candidates.t)
            if not isinstance(prediction, Prediction):
                kind = type(prediction).__name__
                raise ValueError(f"predictor {self.predictor.name!r} returned {kind}, not a Prediction")
        if prediction.mean.shape[1] != len(candidates.t):
            raise ValueError(
                f"prediction has {prediction.mean.shape[1]} steps; the planner needs "
                f"{len(candidates.t)} (horizon {max(config.sampling.horizons)} s, dt {config.sampling.dt} s)"
            )
        prediction = prediction.with_covariance_floor(config.prediction.covariance_floor)
        if len(road_users) != prediction.n_obs:
            raise ValueError(
                f"prediction covers {prediction.n_obs} road users but {len(road_users)} were given"
            )
        corridors = LegalCorridors.of(road_users, self.environment)
        timings["prediction"] = _since(clock)

        lane_rules = (
            LaneRules.of(self.environment, start, self.ego_shape.length, prediction, rules)
            if rules.enabled
            else None
        )
        grid = self._evaluate(candidates, prediction, corridors, timings, lines, lane_rules)
        clock = _clock()
        best_level = int(grid.levels.max())
        chosen = grid
        emergency = False
        if best_level == Validity.PHYSICALLY_INVALID:
            brake = emergency_braking(start, path, candidates.t, config.vehicle)
            chosen = self._evaluate(brake, prediction, corridors, timings, lines, lane_rules)
            index, emergency, continued = 0, True, False
            self._outvoted = 0
            reason = (
                "emergency braking: every sampled candidate breaks a physical limit ("
                + ", ".join(f"{k} {int(v.sum())}" for k, v in grid.invalid.items())
                + ")"
            )
        else:
            index, reason, continued = self._choose(grid, best_level)
        self._previous = PreviousPlan.of(chosen.candidates, index)
        timings["selection"] = _since(clock)
        clock = _clock()
        decision = self._record(grid, chosen, index, reason, emergency, continued, prediction, corridors)
        timings["record"] = _since(clock)
        timings["total"] = _since(start_clock)
        timings["wall"] = (time.perf_counter() - wall_clock) * 1e3
        return replace(decision, timings_ms={k: round(v, 3) for k, v in timings.items()})

    def reset(self) -> None:
        """Forget the previous plan and the stop signs stood at (a new run, or the ego was moved)."""
        self._previous = None
        self._outvoted = 0
        self._stood[:] = False

    def _choose(self, grid: _Evaluation, best_level: int) -> tuple[int, str, bool]:
        """Cheapest candidate of the highest level, unless the previous plan is as good.

        Comfort and mobility break ties. The continuation of the previous plan is kept
        if it is on the same level and within the commitment margin of the cheapest,
        unless it has cost more than the cheapest on ``switch_after_cycles``
        consecutive cycles (``CommitmentConfig``, ``keep_previous_plan``).

        Returns:
            (index, reason, whether the continuation was kept).
        """
        in_level = np.flatnonzero(grid.levels == best_level)
        costs = grid.costs
        secondary = costs.comfort[in_level] + costs.mobility[in_level]
        order = np.lexsort((secondary, costs.total[in_level]))
        index = int(in_level[order[0]])
        kind = grid.candidates.kind
        name = Validity(best_level).name.lower().replace("_", " ")
        equation = "Eq. 5" if best_level == Validity.VALID else "Eq. 6"
        if best_level == Validity.VALID:
            reason = f"lowest total cost (Eq. 5) among {len(in_level)} valid candidates"
            left_out = int((grid.levels == UNASSESSED).sum())
            if left_out:
                reason += (
                    f" ({left_out} more not risk-assessed: their Eq. 5 cost at zero risk is "
                    "already above the chosen plan's)"
                )
            reason += self._refused_by_max_risk(grid, index)
        elif best_level == Validity.COLLISION:
            reason = self._fallback_reason(grid, _level_members(grid, best_level), index)
        else:
            reason = (
                f"no valid candidate; highest available level is {best_level} ({name}); "
                f"lowest risk cost (Eq. 6) among its {len(_level_members(grid, best_level))} candidates"
            )
        commitment = self.config.commitment
        kept = np.flatnonzero((kind == CandidateKind.CONTINUATION) & (grid.levels == best_level))
        j_best = float(costs.total[index])
        j_kept = float(costs.total[kept[0]]) if commitment.enabled and kept.size else None
        valid = best_level == Validity.VALID
        outvoted = self._outvoted
        keep, self._outvoted = keep_previous_plan(j_best, j_kept, valid, outvoted, commitment)
        if j_kept is not None and int(kept[0]) != index:
            margin = commitment_margin(j_best, valid, commitment)
            if keep:
                reason += (
                    f"; kept the previous plan: its cost {j_kept:.4g} is within the commitment "
                    f"margin {margin:.3g} of the cheapest ({j_best:.4g}, {equation})"
                )
                return int(kept[0]), reason, True
            if j_kept <= j_best + margin:
                reason += (
                    f"; dropped the previous plan (cost {j_kept:.4g}, within the commitment margin "
                    f"{margin:.3g}): it cost more than the cheapest on {outvoted + 1} consecutive "
                    "cycles (commitment.switch_after_cycles)"
                )
        return index, reason, bool(kind[index] == CandidateKind.CONTINUATION)

    def _refused(self, grid: _Evaluation, index: int) -> np.ndarray:
        """Candidates above R_max (level 3) that Eq. 5 would have preferred to ``index``."""
        if grid.levels[index] != Validity.VALID:
            return np.zeros(0, dtype=int)
        costs, weights = grid.costs, self.config.weights
        eq5 = weights.risk * costs.risk + costs.comfort + costs.mobility
        return np.flatnonzero((grid.levels == Validity.ABOVE_MAX_RISK) & (eq5 < costs.total[index]))

    def _refused_by_max_risk(self, grid: _Evaluation, index: int) -> str:
        """Text on the candidates R_max refused that Eq. 5 would have preferred (or "")."""
        refused = self._refused(grid, index)
        if not refused.size:
            return ""
        costs = grid.costs
        eq5 = self.config.weights.risk * costs.risk + costs.comfort + costs.mobility
        best = int(refused[np.argmin(eq5[refused])])
        worst = max(float(grid.ego_combined[best]), float(grid.risk_obs[best].max(initial=0.0)))
        return (
            f"; R_max refused {refused.size} cheaper candidates (cheapest: "
            f"{_describe(grid.candidates, best)}, Eq. 5 cost {eq5[best]:.4g}, risk {worst:.3g} > "
            f"R_max {self.config.risk.max_acceptable_risk:g})"
        )

    def _fallback_reason(self, grid: _Evaluation, in_level: np.ndarray, index: int) -> str:
        """Why the fallback chose ``index`` when every candidate is predicted to collide.

        ``in_level``: every candidate of the level, those the fallback's branch and bound
        left out included (all braking candidates were evaluated).
        """
        candidates, risk_cost = grid.candidates, grid.costs.risk
        stops = in_level[candidates.kind[in_level] == CandidateKind.BRAKE]
        n_invalid = int((grid.levels == Validity.PHYSICALLY_INVALID).sum())
        reason = (
            f"every candidate is predicted to collide: {len(in_level)} possible candidates "
            f"(hard stops included) all meet a predicted mean occupancy ({n_invalid} more "
            f"break a physical limit); least expected harm by the risk cost (Eq. 6) over all "
            f"of them: {_describe(candidates, index)}, J_risk {risk_cost[index]:.4g}"
        )
        n_terminal = int(grid.terminal[in_level].sum())
        if n_terminal:
            reason += f"; {n_terminal} of them end in oncoming traffic's way too late to get out"
        if stops.size and candidates.kind[index] != CandidateKind.BRAKE:
            best_stop = int(stops[np.argmin(risk_cost[stops])])
            stop = _describe(candidates, best_stop)
            reason += f"; best hard stop ({stop}) J_risk {risk_cost[best_stop]:.4g}"
        return reason

    def _record(
        self,
        grid: _Evaluation,
        chosen: _Evaluation,
        index: int,
        reason: str,
        emergency: bool,
        continued: bool,
        prediction: Prediction,
        corridors: LegalCorridors,
    ) -> Decision:
        config = self.config
        risk, j = chosen.risk, chosen.position(index)
        detail = risk_detail(
            chosen.physical,
            index,
            prediction,
            self.ego_shape,
            self.ego_mass,
            config.risk,
        )
        p = detail.probability  # (k, t)
        peak = p.argmax(axis=1) if p.shape[1] else np.zeros(p.shape[0], dtype=int)
        costs = chosen.costs.row(index)
        if chosen.r_obs is None:
            # Responsibility carries no weight: the chosen plan's alone, for the record.
            r_obs, r_ego = responsibilities(
                chosen.physical,
                np.array([index]),
                *(value[None] for value in collision_onset(p)),
                prediction,
                corridors,
                self.ego_mass,
                config.responsibility,
            )
            r_obs, r_ego = r_obs[0], r_ego[0]
            leaves = chosen.risk.leaves_road[j : j + 1]
            risks, present = risk_set(
                risk.risk_obs[j : j + 1], risk.risk_ego[j : j + 1], risk.boundary_risk[j : j + 1], leaves
            )
            r = np.concatenate([r_obs, r_ego, [0.0]])[None]
            costs["responsibility"] = float(responsibility(risks, r, present)[0])
        else:
            r_obs, r_ego = chosen.r_obs[j], chosen.r_ego[j]
        rows = np.arange(p.shape[0])
        assessments = tuple(
            RoadUserAssessment(
                id=int(prediction.ids[k]),
                type=prediction.types[k],
                risk=float(risk.risk_obs[j, k]),
                ego_risk=float(risk.risk_ego[j, k]),
                collision_probability=float(p[k].max(initial=0.0)),
                harm=float(detail.harm_obs[k, peak[k]]),
                ego_harm=float(detail.harm_ego[k, peak[k]]),
                responsibility=float(r_obs[k]),
                ego_responsibility=float(r_ego[k]),
            )
            for k in rows
        )
        lowest = int(grid.levels.min())
        counts = np.bincount(grid.levels - lowest)
        values = np.flatnonzero(counts) + lowest
        counts = counts[values - lowest]
        return Decision(
            planner=self.config.name,
            trajectory=Trajectory.from_candidates(chosen.candidates, index),
            chosen_index=-1 if emergency else index,
            candidate=CandidateParameters.of(chosen.candidates, index),
            continued=continued,
            max_risk_refused=0 if emergency else int(self._refused(grid, index).size),
            level=int(chosen.levels[index]),
            level_counts={int(v): int(c) for v, c in zip(values, counts, strict=True)},
            invalid_counts={k: int(v.sum()) for k, v in grid.invalid.items()},
            terminal_unsafe=int((grid.terminal & (grid.possible == Validity.COLLISION)).sum()),
            best_by_level=_best_by_level(grid),
            reason=reason,
            emergency=emergency,
            ego_combined_risk=float(risk.ego_combined[j]),
            boundary_risk=float(risk.boundary_risk[j]),
            max_acceptable_risk=config.risk.max_acceptable_risk,
            costs=costs,
            road_users=assessments,
            timings_ms={},
            candidate_x=grid.candidates.x,
            candidate_y=grid.candidates.y,
            candidate_levels=grid.levels,
            prediction=prediction,
        )


def commitment_margin(j_best: float, valid_level: bool, commitment: CommitmentConfig) -> float:
    """How much more than the cheapest candidate the previous plan may cost and be kept.

    ``relative_margin`` |J_best|, plus ``absolute_margin`` on the valid level (Eq. 5's
    comfort and mobility set its scale; Eq. 6's risk costs have none).

    Args:
        j_best: the cheapest candidate's cost of its level (Eq. 5 or Eq. 6).
        valid_level: the level is ``Validity.VALID``.
        commitment: the margins.
    """
    margin = commitment.relative_margin * abs(j_best)
    return margin + commitment.absolute_margin if valid_level else margin


def keep_previous_plan(
    j_best: float,
    j_kept: float | None,
    valid_level: bool,
    outvoted: int,
    commitment: CommitmentConfig,
) -> tuple[bool, int]:
    """Whether the continuation of the previous plan is kept over the cheapest candidate.

    Hysteresis with persistence (``CommitmentConfig``): the continuation, on the same
    level as the cheapest candidate, is kept while it costs at most ``commitment_margin``
    more; but if it has cost more than the cheapest on the ``outvoted`` cycles before
    this one and does again, and that makes ``switch_after_cycles`` consecutive cycles,
    the cheapest is taken. A continuation that costs no more than the cheapest (it is
    the cheapest, or ties with it) is kept and is not outvoted.

    Args:
        j_best: the cheapest candidate's cost (Eq. 5 on the valid level, else Eq. 6).
        j_kept: the continuation's cost, of the same level; None if there is none on
            that level (or the commitment is off): nothing to keep, the count restarts.
        valid_level: the level is ``Validity.VALID``.
        outvoted: consecutive cycles before this one on which the previous plan was kept
            at a cost above the cheapest.
        commitment: margins and ``switch_after_cycles``.

    Returns:
        (keep it, the count of consecutive outvoted cycles to carry to the next cycle:
        0 unless it is kept at a cost above the cheapest).
    """
    if j_kept is None:
        return False, 0
    if j_kept <= j_best:
        return True, 0
    if not j_kept <= j_best + commitment_margin(j_best, valid_level, commitment):
        return False, 0  # beyond the margin, or a cost is NaN: nothing to defend
    outvoted += 1
    if commitment.switch_after_cycles and outvoted >= commitment.switch_after_cycles:
        return False, 0
    return True, outvoted


def _best_by_level(grid: _Evaluation) -> dict[int, LevelBest]:
    """The cheapest candidate of every level costed completely (one sort, no loop over candidates).

    A candidate the branch and bound left out (``UNASSESSED``) is at its integral-free
    level or above R_max: those levels get no entry unless it is the valid level, whose
    cheapest candidate the branch and bound finds exactly.
    """
    costs = grid.costs
    rows = grid.risk.rows
    order = rows[
        np.lexsort((costs.comfort[rows] + costs.mobility[rows], costs.total[rows], grid.levels[rows]))
    ]
    # ``order`` runs by level first: each level's cheapest is where the level changes.
    ordered = grid.levels[order]
    first = np.flatnonzero(np.concatenate(([True], ordered[1:] != ordered[:-1])))
    levels = ordered[first]
    # Left out at a fallback level (``Planner._fallback_branch_and_bound``): their level
    # is final and their cost not below the chosen plan's, so that level's entry is exact.
    left_out = grid.levels == UNASSESSED
    for level in _FALLBACK_LEVELS:
        left_out &= grid.possible != level
    unknown: set[int] = set()
    if left_out.any():
        unknown = {int(v) for v in np.unique(grid.possible[left_out])} - {int(Validity.VALID)}
        unknown.add(int(Validity.ABOVE_MAX_RISK))
    return {
        int(level): LevelBest(int(i), float(costs.total[i]), CandidateParameters.of(grid.candidates, int(i)))
        for level, i in zip(levels, order[first], strict=True)
        if int(level) not in unknown
    }


def _risk_bounded(weights: CostWeights) -> bool:
    """The fallback's lower bound can rise above 0: J_B, J_M or R_ego weighs, J_R does not."""
    return weights.responsibility == 0.0 and (
        weights.bayes > 0 or weights.maximin > 0 or weights.ego_risk > 0
    )


def _level_members(grid: _Evaluation, level: int) -> np.ndarray:
    """Candidates at ``level``, with those the fallback's branch and bound left out there.

    A candidate left out at a fallback level (``_FALLBACK_LEVELS``) is at its
    integral-free level; elsewhere a left-out candidate's level is unknown and not counted.
    """
    members = grid.levels == level
    if level in _FALLBACK_LEVELS:
        members |= (grid.levels == UNASSESSED) & (grid.possible == level)
    return np.flatnonzero(members)


def _rule_levels(levels: np.ndarray, breaks: np.ndarray) -> np.ndarray:
    """``levels`` with the rule breakers lowered to ``BREAKS_TRAFFIC_RULE`` (never raised)."""
    return np.where(breaks, np.minimum(levels, int(Validity.BREAKS_TRAFFIC_RULE)), levels)


def _full_costs(costs: CostBreakdown, rows: np.ndarray, n: int) -> CostBreakdown:
    """``costs`` of candidates ``rows`` spread over all n candidates, NaN for the others."""
    full = {}
    for name in CostBreakdown.__slots__:
        values = np.full(n, np.nan)
        values[rows] = getattr(costs, name)
        full[name] = values
    return CostBreakdown(**full)


def _describe(candidates: Candidates, index: int) -> str:
    return CandidateParameters.of(candidates, index).describe()


def _clock() -> float:
    """The stage timers' clock [s]: process CPU time, all threads (the collision-probability pool's too)."""
    return time.process_time()


def _since(clock: float) -> float:
    """CPU time since ``clock`` [ms]."""
    return (_clock() - clock) * 1e3
