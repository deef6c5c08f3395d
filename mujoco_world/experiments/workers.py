"""Worker processes of a batch: one job at a time per worker, so every death has a name.

``run_jobs`` hands each job to a ``spawn``-started worker process and waits for its
answer before giving that worker the next one. The parent therefore always knows which
job a worker holds:

* A worker that dies (a segfault in native code, ``os.abort``, the OOM killer,
  ``kill -9``) loses exactly the job it held: ``on_lost`` is called for that job with
  the cause (``"SIGSEGV"``, ``"exit code 3"``), a fresh worker replaces it, and the
  other jobs go on.
* Ctrl-C (SIGINT to the parent, or to the whole process group): no new job starts;
  every busy worker gets one SIGINT (a second one is ignored, so a Ctrl-C that reached
  the group already does no harm) and has ``grace`` seconds to close its job and
  answer; a worker still busy then is killed and its job lost (``on_lost``); then
  ``KeyboardInterrupt`` propagates. A second Ctrl-C in the parent ends the grace period.
* Workers die with the parent: on Linux the kernel sends them SIGKILL when the parent
  dies (``PR_SET_PDEATHSIG``), elsewhere a watchdog thread notices within
  ``WATCHDOG_INTERVAL``. A ``kill -9`` of the batch leaves no worker running on.

``deferred_interrupts`` holds back SIGINT while a result is stored or sent, so an
interrupt never splits a write.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from multiprocessing import resource_tracker
from multiprocessing.connection import Connection, wait
from typing import Any

#: Seconds the busy workers get to close their jobs after a Ctrl-C.
GRACE = 20.0
#: Seconds between the watchdog's checks that the parent lives (where there is no PDEATHSIG).
WATCHDOG_INTERVAL = 0.5
_PR_SET_PDEATHSIG = 1

#: Why ``on_lost`` is called for a job that Ctrl-C stopped.
INTERRUPTED = "interrupted"
#: Workers that may die before taking a job, per worker slot, before the batch gives up.
_MAX_IDLE_DEATHS = 3

#: Set in a worker by its first SIGINT.
_interrupted = False
#: True in a worker while it runs a job (only then does SIGINT raise).
_in_job = False


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Hold back SIGINT for the duration of the block (delivered at its end).

    The block's SIGINT is only noted; at its end the handler in force before is restored
    and the signal raised again, so that handler sees it once. (Masking the signal with
    ``pthread_sigmask`` is not enough: it masks one thread, and the kernel then hands the
    signal to another one, a watchdog or tqdm's monitor, whose Python handler still runs
    in the main thread inside the block.) Only in the main thread, where Python allows
    setting handlers; elsewhere a plain block.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        # None: a handler set outside Python; the default is the closest we can restore.
        signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)
        if received:
            signal.raise_signal(signal.SIGINT)


def describe_exit(exitcode: int | None) -> str:
    """A process's exit code in words: ``"SIGSEGV"`` for -11, ``"exit code 3"`` for 3."""
    if exitcode is None:
        return "still running"
    if exitcode < 0:
        try:
            return signal.Signals(-exitcode).name
        except ValueError:
            return f"signal {-exitcode}"
    return f"exit code {exitcode}"


# --------------------------------------------------------------------------- worker side


def _die_with_parent(parent: int) -> None:
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL))

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(WATCHDOG_INTERVAL)
        os._exit(1)

    if os.getppid() != parent:  # the parent died before the kernel was told
        os._exit(1)
    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def _on_sigint(signum: int, frame: object) -> None:
    global _interrupted
    if _interrupted:
        return  # the group's Ctrl-C and the parent's forwarded one: close the job once
    _interrupted = True
    if _in_job:
        raise KeyboardInterrupt  # outside a job the flag suffices: the worker leaves


