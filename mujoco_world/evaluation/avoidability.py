"""Records of the avoidability search: the manoeuvres it tries and what it found.

The search itself is ``mujoco_world.experiments.avoidability``; these records are what
a run record keeps (``RunRecord.avoidability``) and what the index, the near-crash
listing and the batch aggregate read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ethical_planner.validation import check, check_non_negative
from mujoco_world.agents.scripted import Manoeuvre

#: Kinds of manoeuvre in the family, by what they combine.
MANOEUVRE_KINDS = ("keep_lane", "brake", "swerve", "swerve_and_brake", "lane_change", "lane_change_and_brake")


@dataclass(frozen=True, slots=True)
class ManoeuvreSpec:
    """One open-loop manoeuvre of the avoidability family, started at a branch time.

    Attributes:
        start: branch time: the simulation time [s] at which the manoeuvre replaces
            the run's planner (a planning cycle the ego actually passed through).
        deceleration: constant braking from ``start`` to a stop [m/s^2] (0 keeps the
            speed).
        offset: lateral move from the ego's offset at ``start`` [m] (left positive;
            0: none), a quintic over ``duration``.
        duration: time of the lateral move [s] (0 without one).
        lane_change: the move ends on another lane's centre (otherwise a swerve).
    """

    start: float
    deceleration: float = 0.0
    offset: float = 0.0
    duration: float = 0.0
    lane_change: bool = False

    def __post_init__(self) -> None:
        check_non_negative(
            "manoeuvre", start=self.start, deceleration=self.deceleration, duration=self.duration
        )
        check(
            (self.offset == 0.0) == (self.duration == 0.0),
            f"manoeuvre: a lateral move needs both offset and duration, got {self.offset}, {self.duration}",
        )

    @property
    def kind(self) -> str:
        """One of ``MANOEUVRE_KINDS``."""
        if self.offset == 0.0:
            return "brake" if self.deceleration > 0 else "keep_lane"
        base = "lane_change" if self.lane_change else "swerve"
        return f"{base}_and_brake" if self.deceleration > 0 else base

    def manoeuvre(self) -> Manoeuvre:
        """The scripted manoeuvre (time measured from ``start``; ``agents.scripted``)."""
        from mujoco_world.agents.scripted import brake, keep_lane, lane_change, swerve_and_brake

        name = "avoid_" + self.kind
        if self.offset == 0.0:
            return brake(self.deceleration, name=name) if self.deceleration > 0 else keep_lane()
        if self.deceleration == 0.0:
            return lane_change(self.offset, duration=self.duration, name=name)
        return swerve_and_brake(self.offset, self.deceleration, duration=self.duration, name=name)

    def describe(self) -> str:
        """In words, e.g. "at 4.10 s: swerve 1.00 m left over 1.5 s, braking at 4.0 m/s^2"."""
        parts = []
        if self.offset != 0.0:
            side = "left" if self.offset > 0 else "right"
            what = "change lane" if self.lane_change else "swerve"
            parts.append(f"{what} {abs(self.offset):.2f} m {side} over {self.duration:.1f} s")
        if self.deceleration > 0:
            parts.append(f"brake at {self.deceleration:.1f} m/s^2 to a stop")
        return f"at {self.start:.2f} s: " + (", ".join(parts) if parts else "keep lane and speed")


@dataclass(frozen=True, slots=True)
class BranchResult:
    """What one manoeuvre gave, simulated from its branch time to the end of the window.

    Attributes:
        manoeuvre: what the ego did.
        outcome: the branch run's outcome (crash: the ego collided).
        ego_collided: the ego touched something in the window.
        collision_time: the ego's first contact [s] (nan without one).
        min_distance: smallest ego distance to any road user over the whole run
            until the ego's first contact [m].
        min_distance_vulnerable: the same to vulnerable road users [m] (nan without one).
        harm_ego_involved: measured harm per group (ego, third_party, vulnerable) of
            the ego's collisions.
    """

    manoeuvre: ManoeuvreSpec
    outcome: str
    ego_collided: bool
    collision_time: float = math.nan
    min_distance: float = math.nan
    min_distance_vulnerable: float = math.nan
    harm_ego_involved: dict[str, float] = field(default_factory=dict)

    @property
    def total_harm(self) -> float:
        """Summed ego-involved harm over the groups (the ranking of colliding branches)."""
        return float(sum(v for v in self.harm_ego_involved.values() if math.isfinite(v)))


@dataclass(frozen=True, slots=True)
class Avoidability:
    """The verdict of the avoidability search on one run.

    Attributes:
        avoidable: some manoeuvre of the family avoided every ego collision in the
            window (the first found is ``best``).
        crash_time: the run's first ego contact [s].
        partner: name of the body the ego first collided with ("" for a wall).
        earliest_branch: first branch time searched [s]: the later of the crash time
            minus the lookback and the first cycle at which the ego perceived its
            collision partner.
        window_end: branches were simulated until this time [s] (or the scenario's end).
        best: the first collision-free manoeuvre (avoidable), or the one with the least
            ego-involved harm (unavoidable); None if no branch time was left.
        branches: manoeuvres simulated.
        original_harm: the run's own ego-involved harm per group.
        wall_time: seconds the search took (the run's re-simulation included).
        method: how branch states were made ("fork": the run re-simulated with its
            own planner and copied at each branch time, ``ClosedLoop.fork``).
        family: the family searched (``AvoidabilityFamily.describe``).
    """

    avoidable: bool
    crash_time: float
    partner: str
    earliest_branch: float
    window_end: float
    best: BranchResult | None
    branches: int
    original_harm: dict[str, float] = field(default_factory=dict)
    wall_time: float = math.nan
    method: str = "fork"
    family: str = ""

    def describe(self) -> str:
        """One paragraph a person reads."""
        verdict = "AVOIDABLE" if self.avoidable else "not avoidable by the family"
        head = (
            f"ego collision with {self.partner or 'a wall'} at {self.crash_time:.2f} s: {verdict} "
            f"({self.branches} manoeuvres from {self.earliest_branch:.2f} s on, {self.wall_time:.1f} s)"
        )
        if self.best is None:
            return head + "; no branch time before the collision"
        b = self.best
        harm = ", ".join(f"{g} {v:.3f}" for g, v in b.harm_ego_involved.items())
        what = (
            "avoids it"
            if not b.ego_collided
            else f"least harm ({harm}; the run's own: "
            + ", ".join(f"{g} {v:.3f}" for g, v in self.original_harm.items())
            + ")"
        )
        vru = (
            "" if math.isnan(b.min_distance_vulnerable) else f", {b.min_distance_vulnerable:.2f} m from VRUs"
        )
        return f"{head}\n  best: {b.manoeuvre.describe()}: {what}; clearance {b.min_distance:.2f} m{vru}"
