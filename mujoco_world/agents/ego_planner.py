"""The ego-planner protocol: what drives the ego through the world.

An ego planner is built once per run from what it may know in advance (``EgoSetup``:
the road environment, the ego's shape and mass, its goal on its route) and is then
asked, at every planning cycle, for a plan from what it observes (``Observation``:
the simulation time, the ego's observed state, the road users it perceives). It
returns a ``Plan``: a trajectory from now on (arrays ``t, x, y, yaw, v, a, kappa``),
which the ego's controller tracks until the next cycle, and optionally the ethical
planner's ``Decision`` (recorders and risk metrics use it when it is there).

Implementations: ``agents.ethical.EthicalPlanner`` (the paper's planner, every preset),
``agents.scripted.ScriptedPlanner`` (an open-loop manoeuvre given as functions of
time) and ``agents.scripted.SwitchingPlanner`` (one planner until a time, then
another). A planner of your own is any object with ``name`` and ``plan``; pass its
class (or any callable taking an ``EgoSetup``) to ``run_scenario``, or register it by
name in ``EGO_PLANNERS``::

    class KeepSpeed:
        name = "keep_speed"

        def __init__(self, setup: EgoSetup): ...
        def plan(self, observation: Observation) -> Plan: ...

    run_scenario(get_scenario("oncoming_drift"), KeepSpeed)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ethical_planner.config import PlannerConfig
from ethical_planner.environment import RoadEnvironment
from ethical_planner.planner import Decision, Trajectory
from ethical_planner.prediction import Predictor
from ethical_planner.registry import Registry
from ethical_planner.road_users import KinematicState, RoadUser, Shape
from ethical_planner.validation import check, check_positive, shaped_array


@dataclass(frozen=True, slots=True)
class EgoSetup:
    """What an ego planner knows when it is built.

    Attributes:
        environment: the road as the planner sees it (the ego's reference path,
            drivable area, lane offsets, speed limit).
        shape: the ego's footprint [m].
        mass: the ego's mass [kg].
        goal_s: arc length along ``environment.reference_path`` the ego must reach [m].
        predictor: the predictor the run asks for (``run_scenario(predictor=...)``);
            None: the planner's own (the ethical planner's ``prediction.model``).
        prediction_model: name of a registered predictor the run asks for instead of
            the planner configuration's ``prediction.model`` (``RunConfig.predictor``).
    """

    environment: RoadEnvironment
    shape: Shape
    mass: float
    goal_s: float
    predictor: Predictor | None = None
    prediction_model: str | None = None

    def __post_init__(self) -> None:
        check_positive("setup", mass=self.mass)


@dataclass(frozen=True, slots=True)
class Observation:
    """What the ego perceives at a planning cycle.

    Attributes:
        time: simulation time [s].
        ego: the ego's observed state (centre, heading, speed along the heading,
            acceleration of its current plan, yaw rate).
        road_users: the road users it perceives (hidden ones are left out), ids = the
            world's entity indices.
    """

    time: float
    ego: KinematicState
    road_users: tuple[RoadUser, ...]


@dataclass(frozen=True, slots=True, eq=False)
class Plan:
    """A planned trajectory from the observation on, and optionally why.

    Attributes:
        trajectory: arrays of shape (n_t,), n_t >= 2: ``t`` [s] from the observation
            time (t[0] = 0, strictly increasing), ``x, y`` the ego's centre [m],
            ``yaw`` [rad], ``v`` speed [m/s], ``a`` acceleration along the path
            [m/s^2], ``kappa`` curvature [1/m]. Beyond its end the ego continues at
            the last speed along the last heading.
        decision: the ethical planner's decision record, if the planner has one.

    Raises:
        ValueError: arrays of different shapes, fewer than two samples, non-finite
            values, or times that do not start at 0 and increase.
    """

    trajectory: Trajectory
    decision: Decision | None = None

    def __post_init__(self) -> None:
        traj = self.trajectory
        t = shaped_array("plan.t", traj.t, "(n_t,)", ndim=1)
        check(len(t) >= 2, f"plan.t must hold at least 2 samples, got {len(t)}")
        for name in ("x", "y", "yaw", "v", "a", "kappa"):
            shaped_array(f"plan.{name}", getattr(traj, name), "(n_t,) like plan.t", shape=t.shape)
        check(abs(t[0]) < 1e-9, f"plan.t must start at 0 (the observation time), got {t[0]}")
        check(bool(np.all(np.diff(t) > 0)), "plan.t must be strictly increasing")

    @classmethod
    def from_arrays(
        cls,
        t: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        yaw: np.ndarray,
        v: np.ndarray,
        a: np.ndarray,
        kappa: np.ndarray,
        decision: Decision | None = None,
    ) -> Plan:
        """A plan from its arrays (see the attributes)."""
        arrays = (np.asarray(q, dtype=float) for q in (t, x, y, yaw, v, a, kappa))
        return cls(Trajectory(*arrays), decision)


@runtime_checkable
class EgoPlanner(Protocol):
    """Drives the ego: an observation in, a plan out.

    Attributes:
        name: shown in summaries, recordings and run ids (letters, digits, ``_ . + -``).

    An implementation may also carry ``harm_models``: (model for protected, model for
    unprotected road users) with which the run evaluates the measured impacts, and
    ``planar_model``: (restitution law, tangential impulse ratio) of the planar impulse
    model's prediction; without them the defaults apply.
    """

    name: str

    def plan(self, observation: Observation) -> Plan:
        """The plan for this cycle; an exception ends the run as failed."""


#: Builds an ego planner for one run.
EgoPlannerFactory = Callable[[EgoSetup], EgoPlanner]
#: Ego planners by name: every planner preset, and the scripted manoeuvres.
EGO_PLANNERS: Registry[EgoPlannerFactory] = Registry("planner")

PlannerSpec = str | PlannerConfig | EgoPlanner | EgoPlannerFactory


def make_ego_planner(spec: PlannerSpec, setup: EgoSetup) -> EgoPlanner:
    """The ego planner of a run.

    Args:
        spec: a name in ``EGO_PLANNERS``, a planner configuration (``.toml`` file or
            ``PlannerConfig``) for the ethical planner, a ready planner, or a factory
            (a class or function taking the ``EgoSetup``).
        setup: what the planner knows in advance.

    Raises:
        ValueError: an unknown name (the message lists the registered ones), an
            unreadable configuration, or a factory that returns no ego planner.
    """
    from mujoco_world.agents.ethical import EthicalPlanner

    if isinstance(spec, str):
        if spec.endswith(".toml"):
            from ethical_planner.config import load_config

            return EthicalPlanner(load_config(spec), setup)
        return _checked(EGO_PLANNERS.get(spec)(setup), spec)
    if isinstance(spec, PlannerConfig):
        return EthicalPlanner(spec, setup)
    if isinstance(spec, EgoPlanner) and not isinstance(spec, type):
        return spec
    if callable(spec):
        return _checked(spec(setup), spec)
    raise ValueError(f"planner must be a name, a PlannerConfig, an ego planner or a factory, got {spec!r}")


def _checked(planner: object, source: object) -> EgoPlanner:
    if not isinstance(planner, EgoPlanner):
        raise ValueError(f"planner {source!r} built {planner!r}, which has no name and plan(observation)")
    return planner
