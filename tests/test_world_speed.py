"""benchmarks/world_speed.py: the closed loop it times really runs (the observer sees plans)."""

from benchmarks.world_speed import closed_loop


def test_the_timed_closed_loop_runs_and_counts_the_candidates():
    row = closed_loop(duration=0.25, replan_rate=10.0)
    assert row["sim"] >= 0.25 - 1e-9 and row["cycles"] >= 2
    assert row["candidates"] > 900  # the ethical preset's default candidate set
    assert row["planning"] > 0 and row["physics"] > 0
