"""Closed loop: the planner drives the ego through the world; every impact is measured.

``run_scenario`` replans at ``RunConfig.replan_rate`` from observed states, tracks the
chosen trajectory with the ego's controller between cycles, measures every collision
and ends the run at the goal, at the time limit, or after a crash once the bodies
that collided have come to rest. A diverging simulation or a planner exception ends
the run as ``failed`` with the reason; what was measured until then is kept.

Attach a ``RunObserver`` (for example a recorder) to see every cycle, step and impact
without touching the loop.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ethical_planner.config import PlannerConfig, preset
from ethical_planner.planner import Decision, Planner
from ethical_planner.prediction import Predictor
from ethical_planner.records import to_plain
from ethical_planner.road_users import VULNERABLE_TYPES, Shape
from ethical_planner.validation import check, check_positive
from mujoco_world.evaluation.compare import ImpactRecord, compare_impact
from mujoco_world.loop.world import ObservationNoise, World
from mujoco_world.physics.control import ControlConfig, TrajectoryReference
from mujoco_world.scenario.spec import Scenario

#: Run outcomes.
OUTCOMES = ("goal", "timeout", "crash", "failed")
#: Risk groups of the paper's Fig. 5.
GROUPS = ("ego", "third_party", "vulnerable")
#: Number of highest risk values kept per group (paper Fig. 5 uses 100).
TOP_RISKS = 100


@dataclass(frozen=True, slots=True)
class RunConfig:
    """Settings of the closed loop.

    Attributes:
        replan_rate: planning cycles per second [Hz].
        behaviour_rate: road-user decisions per second [Hz].
        timestep: physics step [s].
        noise: observation noise.
        max_penetration: geom overlap beyond which the run fails as diverged [m].
        rest_speed: a body below this speed is at rest [m/s].
        settle_time: the run ends this long after every body involved in a collision
            has come to rest (secondary collisions may still follow) [s].
        post_crash_time: longest time after the first collision before ending [s].
        distance_interval: physics steps between minimum-distance checks.
        control_interval: physics steps between controller updates (10: 100 Hz).
        control: tracking controller.
        predictor: name of a registered predictor that replaces the planner
            configuration's ``[prediction] model`` (None keeps it).
    """

    replan_rate: float = 10.0
    behaviour_rate: float = 20.0
    timestep: float = 0.001
    noise: ObservationNoise = field(default_factory=ObservationNoise)
    max_penetration: float = 1.5
    rest_speed: float = 0.1
    settle_time: float = 2.0
    post_crash_time: float = 10.0
    distance_interval: int = 10
    control_interval: int = 10
    control: ControlConfig = field(default_factory=ControlConfig)
    predictor: str | None = None

    def __post_init__(self) -> None:
        check_positive(
            "run",
            replan_rate=self.replan_rate,
            behaviour_rate=self.behaviour_rate,
            timestep=self.timestep,
            max_penetration=self.max_penetration,
            rest_speed=self.rest_speed,
            settle_time=self.settle_time,
            post_crash_time=self.post_crash_time,
        )
        for name in ("distance_interval", "control_interval"):
            value = getattr(self, name)
            check(
                isinstance(value, int) and not isinstance(value, bool) and value >= 1,
                f"run.{name} must be an integer >= 1, got {value!r}",
            )
        check(
            self.replan_rate * self.timestep <= 1.0,
            "run.replan_rate must not exceed one cycle per physics step",
        )


class RunObserver:
    """Hooks of the closed loop; subclass and override what you need (all no-ops here).

    The loop calls ``on_start`` once, ``on_cycle`` after every planning cycle,
    ``on_step`` every ``step_interval`` physics steps, ``on_impact`` when a collision
    episode ends and ``on_end`` with the summary. Observers must not change the world.

    Attributes:
        step_interval: physics steps between ``on_step`` calls (e.g. 20 for 50 Hz).
    """

    step_interval: int = 1

    def on_start(self, world: World, scenario: Scenario, planner: str, seed: int) -> None:
        """Called before the first step."""

    def on_cycle(self, decision: Decision, time: float) -> None:
        """Called after each planning cycle at simulation ``time`` [s]."""

    def on_step(self, world: World, time: float) -> None:
        """Called after every ``step_interval``-th physics step; ``time`` after the step [s]."""

    def on_impact(self, record: ImpactRecord) -> None:
        """Called when a collision episode has been measured."""

    def on_end(self, summary: RunSummary) -> None:
        """Called with the summary when the run is over."""


class ObserverGroup(RunObserver):
    """Forwards every hook to several observers (``step_interval`` 1, filtered per member)."""

    def __init__(self, observers: Sequence[RunObserver]) -> None:
        self.observers = tuple(observers)
        self._steps = 0

    def on_start(self, world: World, scenario: Scenario, planner: str, seed: int) -> None:
        """Forward ``on_start``."""
        for o in self.observers:
            o.on_start(world, scenario, planner, seed)

    def on_cycle(self, decision: Decision, time: float) -> None:
        """Forward ``on_cycle``."""
        for o in self.observers:
            o.on_cycle(decision, time)

    def on_step(self, world: World, time: float) -> None:
        """Forward ``on_step`` to members whose interval is due."""
        self._steps += 1
        for o in self.observers:
            if self._steps % max(int(o.step_interval), 1) == 0:
                o.on_step(world, time)

    def on_impact(self, record: ImpactRecord) -> None:
        """Forward ``on_impact``."""
        for o in self.observers:
            o.on_impact(record)

    def on_end(self, summary: RunSummary) -> None:
        """Forward ``on_end``."""
        for o in self.observers:
            o.on_end(summary)


@dataclass(frozen=True, slots=True)
class RunSummary:
    """Result of one closed-loop run.

    Attributes:
        scenario: scenario name. planner: preset name. seed: run seed.
        outcome: goal, timeout, crash or failed. reason: why the run ended.
        duration: simulated time [s]. steps: physics steps. cycles: planning cycles.
        collisions: every measured collision with the model's prediction beside it.
        ego_collided: the ego took part in a collision.
        max_risk: highest risk per group (ego, third_party, vulnerable) along the
            executed plans. top_risks: up to 100 highest risk values per group.
        harm: summed measured harm per group over all collisions.
        min_distance: smallest ego-to-road-user distance [m] (negative: overlap).
        min_distance_vulnerable: the same to vulnerable road users [m].
        tracking_rms, tracking_max: ego tracking error before any contact [m].
        progress: ego arc length along its route at the end [m].
        levels: planning cycles per chosen validity level.
        timings: wall-clock seconds per part (physics, planning, measurement,
            behaviour, total) and the real-time factor.
    """

    scenario: str
    planner: str
    seed: int
    outcome: str
    reason: str
    duration: float
    steps: int
    cycles: int
    collisions: tuple[ImpactRecord, ...]
    ego_collided: bool
    max_risk: dict[str, float]
    top_risks: dict[str, tuple[float, ...]]
    harm: dict[str, float]
    min_distance: float
    min_distance_vulnerable: float
    tracking_rms: float
    tracking_max: float
    progress: float
    levels: dict[str, int]
    timings: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict (the content of ``summary.json``)."""
        out = {f: to_plain(getattr(self, f)) for f in self.__slots__ if f != "collisions"}
        out["collisions"] = [c.to_dict() for c in self.collisions]
        return out

    def comparable_dict(self) -> dict[str, Any]:
        """``to_dict`` without wall-clock timings (for determinism checks)."""
        out = self.to_dict()
        out.pop("timings")
        return out


