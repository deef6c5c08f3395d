"""Scripted ego planners: open-loop manoeuvres given as functions of time.

A ``Manoeuvre`` gives the longitudinal acceleration along the ego's route and the
lateral offset from where the ego started it, both as functions of the time since
it started. ``ScriptedPlanner`` anchors the manoeuvre at its first planning cycle
(the ego's observed arc length, lateral offset and speed), never reacts to what it
observes afterwards, and hands the controller the manoeuvre's next ``horizon``
seconds at every cycle. The speed is integrated from the acceleration and held at
zero once the ego stops (it does not reverse). ``SwitchingPlanner`` runs one planner
until a time and another afterwards: a manoeuvre started from a state the ego
actually passed through (the avoidability search builds on it).

Registered by name: ``keep_lane`` (constant speed in the lane) and
``emergency_brake`` (braking at the vehicle's emergency deceleration from the start).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ethical_planner.config import VehicleConfig
from ethical_planner.planner import Trajectory
from ethical_planner.sampling import frenet_to_candidates
from ethical_planner.validation import check, check_non_negative, check_positive
from mujoco_world.agents.ego_planner import EGO_PLANNERS, EgoPlanner, EgoSetup, Observation, Plan

#: A function of time [s] (numpy array in, array of the same shape out).
TimeFunction = Callable[[np.ndarray], np.ndarray]
#: Step of the integration of the speed and the arc length [s].
INTEGRATION_STEP = 0.01


def _zero(t: np.ndarray) -> np.ndarray:
    return np.zeros_like(t)


@dataclass(frozen=True, slots=True)
class Manoeuvre:
    """An open-loop manoeuvre as functions of the time since it started.

    Attributes:
        acceleration: longitudinal acceleration along the route [m/s^2] at time t [s]
            (vectorised); the speed stops at 0 and stays there while it is negative.
        offset: lateral offset [m] (left positive) added to the ego's offset at the
            start, at time t [s] (vectorised); it should be 0 at t = 0.
        name: planner name in summaries.
    """

    acceleration: TimeFunction = _zero
    offset: TimeFunction = _zero
    name: str = "scripted"


def _smoothstep(u: np.ndarray) -> np.ndarray:
    """Quintic 0 -> 1 on u in [0, 1] with zero velocity and acceleration at both ends."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10.0 - 15.0 * u + 6.0 * u**2)


def keep_lane() -> Manoeuvre:
    """Constant speed in the lane the ego is in."""
    return Manoeuvre(name="keep_lane")


def brake(deceleration: float, start: float = 0.0, name: str = "brake") -> Manoeuvre:
    """Brake at ``deceleration`` [m/s^2] (> 0) from ``start`` [s] on, to a stop."""
    check_positive("brake", deceleration=deceleration)
    check_non_negative("brake", start=start)
    return Manoeuvre(acceleration=lambda t: np.where(t >= start, -deceleration, 0.0), name=name)


def lane_change(
    offset: float, start: float = 0.0, duration: float = 3.0, name: str = "lane_change"
) -> Manoeuvre:
    """Move ``offset`` [m] sideways (left positive) between ``start`` and ``start + duration`` [s].

    The lateral offset follows the quintic d(u) = offset (10 u^3 - 15 u^4 + 6 u^5),
    u = (t - start) / duration, at constant speed.
    """
    check_positive("lane_change", duration=duration)
    check_non_negative("lane_change", start=start)
    return Manoeuvre(offset=lambda t: offset * _smoothstep((t - start) / duration), name=name)


def swerve_and_brake(
    offset: float,
    deceleration: float,
    start: float = 0.0,
    duration: float = 1.5,
    name: str = "swerve_and_brake",
) -> Manoeuvre:
    """A lane change of ``offset`` [m] over ``duration`` [s] while braking at ``deceleration`` [m/s^2]."""
    braking, moving = brake(deceleration, start), lane_change(offset, start, duration)
    return Manoeuvre(acceleration=braking.acceleration, offset=moving.offset, name=name)


