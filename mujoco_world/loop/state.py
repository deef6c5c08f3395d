"""The state of a run in progress, shared by the loop with its stop rules and metrics."""

from __future__ import annotations

from dataclasses import dataclass, field

from ethical_planner.config import PlannerConfig
from mujoco_world.evaluation.compare import ImpactRecord
from mujoco_world.loop.world import World
from mujoco_world.scenario.spec import Scenario


@dataclass(slots=True, eq=False)
class RunState:
    """What the loop knows about a run in progress.

    The loop owns and updates it; stop rules and metrics read it and never change it
    (nor the world).

    Attributes:
        world: the simulated world (time, bodies, contacts, the ego's route).
        scenario: what is simulated.
        planner: name of the ego's planner.
        seed: run seed.
        step: physics steps done.
        cycles: planning cycles done.
        collisions: collisions measured so far, in the order their episodes ended.
        crash_time: simulated time of the first contact that counts as a crash (see
            ``rules.CrashCriterion``) [s]; None before.
        planner_config: the ego planner's configuration (its ``config`` if it has a
            ``PlannerConfig``, the default otherwise): the vehicle and traffic-rule
            settings the world's rule judge measures the ego by.
    """

    world: World
    scenario: Scenario
    planner: str
    seed: int
    step: int = 0
    cycles: int = 0
    collisions: list[ImpactRecord] = field(default_factory=list)
    crash_time: float | None = None
    planner_config: PlannerConfig = field(default_factory=PlannerConfig)

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self.world.time

    @property
    def dt(self) -> float:
        """Physics step [s]."""
        return self.world.scene.dt
