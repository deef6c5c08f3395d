"""The study end to end on CommonRoad files written here: both backends, resume, refusals, outputs."""

import json
import math

import pytest

pytest.importorskip("commonroad")
pytest.importorskip("commonroad_route_planner")

from harm_calibration.cli import main  # noqa: E402
from harm_calibration.study.runner import BackendOptions, run_study  # noqa: E402
from harm_calibration.study.scenarios import expand_scenarios  # noqa: E402
from mujoco_world.experiments.batch import make_tasks  # noqa: E402
from tests.mujoco_world.scenario.commonroad_builder import (  # noqa: E402
    LANE,
    ObstacleType,
    Rectangle,
    moving_obstacle,
    planning_problem,
    straight_line,
    straight_road_file,
)

PLANNERS = ["ethical", "standard"]


@pytest.fixture(scope="module")
def scenario_folder(tmp_path_factory):
    """A short file (1 s, a car ahead) and one without a planning problem."""
    folder = tmp_path_factory.mktemp("scenarios")
    car = moving_obstacle(
        10, ObstacleType.CAR, Rectangle(4.4, 1.8), 0, straight_line((40, -LANE / 2), 6, 0, 20), 0.0
    )
    short = [planning_problem(goal_steps=(0, 10))]
    straight_road_file(folder, [car], problems=short, name="ZAM_Study-1_1_T-1")
    straight_road_file(folder, problems=[], name="ZAM_Study-3_1_T-1")
    return folder


def _study(folder, out, backend, workers=2, planners=PLANNERS):
    scenarios = expand_scenarios([str(folder)])
    tasks = make_tasks(scenarios, planners, [0], out, record=False)
    options = BackendOptions(workers=workers, progress=False)
    return run_study(tasks, planners, backend=backend, options=options, resamples=200)


def _by_id(study):
    return {r.record.run_id: r.record.summary.comparable_dict() for r in study.results}


def test_process_and_dask_backends_give_identical_runs_and_a_rerun_resumes(scenario_folder, tmp_path):
    pytest.importorskip("distributed")
    process = _study(scenario_folder, tmp_path / "process", "process")
    dask = _study(scenario_folder, tmp_path / "dask", "dask")
    assert len(process.results) == 4
    assert _by_id(process) == _by_id(dask)
    outcomes = [r.record.summary.outcome for r in process.results]
    assert outcomes.count("failed") == 2 and outcomes.count("timeout") == 2

    # The refused file is recorded with its reason; the others produced risks per type.
    stats = json.loads(process.paths["statistics"].read_text())
    assert list(stats["rejected"].values()) == ["no_planning_problem"]
    assert stats["scenarios"] == 1 and stats["failed"] == []
    ran = [r.record.summary for r in process.results if r.record.summary.outcome != "failed"]
    assert all(s.top_risks_by_type.get("car") for s in ran if s.planner == "ethical")

    # Every output is written, figures as PNG and PDF.
    for name in ("fig5_png", "fig5_pdf", "fig6_png", "fig6_pdf", "report", "aggregate"):
        assert process.paths[name].stat().st_size > 0, name
    report = process.paths["report"].read_text()
    assert "no_planning_problem" in report and "runs per minute" in report
    # Every refused file with its own reason, without the exception name, path or key.
    assert "ZAM_Study-3_1_T-1" in report and "no planning problem, so no ego to simulate" in report
    assert "[rejected:" not in report and "CommonRoadImportError" not in report
    assert "1 scenarios ran with every planner, 0 had a run that failed in the world, 1 were refused" in (
        report
    )

    # A rerun reads every record back and runs nothing again.
    records = sorted((tmp_path / "process").glob("*/summary.json"))
    stamps = [p.stat().st_mtime_ns for p in records]
    again = _study(scenario_folder, tmp_path / "process", "process")
    assert all(r.resumed for r in again.results)
    assert [p.stat().st_mtime_ns for p in records] == stamps
    assert _by_id(again) == _by_id(process)


def test_an_interrupted_study_resumes_the_missing_runs(scenario_folder, tmp_path):
    out = tmp_path / "study"
    first = _study(scenario_folder, out, "process", workers=1, planners=["standard"])
    victim = first.results[0].record.run_id
    (out / victim / "summary.json").unlink()  # as if stopped before this run finished
    stored = _study(scenario_folder, out, "none", planners=["standard"])  # --analyse-only: runs nothing
    assert [r.record.run_id for r in stored.results] == [r.record.run_id for r in first.results[1:]]
    assert stored.paths["report"].is_file()
    again = _study(scenario_folder, out, "process", workers=1, planners=["standard"])
    fresh = [r.record.run_id for r in again.results if not r.resumed]
    assert fresh == [victim]


def test_etp_study_command_line(scenario_folder, tmp_path, capsys):
    out = tmp_path / "cli"
    argv = [
        "study",
        str(scenario_folder / "ZAM_Study-1_1_T-1.xml"),
        "--planners",
        "standard",
        "--out",
        str(out),
        "--workers",
        "1",
        "--no-record",
        "--resamples",
        "100",
        "--no-progress",
        "--json",
    ]
    assert main(argv) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["runs"] == 1 and math.isfinite(printed["runs_per_minute"])
    assert (out / "report.md").is_file() and (out / "fig5_risks.pdf").is_file()


@pytest.mark.parametrize(
    "argv,message",
    [
        (["nowhere_folder_xyz"], "unknown scenario 'nowhere_folder_xyz'"),
        (["{folder}", "--backend", "ray"], "unknown study backend 'ray'; allowed: process, dask, none"),
        (["{folder}", "--scheduler", "tcp://10.0.0.1:8786"], "--scheduler needs --backend dask"),
        (["{folder}", "--workers", "0"], "--workers must be >= 1"),
        (["{folder}", "--planners", "ethical,ethical"], "--planners lists ethical more than once"),
    ],
)
def test_bad_study_input_exits_2_with_a_message(scenario_folder, tmp_path, capsys, argv, message):
    argv = [a.format(folder=scenario_folder) for a in argv]
    assert main(["study", *argv, "--out", str(tmp_path / "bad"), "--no-progress"]) == 2
    assert message in capsys.readouterr().err
