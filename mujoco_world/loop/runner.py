"""Closed loop: the planner drives the ego through the world; every impact is measured.

``run_scenario`` replans at ``RunConfig.replan_rate`` from observed states, tracks the
chosen trajectory with the ego's controller between cycles and measures every
collision. The loop itself is short (``ClosedLoop._step``); around it:

* stop rules (``loop.rules``): one object per way a run ends (diverged, crash at
  rest, post-crash time, goal, and the time limit, always last);
* metrics (``loop.metrics``): one object per quantity the summary reports;
* observers (``loop.observers``): recording, live plots; they watch, never change;
* the exception policy (``ClosedLoop._failure``): a planner exception, a failing
  simulation or a failing impact measurement ends the run as ``failed`` with the
  reason, and what was measured until then is kept; Ctrl-C closes the run as failed
  (observers see ``on_end``) and then raises ``RunInterrupted``;
* summary building (``summary.build_summary``), with the scenario's ``[expect]``
  items checked (``loop.expectations``).

Adding a stop rule or a metric is a new object passed to ``run_scenario``; the loop
does not change.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from ethical_planner.config import PlannerConfig
from ethical_planner.harm import DEFAULT_MODEL, DEFAULT_PEDESTRIAN_MODEL
from ethical_planner.prediction import Predictor
from ethical_planner.road_users import Shape
from mujoco_world.agents.ego_planner import (
    EgoPlanner,
    EgoSetup,
    Observation,
    Plan,
    PlannerSpec,
    make_ego_planner,
)
from mujoco_world.evaluation.compare import compare_impact
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.expectations import check_expectations
from mujoco_world.loop.metrics import Metric, default_metrics
from mujoco_world.loop.observers import ObserverGroup, RunObserver
from mujoco_world.loop.rules import (
    CrashCriterion,
    EgoContact,
    Stop,
    StopRule,
    TimeLimit,
    check_rules,
    default_rules,
    final_outcome,
)
from mujoco_world.loop.state import RunState
from mujoco_world.loop.summary import BodyRecord, RunSummary, build_summary
from mujoco_world.loop.world import World
from mujoco_world.physics.control import TrajectoryReference
from mujoco_world.physics.impact import ImpactMeasurement
from mujoco_world.scenario.spec import Scenario

__all__ = [
    "ClosedLoop",
    "ObserverGroup",
    "RunConfig",
    "RunInterrupted",
    "RunObserver",
    "RunSummary",
    "closed_loop",
    "run_scenario",
]


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C during a run: the run was closed as failed (observers saw ``on_end``).

    Attributes:
        summary: the failed run's summary.
    """

    def __init__(self, summary: RunSummary) -> None:
        super().__init__(summary.reason)
        self.summary = summary


#: ``advance`` reached its time without a stop.
_NOT_STOPPED = Stop("timeout", "not stopped")


class _PlannerError(Exception):
    """Carries an exception raised inside the planner."""

    def __init__(self, error: Exception) -> None:
        super().__init__(str(error))
        self.error = error


def _plan_reference(plan: Plan, t0: float) -> TrajectoryReference:
    traj = plan.trajectory
    return TrajectoryReference(t0, traj.t, traj.x, traj.y, traj.yaw, traj.v, traj.a, traj.kappa)


def _bodies(world: World) -> tuple[BodyRecord, ...]:
    scene = world.scene
    kinds = (None, *(u.kind for u in world.scenario.road_users))
    behaviours = (None, *(u.behaviour.kind.value for u in world.scenario.road_users))
    return tuple(
        BodyRecord(i, b.name, b.type, b.length, b.width, float(scene.masses[i]), kinds[i], behaviours[i])
        for i, b in enumerate(scene.bodies)
    )


