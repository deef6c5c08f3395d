"""Closed-loop MuJoCo world in which the ethical planner drives an ego body.

Grouped by concern (each group imports only those before it in this list):

* ``scenario``: what to simulate: frozen scenario records, TOML loading, road
  geometry, the catalog.
* ``physics``: the MuJoCo scene, impact measurement, force controllers.
* ``agents``: what drives the bodies: the ego-planner protocol and its planners
  (ethical, scripted), the behaviours of the other road users.
* ``evaluation``: measured impacts against the harm model's prediction.
* ``loop``: one world, the closed loop (stop rules, metrics, observers, summary).
* ``storage``: run records, run folders, the run index, Rerun recordings.
* ``experiments``: many runs: batches (``etp run``, ``etp demo``).

This package never imports ``harm_calibration``; only ``storage.recording`` imports
``rerun``.
"""

from mujoco_world.agents.ego_planner import EGO_PLANNERS, EgoPlanner, EgoSetup, Observation, Plan
from mujoco_world.agents.scripted import Manoeuvre, ScriptedPlanner, SwitchingPlanner
from mujoco_world.evaluation.compare import BodyComparison, ImpactRecord, compare_impact
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.metrics import Metric, default_metrics
from mujoco_world.loop.observers import RunObserver
from mujoco_world.loop.rules import Stop, StopRule, default_rules
from mujoco_world.loop.runner import run_scenario
from mujoco_world.loop.summary import RunSummary
from mujoco_world.loop.world import ObservationNoise, World
from mujoco_world.physics.control import ControlConfig
from mujoco_world.physics.impact import (
    BodyImpact,
    ImpactMeasurement,
    ImpactRecorder,
    ImpactRig,
    measure_impact,
)
from mujoco_world.physics.scene import BodyProxy, Scene
from mujoco_world.scenario.catalog import (
    CATALOG,
    catalog_names,
    generate_scenarios,
    get_scenario,
    random_scenario,
)
from mujoco_world.scenario.spec import Scenario, load_scenario, scenario_from_dict

__all__ = [
    "CATALOG",
    "EGO_PLANNERS",
    "EgoPlanner",
    "EgoSetup",
    "Manoeuvre",
    "Metric",
    "Observation",
    "Plan",
    "ScriptedPlanner",
    "Stop",
    "StopRule",
    "SwitchingPlanner",
    "default_metrics",
    "default_rules",
    "BodyComparison",
    "BodyImpact",
    "BodyProxy",
    "ControlConfig",
    "ImpactMeasurement",
    "ImpactRecord",
    "ImpactRecorder",
    "ImpactRig",
    "ObservationNoise",
    "RunConfig",
    "RunObserver",
    "RunSummary",
    "Scenario",
    "Scene",
    "World",
    "catalog_names",
    "compare_impact",
    "generate_scenarios",
    "get_scenario",
    "load_scenario",
    "measure_impact",
    "random_scenario",
    "run_scenario",
    "scenario_from_dict",
]
