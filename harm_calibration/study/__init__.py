"""The paper's study (``etp study``): runs, statistics, figures and report."""
