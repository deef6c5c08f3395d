"""``etp study``: the paper's experiment on a folder of scenarios, with its figures and report.

A study is a batch (``mujoco_world.experiments.batch``): every scenario x planner x seed
is a ``RunTask`` stored in ``<out>/<run id>/summary.json`` with a row in
``<out>/index.jsonl``, so a study resumes where it stopped, a failed run (a scenario the
importer refuses, an error in the planner or the physics, a crashed worker) is stored
with its reason and the study goes on. Two backends run the same tasks
(``STUDY_BACKENDS``):

* ``process`` (default): a local process pool (``run_batch``);
* ``dask``: a Dask ``distributed`` cluster: a ``LocalCluster`` on 127.0.0.1 by default,
  or a running scheduler (``scheduler="tcp://host:8786"``). Its workers must see ``out``
  and the scenario files under the same paths (a shared file system), since each
  worker writes its run's folder itself.

After the runs, ``write_study`` reads every record of the tasks back, analyses them
(``analysis.analyse``) and writes ``statistics.json``, ``fig5_risks.png/.pdf``,
``fig6_harm.png/.pdf``, ``table.txt``, ``aggregate.json`` and ``report.md``.
"""

from __future__ import annotations

import math
import re
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ethical_planner.registry import Registry
from ethical_planner.road_users import RoadUserType
from ethical_planner.validation import check
from harm_calibration.study.analysis import (
    BodyHarm,
    GroupDefinition,
    StudyAnalysis,
    StudyRun,
    analyse,
    to_plain_analysis,
)
from harm_calibration.study.attribution import REPLAY, attribute
from harm_calibration.study.figures import figure_harm, figure_risks
from harm_calibration.study.report import render
from mujoco_world.experiments.batch import (
    RunTask,
    TaskResult,
    run_batch,
    run_task,
    store_failed,
    write_aggregate,
)
from mujoco_world.loop.config import RunConfig
from mujoco_world.scenario.commonroad import REJECTION_REASONS, rejection_reason
from mujoco_world.storage.run_record import RunRecord, read_record, write_json

#: The paper's study: about 48 h on 10 threads with a GPU for 2000 scenarios x 3 planners.
PAPER_RUNS = 2000 * 3


@dataclass(frozen=True, slots=True)
class BackendOptions:
    """How a backend runs the tasks.

    Attributes:
        workers: processes (process pool, or the LocalCluster's workers).
        scheduler: address of a running Dask scheduler (dask only; None: a LocalCluster
            on 127.0.0.1).
        progress: show a progress bar.
        worker_initializer: called once in each pool worker (process backend).
    """

    workers: int = 2
    scheduler: str | None = None
    progress: bool = True
    worker_initializer: Callable[[], object] | None = None


def _process_backend(
    tasks: Sequence[RunTask], config: RunConfig | None, options: BackendOptions
) -> list[TaskResult]:
    return run_batch(
        tasks,
        workers=options.workers,
        config=config,
        progress=options.progress,
        worker_initializer=options.worker_initializer,
    )


def _dask_backend(
    tasks: Sequence[RunTask], config: RunConfig | None, options: BackendOptions
) -> list[TaskResult]:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise ValueError(
            "the dask backend needs Dask distributed: pip install 'distributed>=2024.8'"
        ) from None
    from tqdm import tqdm

    results: dict[int, TaskResult] = {}
    todo = []
    for index, task in enumerate(tasks):
        resumed = _resumed(task)
        if resumed is not None:
            results[index] = resumed
        else:
            todo.append((index, task))
    bar = tqdm(total=len(tasks), initial=len(results), disable=not options.progress, unit="run")
    cluster = None
    if options.scheduler is None:
        cluster = LocalCluster(
            n_workers=options.workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
        )
    client = Client(cluster if cluster is not None else options.scheduler)
    try:
        futures = {
            client.submit(run_task, task, config, pure=False, key=f"etp-{task.run_id}"): (index, task)
            for index, task in todo
        }
        for future in as_completed(futures):
            index, task = futures[future]
            try:
                result = future.result()
            except Exception as error:  # noqa: BLE001 - e.g. KilledWorker: recorded, the study goes on
                result = TaskResult(store_failed(task, f"worker failed: {type(error).__name__}: {error}"))
            results[index] = result
            bar.update(1)
            summary = result.record.summary
            bar.set_postfix_str(f"{summary.scenario}/{summary.planner}: {summary.outcome}")
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
        bar.close()
    return [results[i] for i in range(len(tasks))]


