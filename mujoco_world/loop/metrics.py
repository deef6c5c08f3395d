"""Metrics of a closed-loop run: each metric is one small object behind ``Metric``.

A metric sees the run's planning cycles (``on_cycle``), its measured collisions
(``on_impact``) and, every ``interval`` physics steps, its state (``sample``); at the
end it hands its values to the run's summary (``values``: field name -> value). The
loop samples a state only if no rule stopped the run on it or the rule trusts it (a
diverged simulation is not measured).

``default_metrics`` gives the built-in metrics; their values fill the typed fields of
``RunSummary``. A metric of your own returns other names; they land in
``RunSummary.extra_metrics`` (JSON-able values), and a new built-in one gets a field
(with a default, so older run records still read):
``run_scenario(..., metrics=(*default_metrics(config), MyMetric()))``.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ethical_planner.geometry import rectangle_overlap
from ethical_planner.road_users import VULNERABLE_TYPES, RoadUserType
from ethical_planner.sampling import FrenetState
from ethical_planner.traffic_rules import STANDSTILL_MPS, lane_blocked, stop_distance
from mujoco_world.agents.ego_planner import Plan
from mujoco_world.evaluation.compare import ImpactRecord
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.state import RunState
from mujoco_world.loop.summary import GROUPS, RuleViolation
from mujoco_world.loop.world import World
from mujoco_world.physics.safety import time_to_collision

#: Number of highest risk values kept per group (paper Fig. 5 uses 100).
TOP_RISKS = 100
#: Distances beyond this are not resolved (``MinDistance``) [m].
DISTANCE_CAP = 50.0


@runtime_checkable
class Metric(Protocol):
    """Something a run measures; subclass it and override what you need (no-ops here).

    Attributes:
        interval: physics steps between ``sample`` calls (0: never sampled).
    """

    interval: int = 0

    def start(self, run: RunState) -> None:
        """Reset before the first step (a metric object may serve several runs)."""

    def on_cycle(self, run: RunState, plan: Plan) -> None:
        """After each planning cycle (``plan.decision`` is None for planners without one)."""

    def on_impact(self, run: RunState, record: ImpactRecord) -> None:
        """When a collision has been measured."""

    def sample(self, run: RunState) -> None:
        """Every ``interval`` physics steps."""

    def values(self, run: RunState) -> dict[str, Any]:
        """Summary fields at the end of the run (name -> value)."""
        return {}


class RiskLog(Metric):
    """Highest risk values per group along the executed plans (paper Fig. 5).

    Values: ``max_risk`` and ``top_risks`` (up to ``TOP_RISKS`` per group, highest first).
    """

    def start(self, run: RunState) -> None:
        """Empty heaps per group."""
        self.top: dict[str, list[float]] = {g: [] for g in GROUPS}

    def _push(self, group: str, values: np.ndarray) -> None:
        heap = self.top[group]
        for value in values:
            if len(heap) < TOP_RISKS:
                heapq.heappush(heap, float(value))
            elif value > heap[0]:
                heapq.heapreplace(heap, float(value))

    def on_cycle(self, run: RunState, plan: Plan) -> None:
        """The ego's combined risk and every road user's risk of the chosen plan."""
        decision = plan.decision
        if decision is None:
            return
        self._push("ego", np.array([decision.ego_combined_risk]))
        if decision.road_users:
            risk = np.array([u.risk for u in decision.road_users])
            vru = np.array([u.type in VULNERABLE_TYPES for u in decision.road_users])
            self._push("vulnerable", risk[vru])
            self._push("third_party", risk[~vru])

    def values(self, run: RunState) -> dict[str, Any]:
        """``max_risk`` and ``top_risks`` per group."""
        return {
            "max_risk": {g: (max(v) if v else 0.0) for g, v in self.top.items()},
            "top_risks": {g: tuple(sorted(v, reverse=True)) for g, v in self.top.items()},
        }


class RiskByType(Metric):
    """Highest risk values per road-user type along the executed plans.

    The study forms any grouping from these afterwards (with or without motorcycles
    among the vulnerable road users). Values: ``top_risks_by_type`` (the road users'
    R_k of the chosen plans) and ``top_ego_risks_by_type`` (the ego's R_ego,k per
    partner type, as the paper's reference evaluation counts the ego's risk), up to
    ``TOP_RISKS`` per type, highest first.
    """

    def start(self, run: RunState) -> None:
        """Empty heaps."""
        self.top: dict[str, list[float]] = {}
        self.top_ego: dict[str, list[float]] = {}

    @staticmethod
    def _push(heap: list[float], value: float) -> None:
        if len(heap) < TOP_RISKS:
            heapq.heappush(heap, value)
        elif value > heap[0]:
            heapq.heapreplace(heap, value)

    def on_cycle(self, run: RunState, plan: Plan) -> None:
        """Every road user's R_k and R_ego,k of the chosen plan."""
        for u in plan.decision.road_users if plan.decision is not None else ():
            kind = RoadUserType(u.type).value
            self._push(self.top.setdefault(kind, []), float(u.risk))
            self._push(self.top_ego.setdefault(kind, []), float(u.ego_risk))

    def values(self, run: RunState) -> dict[str, Any]:
        """``top_risks_by_type`` and ``top_ego_risks_by_type``."""
        return {
            "top_risks_by_type": {k: tuple(sorted(v, reverse=True)) for k, v in self.top.items()},
            "top_ego_risks_by_type": {k: tuple(sorted(v, reverse=True)) for k, v in self.top_ego.items()},
        }


