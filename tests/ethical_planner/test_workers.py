"""The executor of the risk kernels: thread count, jobs, scratch buffers."""

import threading

import numpy as np
import pytest

from ethical_planner.workers import Workers, threads_from_environment


def test_thread_count_comes_from_the_environment(monkeypatch):
    monkeypatch.setenv("ETHICAL_PLANNER_THREADS", "3")
    assert threads_from_environment() == 3 and Workers().threads == 3
    for bad in ("0", "-1", "two"):
        monkeypatch.setenv("ETHICAL_PLANNER_THREADS", bad)
        with pytest.raises(ValueError, match="ETHICAL_PLANNER_THREADS must be a positive integer"):
            Workers()
    monkeypatch.delenv("ETHICAL_PLANNER_THREADS")
    assert 1 <= threads_from_environment() <= 2
    with pytest.raises(ValueError, match="Workers.threads"):
        Workers(0)


@pytest.mark.parametrize("threads", [1, 2, 4])
def test_parallel_for_runs_every_job_once(threads):
    workers = Workers(threads)
    out = np.zeros(50, dtype=int)
    names = set()

    def run(job):
        out[job] += job
        names.add(threading.current_thread().name)

    workers.parallel_for(list(range(50)), run)
    np.testing.assert_array_equal(out, np.arange(50))
    if threads == 1:
        assert names == {threading.current_thread().name}
    workers.close()


def test_submit_runs_on_a_helper_or_says_run_it_yourself():
    assert Workers(1).submit(lambda: 1) is None
    workers = Workers(2)
    future = workers.submit(threading.current_thread)
    assert future.result() is not threading.current_thread()
    workers.close()
