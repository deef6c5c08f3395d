"""Batches of closed-loop runs on several cores, resumable, with a comparison table.

Every run is stored by ``mujoco_world.storage.run_folder``: its record in
``<out>/<run id>/summary.json`` (``run_folder.run_id``), its row in
``<out>/index.jsonl``. What a batch promises (each checked by a fault-injection test
in ``tests/mujoco_world/experiments/test_batch_faults.py``):

* A run that fails (an exception in the planner or the physics, or a worker process
  that dies in native code or is killed) is stored as ``outcome = "failed"`` with
  the reason, under its own run id (each worker holds one run at a time,
  ``experiments.workers``), and the batch goes on.
* Resume: a run whose record exists is read, not run again; ``retry_failed`` runs
  the failed ones again.
* Ctrl-C: nothing new starts, the runs in flight are closed as failed
  ("interrupted ...", indexed, no record, so a rerun runs them again), and
  ``BatchInterrupted`` carries what finished (``etp demo`` writes its aggregate and
  exits with 130).
* ``kill -9`` of the batch: its workers die with it; a rerun resumes.
* The index lists every run of the batch exactly once, in the batch's order, when the
  batch ends (also when interrupted): it is rewritten from the records
  (``run_index.compact_index``). One batch at a time writes into an output folder
  (``run_folder.root_lock``), and a batch whose runs share a run id is refused.

Workers are started with the ``spawn`` method, so the module is safe on every
platform. ``etp run`` is a batch of one task.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ethical_planner.config import PlannerConfig
from ethical_planner.validation import check
from mujoco_world.experiments.workers import INTERRUPTED, deferred_interrupts, run_jobs
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.observers import ObserverGroup, RunObserver
from mujoco_world.loop.runner import RunInterrupted, run_scenario
from mujoco_world.loop.summary import GROUPS, OUTCOMES, RunSummary
from mujoco_world.scenario.sources import resolve_scenario
from mujoco_world.storage.recording import PARTIAL_RECORDING_FILE, RerunRecorder
from mujoco_world.storage.run_folder import (
    parse_keep,
    root_lock,
    run_dir,
    run_id,
    source_key,
    source_of,
    store_run,
)
from mujoco_world.storage.run_index import NearCrashThresholds, compact_index, make_row
from mujoco_world.storage.run_record import RECORD_FILE, RunRecord, read_record, write_json, write_text

#: Planner presets of the paper's comparison.
PLANNERS = ("ethical", "selfish", "standard")
#: Scenarios of ``etp demo --quick``.
QUICK_SCENARIOS = ("pedestrian_behind_parked", "tailgater_sudden_stop", "oncoming_drift", "red_light_runner")


@dataclass(frozen=True, slots=True)
class RunTask:
    """One run of a batch.

    Attributes:
        scenario: catalog or generated name, or path to a scenario TOML file.
        planner: planner name (in ``agents.EGO_PLANNERS``, or ``planner_config.name``).
        seed: run seed.
        out: batch output folder (holds the run folders and ``index.jsonl``).
        record: write a Rerun recording.
        keep: "all" or "near_crash" (which recordings to keep).
        planner_config: the ethical planner's configuration to plan with; None resolves
            ``planner`` by name.

    Raises:
        ValueError: a scenario or planner name that cannot name a run, a non-integer
            seed or an unknown ``keep``.
    """

    scenario: str
    planner: str
    seed: int
    out: str
    record: bool = True
    keep: str = "all"
    planner_config: PlannerConfig | None = None

    def __post_init__(self) -> None:
        run_id(self.scenario, self.planner, self.seed, self.planner_config)
        parse_keep(self.keep)

    @property
    def run_id(self) -> str:
        """Id of this run (``run_folder.run_id``)."""
        return run_id(self.scenario, self.planner, self.seed, self.planner_config)

    @property
    def run_dir(self) -> Path:
        """Folder of this run."""
        return run_dir(self.out, self.run_id)

    @property
    def record_path(self) -> Path:
        """Path of this run's record."""
        return self.run_dir / RECORD_FILE


@dataclass(frozen=True, slots=True)
class TaskResult:
    """A task's stored record, and whether it was read from an earlier batch (resumed)."""

    record: RunRecord
    resumed: bool = False