class ClosedLoop:
    """One run: the world, the ego's planner, the rules that end it, the metrics it keeps.

    Args:
        scenario: what to simulate.
        planner: the ego's planner (see ``agents.ego_planner.make_ego_planner``).
        seed: seeds the observation noise.
        config: loop settings.
        observer: hooks (recording, live plots...).
        rules: stop rules, checked in order; ``TimeLimit`` is appended.
        metrics: what the summary reports.
        crash: which contacts make a crash.
        predictor: the planner's predictor (None: the configuration's ``prediction.model``).

    Raises:
        ValueError: an unknown planner, a scenario that cannot be built, or a rule
            without a valid interval.
    """

    def __init__(
        self,
        scenario: Scenario,
        planner: PlannerSpec,
        seed: int,
        config: RunConfig,
        observer: RunObserver,
        rules: Sequence[StopRule],
        metrics: Sequence[Metric],
        crash: CrashCriterion,
        predictor: Predictor | None = None,
    ) -> None:
        self.wall_start = time.perf_counter()
        self.config, self.observer, self.crash = config, observer, crash
        world = World(
            scenario,
            config.control,
            1.0 / config.behaviour_rate,
            config.timestep,
            config.control_interval,
            post_crash=config.post_crash,
        )
        ego = scenario.ego
        shape = Shape(ego.length, ego.width)
        setup = EgoSetup(world.environment(), shape, ego.mass, world.goal_s, predictor, config.predictor)
        self.planner = make_ego_planner(planner, setup)
        self.harm_models = getattr(self.planner, "harm_models", (DEFAULT_MODEL, DEFAULT_PEDESTRIAN_MODEL))
        self.planar_model = getattr(self.planner, "planar_model", (None, None))
        self.world = world
        self.rng = np.random.default_rng(seed)
        own = getattr(self.planner, "config", None)
        own = own if isinstance(own, PlannerConfig) else PlannerConfig()
        self.run = RunState(world, scenario, str(self.planner.name), int(seed), planner_config=own)
        self.rules = (*rules, TimeLimit(config.stall))
        self.metrics = tuple(metrics)
        self.timing = {"planning": 0.0, "measurement": 0.0}
        self.steps_per_cycle = max(int(round(1.0 / (config.replan_rate * world.scene.dt))), 1)
        self.observer_interval = 1

    # ------------------------------------------------------------------ the run

    def execute(self) -> RunSummary:
        """Run to the end and return the summary (see ``run_scenario``)."""
        self.start()
        return self.resume()

    def start(self) -> None:
        """Before the first step: observers, rules and metrics start (``execute`` does it)."""
        self._start()

    def advance(self, until: float) -> Stop | None:
        """Step until the simulated time reaches ``until`` [s]; the stop verdict if the run ended first.

        After ``start``; ``resume`` then runs on to the end. A run advanced to a
        planning cycle's time and then forked (``fork``) plans that cycle with the
        fork's planner.
        """
        target = int(round(until / self.world.scene.dt))

        def steps() -> Stop:
            while self.run.step < target:
                stop = self._step()
                if stop is not None:
                    return stop
            return _NOT_STOPPED

        stop, interrupted = self._guarded(steps)
        if interrupted:
            self.finish(stop, interrupted=True)
        return None if stop is _NOT_STOPPED else stop

    def resume(self) -> RunSummary:
        """Run on from the current state to the end and return the summary."""
        stop, interrupted = self._guarded(self._loop)
        return self.finish(stop, interrupted)

    def finish(self, stop: Stop, interrupted: bool = False) -> RunSummary:
        """Close the run with ``stop``: open contact episodes measured, the summary built.

        Raises:
            RunInterrupted: ``interrupted`` (Ctrl-C), after the observers saw the end.
        """
        stop = self._close(stop)
        summary = self._summary(stop)
        self.observer.on_end(summary)
        if interrupted:
            raise RunInterrupted(summary)
        return summary

    def fork(self, planner: EgoPlanner | None, rules: Sequence[StopRule] = ()) -> ClosedLoop:
        """An independent copy of this run in its current state, driven by ``planner`` from now on.

        Everything that evolves is copied (world, run state, metrics, rules, the noise
        generator; ``World.__deepcopy__``), so the copy continues exactly as the run
        would with the new planner: forking with a planner that returns the same plans
        gives the run's own summary bit for bit (tested). The copy has no observers
        (nothing is recorded twice).

        Args:
            planner: the planner of the copy (None: none yet; set ``planner`` before
                stepping it, or fork the copy again).
            rules: stop rules checked before the run's own (``TimeLimit`` stays last).
        """
        memo: dict[int, object] = {id(self.observer): RunObserver()}
        if self.planner is not None:
            memo[id(self.planner)] = None
        new = copy.deepcopy(self, memo)
        new.planner = planner
        new.observer_interval = 1
        for rule in rules:
            rule.start(new.run)
        check_rules(rules)
        new.rules = (*rules, *new.rules)
        return new

    def _start(self) -> None:
        run = self.run
        self.observer.on_start(self.world, run.scenario, run.planner, run.seed)
        self.observer_interval = max(int(self.observer.step_interval), 1)
        for rule in self.rules:
            rule.start(run)
        check_rules(self.rules)
        for metric in self.metrics:
            metric.start(run)
        self.sampled = tuple(m for m in self.metrics if getattr(m, "interval", 0) > 0)

    def _loop(self) -> Stop:
        while True:
            stop = self._step()
            if stop is not None:
                return stop

    def _step(self) -> Stop | None:
        """One physics step (and a planning cycle when due); the stop verdict, if any."""
        run, world = self.run, self.world
        # Plans drive the ego while it is on them (``World.ego_on_plan``: before its first
        # contact, and after it under the ``continue`` policy, replanned at once from
        # the measured state when the ego comes out of an impact).
        if world.ego_on_plan and (run.step % self.steps_per_cycle == 0 or world.ego_left_impact):
            self._plan()
        ended = world.step()
        run.step += 1
        if ended:
            self._measure(ended)
        if run.crash_time is None and self.crash.touched(world):
            run.crash_time = world.time
        if run.step % self.observer_interval == 0:
            self.observer.on_step(world, world.time)
        stop = self._check_rules()
        if stop is None or stop.trusted:
            self._sample_metrics()
        return stop

    def _plan(self) -> None:
        clock = time.perf_counter()
        world, run = self.world, self.run
        ego_state, users = world.observe(self.rng, self.config.noise)
        try:
            plan = self.planner.plan(Observation(world.time, ego_state, tuple(users)))
            reference = _plan_reference(plan, world.time)
        except Exception as error:
            raise _PlannerError(error) from error
        world.set_ego_plan(reference)
        self.timing["planning"] += time.perf_counter() - clock
        run.cycles += 1
        for metric in self.metrics:
            metric.on_cycle(run, plan)
        self.observer.on_cycle(plan, world.time)

    def _measure(self, measurements: Sequence[ImpactMeasurement]) -> None:
        clock = time.perf_counter()
        run = self.run
        for m in measurements:
            record = compare_impact(m, *self.harm_models, *self.planar_model)
            run.collisions.append(record)
            if run.crash_time is None and self.crash.counts(record):
                run.crash_time = m.time
            for metric in self.metrics:
                metric.on_impact(run, record)
            self.observer.on_impact(record)
        self.timing["measurement"] += time.perf_counter() - clock

    def _check_rules(self) -> Stop | None:
        run = self.run
        for rule in self.rules:
            if run.step % rule.interval == 0:
                stop = rule.check(run)
                if stop is not None:
                    return stop
        return None

    def _sample_metrics(self) -> None:
        step = self.run.step
        due = [m for m in self.sampled if step % m.interval == 0]
        if due:
            clock = time.perf_counter()
            for metric in due:
                metric.sample(self.run)
            self.timing["measurement"] += time.perf_counter() - clock

    # ------------------------------------------------------------------ failures and the end

    def _failure(self, error: BaseException, stage: str) -> Stop:
        """The exception policy: what an exception in ``stage`` makes of the run."""
        at = f" at t = {self.world.time:.3f} s"
        if isinstance(error, KeyboardInterrupt):
            return Stop("failed", f"interrupted{at}", trusted=False)
        if isinstance(error, _PlannerError):
            error, stage = error.error, "planner"
        if stage == "impact measurement":
            at = ""
        return Stop("failed", f"{stage} raised {type(error).__name__}{at}: {error}", trusted=False)

    def _guarded(self, body: Callable[[], Stop]) -> tuple[Stop, bool]:
        """Run ``body``; an exception becomes a failed stop. Returns (stop, interrupted)."""
        try:
            return body(), False
        except KeyboardInterrupt as interrupt:
            return self._failure(interrupt, "simulation"), True
        except Exception as error:  # noqa: BLE001 - a failed run is data, the batch goes on
            return self._failure(error, "simulation"), False

    def _close(self, stop: Stop) -> Stop:
        """Measure the contact episodes still open, then settle the outcome."""
        try:
            self._measure(self.world.finish(complete=stop.at_rest))
        except Exception as error:  # noqa: BLE001
            return self._failure(error, "impact measurement")
        return final_outcome(stop, self.run.collisions, self.crash)

    def _summary(self, stop: Stop) -> RunSummary:
        run, world = self.run, self.world
        values: dict[str, object] = {}
        for metric in self.metrics:
            values.update(metric.values(run))
        wall = time.perf_counter() - self.wall_start
        timings = {
            **self.timing,
            "total": wall,
            # The world's step time split into physics proper, control/behaviours and measurement.
            "physics": world.timing["mj_step"],
            "control": world.timing["control"],
            "measurement": self.timing["measurement"] + world.timing["measurement"],
            "real_time_factor": world.time / wall if wall > 0 else float("inf"),
        }
        summary = build_summary(
            scenario=run.scenario.name,
            planner=run.planner,
            seed=run.seed,
            outcome=stop.outcome,
            reason=stop.reason,
            duration=round(world.time, 6),
            steps=run.step,
            cycles=run.cycles,
            bodies=_bodies(world),
            collisions=run.collisions,
            values=values,
            timings=timings,
            notes=(*run.scenario.notes, *world.notes),
            post_crash=world.post_crash.value,
        )
        return replace(summary, expectations=check_expectations(run.scenario.expect, summary))