class ValidityLevels(Metric):
    """Planning cycles per chosen validity level. Value: ``levels``."""

    def start(self, run: RunState) -> None:
        """No cycles yet."""
        self.levels: dict[str, int] = {}

    def on_cycle(self, run: RunState, plan: Plan) -> None:
        """Count the chosen plan's level."""
        if plan.decision is None:
            return
        key = str(plan.decision.level)
        self.levels[key] = self.levels.get(key, 0) + 1

    def values(self, run: RunState) -> dict[str, Any]:
        """``levels``."""
        return {"levels": dict(self.levels)}


class PlannedCollisionProbability(Metric):
    """Highest collision probability of any road user along the chosen plans.

    Value: ``max_collision_probability`` (0 without road users or cycles).
    """

    def start(self, run: RunState) -> None:
        """Nothing planned yet."""
        self.highest = 0.0

    def on_cycle(self, run: RunState, plan: Plan) -> None:
        """The plan's highest per-road-user collision probability."""
        for u in plan.decision.road_users if plan.decision is not None else ():
            if u.collision_probability > self.highest:
                self.highest = float(u.collision_probability)

    def values(self, run: RunState) -> dict[str, Any]:
        """``max_collision_probability``."""
        return {"max_collision_probability": self.highest}


class MinDistance(Metric):
    """Smallest ego-to-road-user geom distance while the ego drives on its plans.

    That is until the ego's first contact under the ``brake`` post-crash policy, and
    the whole run under ``continue`` (``World.ego_on_plan``): how closely the ego
    passed a pedestrian after scraping a wall is what that policy is about.

    Values: ``min_distance`` and ``min_distance_vulnerable`` [m] (negative: overlap;
    nan if there was none to measure), and ``clearance_vulnerable``: the smallest
    distance to each vulnerable road user by name [m] (distances are capped at
    ``DISTANCE_CAP``: 50.0 means "never closer than 50 m").

    Args:
        interval: physics steps between measurements.
    """

    def __init__(self, interval: int) -> None:
        self.interval = interval

    def start(self, run: RunState) -> None:
        """Which road users are vulnerable."""
        self.vulnerable = np.array([t in VULNERABLE_TYPES for t in run.world.types[1:]], dtype=bool)
        self.names = tuple(run.world.scene.names[1:])
        self.closest = math.inf
        self.per_user = np.full(len(self.names), math.inf)

    def sample(self, run: RunState) -> None:
        """``mj_geomDistance`` from the ego to every road user."""
        world = run.world
        if world.n < 2 or not world.ego_on_plan:
            return
        dist = world.ego_distances(DISTANCE_CAP)
        self.closest = min(self.closest, float(dist.min()))
        np.minimum(self.per_user, dist, out=self.per_user)

    def values(self, run: RunState) -> dict[str, Any]:
        """``min_distance``, ``min_distance_vulnerable`` and ``clearance_vulnerable``."""
        vulnerable = self.per_user[self.vulnerable]
        closest_vulnerable = float(vulnerable.min()) if vulnerable.size else math.inf
        return {
            "min_distance": self.closest if math.isfinite(self.closest) else math.nan,
            "min_distance_vulnerable": closest_vulnerable if math.isfinite(closest_vulnerable) else math.nan,
            "clearance_vulnerable": {
                name: float(d)
                for name, d, vru in zip(self.names, self.per_user, self.vulnerable, strict=True)
                if vru and math.isfinite(d)
            },
        }


