"""The closed loop.

One scenario in MuJoCo (``world``); the run loop with the ego's planner (``runner``),
beside it the stop rules (``rules``), metrics (``metrics``), observers
(``observers``), the run's settings (``config``) and its result (``summary``).
"""