def _resumed(task: RunTask) -> TaskResult | None:
    if not task.record_path.exists():
        return None
    try:
        return TaskResult(read_record(task.record_path), resumed=True)
    except ValueError:
        return None  # a damaged record is run again


def _analyse_only(
    tasks: Sequence[RunTask], config: RunConfig | None, options: BackendOptions
) -> list[TaskResult]:
    """The tasks that already have a record (nothing is run)."""
    found = [_resumed(task) for task in tasks]
    return [r for r in found if r is not None]


#: Study backends: name -> function(tasks, config, options) -> results in task order.
STUDY_BACKENDS: Registry = Registry("study backend")
STUDY_BACKENDS.register("process", _process_backend)
STUDY_BACKENDS.register("dask", _dask_backend)
#: Reads the runs already stored and runs nothing (``etp study --analyse-only``).
STUDY_BACKENDS.register("none", _analyse_only)


def run_tasks(
    tasks: Sequence[RunTask],
    backend: str = "process",
    config: RunConfig | None = None,
    options: BackendOptions | None = None,
) -> list[TaskResult]:
    """Run (or resume) a study's tasks on ``backend``; results in task order.

    Backend "none" runs nothing and returns the tasks that already have a record.

    Raises:
        ValueError: an unknown backend (the allowed ones listed), a scheduler with the
            process backend, or fewer than one worker.
    """
    options = options or BackendOptions()
    check(options.workers >= 1, f"workers must be >= 1, got {options.workers}")
    run = STUDY_BACKENDS.get(backend)
    check(options.scheduler is None or backend == "dask", "a scheduler address needs the dask backend")
    return run(tasks, config, options)


# --------------------------------------------------------------------------- records -> study runs


def _behaviours(record: RunRecord) -> dict[int, str | None]:
    """Entity -> how the body moved (``BodyRecord.behaviour``).

    Records written before bodies carried their behaviour (None) are read by the
    importer's rule: every dynamic obstacle of a CommonRoad file replays its recording,
    its static obstacles are parked.
    """
    s = record.summary
    commonroad = str(record.scenario_source or "").split("#")[0].endswith(".xml")
    out: dict[int, str | None] = {}
    for body in s.bodies:
        behaviour = body.behaviour
        if behaviour is None and body.id != 0 and commonroad:
            behaviour = "parked" if body.type is RoadUserType.PARKED_VEHICLE else REPLAY
        out[body.id] = behaviour
    return out


def _scenario_key(record: RunRecord) -> str:
    """The scenario part of the run id: one per scenario file (``run_folder.run_id``).

    Not the scenario's name: two files may carry one benchmark id (``ZAM_Tutorial-1_1_T-1``
    in ZAM_Tutorial-1_1_T-1.xml and ZAM_Tutorial-1_2_T-1.xml), and pairing their runs as one
    scenario would mix two experiments.
    """
    parts = record.run_id.rsplit("__", 2)
    return parts[0] if len(parts) == 3 else record.summary.scenario


def study_run(record: RunRecord) -> StudyRun:
    """What the analysis needs of one run record."""
    s = record.summary
    ego_collisions = sorted(s.ego_collisions, key=lambda c: c.measurement.time)
    crash = attribute(ego_collisions[0], _behaviours(record)) if ego_collisions else None
    harms = []
    for impact in s.collisions:
        for body, comparison in ((impact.measurement.a, impact.a), (impact.measurement.b, impact.b)):
            if comparison.group == "static":
                kind = "static"
            elif body.entity == 0:
                kind = "ego"
            else:
                kind = str(body.type)
            harms.append(BodyHarm(kind, float(comparison.harm_measured), impact.involves_ego))
    rejected = rejection_reason(s.reason) if s.outcome == "failed" else None
    return StudyRun(
        run_id=record.run_id,
        scenario=_scenario_key(record),
        planner=s.planner,
        seed=s.seed,
        outcome=s.outcome,
        reason=s.reason,
        rejected=rejected,
        distance=float(s.progress) if math.isfinite(s.progress) else 0.0,
        duration=float(s.duration),
        wall_time=float(s.timings.get("total", math.nan)),
        risks={k: tuple(v) for k, v in s.top_risks_by_type.items()},
        ego_risks={k: tuple(v) for k, v in s.top_ego_risks_by_type.items()},
        ego_collided=s.ego_collided,
        crash=crash,
        harms=tuple(harms),
        avoidable=record.avoidability.avoidable if record.avoidability is not None else None,
    )