def _worker_main(
    conn: Connection,
    parent: int,
    function: Callable[[Any], Any],
    initializer: Callable[[], object] | None,
) -> None:
    global _in_job
    _die_with_parent(parent)
    signal.signal(signal.SIGINT, _on_sigint)
    if hasattr(signal, "pthread_sigmask"):  # started with SIGINT held back (_Pool.start)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    if initializer is not None:
        initializer()
    while not _interrupted:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        key, item = job
        if _interrupted:  # Ctrl-C reached this worker while it waited
            answer: tuple[Any, bool, Any] = (key, False, INTERRUPTED)
        else:
            try:
                _in_job = True
                answer = (key, True, function(item))
            except KeyboardInterrupt:
                answer = (key, False, INTERRUPTED)
            except Exception as error:  # noqa: BLE001 - reported to the parent, the batch goes on
                answer = (key, False, f"{type(error).__name__}: {error}")
            finally:
                _in_job = False
        try:
            conn.send((*answer, _interrupted))
        except (OSError, ValueError):
            return


# --------------------------------------------------------------------------- parent side


@dataclass(slots=True)
class _Worker:
    process: multiprocessing.process.BaseProcess
    conn: Connection
    job: tuple[Any, Any] | None = None
    leaving: bool = False


class _Pool:
    def __init__(
        self,
        function: Callable[[Any], Any],
        initializer: Callable[[], object] | None,
        on_result: Callable[[Any, Any], None],
        on_lost: Callable[[Any, str], None],
    ) -> None:
        self.context = multiprocessing.get_context("spawn")
        self.function, self.initializer = function, initializer
        self.on_result, self.on_lost = on_result, on_lost
        self.workers: list[_Worker] = []
        self.interrupting = False
        self.idle_deaths = 0

    def start(self) -> None:
        parent_end, child_end = self.context.Pipe(duplex=True)
        process = self.context.Process(
            target=_worker_main,
            args=(child_end, os.getpid(), self.function, self.initializer),
            name="etp-batch-worker",
            daemon=True,
        )
        # The worker starts with SIGINT held back until its handler is set. The resource
        # tracker, which every spawned process needs, unblocks SIGINT when it starts: start it first.
        resource_tracker.ensure_running()
        with deferred_interrupts():
            process.start()
        child_end.close()
        self.workers.append(_Worker(process, parent_end))

    def idle(self) -> list[_Worker]:
        return [w for w in self.workers if w.job is None and not w.leaving]

    def busy(self) -> list[_Worker]:
        return [w for w in self.workers if w.job is not None]

    def give(self, worker: _Worker, job: tuple[Any, Any]) -> bool:
        """Send ``job`` to ``worker``; False if the worker is gone (the job stays unstarted)."""
        # A Ctrl-C between the send and the bookkeeping would leave a job the parent
        # does not know it gave: the worker would index it, the parent never hear of it.
        with deferred_interrupts():
            try:
                worker.conn.send(job)
            except (OSError, ValueError):
                sent = False
            else:
                worker.job = job
                sent = True
        if not sent:
            self._bury(worker)
        return sent

    def wait_once(self, timeout: float | None = None) -> None:
        """Wait for answers or deaths (at most ``timeout`` s) and handle them."""
        handles: dict[Any, _Worker] = {}
        for worker in self.workers:
            handles[worker.process.sentinel] = worker
            if worker.job is not None:
                handles[worker.conn] = worker
        seen: list[_Worker] = []
        for handle in wait(list(handles), timeout):
            worker = handles[handle]
            if worker in self.workers and worker not in seen:
                seen.append(worker)
                self._answer(worker)

    def _answer(self, worker: _Worker) -> None:
        """Take a worker's answer, or bury it if it died."""
        # Received and handed on as one step: a Ctrl-C between them would drop a
        # result whose run the worker has already indexed.
        with deferred_interrupts():
            try:
                answer = worker.conn.recv() if worker.job is not None and worker.conn.poll() else None
            except (EOFError, OSError):
                answer = None
            if answer is not None:
                key, ok, value, leaving = answer
                worker.job = None
                worker.leaving = leaving
                if ok:
                    self.on_result(key, value)
                else:
                    self.on_lost(key, value)
        if answer is not None and not worker.leaving and worker.process.is_alive():
            return
        worker.process.join(timeout=1.0)
        if not worker.process.is_alive():
            self._bury(worker)

    def _bury(self, worker: _Worker) -> None:
        if worker.process.is_alive():
            worker.process.kill()
        worker.process.join(timeout=5.0)
        if worker.job is not None:
            key, _ = worker.job
            worker.job = None
            why = (
                INTERRUPTED
                if self.interrupting
                else f"worker process died ({describe_exit(worker.process.exitcode)})"
            )
            with deferred_interrupts():
                self.on_lost(key, why)
        elif not worker.leaving and not self.interrupting:
            self.idle_deaths += 1
        worker.conn.close()
        self.workers.remove(worker)

    def interrupt(self, grace: float) -> None:
        """Ctrl-C: stop the busy workers' jobs, wait up to ``grace`` s, kill what is left."""
        self.interrupting = True
        for worker in self.workers:
            if worker.job is None:
                with contextlib.suppress(OSError, ValueError):
                    worker.conn.send(None)
            elif worker.process.pid is not None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(worker.process.pid, signal.SIGINT)
        deadline = time.monotonic() + grace
        while self.busy():
            left = deadline - time.monotonic()
            if left <= 0:
                break
            try:
                self.wait_once(left)
            except KeyboardInterrupt:
                break  # a second Ctrl-C: stop waiting
        for worker in self.busy():
            self._bury(worker)

    def close(self) -> None:
        """Stop every worker (ask, then kill) and reap them."""
        for worker in self.workers:
            with contextlib.suppress(OSError, ValueError):
                worker.conn.send(None)
        deadline = time.monotonic() + 2.0
        for worker in list(self.workers):
            worker.process.join(timeout=max(deadline - time.monotonic(), 0.0))
            if worker.process.is_alive():
                worker.process.kill()
                worker.process.join(timeout=5.0)
            worker.conn.close()
        self.workers.clear()


