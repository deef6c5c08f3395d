"""Recording and storage of runs.

Run records, one typed ``summary.json`` per run (``run_record``, the only module that
writes or reads them); the rule for run ids and folders and the storing of a finished
run (``run_folder``); the run index and near-crash search (``run_index``); Rerun
recordings (``recording``, the one module that imports Rerun).
"""
