"""Stop rules of the closed loop: each rule is one small object that may end a run.

The loop checks its rules in order after every physics step whose index is a
multiple of the rule's ``interval``; the first rule that returns a ``Stop`` ends the
run. ``default_rules`` gives the built-in ones in their order:

1. ``Diverged``: the simulation cannot be trusted (NaN state, MuJoCo's bad
   acceleration warning, a penetration beyond the bound): ``failed``.
2. ``CrashAtRest``: after a crash, every body that touched something has been at
   rest for ``settle_time`` with no open contact episode: ``crash`` (not while the
   ego drives on under the ``continue`` post-crash policy: an ego that waits at a
   red light after a contact will drive on).
3. ``PostCrashTime``: ``post_crash_time`` after the crash: ``crash``.
4. ``Goal``: before any crash, the ego passed its goal on its route: ``goal``.
5. ``LeftMap``: before any crash, the ego's centre left a mapped road (``road.kind =
   "map"``, e.g. an imported CommonRoad map) beyond the map's end along its route:
   ``left_map``. Past its last lanelet the ego's path runs on straight (the planner's
   horizon needs a path) over ground the map does not describe: the run ends there, as
   a recorded road user leaves the world where its recording ends. Catalog roads do not
   end before the ego's goal (``ego.goal_s`` lies on the route), so the rule is off there.

``TimeLimit`` (the scenario's duration: ``crash`` after a crash; else ``timeout``,
``stopped_safely`` or ``no_progress`` as ``loop.progress`` tells a slow ego, one that
waits with a reason and one that stalls apart) is always appended last by the
runner, so every run ends. A new rule is a new object
with ``interval``, ``start`` and ``check`` (see ``StopRule``), passed with the
defaults: ``run_scenario(..., rules=(*default_rules(config), MyRule()))``.

Which contacts make a crash is one object too (``CrashCriterion``): ``EgoContact``
(only contacts of the ego, the default: a "crash" is an ego-involved collision) or
``AnyContact`` (any two bodies touching). Under ``EgoContact`` a collision between two
other road users (third party) is measured and reported (``RunSummary.
third_party_collisions``, ``harm_third_party``) but does not end the run: the ego
still has to reach its goal.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import shapely

from mujoco_world.evaluation.compare import ImpactRecord
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.progress import StallConfig, blocked_way, waiting_at_red
from mujoco_world.loop.state import RunState
from mujoco_world.loop.world import World
from mujoco_world.scenario.road import map_end
from mujoco_world.scenario.spec import RoadKind

#: Outcomes that say the run ended without a crash: a counted collision measured when
#: the run is closed (an episode still open at the end) turns them into ``crash``.
NO_CRASH_OUTCOMES = frozenset({"goal", "timeout", "stopped_safely", "no_progress", "left_map"})


@dataclass(frozen=True, slots=True)
class Stop:
    """A rule's verdict that the run is over.

    Attributes:
        outcome: the run's outcome (``summary.OUTCOMES``).
        reason: why, in words a person reads.
        trusted: the last state is valid (metrics still measure it); False for a
            diverged simulation or a failure.
        at_rest: the bodies in contact have come to rest, so open contact episodes
            are complete.
    """

    outcome: str
    reason: str
    trusted: bool = True
    at_rest: bool = False


@runtime_checkable
class StopRule(Protocol):
    """A condition that ends a run.

    Attributes:
        interval: physics steps between checks (set at the latest in ``start``).
    """

    interval: int

    def start(self, run: RunState) -> None:
        """Reset before the first step (a rule object may serve several runs)."""

    def check(self, run: RunState) -> Stop | None:
        """The verdict after the current step, or None to go on."""


@runtime_checkable
class CrashCriterion(Protocol):
    """Which contacts make a run a crash."""

    def touched(self, world: World) -> bool:
        """True once a contact that counts has begun (checked after every step)."""

    def counts(self, record: ImpactRecord) -> bool:
        """True if a measured collision counts as a crash."""


class AnyContact(CrashCriterion):
    """Any two bodies touching (or a body and a wall) make a crash (not the default)."""

    def touched(self, world: World) -> bool:
        """Any body has touched something."""
        return bool(world.recorder.touched.any())

    def counts(self, record: ImpactRecord) -> bool:
        """Every collision counts."""
        return True


class EgoContact(CrashCriterion):
    """Only contacts of the ego make a crash (the default); others' collisions are still measured."""

    def touched(self, world: World) -> bool:
        """The ego (entity 0) has touched something."""
        return bool(world.recorder.touched[0])

    def counts(self, record: ImpactRecord) -> bool:
        """Collisions the ego took part in."""
        return record.involves_ego


