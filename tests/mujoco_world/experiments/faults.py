"""Ego planners that misbehave on purpose, for the batch's fault-injection tests.

Each drives like ``keep_lane`` and adds one fault at its first planning cycle (or at
every cycle: ``fault_slow``). ``register`` adds them to ``EGO_PLANNERS``; it is the
``worker_initializer`` of the batches under test, so spawned workers know them too.
``demo_main`` runs ``etp`` with them registered (the subprocess of the signal tests):

    python -c "from tests.mujoco_world.experiments.faults import demo_main; demo_main()" demo ...
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import time
from pathlib import Path

#: Environment variable naming a file: while it exists, ``fault_flaky`` raises.
FLAKY_FLAG = "ETP_TEST_FLAKY_FLAG"
#: Real seconds ``fault_slow`` sleeps per planning cycle.
SLOW_SECONDS = 0.1


def _segfault() -> None:
    ctypes.string_at(0)  # reads address 0: SIGSEGV


def _raise() -> None:
    raise RuntimeError("injected planner fault")


def _flaky() -> None:
    flag = os.environ.get(FLAKY_FLAG)
    if flag and Path(flag).exists():
        raise RuntimeError(f"flaky planner: {flag} exists")


def _slow() -> None:
    time.sleep(SLOW_SECONDS)


#: name: (fault, at every cycle).
FAULTS = {
    "fault_segv": (_segfault, False),
    "fault_abort": (os.abort, False),
    "fault_exit": (lambda: os._exit(3), False),
    "fault_kill": (lambda: os.kill(os.getpid(), signal.SIGKILL), False),
    "fault_raise": (_raise, False),
    "fault_flaky": (_flaky, False),
    "fault_slow": (_slow, True),
}


class _Faulty:
    def __init__(self, name: str, setup: object) -> None:
        from mujoco_world.agents.scripted import ScriptedPlanner, keep_lane

        self.name = name
        self.fault, self.every = FAULTS[name]
        self.inner = ScriptedPlanner(keep_lane(), setup)
        self.cycles = 0

    def plan(self, observation: object) -> object:
        if self.every or self.cycles == 0:
            self.fault()
        self.cycles += 1
        return self.inner.plan(observation)


def register() -> None:
    """Add the faulty planners to ``EGO_PLANNERS`` (once per process)."""
    from mujoco_world.agents import EGO_PLANNERS

    for name in FAULTS:
        if name not in EGO_PLANNERS:
            EGO_PLANNERS.register(name, lambda setup, name=name: _Faulty(name, setup))


def demo_main() -> None:
    """``etp`` with the faulty planners registered here and in every batch worker."""
    import harm_calibration.cli.world as world
    from harm_calibration.cli import main

    register()
    world.keep_freed_memory = register  # the workers' initializer
    sys.exit(main(sys.argv[1:]))
