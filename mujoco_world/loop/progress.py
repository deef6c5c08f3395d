"""Why an ego that stands still at the end of a run stands: ``stopped_safely`` or ``no_progress``.

A run that reaches its time limit without a crash and without the goal ends in one of
three outcomes (``rules.TimeLimit``):

- ``timeout``: the ego was still making progress (it moved at least ``StallConfig.
  distance`` along its route in the last ``StallConfig.window`` seconds): it was slow,
  not stuck; or the run was shorter than the window (too short to tell);
- ``stopped_safely``: it stood (moved less than that) and had a reason to: it waits at a
  light that is red at the end with its front at most ``lookahead`` before the line, or
  its way is blocked: no passage wide enough for it leads from where it stands to the
  route's cross-section ``lookahead`` ahead of its front (``blocked_way``);
- ``no_progress``: it stood although such a passage was open: it stalled before a
  passable obstacle (or before nothing).

The passage test is a configuration-space test on the road at the end of the run:
the drivable area (the road minus debris) shrunk by the ego's half width plus
``margin``, minus every other body's footprint grown by the same amount, is where the
ego's centre can be; the way is open if the part of it that holds the ego's centre (or
lies nearest to it) reaches the cross-section. It sees the bodies where they are at
the end and ignores right of way; a stop sign does not block (the ego stops and goes
on). Lane direction counts: a road user driving against the ego's route (its velocity
along the route below ``-StallConfig.oncoming_speed``; oncoming traffic in its own lane,
or a wrong-way driver) blocks the stretch it covers in the next
``StallConfig.oncoming_time`` seconds as well as where it is: the ego cannot use that
stretch of the other direction's lanes to pass, so a queue of oncoming cars closes the
way and an ego waiting behind an obstacle for a gap in it has stopped safely. Before,
the test saw oncoming cars only where they stood at the end, and the gaps between them
read as an open passage (``no_progress``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from ethical_planner.geometry import rectangle_corners
from ethical_planner.validation import check_non_negative, check_positive
from mujoco_world.loop.world import World


@dataclass(frozen=True, slots=True)
class StallConfig:
    """When an ego stands at the end, and what counts as a blocked way.

    Attributes:
        window: the last seconds of the run over which progress is measured [s].
        distance: less progress along the route than this in ``window`` is standing [m].
        lookahead: how far ahead of its front the way must be open (and how close a
            red light must be to excuse the wait) [m].
        margin: clearance a passage leaves on each side of the ego [m] (the planner's
            road-edge margin is 0.25 m).
        oncoming_time: an oncoming road user blocks what it covers in this time [s]
            (the time a pass beside an obstacle takes: 5 s covers a 20 m pass from a
            standstill at 1.6 m/s^2).
        oncoming_speed: road users faster than this against the ego's route are
            oncoming [m/s].
    """

    window: float = 5.0
    distance: float = 1.0
    lookahead: float = 20.0
    margin: float = 0.25
    oncoming_time: float = 5.0
    oncoming_speed: float = 0.5

    def __post_init__(self) -> None:
        check_positive("stall", window=self.window, distance=self.distance, lookahead=self.lookahead)
        check_non_negative(
            "stall", margin=self.margin, oncoming_time=self.oncoming_time, oncoming_speed=self.oncoming_speed
        )


def waiting_at_red(world: World, lookahead: float) -> str | None:
    """The name of a light that is red now with the ego's front at most ``lookahead`` before it."""
    front = world.ego_progress() + 0.5 * float(world.lengths[0])
    for line in world.scenario.stop_lines:  # a few lines
        if line.red and line.as_stop_line().red_at(world.time) and 0.0 <= line.s - front <= lookahead:
            return line.name
    return None


def blocked_way(
    world: World, lookahead: float, margin: float, oncoming_time: float = 5.0, oncoming_speed: float = 0.5
) -> bool:
    """True if no passage of the ego's width leads ``lookahead`` ahead of its front (module docstring).

    Args:
        world: the world at the end of the run.
        lookahead: [m].
        margin: [m].
        oncoming_time: an oncoming road user also blocks what it covers in this time [s].
        oncoming_speed: [m/s]; faster than this against the route is oncoming.
    """
    environment = world.environment()  # the road minus debris
    path = environment.reference_path
    reach = 0.5 * float(world.widths[0]) + margin
    free = environment.drivable_area.buffer(-reach)
    others = np.flatnonzero(world.present[1:]) + 1
    if others.size:
        x, y = world.positions[others, 0], world.positions[others, 1]
        # An oncoming body's footprint is stretched back along its velocity: where it
        # will be within ``oncoming_time`` (its length grows, its centre moves half that way).
        s_k, _ = path.to_frenet(x, y)
        theta = path.heading(s_k)
        vx, vy = world.velocities[others, 0], world.velocities[others, 1]
        along = vx * np.cos(theta) + vy * np.sin(theta)
        oncoming = along < -oncoming_speed
        sweep = np.where(oncoming, np.hypot(vx, vy) * oncoming_time, 0.0)
        heading = np.where(oncoming & (sweep > 0.0), np.arctan2(vy, vx), world.yaws[others])
        cx, cy = rectangle_corners(
            x + 0.5 * sweep * np.cos(heading),
            y + 0.5 * sweep * np.sin(heading),
            heading,
            world.lengths[others] + sweep,
            world.widths[others],
        )
        bodies = shapely.polygons(np.stack([cx, cy], axis=-1))
        free = free.difference(shapely.union_all(shapely.buffer(bodies, reach)))
    front = world.ego_progress() + 0.5 * float(world.lengths[0])
    # The shrunk drivable area ends ``reach`` before the road's end: a cross-section
    # beyond that never meets it, and an ego near the end would read "blocked".
    target = min(front + lookahead, path.length - reach - 0.01)
    if target <= front:
        return False  # the road ends ahead: nothing can block the way
    offsets = environment.lane_offsets
    side = np.array([min(offsets) - environment.lane_width, max(offsets) + environment.lane_width])
    tx, ty = path.to_cartesian(np.full(2, target), side)
    section = shapely.LineString(np.column_stack([tx, ty]))
    ego = shapely.Point(float(world.positions[0, 0]), float(world.positions[0, 1]))
    parts = list(getattr(free, "geoms", [free]))
    parts = [p for p in parts if not p.is_empty]
    if not parts:
        return True
    distances = np.array([p.distance(ego) for p in parts])  # a few parts
    mine = parts[int(np.argmin(distances))]
    return not (math.isfinite(distances.min()) and mine.intersects(section))