class ScriptedPlanner(EgoPlanner):
    """Plays a ``Manoeuvre`` open loop from the state of its first planning cycle.

    Args:
        manoeuvre: what to do.
        setup: the ego's route (``setup.environment.reference_path``).
        horizon: length of each handed-out plan [s].
        step: sample spacing of the plans [s].
    """

    def __init__(
        self, manoeuvre: Manoeuvre, setup: EgoSetup, horizon: float = 3.0, step: float = 0.1
    ) -> None:
        check_positive("ScriptedPlanner", horizon=horizon, step=step)
        check(step < horizon, f"ScriptedPlanner.step must be < horizon, got {step} >= {horizon}")
        self.manoeuvre = manoeuvre
        self.name = manoeuvre.name
        self.path = setup.environment.reference_path
        self.horizon, self.step = float(horizon), float(step)
        self.anchor: tuple[float, float, float, float] | None = None  # time, s, d, v

    def plan(self, observation: Observation) -> Plan:
        """The manoeuvre's next ``horizon`` seconds."""
        if self.anchor is None:
            ego = observation.ego
            s, d = self.path.to_frenet(np.array(ego.x), np.array(ego.y))
            self.anchor = (observation.time, float(s), float(d), max(float(ego.v), 0.0))
        t0, s0, d0, v0 = self.anchor
        tau0 = observation.time - t0
        t = np.arange(0.0, self.horizon + 0.5 * self.step, self.step)
        lon, lat = self.profile(tau0 + t, s0, d0, v0)
        candidates = frenet_to_candidates(
            t,
            lon[:, None, :],
            lat[:, None, :],
            self.path,
            lon[1, None, -1],
            lat[0, None, -1],
            np.array([t[-1]]),
        )
        return Plan(Trajectory.from_candidates(candidates, 0))

    def profile(self, tau: np.ndarray, s0: float, d0: float, v0: float) -> tuple[np.ndarray, np.ndarray]:
        """Frenet motion of the manoeuvre at times ``tau`` since its start.

        Args:
            tau: times since the start [s], shape (n,), increasing, >= 0.
            s0, d0: arc length and lateral offset at the start [m].
            v0: speed at the start [m/s].

        Returns:
            (lon, lat), each shape (4, n): s and its first three time derivatives,
            d and its first three time derivatives.
        """
        h = INTEGRATION_STEP
        grid = np.arange(0.0, tau[-1] + 2 * h, h)
        # Midpoint rule: exact for accelerations that change at multiples of the step.
        mid = grid[:-1] + 0.5 * h
        accel = np.asarray(self.manoeuvre.acceleration(mid), dtype=float) * np.ones_like(mid)
        free = v0 + np.concatenate([[0.0], np.cumsum(accel * h)])
        # The speed held at zero: the free integral reflected at 0 (v = c - min(0, min c)).
        speed = free - np.minimum(np.minimum.accumulate(free), 0.0)
        arc = s0 + np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * h)])
        offset = d0 + np.asarray(self.manoeuvre.offset(grid), dtype=float) * np.ones_like(grid)
        lon = [arc, speed, np.gradient(speed, grid), np.zeros_like(grid)]
        d_dot = np.gradient(offset, grid)
        d_ddot = np.gradient(d_dot, grid)
        lat = [offset, d_dot, d_ddot, np.gradient(d_ddot, grid)]
        return (
            np.array([np.interp(tau, grid, q) for q in lon]),
            np.array([np.interp(tau, grid, q) for q in lat]),
        )


class SwitchingPlanner(EgoPlanner):
    """One planner until a time, another from then on (e.g. the ethical planner, then a manoeuvre).

    Args:
        first: plans while the simulation time is before ``at``.
        then: plans from ``at`` on (a ``ScriptedPlanner`` anchors at that moment).
        at: switching time [s].
        name: planner name (default "<first>+<then>").
    """

    def __init__(self, first: EgoPlanner, then: EgoPlanner, at: float, name: str | None = None) -> None:
        check_non_negative("SwitchingPlanner", at=at)
        self.first, self.then, self.at = first, then, float(at)
        self.name = name or f"{first.name}+{then.name}"
        for attribute in ("harm_models", "planar_model"):
            value = getattr(first, attribute, None)
            if value is not None:
                setattr(self, attribute, value)

    def plan(self, observation: Observation) -> Plan:
        """``first``'s plan before ``at``, ``then``'s after."""
        planner = self.first if observation.time < self.at - 1e-9 else self.then
        return planner.plan(observation)


EGO_PLANNERS.register("keep_lane", lambda setup: ScriptedPlanner(keep_lane(), setup))
EGO_PLANNERS.register(
    "emergency_brake",
    lambda setup: ScriptedPlanner(
        brake(VehicleConfig().emergency_deceleration, name="emergency_brake"), setup
    ),
)