class Diverged(StopRule):
    """The simulation cannot be trusted any more: ``failed`` (``World.diverged``).

    Args:
        max_penetration: largest acceptable geom overlap [m].
        interval: physics steps between checks.
    """

    def __init__(self, max_penetration: float, interval: int) -> None:
        self.max_penetration = max_penetration
        self.interval = interval

    def start(self, run: RunState) -> None:
        """Nothing to reset."""

    def check(self, run: RunState) -> Stop | None:
        """``failed`` with the reason MuJoCo or the penetration bound gives."""
        why = run.world.diverged(self.max_penetration)
        if why is None:
            return None
        return Stop("failed", f"simulation diverged at t = {run.time:.3f} s: {why}", trusted=False)


class CrashAtRest(StopRule):
    """After a crash, the bodies that touched have been at rest long enough: ``crash``.

    Not while the ego keeps following its plans after its contact (``World.ego_on_plan``
    under the ``continue`` post-crash policy): resting, it may be waiting (at a red
    light, for a pedestrian) and drive on, so ``PostCrashTime`` or the time limit ends
    such a run.

    Args:
        rest_speed: a body below this speed is at rest [m/s].
        settle_time: how long they must rest, with no contact episode open [s]
            (secondary collisions may still follow meanwhile).
        interval: physics steps between checks.
    """

    def __init__(self, rest_speed: float, settle_time: float, interval: int) -> None:
        self.rest_speed = rest_speed
        self.settle_time = settle_time
        self.interval = interval
        self._since: float | None = None

    def start(self, run: RunState) -> None:
        """Forget an earlier rest."""
        self._since = None

    def check(self, run: RunState) -> Stop | None:
        """``crash`` once the crashed bodies have rested ``settle_time``."""
        world = run.world
        if run.crash_time is None or (world.crashed[0] and world.ego_on_plan):
            self._since = None  # a rest only counts once the crashed ego no longer drives on
            return None
        speeds = world.scene.speeds()[world.crashed]
        if world.recorder.has_open_episodes or not bool((speeds < self.rest_speed).all()):
            self._since = None
            return None
        if self._since is None:
            self._since = run.time
        if run.time - self._since < self.settle_time:
            return None
        return Stop("crash", "collision; the bodies involved have come to rest", at_rest=True)


class PostCrashTime(StopRule):
    """A fixed time after the crash: ``crash``.

    Args:
        limit: time after the first counted contact [s].
        interval: physics steps between checks.
    """

    def __init__(self, limit: float, interval: int) -> None:
        self.limit = limit
        self.interval = interval

    def start(self, run: RunState) -> None:
        """Nothing to reset."""

    def check(self, run: RunState) -> Stop | None:
        """``crash`` ``limit`` after the first counted contact."""
        if run.crash_time is None or run.time - run.crash_time < self.limit:
            return None
        return Stop("crash", f"collision; stopped {self.limit} s after it")