def footprint_extents(world: World) -> np.ndarray:
    """(n, 2) length and width of every body's footprint [m]; a round body as its bounding square."""
    bodies = world.scene.bodies
    length = np.array([2 * b.radius if b.is_round else b.length for b in bodies])
    width = np.array([2 * b.radius if b.is_round else b.width for b in bodies])
    return np.column_stack([length, width])


def ego_time_to_collision(world: World, extent: np.ndarray, horizon: float) -> np.ndarray:
    """Constant-velocity time to collision of the ego with every road user, from the true state.

    Args:
        world: the world now.
        extent: (n, 2) footprints [m] (``footprint_extents``).
        horizon: look-ahead [s].

    Returns:
        (n - 1,) [s]: 0 if overlapping now, inf if no overlap within ``horizon``.
    """
    qpos, qvel = world.scene.qpos, world.scene.qvel
    states = np.column_stack([qpos[:, :2], qpos[:, 2], qvel[:, :2], extent])
    return time_to_collision(states[0], states[1:], horizon)


class TimeToCollision(Metric):
    """Smallest constant-velocity time-to-collision of the ego until its first contact.

    Value: ``min_ttc`` [s] (inf if no approach within ``horizon``).

    Args:
        horizon: look-ahead [s].
        rate: evaluations per simulated second [Hz] (and one at the start).
    """

    def __init__(self, horizon: float = 10.0, rate: float = 20.0) -> None:
        if not (math.isfinite(horizon) and horizon > 0 and math.isfinite(rate) and rate > 0):
            raise ValueError(f"TimeToCollision: horizon and rate must be > 0, got {horizon}, {rate}")
        self.horizon = float(horizon)
        self.rate = float(rate)
        self.interval = 1

    def start(self, run: RunState) -> None:
        """Footprints once, then the TTC of the initial state."""
        self.interval = max(int(round(1.0 / (self.rate * run.dt))), 1)
        self._extent = footprint_extents(run.world)
        self.lowest = math.inf
        self.sample(run)

    def sample(self, run: RunState) -> None:
        """TTC from the true states of every body."""
        world = run.world
        if world.n < 2 or world.crashed[0]:
            return
        ttc = ego_time_to_collision(world, self._extent, self.horizon)
        self.lowest = min(self.lowest, float(ttc.min()))

    def values(self, run: RunState) -> dict[str, Any]:
        """``min_ttc``."""
        return {"min_ttc": self.lowest}


