"""Batches of closed-loop runs on several cores, resumable, with a comparison table.

Every run is stored by ``mujoco_world.storage.run_folder``: its record in
``<out>/<run id>/summary.json`` (``run_folder.run_id``), its row in
``<out>/index.jsonl``. A run whose record exists is skipped, so an interrupted batch
resumes where it stopped. A run that fails (in the planner, the physics, or even a
crashed worker process) is stored as ``outcome = "failed"`` with the reason, and the
batch goes on. Workers are started with the ``spawn`` method, so the module is safe on
every platform. ``etp run`` is a batch of one task.
"""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ethical_planner.config import PlannerConfig
from ethical_planner.validation import check
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.observers import ObserverGroup, RunObserver
from mujoco_world.loop.runner import RunInterrupted, run_scenario
from mujoco_world.loop.summary import GROUPS, OUTCOMES, RunSummary
from mujoco_world.scenario.sources import resolve_scenario
from mujoco_world.storage.recording import RerunRecorder
from mujoco_world.storage.run_folder import parse_keep, run_dir, run_id, source_key, source_of, store_run
from mujoco_world.storage.run_index import NearCrashThresholds
from mujoco_world.storage.run_record import RECORD_FILE, RunRecord, read_record, write_json

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


def _store(task: RunTask, summary: RunSummary, config: RunConfig | None, **kwargs: Any) -> RunRecord:
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


def store_failed(task: RunTask, reason: str) -> RunRecord:
    """Store a run that could not produce its own summary as failed."""
    summary = RunSummary(
        scenario=source_key(task.scenario),
        planner=task.planner,
        seed=task.seed,
        outcome="failed",
        reason=reason,
    )
    return _store(task, summary, None)


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
        _store(task, interrupted.summary, config, recording=recording, write=False)
        raise
    return _store(task, summary, config, recording=recording)


def run_task(
    task: RunTask,
    config: RunConfig | None = None,
    resume: bool = True,
    observers: Sequence[RunObserver] = (),
) -> TaskResult:
    """Run one task and store it (or, with ``resume``, read its existing record).

    Args:
        task: the run.
        config: loop settings.
        resume: return the existing record of the run instead of running it again.
        observers: more observers of the run (in this process), after the recorder.

    Never raises for a failing run: the failure is stored as the run's record.
    Ctrl-C (``RunInterrupted``) indexes the run as failed, keeps its recording but
    writes no record (a rerun runs it again), and propagates.
    """
    if resume and task.record_path.exists():
        try:
            return TaskResult(read_record(task.record_path), resumed=True)
        except ValueError:
            pass  # a damaged record (or another version's) is run again
    try:
        return TaskResult(_execute(task, config, observers))
    except Exception as error:  # noqa: BLE001 - recorded, the batch goes on
        return TaskResult(store_failed(task, f"{type(error).__name__}: {error}"))


def _run_task_in_worker(task: RunTask, config: RunConfig | None) -> TaskResult:
    return run_task(task, config)


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


def run_batch(
    tasks: Sequence[RunTask],
    workers: int = 2,
    config: RunConfig | None = None,
    progress: bool = True,
    on_result: Callable[[TaskResult], None] | None = None,
    worker_initializer: Callable[[], object] | None = None,
) -> list[TaskResult]:
    """Run tasks on ``workers`` processes (1: in this process) and return their results.

    Args:
        tasks: the runs.
        workers: number of processes.
        config: loop settings for every run.
        progress: show a tqdm progress bar.
        on_result: called with each result as it completes.
        worker_initializer: called once in each worker process before its first run
            (the command line passes its process tuning); must be picklable.

    Returns:
        Results in the order of ``tasks``.
    """
    check(isinstance(workers, int) and workers >= 1, f"workers must be >= 1, got {workers!r}")
    from tqdm import tqdm

    results: dict[int, TaskResult] = {}
    bar = tqdm(total=len(tasks), disable=not progress, unit="run", dynamic_ncols=True)

    def done(index: int, result: TaskResult) -> None:
        results[index] = result
        bar.update(1)
        summary = result.record.summary
        bar.set_postfix_str(f"{summary.scenario}/{summary.planner}: {summary.outcome}")
        if on_result is not None:
            on_result(result)

    pending = list(enumerate(tasks))
    if workers == 1 or len(pending) <= 1:
        for index, task in pending:
            done(index, run_task(task, config))
    else:
        context = multiprocessing.get_context("spawn")
        while pending:
            with ProcessPoolExecutor(
                max_workers=workers, mp_context=context, initializer=worker_initializer
            ) as pool:
                futures = {pool.submit(_run_task_in_worker, task, config): (i, task) for i, task in pending}
                broken: list[tuple[int, RunTask]] = []
                for future in as_completed(futures):
                    index, task = futures[future]
                    try:
                        done(index, future.result())
                    except BrokenProcessPool:
                        broken.append((index, task))
                    except Exception as error:  # noqa: BLE001
                        reason = f"worker raised {type(error).__name__}: {error}"
                        done(index, TaskResult(store_failed(task, reason)))
            pending = []
            if broken:
                # A worker died (e.g. a crash in native code): the first unfinished task
                # is recorded as failed, the others are retried in a fresh pool.
                broken.sort()
                index, task = broken[0]
                done(index, TaskResult(store_failed(task, "worker process died while running this task")))
                pending = broken[1:]
    bar.close()
    return [results[i] for i in range(len(tasks))]


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
        f"{s.scenario:<30} {s.planner:<9} {s.seed!s:>4} {_outcome_label(s):<8} "
        f"{_fmt(s.duration, 1):>6} {len(s.ego_collisions):>3} {len(s.third_party_collisions):>3} "
        f"{_fmt(risk.get('ego')):>8} {_fmt(risk.get('third_party')):>7} "
        f"{_fmt(risk.get('vulnerable')):>7} "
        f"{_fmt(harm.get('ego'), 3):>7} {_fmt(harm.get('third_party'), 3):>6} "
        f"{_fmt(harm.get('vulnerable'), 3):>6} {_fmt(third_harm, 3):>7} "
        f"{_fmt(s.min_distance, 2):>6} {_fmt(s.min_distance_vulnerable, 2):>6} {_avoidable(record):>5}"
    )