def closed_loop(
    scenario: Scenario,
    planner: PlannerSpec = "ethical",
    seed: int = 0,
    config: RunConfig | None = None,
    observer: RunObserver | None = None,
    predictor: Predictor | None = None,
    *,
    rules: Sequence[StopRule] | None = None,
    metrics: Sequence[Metric] | None = None,
    crash: CrashCriterion | None = None,
) -> ClosedLoop:
    """The closed loop of one run, not started: ``run_scenario`` with the defaults filled in.

    Step it yourself (``start``, ``advance``, ``fork``, ``resume``) to branch a run;
    the arguments are those of ``run_scenario``.
    """
    config = config or RunConfig()
    return ClosedLoop(
        scenario,
        planner,
        seed,
        config,
        observer or RunObserver(),
        default_rules(config) if rules is None else rules,
        default_metrics(config) if metrics is None else metrics,
        crash or EgoContact(),
        predictor,
    )


def run_scenario(
    scenario: Scenario,
    planner: PlannerSpec = "ethical",
    seed: int = 0,
    config: RunConfig | None = None,
    observer: RunObserver | None = None,
    predictor: Predictor | None = None,
    *,
    rules: Sequence[StopRule] | None = None,
    metrics: Sequence[Metric] | None = None,
    crash: CrashCriterion | None = None,
) -> RunSummary:
    """Run one scenario in closed loop.

    Args:
        scenario: what to simulate.
        planner: the ego's planner: a name in ``agents.EGO_PLANNERS`` (every preset
            "ethical", "selfish", "standard", "ethical_responsible", and the scripted
            "keep_lane", "emergency_brake"), a planner configuration (``PlannerConfig``
            or a ``.toml`` file) for the ethical planner, an ``EgoPlanner``, or a
            factory taking the ``EgoSetup`` (e.g. your planner's class).
        seed: seeds the observation noise (numpy Generator); the physics itself is
            deterministic.
        config: loop settings.
        observer: hooks (recording, live plots...).
        predictor: the planner's predictor (any ``Predictor``); None uses the one
            named by the planner configuration's ``prediction.model``.
        rules: stop rules in the order they are checked (default
            ``rules.default_rules(config)``); ``TimeLimit`` is always added last.
        metrics: what the summary reports (default ``metrics.default_metrics(config)``).
        crash: which contacts make a crash (default ``rules.EgoContact()``: only
            ego-involved collisions; third-party ones are measured, the run goes on).

    Returns:
        The run summary; never raises for planner errors or diverging physics
        (outcome ``failed``).

    Raises:
        ValueError: an unknown planner or a scenario that cannot be built.
        RunInterrupted: Ctrl-C (a ``KeyboardInterrupt``), after the run was closed as failed.
    """
    loop = closed_loop(
        scenario, planner, seed, config, observer, predictor, rules=rules, metrics=metrics, crash=crash
    )
    return loop.execute()