def combined_harm(records: Sequence[ImpactRecord]) -> dict[str, float]:
    """Expected number of MAIS3+ injured per group over measured collisions.

    A body hit several times is injured (MAIS3+) unless every impact spares it, so its
    harms combine as ``1 - prod(1 - h_i)`` (the impacts taken as independent), never
    above 1; a group's value is the sum of its bodies' combined harms: an expected count
    of MAIS3+ injured, not a probability (it can exceed 1 with several bodies). Walls
    and debris have no harm (nan) and are left out; harms are clipped to [0, 1].

    Args:
        records: the collisions.

    Returns:
        group -> expected count, for every group of ``GROUPS``.
    """
    spared: dict[int, float] = {}
    group: dict[int, str] = {}
    for record in records:
        for impact, body in ((record.measurement.a, record.a), (record.measurement.b, record.b)):
            if body.group in GROUPS and math.isfinite(body.harm_measured):
                h = min(max(body.harm_measured, 0.0), 1.0)
                spared[impact.entity] = spared.get(impact.entity, 1.0) * (1.0 - h)
                group[impact.entity] = body.group
    out = {g: 0.0 for g in GROUPS}
    for entity, p in spared.items():
        out[group[entity]] += 1.0 - p
    return out


class HarmPerGroup(Metric):
    """Measured harm per group (ego, third_party, vulnerable) over the collisions.

    Values: ``harm`` (all collisions), ``harm_ego_involved`` (collisions the ego took
    part in: what the ego's planner answers for) and ``harm_third_party`` (collisions
    between other road users), each ``combined_harm``: per body the repeated impacts
    combine as ``1 - prod(1 - h_i)``, per group the bodies add up (an expected count of
    MAIS3+ injured). A body hit in both kinds of collision counts in both splits, so
    ``harm`` may be less than their sum.
    """

    def start(self, run: RunState) -> None:
        """No collisions yet."""
        self.records: list[ImpactRecord] = []

    def on_impact(self, run: RunState, record: ImpactRecord) -> None:
        """Keep the collision."""
        self.records.append(record)

    def values(self, run: RunState) -> dict[str, Any]:
        """``harm``, ``harm_ego_involved`` and ``harm_third_party``."""
        return {
            "harm": combined_harm(self.records),
            "harm_ego_involved": combined_harm([r for r in self.records if r.involves_ego]),
            "harm_third_party": combined_harm([r for r in self.records if not r.involves_ego]),
        }


class TrackingError(Metric):
    """RMS and largest ego tracking error before any contact.

    Values: ``tracking_rms`` and ``tracking_max`` [m].
    """

    def values(self, run: RunState) -> dict[str, Any]:
        """From the world's controller bookkeeping."""
        rms, worst = run.world.tracking_error()
        return {"tracking_rms": rms, "tracking_max": worst}


class Progress(Metric):
    """Ego arc length along its route at the end. Value: ``progress`` [m]."""

    def values(self, run: RunState) -> dict[str, Any]:
        """``World.ego_progress``."""
        return {"progress": run.world.ego_progress()}


class FirstSeen(Metric):
    """When the planner first perceived each road user (``World.first_seen``).

    Value: ``first_seen`` (road user name -> time [s]); road users never perceived are
    absent. With an unlimited sensor every road user in the world at the start is
    seen at 0.
    """

    def values(self, run: RunState) -> dict[str, Any]:
        """``first_seen`` of the road users (entity 1..n-1)."""
        world = run.world
        seen = world.first_seen
        names = world.scene.names
        rows = np.flatnonzero(~np.isnan(seen[1:])) + 1
        return {"first_seen": {names[i]: round(float(seen[i]), 6) for i in rows}}