class _PlannerError(Exception):
    """Carries an exception raised inside ``Planner.plan``."""

    def __init__(self, error: Exception) -> None:
        super().__init__(str(error))
        self.error = error


def _plan_reference(decision: Decision, t0: float) -> TrajectoryReference:
    traj = decision.trajectory
    return TrajectoryReference(t0, traj.t, traj.x, traj.y, traj.yaw, traj.v, traj.a, traj.kappa)


class _RiskLog:
    """Highest risk values per group along the executed plans."""

    def __init__(self) -> None:
        self.top: dict[str, list[float]] = {g: [] for g in GROUPS}

    def _push(self, group: str, values: np.ndarray) -> None:
        heap = self.top[group]
        for value in values:
            if len(heap) < TOP_RISKS:
                heapq.heappush(heap, float(value))
            elif value > heap[0]:
                heapq.heapreplace(heap, float(value))

    def add(self, decision: Decision) -> None:
        self._push("ego", np.array([decision.ego_combined_risk]))
        if decision.road_users:
            risk = np.array([u.risk for u in decision.road_users])
            vru = np.array([u.type in VULNERABLE_TYPES for u in decision.road_users])
            self._push("vulnerable", risk[vru])
            self._push("third_party", risk[~vru])

    def maxima(self) -> dict[str, float]:
        return {g: (max(v) if v else 0.0) for g, v in self.top.items()}

    def tops(self) -> dict[str, tuple[float, ...]]:
        return {g: tuple(sorted(v, reverse=True)) for g, v in self.top.items()}


