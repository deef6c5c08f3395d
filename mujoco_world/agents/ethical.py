"""The paper's ethical planner behind the ego-planner protocol, one name per preset."""

from __future__ import annotations

import dataclasses

from ethical_planner.config import PRESETS, PlannerConfig, preset
from ethical_planner.harm import HarmModel
from ethical_planner.impulse import RestitutionLaw
from ethical_planner.planner import Planner
from mujoco_world.agents.ego_planner import EGO_PLANNERS, EgoPlanner, EgoSetup, Observation, Plan


class EthicalPlanner(EgoPlanner):
    """``ethical_planner.Planner`` as an ego planner: each plan carries its ``Decision``.

    Args:
        config: planner configuration (a preset or loaded from TOML).
        setup: the road, the ego's shape and mass, and the predictor to use (an
            object, or a registered name replacing ``config.prediction.model``; None:
            the configuration's).

    Attributes:
        name: the configuration's name ("ethical", "selfish", ...).
        planner: the wrapped planner.
        harm_models: the configuration's harm models, with which the run evaluates
            the measured impacts.
        planar_model: the configuration's restitution law and tangential impulse
            ratio, with which the run predicts the planar model's delta-v.
    """

    def __init__(self, config: PlannerConfig, setup: EgoSetup) -> None:
        if setup.prediction_model is not None:
            prediction = dataclasses.replace(config.prediction, model=setup.prediction_model)
            config = dataclasses.replace(config, prediction=prediction)
        self.config = config
        self.name = config.name
        self.planner = Planner(config, setup.environment, setup.shape, setup.mass, predictor=setup.predictor)
        self.harm_models: tuple[HarmModel, HarmModel] = (config.risk.harm_model, config.risk.pedestrian_model)
        risk = config.risk
        self.planar_model: tuple[RestitutionLaw, float] = (risk.restitution_law, risk.impulse_ratio)

    def plan(self, observation: Observation) -> Plan:
        """One planning cycle of the ethical planner."""
        decision = self.planner.plan(observation.ego, observation.road_users, now=observation.time)
        return Plan(decision.trajectory, decision)


def _preset_factory(name: str):  # noqa: ANN202 - a closure over the preset name
    def build(setup: EgoSetup) -> EthicalPlanner:
        return EthicalPlanner(preset(name), setup)

    build.__name__ = f"ethical_planner_{name}"
    return build


for _name in PRESETS.names():
    EGO_PLANNERS.register(_name, _preset_factory(_name))
