"""Training and evaluation of the learned predictor on recorded CommonRoad traffic.

``data`` (tracks -> windows, the split by location), ``train`` (optimisation,
recalibration), ``evaluate`` (metrics, baselines, reliability plot), ``pipeline``
(what ``etp predictor train`` and ``etp predictor eval`` run).
"""
