"""What one closed-loop run produced: ``RunSummary`` and the bodies it simulated.

The summary is the loop's typed result. ``mujoco_world.storage.run_record`` writes it
(with the run's id, sources and settings) as a run's ``summary.json`` and reads it
back; every reader above the loop (index, batch aggregate, ``harm_calibration``) goes
through these records, never through string keys into the JSON.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

from ethical_planner.records import to_plain
from ethical_planner.road_users import RoadUserType, Shape
from ethical_planner.validation import check, check_positive
from mujoco_world.evaluation.compare import ImpactRecord
from mujoco_world.scenario.spec import OUTCOMES as OUTCOMES  # re-exported: the run outcomes

#: Risk groups of the paper's Fig. 5.
GROUPS = ("ego", "third_party", "vulnerable")


@dataclass(frozen=True, slots=True)
class BodyRecord:
    """One simulated body as the run saw it.

    Attributes:
        id: entity index in the scene (0 is the ego; ``ImpactMeasurement`` bodies
            carry the same index as ``entity``).
        name: body name ("ego" or the road user's name).
        type: road-user type.
        length, width: footprint [m] (pedestrians: a round proxy of diameter
            min(length, width)).
        mass: [kg].
        kind: the scenario's finer kind of its type (``child``), or None.
        behaviour: how the road user moved, its ``BehaviourKind`` value (``recorded``: a
            replayed recording, blind to the ego; ``idm``, ``scripted``, ``pedestrian``,
            ``parked``); None for the ego and in records written before this field.
    """

    id: int
    name: str
    type: RoadUserType
    length: float
    width: float
    mass: float
    kind: str | None = None
    behaviour: str | None = None

    def __post_init__(self) -> None:
        check(
            isinstance(self.id, int) and not isinstance(self.id, bool) and self.id >= 0,
            f"body.id must be an integer >= 0, got {self.id!r}",
        )
        object.__setattr__(self, "type", RoadUserType.parse(self.type))
        check_positive("body", length=self.length, width=self.width, mass=self.mass)

    @property
    def shape(self) -> Shape:
        """Footprint as the planner's ``Shape`` [m]."""
        return Shape(self.length, self.width)


@dataclass(frozen=True, slots=True)
class ExpectationResult:
    """One item of a scenario's ``[expect]`` table, checked against a run.

    Attributes:
        name: the item (``ego_collision``, ``max_vulnerable_harm``...).
        expected: what the scenario expects, as text (``false``, ``<= 0.1``, ``goal``).
        measured: what the run gave, as text.
        passed: the run meets it.
    """

    name: str
    expected: str
    measured: str
    passed: bool


@dataclass(frozen=True, slots=True)
class RuleViolation:
    """A traffic rule the ego broke (``loop.metrics.RuleViolations``).

    Attributes:
        rule: ``red_light`` (crossed a stop line on red, not in the dilemma zone),
            ``stop_sign`` (crossed a stop sign's line without standing still before it),
            ``no_overtaking`` (its footprint entered the other direction's lanes in a
            no-overtaking zone) or ``shoulder`` (its footprint went beyond an outer lane
            edge).
        line: the stop line's or the zone's name; ``right`` or ``left`` for a shoulder.
        time: when the ego's front crossed the line, or its footprint the marking [s].
        speed: the ego's speed then [m/s].
    """

    rule: str
    line: str
    time: float
    speed: float


@dataclass(frozen=True, slots=True)
class RunSummary:
    """Result of one closed-loop run.

    Only the identity, the outcome and the reason are required: a run that failed
    before its world was built keeps the defaults (nothing measured, nan).

    Attributes:
        scenario: scenario name. planner: planner name. seed: run seed.
        outcome: goal, timeout, crash or failed. reason: why the run ended.
        duration: simulated time [s]. steps: physics steps. cycles: planning cycles.
        bodies: every simulated body (id = entity index, shape, mass), ego first.
        collisions: every measured collision with the model's prediction beside it,
            ego-involved and third-party (``ego_collisions``, ``third_party_collisions``).
        ego_collided: the ego took part in a collision (the run is then a ``crash``
            under the default crash criterion ``rules.EgoContact``).
        max_risk: highest risk per group (ego, third_party, vulnerable) along the
            executed plans. top_risks: up to 100 highest risk values per group.
        top_risks_by_type, top_ego_risks_by_type: up to 100 highest road-user risks
            R_k, and ego risks R_ego,k, per road-user type (``metrics.RiskByType``).
        harm: measured harm per group over all collisions, an expected count of MAIS3+
            injured: per body its impacts combine as 1 - prod(1 - h_i), the group sums
            its bodies (``loop.metrics.combined_harm``).
        harm_ego_involved: the same over the collisions the ego took part in.
        harm_third_party: the same over collisions between other road users.
        min_distance: smallest ego-to-road-user distance [m] (negative: overlap).
        min_distance_vulnerable: the same to vulnerable road users [m].
        clearance_vulnerable: smallest ego distance to each vulnerable road user by
            name [m], while the ego drives on its plans (until its first contact under
            the ``brake`` post-crash policy, the whole run under ``continue``; capped at 50 m).
        min_ttc: smallest constant-velocity time-to-collision of the ego [s] (inf:
            no approach within the horizon).
        max_collision_probability: highest collision probability of any road user
            along the chosen plans.
        tracking_rms, tracking_max: ego tracking error before any contact [m].
        progress: ego arc length along its route at the end [m].
        first_seen: when the planner first perceived each road user, by name [s]
            (absent: never; ``SensorSpec`` limits what it perceives).
        rule_violations: the ego's traffic-rule violations, in time order.
        levels: planning cycles per chosen validity level.
        timings: wall-clock seconds per part (physics, planning, measurement,
            control, total) and the real-time factor.
        extra_metrics: values of metrics added to the run beyond the built-in ones
            (``loop.metrics``), by name; JSON-able.
        notes: what the scenario's import and the world found (CommonRoad files: time
            step corrections, overlapping recorded shapes, recordings beyond tyre
            friction...).
        expectations: the scenario's ``[expect]`` items checked against this run
            (empty if it expects nothing).
        post_crash: what the ego did after its first contact in this run (the
            scenario's ``ego.post_crash`` or ``RunConfig.post_crash``): "brake" or "continue".
    """

    scenario: str
    planner: str
    seed: int
    outcome: str
    reason: str
    duration: float = 0.0
    steps: int = 0
    cycles: int = 0
    bodies: tuple[BodyRecord, ...] = ()
    collisions: tuple[ImpactRecord, ...] = ()
    ego_collided: bool = False
    max_risk: dict[str, float] = field(default_factory=dict)
    top_risks: dict[str, tuple[float, ...]] = field(default_factory=dict)
    top_risks_by_type: dict[str, tuple[float, ...]] = field(default_factory=dict)
    top_ego_risks_by_type: dict[str, tuple[float, ...]] = field(default_factory=dict)
    harm: dict[str, float] = field(default_factory=dict)
    harm_ego_involved: dict[str, float] = field(default_factory=dict)
    harm_third_party: dict[str, float] = field(default_factory=dict)
    min_distance: float = math.nan
    min_distance_vulnerable: float = math.nan
    clearance_vulnerable: dict[str, float] = field(default_factory=dict)
    min_ttc: float = math.nan
    max_collision_probability: float = math.nan
    tracking_rms: float = math.nan
    tracking_max: float = math.nan
    progress: float = math.nan
    first_seen: dict[str, float] = field(default_factory=dict)
    rule_violations: tuple[RuleViolation, ...] = ()
    levels: dict[str, int] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    extra_metrics: dict[str, Any] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    expectations: tuple[ExpectationResult, ...] = ()
    post_crash: str = "brake"

    @property
    def verdict(self) -> str:
        """``pass`` (every expectation met), ``fail`` (one is not) or ``none`` (nothing expected)."""
        if not self.expectations:
            return "none"
        return "pass" if all(e.passed for e in self.expectations) else "fail"

    @property
    def ego_collisions(self) -> tuple[ImpactRecord, ...]:
        """The collisions the ego took part in."""
        return tuple(c for c in self.collisions if c.involves_ego)

    @property
    def third_party_collisions(self) -> tuple[ImpactRecord, ...]:
        """The collisions between other road users (or a road user and a wall)."""
        return tuple(c for c in self.collisions if not c.involves_ego)

    def body(self, entity: int) -> BodyRecord:
        """The body with entity index ``entity``.

        Raises:
            ValueError: no such body in this run.
        """
        for body in self.bodies:
            if body.id == entity:
                return body
        raise ValueError(f"run {self.scenario}/{self.planner}/s{self.seed} has no body {entity}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict of every field (``ethical_planner.records.to_plain``)."""
        return to_plain(self)

    def comparable_dict(self) -> dict[str, Any]:
        """``to_dict`` without wall-clock timings (for determinism checks)."""
        out = self.to_dict()
        out.pop("timings")
        return out


#: Summary fields the loop fills itself; a metric may not set them.
_LOOP_FIELDS = frozenset(
    {"scenario", "planner", "seed", "outcome", "reason", "duration", "steps", "cycles"}
    | {"bodies", "collisions", "ego_collided", "timings", "extra_metrics", "notes", "expectations"}
    | {"post_crash"}
)


def build_summary(
    *,
    scenario: str,
    planner: str,
    seed: int,
    outcome: str,
    reason: str,
    duration: float,
    steps: int,
    cycles: int,
    bodies: Sequence[BodyRecord],
    collisions: Sequence[ImpactRecord],
    values: Mapping[str, Any],
    timings: Mapping[str, float],
    notes: Sequence[str] = (),
    post_crash: str = "brake",
) -> RunSummary:
    """The summary of a finished run from what the loop counted and what its metrics measured.

    Args:
        scenario, planner, seed, outcome, reason, duration, steps, cycles, bodies,
            collisions, timings: as in ``RunSummary``.
        values: the metrics' values by name: a ``RunSummary`` field sets it, any
            other name goes to ``extra_metrics``.
        notes, post_crash: as in ``RunSummary``.

    Raises:
        ValueError: a metric value names a field the loop fills itself.
    """
    clash = sorted(_LOOP_FIELDS & values.keys())
    if clash:
        raise ValueError(f"metric values may not set the summary's own fields {clash}")
    known = {f.name for f in fields(RunSummary)}
    return RunSummary(
        scenario=scenario,
        planner=planner,
        seed=int(seed),
        outcome=outcome,
        reason=reason,
        duration=duration,
        steps=steps,
        cycles=cycles,
        bodies=tuple(bodies),
        collisions=tuple(collisions),
        ego_collided=any(c.involves_ego for c in collisions),
        timings=dict(timings),
        notes=tuple(notes),
        post_crash=str(post_crash),
        extra_metrics={k: v for k, v in values.items() if k not in known},
        **{k: v for k, v in values.items() if k in known},
    )