class RuleViolations(Metric):
    """The ego's traffic-rule violations: stop lines, no-overtaking zones, shoulders.

    Every ``interval`` physics steps:

    - Stop lines (``StopLineSpec``): the ego's front arc length (``World.ego_progress``
      + half its length) is compared with each line: crossing it while the light is
      red is a ``red_light`` violation; crossing a stop sign's line without having
      stood still (speed below ``STANDSTILL_MPS``) while its front was within
      ``stop_zone`` before the line is a ``stop_sign`` violation. A line is judged
      once, when first crossed. A crossing on red that the ego could no longer avoid
      when the light turned red (its stopping distance at the emergency deceleration
      after the jerk ramp, ``traffic_rules.stop_distance``, exceeded its gap to the
      line at the first sample in the red) is the planner's dilemma zone: it is not a
      violation and is listed in ``amber_crossings`` instead. The emergency
      deceleration (8 m/s^2 by default), the jerk and ``pass_lookahead`` (below) are
      the ego planner's (``RunState.planner_config``: ``vehicle``, ``traffic_rules``).
    - Lane markings (``World.lane_extent``, the footprint's offsets across the ego's
      route): each time the footprint reaches more than ``LANE_TOLERANCE_M`` beyond an
      outer lane edge it is a ``shoulder`` violation (line ``right`` or ``left``);
      each time it reaches that far across the centre line while any part of it lies
      in a no-overtaking zone, and did not a sample before, a ``no_overtaking``
      violation (line: the zone's name), unless debris or a road user slower than the
      zone's ``pass_below`` lay in the ego's lane within ``pass_lookahead`` ahead
      (``traffic_rules.lane_blocked``, as the planner asks it: ``passing``). Either
      entry is ``evasive`` if the ego kept in its lane and braking at
      ``EVASIVE_DECELERATION`` would still hit a road user or debris within
      ``EVASIVE_HORIZON_S`` (``_stays_in_lane_and_collides``). Excused entries are not
      violations.

    Values: ``rule_violations`` (``RuleViolation`` records, in time order) and, if any,
    ``amber_crossings`` (line name, time [s], speed [m/s]) and ``excused_rule_entries``
    (rule, line, time, speed, excuse) in ``extra_metrics``.
    """

    def __init__(self, interval: int = 10) -> None:
        self.interval = interval

    def start(self, run: RunState) -> None:
        """Nothing crossed, no standstill yet."""
        lines = run.scenario.stop_lines
        self.lines = lines
        self.red = [line.as_stop_line() for line in lines]
        self.s = np.array([line.s for line in lines])
        self.zone = np.array([line.stop_zone for line in lines])
        self.crossed = np.zeros(len(lines), dtype=bool)
        self.stood = np.zeros(len(lines), dtype=bool)
        self.was_red = np.zeros(len(lines), dtype=bool)
        self.dilemma = np.zeros(len(lines), dtype=bool)
        self.found: list[RuleViolation] = []
        self.amber: list[dict[str, Any]] = []
        self.excused: list[dict[str, Any]] = []
        world = run.world
        self.vehicle = run.planner_config.vehicle
        self.pass_lookahead = run.planner_config.traffic_rules.pass_lookahead
        self.environment = world.environment()
        environment = self.environment
        self.zones = environment.no_overtaking
        self.zone_names = [zone.name for zone in run.scenario.road.no_overtaking]
        self.marked = environment.lane_edges is not None
        self.on_shoulder = {"right": False, "left": False}
        self.across = False

    def sample(self, run: RunState) -> None:
        """Judge the lines the ego's front has just crossed and its place across the lanes."""
        if self.lines:
            self._stop_lines(run.world)
        if self.marked:
            self._markings(run.world)

    def _stop_lines(self, world: World) -> None:
        front = world.ego_progress() + 0.5 * float(world.lengths[0])
        speed = float(world.scene.speeds()[0])
        near = ~self.crossed & (front >= self.s - self.zone)
        self.stood |= near & (speed < STANDSTILL_MPS)
        t = world.time
        red = np.array([line.red_at(t) for line in self.red], dtype=bool)  # a few lines
        onset = red & ~self.was_red & ~self.crossed
        if onset.any():
            vehicle = self.vehicle
            accel = float(world.accelerations_along_heading()[0])
            state = FrenetState(s=front, s_dot=speed, s_ddot=accel, d=0.0, d_dot=0.0, d_ddot=0.0)
            stop = float(
                stop_distance(state, np.array([vehicle.emergency_deceleration]), vehicle.max_jerk)[0]
            )
            self.dilemma[onset] = stop > self.s[onset] - front
        self.dilemma &= red | self.crossed  # a dilemma lasts for its red window
        self.was_red = red
        for k in np.flatnonzero(~self.crossed & (front >= self.s)):
            self.crossed[k] = True
            line = self.lines[k]
            if line.stop and not self.stood[k]:
                self.found.append(RuleViolation("stop_sign", line.name, round(t, 6), speed))
            elif red[k] and self.dilemma[k]:
                self.amber.append({"line": line.name, "time": round(t, 6), "speed": round(speed, 6)})
            elif red[k]:
                self.found.append(RuleViolation("red_light", line.name, round(t, 6), speed))

    def _markings(self, world: World) -> None:
        environment = self.environment
        speed = float(world.scene.speeds()[0])
        s, d, right, left = world.lane_extent()
        edge_r, edge_l = environment.lane_edges  # type: ignore[misc]
        for side, beyond in (("right", edge_r - right), ("left", left - edge_l)):
            now = beyond > LANE_TOLERANCE_M
            if now and not self.on_shoulder[side]:
                self._entry(world, "shoulder", side, s, speed, None)
            self.on_shoulder[side] = now
        if not self.zones or environment.centre_line is None:
            return
        across = left - environment.centre_line > LANE_TOLERANCE_M
        half = 0.5 * float(world.lengths[0])
        zone = next(
            (i for i, z in enumerate(self.zones) if s + half > z.start and s - half < z.end),
            None,
        )
        if across and not self.across and zone is not None:
            others = np.flatnonzero(world.present[1:]) + 1
            passing = self.zones[zone].pass_below > 0.0 and lane_blocked(
                environment,
                (s, d),
                2.0 * half,
                world.positions[others],
                world.scene.speeds()[others],
                world.widths[others],
                self.zones[zone].pass_below,
                self.pass_lookahead,
            )
            self._entry(
                world, "no_overtaking", self.zone_names[zone], s, speed, "passing" if passing else None
            )
        self.across = across

    def _entry(self, world: World, rule: str, line: str, s: float, speed: float, excuse: str | None) -> None:
        """A violation, or an excused entry (``passing`` a slow obstacle, ``evasive``)."""
        if excuse is None and _stays_in_lane_and_collides(world, s):
            excuse = "evasive"
        t = round(world.time, 6)
        if excuse is None:
            self.found.append(RuleViolation(rule, line, t, speed))
        else:
            self.excused.append(
                {"rule": rule, "line": line, "time": t, "speed": round(speed, 6), "excuse": excuse}
            )

    def values(self, run: RunState) -> dict[str, Any]:
        """``rule_violations`` (and ``amber_crossings`` if any)."""
        out: dict[str, Any] = {"rule_violations": tuple(sorted(self.found, key=lambda v: v.time))}
        if self.amber:
            out["amber_crossings"] = list(self.amber)
        if self.excused:
            out["excused_rule_entries"] = list(self.excused)
        return out


