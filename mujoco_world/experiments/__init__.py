"""Experiments made of many runs, above the loop and its storage.

``batch``: many runs on several cores, resumable, each stored by
``storage.run_folder`` (``etp run`` is a batch of one, ``etp demo`` a batch of the
catalog), with the comparison table. Studies over scenario sets and searches that
replay a run with other ego planners build on it.
"""