class TaskInterrupted(KeyboardInterrupt):
    """Ctrl-C during a task: the run was closed as failed and indexed, without a record.

    Attributes:
        result: the failed run (a rerun of the batch runs it again).
    """

    def __init__(self, result: TaskResult) -> None:
        super().__init__(result.record.summary.reason)
        self.result = result


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C during a batch, after the runs in flight were closed and the index written.

    Attributes:
        results: the results that exist (finished, resumed, and the runs closed as
            interrupted), in the order of the tasks; runs never started have none.
        total: number of tasks of the batch.
    """

    def __init__(self, results: list[TaskResult], total: int) -> None:
        super().__init__(f"batch interrupted after {len(results)} of {total} runs")
        self.results = results
        self.total = total


def _store(task: RunTask, summary: RunSummary, config: RunConfig | None, **kwargs: Any) -> RunRecord:
    with deferred_interrupts():  # a Ctrl-C never splits a record from its index row
        return store_run(
            summary,
            task.out,
            task.run_id,
            scenario_source=source_of(task.scenario),
            planner_source=source_of(task.planner),
            config=config,
            keep=task.keep,
            **kwargs,
        )


def store_failed(task: RunTask, reason: str, write: bool = True) -> RunRecord:
    """Store a run that could not produce its own summary as failed.

    A recording its process left unfinished (``recording.partial.rrd``, a worker that
    died) is kept as the run's recording (subject to ``task.keep``).

    Args:
        task: the run.
        reason: why it failed.
        write: False indexes it without a record (an interrupted run: a rerun runs it).
    """
    summary = RunSummary(
        scenario=source_key(task.scenario),
        planner=task.planner,
        seed=task.seed,
        outcome="failed",
        reason=reason,
    )
    partial = task.run_dir / PARTIAL_RECORDING_FILE
    return _store(task, summary, None, write=write, recording=partial if partial.is_file() else None)


def _execute(task: RunTask, config: RunConfig | None, observers: Sequence[RunObserver]) -> RunRecord:
    scenario = resolve_scenario(task.scenario)
    recorder = RerunRecorder(task.run_dir, recording_id=task.run_id) if task.record else None
    observer = ObserverGroup([*([recorder] if recorder is not None else []), *observers])
    recording = recorder.path if recorder is not None else None
    config = config or RunConfig()
    planner = task.planner_config if task.planner_config is not None else task.planner
    try:
        summary = run_scenario(scenario, planner, task.seed, config, observer)
    except RunInterrupted as interrupted:
        # Indexed as failed with its recording, but no record: a rerun runs it again.
        record = _store(task, interrupted.summary, config, recording=recording, write=False)
        raise TaskInterrupted(TaskResult(record)) from None
    return _store(task, summary, config, recording=recording)


def _interrupted(task: RunTask) -> TaskInterrupted:
    return TaskInterrupted(TaskResult(store_failed(task, "interrupted before the run started", write=False)))


def run_task(
    task: RunTask,
    config: RunConfig | None = None,
    resume: bool = True,
    observers: Sequence[RunObserver] = (),
    retry_failed: bool = False,
) -> TaskResult:
    """Run one task and store it (or, with ``resume``, read its existing record).

    Args:
        task: the run.
        config: loop settings.
        resume: return the existing record of the run instead of running it again.
        observers: more observers of the run (in this process), after the recorder.
        retry_failed: with ``resume``, run a run whose record says ``failed`` again.

    Never raises for a failing run: the failure is stored as the run's record.

    Raises:
        TaskInterrupted: Ctrl-C; the run was indexed as failed (its recording kept)
            without a record, so a rerun runs it again.
    """
    if resume and task.record_path.exists():
        try:
            record = read_record(task.record_path)
        except ValueError:
            pass  # a damaged record (or another version's) is run again
        else:
            if not (retry_failed and record.summary.outcome == "failed"):
                return TaskResult(record, resumed=True)
    try:
        return TaskResult(_execute(task, config, observers))
    except TaskInterrupted:
        raise
    except KeyboardInterrupt:
        raise _interrupted(task) from None
    except Exception as error:  # noqa: BLE001 - recorded, the batch goes on
        return TaskResult(store_failed(task, f"{type(error).__name__}: {error}"))


def _run_task_in_worker(job: tuple[RunTask, RunConfig | None, bool]) -> TaskResult:
    task, config, retry_failed = job
    try:
        return run_task(task, config, retry_failed=retry_failed)
    except TaskInterrupted as interrupted:
        return interrupted.result  # the worker leaves after answering (experiments.workers)


def make_tasks(
    scenarios: Sequence[str],
    planners: Sequence[str | PlannerConfig],
    seeds: Sequence[int],
    out: str | Path,
    record: bool = True,
    keep: str = "all",
) -> list[RunTask]:
    """All combinations, scenario-major; ``record``/``keep`` as in ``RunTask``.

    ``planners`` are planner names or configurations (run under their ``name``).
    """
    named = [(p, None) if isinstance(p, str) else (p.name, p) for p in planners]
    return [
        RunTask(s, name, int(seed), str(out), record, keep, config)
        for s in scenarios
        for seed in seeds
        for name, config in named
    ]


def check_unique(tasks: Sequence[RunTask]) -> None:
    """Refuse a batch in which two tasks would write one run folder.

    Raises:
        ValueError: tasks that share a run id (the same scenario file named twice, a
            scenario listed twice); the message names them.
    """
    seen: dict[tuple[str, str], RunTask] = {}
    for task in tasks:
        key = (str(Path(task.out).resolve()), task.run_id)
        first = seen.setdefault(key, task)
        if first is not task:
            raise ValueError(
                f"tasks: {first.scenario!r} and {task.scenario!r} with planner {task.planner!r} and "
                f"seed {task.seed} are one run ({task.run_id}); a batch runs each run once"
            )


def run_batch(
    tasks: Sequence[RunTask],
    workers: int = 2,
    config: RunConfig | None = None,
    progress: bool = True,
    on_result: Callable[[TaskResult], None] | None = None,
    worker_initializer: Callable[[], object] | None = None,
    retry_failed: bool = False,
) -> list[TaskResult]:
    """Run tasks on ``workers`` processes (1: in this process) and return their results.

    Args:
        tasks: the runs (each run id once).
        workers: number of worker processes; 1 runs in this process (no protection
            against a crash in native code).
        config: loop settings for every run.
        progress: show a tqdm progress bar.
        on_result: called with each result as it completes.
        worker_initializer: called once in each worker process before its first run
            (the command line passes its process tuning); must be picklable.
        retry_failed: run the runs whose stored record says ``failed`` again.

    Returns:
        Results in the order of ``tasks``.

    Raises:
        ValueError: tasks sharing a run id, or another batch writing to an output folder.
        BatchInterrupted: Ctrl-C, after the runs in flight were closed as failed and
            the index was written; it carries the results that exist.
    """
    check(isinstance(workers, int) and workers >= 1, f"workers must be >= 1, got {workers!r}")
    check_unique(tasks)
    from tqdm import tqdm

    results: dict[int, TaskResult] = {}
    with ExitStack() as stack:
        for out in sorted({str(Path(t.out)) for t in tasks}):
            stack.enter_context(root_lock(out))
        bar = tqdm(total=len(tasks), disable=not progress, unit="run", dynamic_ncols=True)
        stack.callback(bar.close)

        def done(index: int, result: TaskResult) -> None:
            results[index] = result
            bar.update(1)
            summary = result.record.summary
            bar.set_postfix_str(f"{summary.scenario}/{summary.planner}: {summary.outcome}")
            if on_result is not None:
                on_result(result)

        def lost(index: int, why: str) -> None:
            task = tasks[index]
            if why == INTERRUPTED:
                done(index, _interrupted(task).result)
            else:
                done(index, TaskResult(store_failed(task, why)))

        try:
            if workers == 1 or len(tasks) <= 1:
                for index, task in enumerate(tasks):
                    try:
                        done(index, run_task(task, config, retry_failed=retry_failed))
                    except TaskInterrupted as interrupted:
                        done(index, interrupted.result)
                        raise
            else:
                jobs = [(i, (task, config, retry_failed)) for i, task in enumerate(tasks)]
                run_jobs(jobs, _run_task_in_worker, workers, done, lost, worker_initializer)
        except KeyboardInterrupt:
            _compact(tasks, results)
            raise BatchInterrupted([results[i] for i in sorted(results)], len(tasks)) from None
        _compact(tasks, results)
    return [results[i] for i in range(len(tasks))]


def _compact(tasks: Sequence[RunTask], results: dict[int, TaskResult]) -> None:
    """Rewrite each output folder's index: one row per run, this batch's in task order."""
    by_out: dict[str, list[RunRecord]] = {}
    for index in sorted(results):
        by_out.setdefault(tasks[index].out, []).append(results[index].record)
    with deferred_interrupts():
        for out, records in by_out.items():
            compact_index(out, [make_row(r) for r in records])


# --------------------------------------------------------------------------- reporting


def _fmt(value: Any, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}"


#: Clearance to a vulnerable road user below which a goal is not a clean one [m]
#: (``run_index.NearCrashThresholds.vulnerable_clearance``).
VULNERABLE_CLEARANCE = NearCrashThresholds().vulnerable_clearance


def _finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None


def aggregate_row(record: RunRecord) -> dict[str, Any]:
    """The compact JSON row of a run in ``aggregate.json``.

    ``collisions`` counts all of them; ``ego_collisions`` those the ego took part in
    (a crash), ``third_party_collisions`` those between others. ``harm`` sums over all
    collisions, ``harm_ego_involved`` and ``harm_third_party`` split it.
    """
    s = record.summary
    return {
        "run_id": record.run_id,
        "scenario": s.scenario,
        "planner": s.planner,
        "seed": s.seed,
        "outcome": s.outcome,
        "reason": s.reason,
        "duration": s.duration,
        "collisions": len(s.collisions),
        "ego_collisions": len(s.ego_collisions),
        "third_party_collisions": len(s.third_party_collisions),
        "ego_collided": s.ego_collided,
        "max_risk": dict(s.max_risk),
        "harm": dict(s.harm),
        "harm_ego_involved": dict(s.harm_ego_involved),
        "harm_third_party": dict(s.harm_third_party),
        "min_distance": _finite_or_none(s.min_distance),
        "min_distance_vulnerable": _finite_or_none(s.min_distance_vulnerable),
        "clearance_vulnerable": dict(s.clearance_vulnerable),
        "avoidable": record.avoidability.avoidable if record.avoidability is not None else None,
        "avoidance": (
            record.avoidability.best.manoeuvre.describe()
            if record.avoidability is not None and record.avoidability.best is not None
            else None
        ),
        "verdict": s.verdict,
        "failed_expectations": [e.name for e in s.expectations if not e.passed],
        "wall_time": s.timings.get("total"),
    }


def _outcome_label(s: RunSummary) -> str:
    """The outcome, with ``goal~`` for a goal that passed a vulnerable road user too closely."""
    close = math.isfinite(s.min_distance_vulnerable) and s.min_distance_vulnerable < VULNERABLE_CLEARANCE
    return "goal~" if s.outcome == "goal" and close else s.outcome


def _avoidable(record: RunRecord) -> str:
    """``yes``/``no`` for a searched ego collision, ``?`` for an unsearched one, ``-`` without."""
    if record.avoidability is not None:
        return "yes" if record.avoidability.avoidable else "no"
    return "?" if record.summary.ego_collisions else "-"


def _table_line(record: RunRecord) -> str:
    s = record.summary
    risk, harm = s.max_risk, s.harm_ego_involved
    third_harm = sum(v for v in s.harm_third_party.values() if math.isfinite(v))
    return (
        f"{s.scenario:<30} {s.planner:<9} {s.seed!s:>4} {_outcome_label(s):<14} "
        f"{_fmt(s.duration, 1):>6} {len(s.ego_collisions):>3} {len(s.third_party_collisions):>3} "
        f"{_fmt(risk.get('ego')):>8} {_fmt(risk.get('third_party')):>7} "
        f"{_fmt(risk.get('vulnerable')):>7} "
        f"{_fmt(harm.get('ego'), 3):>7} {_fmt(harm.get('third_party'), 3):>6} "
        f"{_fmt(harm.get('vulnerable'), 3):>6} {_fmt(third_harm, 3):>7} "
        f"{_fmt(s.min_distance, 2):>6} {_fmt(s.min_distance_vulnerable, 2):>6} {_avoidable(record):>5} "
        f"{_VERDICT_CELL[s.verdict]:<6}"
    )


def _planner_totals(planner: str, records: Sequence[RunRecord]) -> str:
    mine = [r.summary for r in records]
    counts = {o: sum(1 for s in mine if s.outcome == o) for o in OUTCOMES}
    verdicts = [_avoidable(r) for r in records]
    close = sum(1 for s in mine if _outcome_label(s) == "goal~")
    finished = [s for s in mine if s.outcome != "failed"]  # a failed run has no risk, not 0
    mean_risk = {g: _mean([s.max_risk.get(g, math.nan) for s in finished]) for g in GROUPS}
    nothing = math.nan if not finished else 0.0
    harm = {g: math.fsum(s.harm_ego_involved.get(g, 0.0) for s in finished) + nothing for g in GROUPS}
    third = sum(len(s.third_party_collisions) for s in mine)
    third_harm = math.fsum(math.fsum(s.harm_third_party.values()) for s in finished) + nothing
    return (
        f"  {planner:<9} {len(mine):>3} runs  "
        + " ".join(f"{k} {v}" for k, v in counts.items())
        + f" (goal~ {close}; ego collisions avoidable {verdicts.count('yes')}, not avoidable "
        + f"{verdicts.count('no')}, not searched {verdicts.count('?')})  3rd-party collisions {third}"
        + f"  | max risk ego {_fmt(mean_risk['ego'])} 3rd {_fmt(mean_risk['third_party'])} "
        + f"VRU {_fmt(mean_risk['vulnerable'])}"
        + f"  | ego-involved harm ego {_fmt(harm['ego'], 3)} 3rd {_fmt(harm['third_party'], 3)} "
        + f"VRU {_fmt(harm['vulnerable'], 3)}"
        + f"  | 3rd-party harm {_fmt(third_harm, 3)}"
    )


def suite_result(records: Iterable[RunRecord]) -> dict[str, int]:
    """The batch as a test suite: runs whose scenario expectations pass, fail, or that expect nothing."""
    verdicts = [r.summary.verdict for r in records]
    return {v: verdicts.count(v) for v in ("pass", "fail", "none")}


_VERDICT_CELL = {"pass": "pass", "fail": "FAIL", "none": "-"}


def comparison_table(records: Iterable[RunRecord]) -> str:
    """Plain-text table: one line per run, then per-planner totals (paper Figs. 5, 6).

    A crash is an ego-involved collision; collisions between other road users are
    counted and their harm summed apart ("3rd" columns).
    """
    runs = sorted(records, key=lambda r: (r.summary.scenario, r.summary.planner, r.summary.seed))
    head = (
        f"{'scenario':<30} {'planner':<9} {'seed':>4} {'outcome':<14} {'t [s]':>6} {'ego':>3} {'3rd':>3} "
        f"{'risk ego':>8} {'3rd':>7} {'VRU':>7} {'harm ego':>7} {'3rd':>6} {'VRU':>6} {'3rd-pty':>7} "
        f"{'min d':>6} {'VRU d':>6} {'avoid':>5} {'expect':<6}"
    )
    lines = [head, "-" * len(head)]
    lines += [_table_line(s) for s in runs]
    lines += [
        "",
        "ego / 3rd: ego-involved / third-party collisions; risk: highest risk per group along the "
        "executed plans;",
        "harm ego 3rd VRU: measured harm per group in the ego's collisions; 3rd-pty: measured harm in "
        "third-party collisions;",
        f"min d / VRU d: smallest ego distance to any road user / a vulnerable one [m]; goal~: a goal "
        f"passing a vulnerable road user closer than {VULNERABLE_CLEARANCE} m;",
        "avoid: the ego collision was avoidable by an open-loop manoeuvre (etp avoidability; ?: not "
        "searched, -: no ego collision); expect: the scenario's [expect] table passed or FAILED",
        "",
        "test suite (scenario [expect] tables): pass / fail / no expectations",
    ]
    for planner in sorted({r.summary.planner for r in runs}):
        verdicts = [r.summary.verdict for r in runs if r.summary.planner == planner]
        failing = sorted(
            {r.summary.scenario for r in runs if r.summary.planner == planner and r.summary.verdict == "fail"}
        )
        lines.append(
            f"  {planner:<9} {verdicts.count('pass'):>3} pass {verdicts.count('fail'):>3} fail "
            f"{verdicts.count('none'):>3} none" + (f"  | failing: {', '.join(failing)}" if failing else "")
        )
    lines += [
        "",
        "per planner: runs, outcomes; mean of max risk per group and summed measured harm per group "
        "over the runs that did not fail",
    ]
    for planner in sorted({r.summary.planner for r in runs}):
        lines.append(_planner_totals(planner, [r for r in runs if r.summary.planner == planner]))
    return "\n".join(lines)


def _mean(values: Sequence[float]) -> float:
    """Mean of the finite values (nan if there is none)."""
    finite = [v for v in values if math.isfinite(v)]
    return math.fsum(finite) / len(finite) if finite else math.nan


def aggregate_rows(results: Sequence[TaskResult]) -> list[dict[str, Any]]:
    """The ``runs`` of ``aggregate.json``: one compact row per result (``skipped`` if resumed)."""
    return [{**aggregate_row(r.record), **({"skipped": True} if r.resumed else {})} for r in results]


def write_aggregate(out: str | Path, results: Sequence[TaskResult], wall_time: float) -> Path:
    """Write ``aggregate.json`` and ``table.txt`` into ``out``; return the JSON path."""
    out = Path(out)
    runs = aggregate_rows(results)
    path = write_json(
        out / "aggregate.json",
        {
            "runs": runs,
            "suite": suite_result(r.record for r in results),
            "wall_time": wall_time,
            "written": time.strftime("%Y-%m-%dT%H:%M:%S"),
        },
    )
    write_text(out / "table.txt", comparison_table(r.record for r in results) + "\n")
    return path
