"""Agents: what drives the bodies of the world.

The ego is driven by an ego planner (``ego_planner``: the protocol, ``Observation`` in,
``Plan`` out, and the ``EGO_PLANNERS`` registry): the paper's ethical planner
(``ethical``, one name per preset) or a scripted open-loop manoeuvre (``scripted``).
The other road users follow behaviours (``behaviour``: scripted, car following,
crossing pedestrians, rule violators).
"""

from mujoco_world.agents import ethical, scripted
from mujoco_world.agents.ego_planner import (
    EGO_PLANNERS,
    EgoPlanner,
    EgoSetup,
    Observation,
    Plan,
    make_ego_planner,
)
from mujoco_world.agents.ethical import EthicalPlanner
from mujoco_world.agents.scripted import (
    Manoeuvre,
    ScriptedPlanner,
    SwitchingPlanner,
    brake,
    keep_lane,
    lane_change,
    swerve_and_brake,
)

__all__ = [
    "EGO_PLANNERS",
    "EgoPlanner",
    "EgoSetup",
    "EthicalPlanner",
    "Manoeuvre",
    "Observation",
    "Plan",
    "ScriptedPlanner",
    "SwitchingPlanner",
    "brake",
    "ethical",
    "keep_lane",
    "lane_change",
    "make_ego_planner",
    "scripted",
    "swerve_and_brake",
]