def run_scenario(
    scenario: Scenario,
    planner: str | PlannerConfig = "ethical",
    seed: int = 0,
    config: RunConfig | None = None,
    observer: RunObserver | None = None,
    predictor: Predictor | None = None,
) -> RunSummary:
    """Run one scenario in closed loop.

    Args:
        scenario: what to simulate.
        planner: preset name ("ethical", "selfish", "standard") or a configuration.
        seed: seeds the observation noise (numpy Generator); the physics itself is
            deterministic.
        config: loop settings.
        observer: hooks (recording, live plots...).
        predictor: the planner's predictor (any ``Predictor``); None uses the one
            named by the planner configuration's ``prediction.model``.

    Returns:
        The run summary; never raises for planner errors or diverging physics
        (outcome ``failed``).

    Raises:
        ValueError: an unknown preset or a scenario that cannot be built.
    """
    config = config or RunConfig()
    observer = observer or RunObserver()
    planner_config = preset(planner) if isinstance(planner, str) else planner
    if config.predictor is not None:
        prediction = dataclasses.replace(planner_config.prediction, model=config.predictor)
        planner_config = dataclasses.replace(planner_config, prediction=prediction)
    wall_start = time.perf_counter()
    world = World(
        scenario, config.control, 1.0 / config.behaviour_rate, config.timestep, config.control_interval
    )
    ego = scenario.ego
    planner_obj = Planner(
        planner_config, world.environment(), Shape(ego.length, ego.width), ego.mass, predictor=predictor
    )
    rng = np.random.default_rng(seed)
    risk_model = planner_config.risk
    steps_per_cycle = max(int(round(1.0 / (config.replan_rate * world.scene.dt))), 1)
    max_steps = int(round(scenario.duration / world.scene.dt))
    vulnerable = np.array([t in VULNERABLE_TYPES for t in world.types])
    risk_log = _RiskLog()
    collisions: list[ImpactRecord] = []
    levels: dict[str, int] = {}
    timing = {"planning": 0.0, "measurement": 0.0}
    min_dist = math.inf
    min_dist_vru = math.inf
    outcome, reason = "", ""
    first_crash: float | None = None
    rested = False
    rest_since: float | None = None
    cycles = 0
    step = 0
    observer.on_start(world, scenario, planner_config.name, seed)
    interval = max(int(observer.step_interval), 1)
    # The goal test projects onto the route (a k-d tree query): 10 times per second.
    goal_interval = config.distance_interval * max(
        1, int(round(0.1 / (config.distance_interval * config.timestep)))
    )
    clock = time.perf_counter

    def record(measurements: list) -> None:
        nonlocal first_crash
        t0 = clock()
        for m in measurements:
            rec = compare_impact(m, risk_model.harm_model, risk_model.pedestrian_model)
            collisions.append(rec)
            if first_crash is None:
                first_crash = m.time
            observer.on_impact(rec)
        timing["measurement"] += clock() - t0

    interrupted = False
    try:
        while step < max_steps:
            if step % steps_per_cycle == 0 and not world.crashed[0]:
                t0 = clock()
                ego_state, users = world.observe(rng, config.noise)
                try:
                    decision = planner_obj.plan(ego_state, users)
                except Exception as error:  # noqa: BLE001
                    raise _PlannerError(error) from error
                world.set_ego_plan(_plan_reference(decision, world.time))
                timing["planning"] += clock() - t0
                cycles += 1
                risk_log.add(decision)
                levels[str(decision.level)] = levels.get(str(decision.level), 0) + 1
                observer.on_cycle(decision, world.time)
            done = world.step()
            step += 1
            if done:
                record(done)
            if world.recorder.touched.any() and first_crash is None:
                first_crash = world.time
            if step % interval == 0:
                observer.on_step(world, world.time)
            if step % config.distance_interval == 0:
                why = world.diverged(config.max_penetration)
                if why is not None:
                    outcome, reason = "failed", f"simulation diverged at t = {world.time:.3f} s: {why}"
                    break
                if world.n > 1 and not world.crashed[0]:
                    t0 = clock()
                    dist = world.ego_distances()
                    min_dist = min(min_dist, float(dist.min()))
                    if vulnerable[1:].any():
                        min_dist_vru = min(min_dist_vru, float(dist[vulnerable[1:]].min()))
                    timing["measurement"] += clock() - t0
                if first_crash is not None:
                    crashed = world.crashed
                    resting = not world.recorder.has_open_episodes and bool(
                        (world.scene.speeds()[crashed] < config.rest_speed).all()
                    )
                    if not resting:
                        rest_since = None
                    elif rest_since is None:
                        rest_since = world.time
                    rested = rest_since is not None and world.time - rest_since >= config.settle_time
                    if rested or world.time - first_crash >= config.post_crash_time:
                        outcome = "crash"
                        reason = (
                            "collision; the bodies involved have come to rest"
                            if rested
                            else f"collision; stopped {config.post_crash_time} s after it"
                        )
                        break
                elif step % goal_interval == 0 and world.ego_progress() >= world.goal_s:
                    outcome, reason = "goal", f"ego reached s = {world.goal_s:.1f} m on its route"
                    break
        else:
            outcome = "crash" if first_crash is not None else "timeout"
            reason = f"time limit of {scenario.duration} s reached"
    except KeyboardInterrupt:
        # Ctrl-C: close the run as failed (recording, index row), then stop the caller.
        interrupted = True
        outcome, reason = "failed", f"interrupted at t = {world.time:.3f} s"
    except _PlannerError as wrapped:
        error = wrapped.error
        outcome = "failed"
        reason = f"planner raised {type(error).__name__} at t = {world.time:.3f} s: {error}"
    except Exception as error:  # noqa: BLE001 - a failed run is data, the batch goes on
        outcome = "failed"
        reason = f"simulation raised {type(error).__name__} at t = {world.time:.3f} s: {error}"
    try:
        record(world.finish(complete=rested))
    except Exception as error:  # noqa: BLE001
        outcome, reason = "failed", f"impact measurement raised {type(error).__name__}: {error}"
    if collisions and outcome in ("goal", "timeout"):
        outcome = "crash"
    harm = {g: 0.0 for g in GROUPS}
    for rec in collisions:
        for body in (rec.a, rec.b):
            if body.group in harm and math.isfinite(body.harm_measured):
                harm[body.group] += body.harm_measured
    rms, worst = world.tracking_error()
    wall = time.perf_counter() - wall_start
    timing["total"] = wall
    # Split the world's step time into physics proper, control/behaviours and measurement.
    timing["physics"] = world.timing["mj_step"]
    timing["control"] = world.timing["control"]
    timing["measurement"] += world.timing["measurement"]
    timing["real_time_factor"] = world.time / wall if wall > 0 else math.inf
    summary = RunSummary(
        scenario=scenario.name,
        planner=planner_config.name,
        seed=int(seed),
        outcome=outcome,
        reason=reason,
        duration=round(world.time, 6),
        steps=step,
        cycles=cycles,
        collisions=tuple(collisions),
        ego_collided=any(c.involves_ego for c in collisions),
        max_risk=risk_log.maxima(),
        top_risks=risk_log.tops(),
        harm=harm,
        min_distance=min_dist if math.isfinite(min_dist) else math.nan,
        min_distance_vulnerable=min_dist_vru if math.isfinite(min_dist_vru) else math.nan,
        tracking_rms=rms,
        tracking_max=worst,
        progress=world.ego_progress(),
        levels=levels,
        timings=timing,
    )
    observer.on_end(summary)
    if interrupted:
        raise KeyboardInterrupt(reason)
    return summary
