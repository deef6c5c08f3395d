"""Observers of the closed loop: hooks that watch a run without changing it.

A recorder (``storage.recording.RerunRecorder``), a live plot or a test's probe is a
``RunObserver``; several are combined with ``ObserverGroup``. Observers see every
planning cycle, every ``step_interval``-th physics step, every measured impact and
the summary; what a run *measures* (its summary's metrics) is done by
``loop.metrics`` instead.
"""

from __future__ import annotations

from collections.abc import Sequence

from mujoco_world.agents.ego_planner import Plan
from mujoco_world.evaluation.compare import ImpactRecord
from mujoco_world.loop.summary import RunSummary
from mujoco_world.loop.world import World
from mujoco_world.scenario.spec import Scenario


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

    def on_cycle(self, plan: Plan, time: float) -> None:
        """Called after each planning cycle at simulation ``time`` [s] (``plan.decision`` may be None)."""

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

    def on_cycle(self, plan: Plan, time: float) -> None:
        """Forward ``on_cycle``."""
        for o in self.observers:
            o.on_cycle(plan, time)

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