class Goal(StopRule):
    """The ego reached its goal before any crash: ``goal`` (``World.goal_reached``).

    A CommonRoad goal region is reached when the ego's centre is inside it, a goal of
    time only when the run has lasted its time; otherwise the ego's arc length along
    its route reaches ``World.goal_s``.

    Args:
        rate: checks per simulated second [Hz] (projecting onto the route costs a
            k-d tree query).
        interval_multiple: the interval is rounded to a multiple of this (the other
            rules' interval), so the goal is checked on the same steps as they are.
    """

    def __init__(self, rate: float = 10.0, interval_multiple: int = 1) -> None:
        self.rate = rate
        self.multiple = interval_multiple
        self.interval = interval_multiple

    def start(self, run: RunState) -> None:
        """Set the interval from the physics step."""
        self.interval = _rate_interval(self.rate, self.multiple, run.dt)

    def check(self, run: RunState) -> Stop | None:
        """``goal`` once ``World.goal_reached``: the goal region, a goal of time only, or ``goal_s``."""
        world = run.world
        if run.crash_time is not None or not world.goal_reached():
            return None
        return Stop("goal", world.goal_description())


def _rate_interval(rate: float, multiple: int, dt: float) -> int:
    """Physics steps between checks at ``rate`` [Hz], a multiple of ``multiple``, at step ``dt`` [s]."""
    return multiple * max(1, int(round(1.0 / (rate * multiple * dt))))


class LeftMap(StopRule):
    """The ego's centre left a mapped road beyond its end, before any crash: ``left_map``.

    Only for ``road.kind = "map"``. The map's end is where the ego's reference path,
    followed from the ego's start, leaves the drivable area for good
    (``road.map_end``); the rule fires once the ego's centre is outside the drivable
    area and beyond that arc length. An ego that swerves off a road's side, or crosses a
    sliver between lanelets, is not past the end. The reason gives how far beyond the
    end the ego is and, for a goal region, how close the ego came to it (at the checks).

    Args:
        rate: checks per simulated second [Hz].
        interval_multiple: the interval is rounded to a multiple of this (``Goal``).
    """

    def __init__(self, rate: float = 10.0, interval_multiple: int = 1) -> None:
        self.rate = rate
        self.multiple = interval_multiple
        self.interval = interval_multiple
        self.end = math.inf
        self.area = None
        self.closest = math.inf

    def start(self, run: RunState) -> None:
        """The interval, and the map's end along the ego's route (``inf``: not a map)."""
        self.interval = _rate_interval(self.rate, self.multiple, run.dt)
        world = run.world
        self.closest = math.inf
        self.end, self.area = math.inf, None
        if run.scenario.road.kind is RoadKind.MAP:
            self.area = world.road.drivable_area
            self.end = map_end(self.area, world.ego_path, world.ego_progress())

    def check(self, run: RunState) -> Stop | None:
        """``left_map`` once the ego's centre is off the map and beyond its end."""
        if self.area is None or not math.isfinite(self.end) or run.crash_time is not None:
            return None
        world = run.world
        x, y = float(world.positions[0, 0]), float(world.positions[0, 1])
        if world.goal_area is not None:
            self.closest = min(self.closest, float(world.goal_area.distance(shapely.Point(x, y))))
        if shapely.contains_xy(self.area, x, y):
            return None
        s = world.ego_progress()
        if s <= self.end:
            return None
        reason = (
            f"the ego left the map {s - self.end:.1f} m beyond its end along the route "
            f"(s = {s:.1f} m; the mapped road ends at s = {self.end:.1f} m)"
        )
        if world.goal_area is not None:
            reason += f"; it came within {self.closest:.2f} m of its goal region"
        return Stop("left_map", reason)