# --------------------------------------------------------------------------- outputs


def _refusal_detail(reason: str) -> str:
    """An import refusal's message without the exception name, the file path and the key."""
    detail = reason.split(": ", 1)[1] if reason.startswith("CommonRoadImportError: ") else reason
    head, sep, rest = detail.partition(": ")
    if sep and head.endswith(".xml"):
        detail = rest
    return re.sub(r"\s*\[rejected: [a-z_]+\]\s*$", "", detail)


DIFFERENCES = (
    "- **Harm** is measured: the CRSS harm model evaluated at the delta-v and impact area "
    "the MuJoCo contact physics produced, not the model's harm at a kinematic overlap of "
    "footprints. Summed harm counts expected MAIS3+ injuries.",
    "- **Road users** follow their recordings through our tracking controllers (they do not "
    "react to the ego), as the paper's recorded scenarios do; after a contact they are "
    "physical bodies.",
    "- **Risk** values are the planner's own R_k (road users) and R_ego,k (the ego, per "
    "partner) of the chosen plan of every planning cycle, as in the reference evaluation.",
    "- **Crashes per 1000 km** count runs with an ego-involved collision over the ego's "
    "distance along its route.",
    "- **Avoidability**: where `etp avoidability` has run on the study's runs (it stores its "
    "verdict in each run record), Fig. 6 and the table split ego crashes into avoidable and "
    "unavoidable; otherwise they are not marked.",
)


def _speed_lines(results: Sequence[TaskResult], wall: float, workers: int, backend: str) -> list[str]:
    fresh = [r for r in results if not r.resumed]
    lines = [f"- Backend {backend}, {workers} worker(s); wall time of this invocation {wall:.0f} s."]
    if fresh and wall > 0:
        rate = len(fresh) / (wall / 60.0)
        hours = PAPER_RUNS / rate / 60.0
        lines.append(
            f"- {len(fresh)} runs in this invocation: {rate:.2f} runs per minute; the paper's "
            f"2000 x 3 study would take about {hours:.0f} h at this rate (the paper: about 48 h on "
            "10 threads with a GPU)."
        )
        simulated = sum(r.record.summary.duration for r in fresh)
        lines.append(
            f"- {simulated:.0f} s simulated in total ({simulated / wall:.2f} s simulated per wall second)."
        )
    else:
        lines.append("- Every run was resumed from an earlier invocation: no speed measured here.")
    return lines


def _spec_lines(
    runs: Sequence[StudyRun], analysis: StudyAnalysis, planners: Sequence[str], groups: GroupDefinition
) -> tuple[list[str], dict[str, list[str]]]:
    """The report's opening lines (what ran, what failed and why) and the refusals by reason."""
    rejected: dict[str, list[str]] = defaultdict(list)
    details = {r.scenario: _refusal_detail(r.reason) for r in runs if r.rejected is not None}
    for scenario, reason in analysis.rejected.items():
        label = f"{reason} ({REJECTION_REASONS.get(reason, reason)})"
        rejected[label].append(f"{scenario}: {details[scenario]}")
    failed = [r for r in runs if r.outcome == "failed" and r.rejected is None]
    by_scenario: dict[str, list[StudyRun]] = defaultdict(list)
    for r in runs:
        by_scenario[r.scenario].append(r)
    seeds = sorted({r.seed for r in runs})
    every = {(p, seed) for p in planners for seed in seeds}
    complete = sum(
        1
        for rs in by_scenario.values()
        if {(r.planner, r.seed) for r in rs} >= every and all(r.outcome != "failed" for r in rs)
    )
    partial = sum(1 for rs in by_scenario.values() if not {(r.planner, r.seed) for r in rs} >= every)
    spec = [
        f"{len(runs)} runs: {len(by_scenario)} scenarios x {len(planners)} planners "
        f"({', '.join(planners)}) x seeds {', '.join(map(str, seeds))}; {complete} scenarios ran with "
        f"every planner, {len({r.scenario for r in failed})} had a run that failed in the world, "
        f"{len(analysis.rejected)} were refused at import"
        + (f", {partial} lack a run (the study has not finished them)" if partial else "")
        + f". {groups.describe()}.",
    ]
    if failed:
        spec += ["", "Runs that failed in the world:", ""]
        spec += [f"- {r.scenario} / {r.planner} / seed {r.seed}: {r.reason}" for r in failed]
    return spec, dict(rejected)


