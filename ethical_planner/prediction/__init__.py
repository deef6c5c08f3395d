"""Prediction of other road users: the ``Predictor`` protocol and its implementations.

``base`` holds the ``Prediction`` record, the protocol and the ``PREDICTORS`` registry;
each implementation is one module that registers itself on import. The default
(``PredictionConfig.model``) is ``constant_acceleration``.
"""

from ethical_planner.prediction import constant_acceleration, constant_turn_rate, learned
from ethical_planner.prediction.base import (
    PREDICTORS,
    Prediction,
    Predictor,
    empty_prediction,
    make_predictor,
)
from ethical_planner.prediction.constant_acceleration import (
    ConstantAccelerationPredictor,
    predict_constant_acceleration,
)
from ethical_planner.prediction.constant_turn_rate import (
    ConstantTurnRatePredictor,
    predict_constant_turn_rate,
)

__all__ = [
    "PREDICTORS",
    "ConstantAccelerationPredictor",
    "ConstantTurnRatePredictor",
    "Prediction",
    "Predictor",
    "constant_acceleration",
    "constant_turn_rate",
    "empty_prediction",
    "learned",
    "make_predictor",
    "predict_constant_acceleration",
    "predict_constant_turn_rate",
]
