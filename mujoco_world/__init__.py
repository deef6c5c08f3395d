"""Closed-loop MuJoCo world in which the ethical planner drives an ego body.

Layers (each module imports only those above it in this list):

* ``scenario``: frozen scenario records, TOML loading (``load_scenario``).
* ``road``: road geometry, routes, walls and kerbs.
* ``scene``: the MuJoCo model of planar body proxies (``Scene``, ``BodyProxy``).
* ``impact``: impact measurement from contact forces (``ImpactRecorder``,
  ``ImpactRig``, ``measure_impact``, ``ImpactMeasurement``), usable without a planner.
* ``compare``: the harm model's prediction beside a measurement (``compare_impact``).
* ``control``, ``behaviour``: tracking controllers and road-user behaviours.
* ``world``: one scenario in MuJoCo (``World``).
* ``runner``: the closed loop with the planner (``run_scenario``, ``RunObserver``).
* ``catalog``: named classic scenarios and a seeded random generator.
* ``batch``, ``cli``: multi-process batches (``etp demo``) and the ``etp`` subcommands.

This package never imports ``rerun`` or ``harm_calibration``.
"""

from .catalog import CATALOG, catalog_names, generate_scenarios, get_scenario, random_scenario
from .compare import BodyComparison, ImpactRecord, compare_impact
from .control import ControlConfig
from .impact import BodyImpact, ImpactMeasurement, ImpactRecorder, ImpactRig, measure_impact
from .runner import RunConfig, RunObserver, RunSummary, run_scenario
from .scenario import Scenario, load_scenario, scenario_from_dict
from .scene import BodyProxy, Scene
from .world import ObservationNoise, World

__all__ = [
    "CATALOG",
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