def _stays_in_lane_and_collides(world: World, s: float) -> bool:
    """True if the ego kept in its lane and braking at ``EVASIVE_DECELERATION`` would still hit something.

    The counterfactual ego drives along its route from arc length ``s`` at its speed,
    braking at ``EVASIVE_DECELERATION`` to a stop; every road user in the world keeps
    its velocity, debris stands. Checked every 0.1 s for ``EVASIVE_HORIZON_S``
    (``geometry.rectangle_overlap``). Overtaking a slower vehicle is not evasive (braking
    behind it avoids it); swerving from an oncoming truck cutting into the lane, or from
    debris too close to stop for, is.
    """
    t = np.arange(0.0, EVASIVE_HORIZON_S + 1e-9, 0.1)
    v = float(world.speeds_along_heading()[0])
    moving = np.minimum(t, max(v, 0.0) / EVASIVE_DECELERATION)
    x, y, theta, _, _ = world.ego_path.evaluate(s + v * moving - 0.5 * EVASIVE_DECELERATION * moving**2)
    others = np.flatnonzero(world.present[1:]) + 1
    rows = [
        np.column_stack(
            [
                world.positions[others],
                world.yaws[others],
                world.velocities[others],
                world.lengths[others],
                world.widths[others],
            ]
        )
    ]
    rows += [
        np.array([[*b.center, b.yaw, 0.0, 0.0, 2.0 * b.half_length, 2.0 * b.half_width]])
        for b in world.debris
    ]
    table = np.concatenate(rows, axis=0)
    if not len(table):
        return False
    tt = t[:, None]
    depth = rectangle_overlap(
        x[:, None],
        y[:, None],
        theta[:, None],
        world.lengths[0],
        world.widths[0],
        table[:, 0] + table[:, 3] * tt,
        table[:, 1] + table[:, 4] * tt,
        table[:, 2],
        table[:, 5],
        table[:, 6],
    )
    return bool(np.any(depth > 0.0))


