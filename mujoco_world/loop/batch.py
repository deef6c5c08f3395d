"""Batches of closed-loop runs on several cores, resumable, with a comparison table.

Every run writes ``<out>/<scenario>__<planner>__s<seed>/summary.json``; a run whose
summary exists is skipped, so an interrupted batch resumes where it stopped. A run
that fails (in the planner, the physics, or even a crashed worker process) is written
as ``outcome = "failed"`` with the reason, and the batch goes on. Workers are started
with the ``spawn`` method, so the module is safe on every platform.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ethical_planner.config import PlannerConfig
from ethical_planner.validation import check
from mujoco_world.loop.runner import GROUPS, OUTCOMES, RunConfig, run_scenario
from mujoco_world.scenario.sources import resolve_scenario

#: Planner presets of the paper's comparison.
PLANNERS = ("ethical", "selfish", "standard")
#: Scenarios of ``etp demo --quick``.
QUICK_SCENARIOS = ("pedestrian_behind_parked", "tailgater_sudden_stop", "oncoming_drift", "red_light_runner")


@dataclass(frozen=True, slots=True)
class RunTask:
    """One run of a batch.

    Attributes:
        scenario: catalog name or path to a scenario TOML file.
        planner: planner name (a preset, or ``planner_config.name``).
        seed: run seed.
        out: batch output folder.
        record: write a Rerun recording. keep: "all" or "near_crash" recordings.
        planner_config: the configuration to plan with; None uses the preset ``planner``.
    """

    scenario: str
    planner: str
    seed: int
    out: str
    record: bool = True
    keep: str = "all"
    planner_config: PlannerConfig | None = None

    @property
    def run_dir(self) -> Path:
        """Folder of this run."""
        name = Path(self.scenario).stem if self.scenario.endswith(".toml") else self.scenario
        return Path(self.out) / f"{name}__{self.planner}__s{self.seed}"

    @property
    def summary_path(self) -> Path:
        """Path of this run's summary.json."""
        return self.run_dir / "summary.json"


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` to ``path`` atomically (temporary file, then rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.tmp")
    with tmp.open("w", encoding="utf-8") as handle:
        json.dump(data, handle, indent=1, allow_nan=False)
    os.replace(tmp, path)


def failed_summary(task: RunTask, reason: str) -> dict[str, Any]:
    """Summary of a run that could not produce its own."""
    return {
        "scenario": task.run_dir.name.split("__")[0],
        "planner": task.planner,
        "seed": task.seed,
        "outcome": "failed",
        "reason": reason,
        "duration": 0.0,
        "collisions": [],
        "timings": {},
    }


def row_of(summary: dict[str, Any]) -> dict[str, Any]:
    """The compact row of a summary used by the aggregate and the table."""
    collisions = summary.get("collisions") or []
    return {
        "scenario": summary.get("scenario"),
        "planner": summary.get("planner"),
        "seed": summary.get("seed"),
        "outcome": summary.get("outcome"),
        "reason": summary.get("reason"),
        "duration": summary.get("duration"),
        "collisions": len(collisions),
        "ego_collided": summary.get("ego_collided", False),
        "max_risk": summary.get("max_risk", {}),
        "harm": summary.get("harm", {}),
        "min_distance": summary.get("min_distance"),
        "wall_time": (summary.get("timings") or {}).get("total"),
    }


def run_task(task: RunTask, config: RunConfig | None = None) -> dict[str, Any]:
    """Run one task (or load its existing summary) and return its row.

    Never raises for a failing run: the failure is written as the run's summary.
    """
    path = task.summary_path
    if path.exists():
        try:
            with path.open(encoding="utf-8") as handle:
                row = row_of(json.load(handle))
            row["skipped"] = True
            return row
        except (OSError, json.JSONDecodeError):
            pass  # a damaged summary is run again
    # Imported here: the recorder is the one module that imports Rerun.
    from mujoco_world.storage.run_folder import recording_observer

    try:
        scenario = resolve_scenario(task.scenario)
        observer = recording_observer(task.run_dir, keep=task.keep, record=task.record, out_root=task.out)
        planner = task.planner_config if task.planner_config is not None else task.planner
        summary = run_scenario(scenario, planner, task.seed, config, observer).to_dict()
        summary["recording"] = observer.row.recording if observer.row is not None else None
    except Exception as error:  # noqa: BLE001 - recorded, the batch goes on
        summary = failed_summary(task, f"{type(error).__name__}: {error}")
    write_json(path, summary)
    return row_of(summary)


def _run_task_in_worker(task: RunTask, config: RunConfig | None) -> dict[str, Any]:
    return run_task(task, config)


def make_tasks(
    scenarios: Sequence[str],
    planners: Sequence[str | PlannerConfig],
    seeds: Sequence[int],
    out: str | Path,
    record: bool = True,
    keep: str = "all",
) -> list[RunTask]:
    """All combinations, scenario-major; ``record``/``keep`` as in ``recording_observer``.

    ``planners`` are preset names or configurations (run under their ``name``).
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
    on_row: Callable[[dict[str, Any]], None] | None = None,
    worker_initializer: Callable[[], object] | None = None,
) -> list[dict[str, Any]]:
    """Run tasks on ``workers`` processes (1: in this process) and return their rows.

    Args:
        tasks: the runs.
        workers: number of processes.
        config: loop settings for every run.
        progress: show a tqdm progress bar.
        on_row: called with each row as it completes.
        worker_initializer: called once in each worker process before its first run
            (the command line passes its process tuning); must be picklable.

    Returns:
        Rows in the order of ``tasks``.
    """
    check(isinstance(workers, int) and workers >= 1, f"workers must be >= 1, got {workers!r}")
    from tqdm import tqdm

    rows: dict[int, dict[str, Any]] = {}
    bar = tqdm(total=len(tasks), disable=not progress, unit="run", dynamic_ncols=True)

    def done(index: int, row: dict[str, Any]) -> None:
        rows[index] = row
        bar.update(1)
        bar.set_postfix_str(f"{row['scenario']}/{row['planner']}: {row['outcome']}")
        if on_row is not None:
            on_row(row)

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
                        summary = failed_summary(task, f"worker raised {type(error).__name__}: {error}")
                        write_json(task.summary_path, summary)
                        done(index, row_of(summary))
            pending = []
            if broken:
                # A worker died (e.g. a crash in native code): the first unfinished task
                # is recorded as failed, the others are retried in a fresh pool.
                broken.sort()
                index, task = broken[0]
                summary = failed_summary(task, "worker process died while running this task")
                write_json(task.summary_path, summary)
                done(index, row_of(summary))
                pending = broken[1:]
    bar.close()
    return [rows[i] for i in range(len(tasks))]


# --------------------------------------------------------------------------- reporting


def _fmt(value: Any, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}"


def comparison_table(rows: Iterable[dict[str, Any]]) -> str:
    """Plain-text table: one line per run, then per-planner totals (paper Figs. 5, 6)."""
    rows = sorted(rows, key=lambda r: (str(r["scenario"]), str(r["planner"]), r["seed"] or 0))
    head = (
        f"{'scenario':<30} {'planner':<9} {'seed':>4} {'outcome':<8} {'t [s]':>6} {'coll':>4} "
        f"{'max risk ego':>12} {'3rd':>7} {'VRU':>7} {'harm ego':>9} {'3rd':>6} {'VRU':>6} {'min d':>6}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        risk, harm = r.get("max_risk") or {}, r.get("harm") or {}
        lines.append(
            f"{str(r['scenario']):<30} {str(r['planner']):<9} {r['seed']!s:>4} {str(r['outcome']):<8} "
            f"{_fmt(r.get('duration'), 1):>6} {r.get('collisions', 0):>4} "
            f"{_fmt(risk.get('ego')):>12} {_fmt(risk.get('third_party')):>7} "
            f"{_fmt(risk.get('vulnerable')):>7} "
            f"{_fmt(harm.get('ego'), 3):>9} {_fmt(harm.get('third_party'), 3):>6} "
            f"{_fmt(harm.get('vulnerable'), 3):>6} {_fmt(r.get('min_distance'), 2):>6}"
        )
    lines += ["", "per planner: runs, outcomes, mean of max risk per group, summed measured harm per group"]
    planners = sorted({str(r["planner"]) for r in rows})
    for planner in planners:
        mine = [r for r in rows if str(r["planner"]) == planner]
        counts = {o: sum(1 for r in mine if r["outcome"] == o) for o in OUTCOMES}
        mean_risk = {
            g: sum((r.get("max_risk") or {}).get(g, 0.0) or 0.0 for r in mine) / max(len(mine), 1)
            for g in GROUPS
        }
        harm = {g: sum((r.get("harm") or {}).get(g, 0.0) or 0.0 for r in mine) for g in GROUPS}
        lines.append(
            f"  {planner:<9} {len(mine):>3} runs  "
            + " ".join(f"{k} {v}" for k, v in counts.items())
            + "  | max risk ego {ego:.4f} 3rd {third_party:.4f} VRU {vulnerable:.4f}".format(**mean_risk)
            + "  | harm ego {ego:.3f} 3rd {third_party:.3f} VRU {vulnerable:.3f}".format(**harm)
        )
    return "\n".join(lines)


def write_aggregate(out: str | Path, rows: Sequence[dict[str, Any]], wall_time: float) -> Path:
    """Write ``aggregate.json`` and ``table.txt`` into ``out``; return the JSON path."""
    out = Path(out)
    path = out / "aggregate.json"
    write_json(
        path,
        {
            "runs": list(rows),
            "wall_time": wall_time,
            "written": time.strftime("%Y-%m-%dT%H:%M:%S"),
        },
    )
    (out / "table.txt").write_text(comparison_table(rows) + "\n", encoding="utf-8")
    return path