def run_jobs(
    jobs: Sequence[tuple[Any, Any]],
    function: Callable[[Any], Any],
    workers: int,
    on_result: Callable[[Any, Any], None],
    on_lost: Callable[[Any, str], None],
    initializer: Callable[[], object] | None = None,
    grace: float = GRACE,
) -> None:
    """Run ``function(item)`` for each ``(key, item)`` of ``jobs`` on worker processes.

    Args:
        jobs: (key, item) pairs, started in this order; ``function`` and the items
            must be picklable (``function`` a module-level function).
        function: what a worker does with an item; its return value goes to ``on_result``.
        workers: number of worker processes (>= 1).
        on_result: called in this process with (key, result) as results arrive.
        on_lost: called with (key, why) for a job that produced no result: its worker
            died (why: ``"worker process died (SIGSEGV)"``), ``function`` raised (why:
            ``"<Exception>: <message>"``) or Ctrl-C stopped it (why: ``INTERRUPTED``).
        initializer: called once in each worker before its first job (picklable).
        grace: seconds the busy workers get to close their jobs after a Ctrl-C.

    Raises:
        KeyboardInterrupt: Ctrl-C, after the busy jobs were closed or lost (module
            docstring); the jobs not started yet got no call.
        RuntimeError: worker processes keep dying before they take a job.
    """
    pool = _Pool(function, initializer, on_result, on_lost)
    pending = list(reversed(jobs))
    try:
        try:
            while pending or pool.busy():
                if pool.idle_deaths > _MAX_IDLE_DEATHS * workers:
                    raise RuntimeError(
                        f"batch worker processes died {pool.idle_deaths} times before taking a run"
                    )
                while pending and len([w for w in pool.workers if not w.leaving]) < workers:
                    pool.start()
                for worker in pool.idle():
                    if pending and pool.give(worker, pending[-1]):
                        pending.pop()
                if pool.busy():
                    pool.wait_once()
        except KeyboardInterrupt:
            pool.interrupt(grace)
            raise
    finally:
        pool.close()
