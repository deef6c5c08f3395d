"""Recording and storage.

Rerun recordings (``recording``, the one module that imports
Rerun), the run index and near-crash search (``run_index``) and the run folder that ties
a run to its recording and index row (``run_folder``).
"""