def _planner_totals(planner: str, records: Sequence[RunRecord]) -> str:
    mine = [r.summary for r in records]
    counts = {o: sum(1 for s in mine if s.outcome == o) for o in OUTCOMES}
    verdicts = [_avoidable(r) for r in records]
    close = sum(1 for s in mine if _outcome_label(s) == "goal~")
    mean_risk = {g: sum(s.max_risk.get(g, 0.0) for s in mine) / max(len(mine), 1) for g in GROUPS}
    harm = {g: sum(s.harm_ego_involved.get(g, 0.0) for s in mine) for g in GROUPS}
    third = sum(len(s.third_party_collisions) for s in mine)
    third_harm = sum(sum(s.harm_third_party.values()) for s in mine)
    return (
        f"  {planner:<9} {len(mine):>3} runs  "
        + " ".join(f"{k} {v}" for k, v in counts.items())
        + f" (goal~ {close}; ego collisions avoidable {verdicts.count('yes')}, not avoidable "
        + f"{verdicts.count('no')}, not searched {verdicts.count('?')})  3rd-party collisions {third}"
        + "  | max risk ego {ego:.4f} 3rd {third_party:.4f} VRU {vulnerable:.4f}".format(**mean_risk)
        + "  | ego-involved harm ego {ego:.3f} 3rd {third_party:.3f} VRU {vulnerable:.3f}".format(**harm)
        + f"  | 3rd-party harm {third_harm:.3f}"
    )


def comparison_table(records: Iterable[RunRecord]) -> str:
    """Plain-text table: one line per run, then per-planner totals (paper Figs. 5, 6).

    A crash is an ego-involved collision; collisions between other road users are
    counted and their harm summed apart ("3rd" columns).
    """
    runs = sorted(records, key=lambda r: (r.summary.scenario, r.summary.planner, r.summary.seed))
    head = (
        f"{'scenario':<30} {'planner':<9} {'seed':>4} {'outcome':<8} {'t [s]':>6} {'ego':>3} {'3rd':>3} "
        f"{'risk ego':>8} {'3rd':>7} {'VRU':>7} {'harm ego':>7} {'3rd':>6} {'VRU':>6} {'3rd-pty':>7} "
        f"{'min d':>6} {'VRU d':>6} {'avoid':>5}"
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
        "searched, -: no ego collision)",
        "",
        "per planner: runs, outcomes, mean of max risk per group, summed measured harm per group",
    ]
    for planner in sorted({r.summary.planner for r in runs}):
        lines.append(_planner_totals(planner, [r for r in runs if r.summary.planner == planner]))
    return "\n".join(lines)


def aggregate_rows(results: Sequence[TaskResult]) -> list[dict[str, Any]]:
    """The ``runs`` of ``aggregate.json``: one compact row per result (``skipped`` if resumed)."""
    return [{**aggregate_row(r.record), **({"skipped": True} if r.resumed else {})} for r in results]


def write_aggregate(out: str | Path, results: Sequence[TaskResult], wall_time: float) -> Path:
    """Write ``aggregate.json`` and ``table.txt`` into ``out``; return the JSON path."""
    out = Path(out)
    runs = aggregate_rows(results)
    path = write_json(
        out / "aggregate.json",
        {"runs": runs, "wall_time": wall_time, "written": time.strftime("%Y-%m-%dT%H:%M:%S")},
    )
    (out / "table.txt").write_text(comparison_table(r.record for r in results) + "\n", encoding="utf-8")
    return path