class TimeLimit(StopRule):
    """The scenario's duration has passed.

    ``crash`` after a crash; otherwise (``loop.progress``) ``timeout`` if the run is
    shorter than ``stall.window`` or the ego still made progress in its last
    ``stall.window`` seconds, ``stopped_safely`` if it stood
    waiting at a red light or with its way blocked, ``no_progress`` if it stood with a
    passage open. The ego's arc length is sampled at 10 Hz for the window.

    Args:
        stall: what counts as standing and as a blocked way.
    """

    #: Seconds between samples of the ego's progress.
    SAMPLE_PERIOD = 0.1

    def __init__(self, stall: StallConfig | None = None) -> None:
        self.interval = 1
        self.max_steps = 0
        self.stall = stall if stall is not None else StallConfig()

    def start(self, run: RunState) -> None:
        """The number of physics steps of the scenario's duration; no progress sampled yet."""
        self.max_steps = int(round(run.scenario.duration / run.dt))
        self.every = max(int(round(self.SAMPLE_PERIOD / run.dt)), 1)
        self.progress: deque[float] = deque(maxlen=int(round(self.stall.window / self.SAMPLE_PERIOD)) + 1)

    def check(self, run: RunState) -> Stop | None:
        """Ends the run after ``max_steps`` steps, with the outcome of the class docstring."""
        if run.step % self.every == 0:
            self.progress.append(run.world.ego_progress())
        if run.step < self.max_steps:
            return None
        reason = f"time limit of {run.scenario.duration} s reached"
        if run.crash_time is not None:
            return Stop("crash", reason)
        return self._verdict(run, reason)

    def _verdict(self, run: RunState, reason: str) -> Stop:
        stall, world = self.stall, run.world
        if run.time < stall.window - 1e-9:
            return Stop(
                "timeout", f"{reason} (shorter than the {stall.window:g} s a standstill is judged over)"
            )
        moved = world.ego_progress() - self.progress[0]
        window = stall.window
        if moved >= stall.distance:
            return Stop("timeout", f"{reason}; the ego moved {moved:.1f} m in the last {window:g} s")
        light = waiting_at_red(world, stall.lookahead)
        if light is not None:
            return Stop("stopped_safely", f"{reason}; the ego waits at the red light {light!r}")
        if blocked_way(world, stall.lookahead, stall.margin, stall.oncoming_time, stall.oncoming_speed):
            return Stop(
                "stopped_safely",
                f"{reason}; the ego stands, no passage of its width open {stall.lookahead:g} m ahead",
            )
        return Stop(
            "no_progress",
            f"{reason}; the ego moved {moved:.2f} m in the last {window:g} s with a passage of its "
            f"width open {stall.lookahead:g} m ahead",
        )


def default_rules(config: RunConfig) -> tuple[StopRule, ...]:
    """The built-in rules, in the order they are checked (``TimeLimit`` is added by the runner)."""
    every = config.distance_interval
    return (
        Diverged(config.max_penetration, every),
        CrashAtRest(config.rest_speed, config.settle_time, every),
        PostCrashTime(config.post_crash_time, every),
        Goal(10.0, every),
        LeftMap(10.0, every),
    )


def final_outcome(stop: Stop, collisions: Sequence[ImpactRecord], crash: CrashCriterion) -> Stop:
    """The run's verdict once its open contact episodes are closed.

    A collision that counts but was measured only when the run was closed (its
    episode was still open) turns an outcome of ``NO_CRASH_OUTCOMES`` into ``crash``.
    """
    if stop.outcome in NO_CRASH_OUTCOMES and any(crash.counts(c) for c in collisions):
        return Stop("crash", stop.reason, stop.trusted, stop.at_rest)
    return stop


def check_rules(rules: Sequence[StopRule]) -> None:
    """Raise ``ValueError`` unless every rule has an integer ``interval`` >= 1 and a ``check``."""
    for rule in rules:
        interval = getattr(rule, "interval", None)
        if not (
            isinstance(interval, int | np.integer)
            and interval >= 1
            and callable(getattr(rule, "check", None))
        ):
            raise ValueError(f"stop rule {rule!r} needs an integer interval >= 1 and a check(run) method")


__all__ = [
    "NO_CRASH_OUTCOMES",
    "AnyContact",
    "CrashAtRest",
    "CrashCriterion",
    "Diverged",
    "EgoContact",
    "Goal",
    "LeftMap",
    "PostCrashTime",
    "Stop",
    "StopRule",
    "TimeLimit",
    "check_rules",
    "default_rules",
    "final_outcome",
]
