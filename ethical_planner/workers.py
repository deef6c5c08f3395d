"""A small executor for the planner's kernels: helper threads.

The hot kernels (collision probability, harm) run in compiled code or numpy loops that
release the GIL, so a second thread pays off on large problems. A ``Workers`` object is
owned by whoever plans (a ``Planner`` holds one) and starts its helper threads on first
use, so nothing is shared through module globals.

Thread count: ``ETHICAL_PLANNER_THREADS`` if set, else min(2, CPU count), and 1 inside
a worker process of a process pool (the other cores are busy with the other workers).
Results never depend on it: jobs write disjoint parts of their outputs.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

_T = TypeVar("_T")
_J = TypeVar("_J")

#: Environment variable that sets the number of threads.
THREADS_VARIABLE = "ETHICAL_PLANNER_THREADS"


def threads_from_environment() -> int:
    """Threads for large inputs: ``ETHICAL_PLANNER_THREADS``, else min(2, CPU count).

    Inside a worker process (a batch of scenarios on a process pool) the default is 1.

    Raises:
        ValueError: the variable is set to something other than a positive integer.
    """
    value = os.environ.get(THREADS_VARIABLE)
    if value:
        try:
            threads = int(value)
        except ValueError:
            threads = 0
        if threads < 1:
            raise ValueError(f"{THREADS_VARIABLE} must be a positive integer, got {value!r}")
        return threads
    if multiprocessing.parent_process() is not None:
        return 1
    return min(2, os.cpu_count() or 1)


class Workers:
    """Helper threads (``threads - 1`` of them, started on first use).

    Args:
        threads: threads to use, the calling one included; None reads
            ``threads_from_environment()``.

    Raises:
        ValueError: ``threads`` below 1.
    """

    def __init__(self, threads: int | None = None) -> None:
        threads = threads_from_environment() if threads is None else threads
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
            raise ValueError(f"Workers.threads must be an integer >= 1, got {threads!r}")
        self.threads = threads
        self._pool: ThreadPoolExecutor | None = None
        self._lock = threading.Lock()

    def __repr__(self) -> str:
        return f"Workers(threads={self.threads})"

    def _executor(self) -> ThreadPoolExecutor | None:
        if self.threads < 2:
            return None
        with self._lock:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(self.threads - 1, thread_name_prefix="ethical-planner")
            return self._pool

    def submit(self, function: Callable[[], _T]) -> Future[_T] | None:
        """Run ``function`` on a helper thread; None (run it yourself) without helpers."""
        pool = self._executor()
        return None if pool is None else pool.submit(function)

    def parallel_for(self, jobs: Sequence[_J], run: Callable[[_J], None]) -> None:
        """Run ``run(job)`` for every job on the calling thread and the helper threads.

        Jobs are handed out one at a time from a shared iterator, so a helper that is
        busy with something else (see ``submit``) simply takes fewer. ``run`` must write
        its results to places no other job touches; the result then does not depend on
        the assignment of jobs to threads.
        """
        pool = self._executor()
        if pool is None or len(jobs) < 2:
            for job in jobs:
                run(job)
            return
        lock = threading.Lock()
        remaining = iter(jobs)

        def worker() -> None:
            while True:
                with lock:
                    job = next(remaining, None)
                if job is None:
                    return
                run(job)

        helpers = [pool.submit(worker) for _ in range(self.threads - 1)]
        worker()
        for helper in helpers:
            # A helper that has not started (its thread still busy elsewhere) has nothing
            # left to do; one that has started finishes the job it holds.
            if not helper.cancel():
                helper.result()

    def close(self) -> None:
        """Stop the helper threads (they would also stop when this object is collected)."""
        with self._lock:
            if self._pool is not None:
                self._pool.shutdown(wait=False)
                self._pool = None


__all__ = ["THREADS_VARIABLE", "Workers", "threads_from_environment"]
