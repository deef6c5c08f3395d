"""Replay a scenario's road users without the ego: do the recordings survive the physics?

Recorded road users did not collide in reality, so their bodies, following their
recordings through the controllers, must not collide in the world either. Where they
do, either the import is wrong or the file's own shapes overlap (which the CommonRoad
importer detects and excludes from contact, saying so in the scenario's notes).
``replay`` runs the world alone (no planner, the ego's body waits outside without
contacts) and reports every collision and how closely each body followed its
reference before any contact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mujoco_world.loop.world import World
from mujoco_world.scenario.spec import BehaviourKind, Scenario


@dataclass(frozen=True, slots=True)
class ReplayCollision:
    """A collision between two bodies (or a body and a fixed obstacle) in a replay.

    Attributes:
        time: first contact [s]. a, b: body names ("kerb"/"wall" for static ones).
        dv_a, dv_b: measured delta-v [m/s] (nan for a static body).
    """

    time: float
    a: str
    b: str
    dv_a: float
    dv_b: float


@dataclass(frozen=True, slots=True)
class ReplayReport:
    """What a replay without the ego found.

    Attributes:
        scenario: scenario name. duration: simulated time [s].
        collisions: every measured collision, in time order.
        tracking_rms, tracking_max: per recorded road user (by name), its distance to
            its recording while in the world before any contact [m].
        overall_rms: RMS over every tracked sample of every recorded road user [m].
        blocked_entries: recorded road users that would have entered inside another
            body (they waited without contacts until clear).
        notes: the scenario's own notes (what its importer found).
    """

    scenario: str
    duration: float
    collisions: tuple[ReplayCollision, ...]
    tracking_rms: dict[str, float]
    tracking_max: dict[str, float]
    overall_rms: float
    blocked_entries: tuple[str, ...]
    notes: tuple[str, ...]

    @property
    def worst_rms(self) -> float:
        """Largest per-body tracking RMS [m] (0 without recorded road users)."""
        finite = [v for v in self.tracking_rms.values() if math.isfinite(v)]
        return max(finite, default=0.0)


def replay(scenario: Scenario, until: float | None = None, timestep: float = 0.001) -> ReplayReport:
    """Run ``scenario``'s road users without the ego and report collisions and tracking.

    Args:
        scenario: any scenario (recorded road users are what it checks best).
        until: simulated time [s]; None runs the scenario's duration.
        timestep: physics step [s].
    """
    world = World(scenario, timestep=timestep, ego_present=False)
    steps = int(round((scenario.duration if until is None else until) / world.scene.dt))
    found = []
    for _ in range(steps):
        found += world.step()
    found += world.finish()
    collisions = tuple(
        ReplayCollision(
            float(m.time),
            m.a.name,
            m.b.name,
            float(np.hypot(*m.a.delta_v_impulse)),
            float(np.hypot(*m.b.delta_v_impulse)) if math.isfinite(m.b.mass) else math.nan,
        )
        for m in sorted(found, key=lambda m: m.time)
    )
    rms, worst, samples = world.road_user_tracking()
    recorded = [
        i + 1 for i, u in enumerate(scenario.road_users) if u.behaviour.kind is BehaviourKind.RECORDED
    ]
    names = world.scene.names
    blocked = tuple(sorted({names[e] for _, e, what in world.presence_events if what == "enter_blocked"}))
    n = samples[recorded].sum() if recorded else 0
    overall = float(np.sqrt(np.nansum((rms[recorded] ** 2) * samples[recorded]) / n)) if n else 0.0
    report = ReplayReport(
        scenario=scenario.name,
        duration=round(world.time, 6),
        collisions=collisions,
        tracking_rms={names[i]: float(rms[i]) for i in recorded},
        tracking_max={names[i]: float(worst[i]) for i in recorded},
        overall_rms=overall,
        blocked_entries=blocked,
        notes=scenario.notes,
    )
    return report


__all__ = ["ReplayCollision", "ReplayReport", "replay"]