#: The world's judge counts a footprint this far beyond a marking [m] (a tracking error is not a crossing).
LANE_TOLERANCE_M = 0.1
#: An entry onto the shoulder or across a zone's centre line is evasive (excused) if the ego kept
#: in its lane and braking at this deceleration would still hit something within the horizon
#: [m/s^2, s] (``_stays_in_lane_and_collides``).
EVASIVE_DECELERATION = 6.0
EVASIVE_HORIZON_S = 3.0


class ScriptEvents(Metric):
    """When each road user's scripted events fired (``BehaviourSpec.events``).

    Value: ``script_events`` (road user name -> fire times [s], in script order), only
    for road users with a script; nothing for scenarios without scripts.
    """

    def values(self, run: RunState) -> dict[str, Any]:
        """``script_events`` in ``extra_metrics``."""
        fleet = run.world.fleet
        fired = {
            spec.name: [round(t, 6) for t in fleet.script.fired[i]]
            for i, spec in enumerate(fleet.specs)
            if spec.behaviour.events
        }
        return {"script_events": fired} if fired else {}


class LaneChanges(Metric):
    """The lane changes MOBIL road users made (``BehaviourSpec.mobil``).

    Values: ``lane_changes``, a list of (road user name, time [s], from lane, to lane),
    lanes from the right in the road user's direction, and ``lane_changes_per_user``,
    the number of changes of every MOBIL road user by name (0 for one that kept its
    lane); nothing for scenarios without MOBIL road users.
    """

    def values(self, run: RunState) -> dict[str, Any]:
        """``lane_changes`` and ``lane_changes_per_user`` in ``extra_metrics``."""
        fleet = run.world.fleet
        if not fleet.k or not fleet.mobil.any():
            return {}
        per_user = {fleet.specs[i].name: 0 for i in np.flatnonzero(fleet.mobil)}
        for _, i, _, _ in fleet.lane_changes:
            per_user[fleet.specs[i].name] += 1
        return {
            "lane_changes": [
                (fleet.specs[i].name, round(t, 6), start, end) for t, i, start, end in fleet.lane_changes
            ],
            "lane_changes_per_user": per_user,
        }


def default_metrics(config: RunConfig) -> tuple[Metric, ...]:
    """The built-in metrics (every metric field of ``RunSummary``)."""
    return (
        RiskLog(),
        RiskByType(),
        FirstSeen(),
        ValidityLevels(),
        PlannedCollisionProbability(),
        MinDistance(config.distance_interval),
        TimeToCollision(),
        HarmPerGroup(),
        TrackingError(),
        Progress(),
        RuleViolations(),
        ScriptEvents(),
        LaneChanges(),
    )