def write_study(
    out: str | Path,
    results: Sequence[TaskResult],
    planners: Sequence[str],
    wall: float,
    *,
    groups: GroupDefinition | None = None,
    workers: int = 2,
    backend: str = "process",
    resamples: int = 2000,
) -> dict[str, Path]:
    """Analyse the study's runs and write its statistics, figures, table and report.

    Returns:
        Output name -> path (statistics, fig5 png/pdf, fig6 png/pdf, report, aggregate).
    """
    out = Path(out)
    groups = groups or GroupDefinition()
    runs = [study_run(r.record) for r in results]
    analysis = analyse(runs, planners, groups, resamples=resamples)
    paths: dict[str, Path] = {"aggregate": write_aggregate(out, results, wall)}
    plain = to_plain_analysis(analysis)
    plain["failed"] = [
        {"run_id": r.run_id, "reason": r.reason} for r in runs if r.outcome == "failed" and r.rejected is None
    ]
    paths["statistics"] = write_json(out / "statistics.json", plain)
    paths["fig5_png"], paths["fig5_pdf"] = figure_risks(analysis, out)
    paths["fig6_png"], paths["fig6_pdf"] = figure_harm(analysis, out)
    spec, rejected = _spec_lines(runs, analysis, planners, groups)
    notes = list(DIFFERENCES)
    if groups.motorcycles:
        notes.append("- Motorcyclists count as VRUs, as in the paper's reference evaluation.")
    report = render(analysis, spec, _speed_lines(results, wall, workers, backend), rejected, notes)
    paths["report"] = out / "report.md"
    paths["report"].write_text(report, encoding="utf-8")
    return paths


@dataclass(frozen=True, slots=True)
class StudyResult:
    """A finished study.

    Attributes:
        results: one per task, in task order. paths: output name -> file
            (``write_study``). wall_time: wall time of the runs [s].
    """

    results: list[TaskResult]
    paths: dict[str, Path]
    wall_time: float


def run_study(
    tasks: Sequence[RunTask],
    planners: Sequence[str],
    backend: str = "process",
    config: RunConfig | None = None,
    options: BackendOptions | None = None,
    groups: GroupDefinition | None = None,
    resamples: int = 2000,
) -> StudyResult:
    """Run (or resume) the tasks and write the study's outputs into the tasks' ``out``.

    Raises:
        ValueError: no tasks, tasks of several output folders, or a bad backend.
    """
    check(len(tasks) > 0, "a study needs at least one run")
    outs = {t.out for t in tasks}
    check(len(outs) == 1, f"a study's runs share one output folder, got {sorted(outs)}")
    options = options or BackendOptions()
    start = time.perf_counter()
    results = run_tasks(tasks, backend, config, options)
    wall = time.perf_counter() - start
    check(len(results) > 0, f"no run of this study is stored in {outs.copy().pop()} yet")
    paths = write_study(
        outs.pop(),
        results,
        planners,
        wall,
        groups=groups,
        workers=options.workers,
        backend=backend,
        resamples=resamples,
    )
    return StudyResult(results, paths, wall)


def speed(results: Sequence[TaskResult], wall: float) -> dict[str, Any]:
    """Runs per minute of the fresh (not resumed) runs and the projected paper study [h]."""
    fresh = sum(1 for r in results if not r.resumed)
    rate = fresh / (wall / 60.0) if wall > 0 and fresh else math.nan
    return {
        "runs": fresh,
        "wall_time": wall,
        "runs_per_minute": rate,
        "paper_study_hours": PAPER_RUNS / rate / 60.0,
    }


__all__ = [
    "PAPER_RUNS",
    "STUDY_BACKENDS",
    "BackendOptions",
    "StudyResult",
    "run_study",
    "run_tasks",
    "speed",
    "study_run",
    "write_study",
]
