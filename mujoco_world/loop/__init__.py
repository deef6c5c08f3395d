"""The closed loop.

One scenario in MuJoCo (``world``), the run loop with the planner
(``runner``) and batches of runs on several processes (``batch``).
"""
