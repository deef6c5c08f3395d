"""``etp scenarios``, ``etp run`` and ``etp demo`` (batch, resume, failures)."""

import json

from harm_calibration.cli import main
from mujoco_world.experiments.batch import RunTask, comparison_table, run_batch
from mujoco_world.loop.runner import run_scenario
from mujoco_world.scenario.catalog import catalog_names, get_scenario
from mujoco_world.storage.run_folder import run_id
from mujoco_world.storage.run_index import read_index
from mujoco_world.storage.run_record import read_record
from tests.harm_calibration.cli.conftest import write_scenario


def test_scenarios_lists_the_catalog(capsys):
    assert main(["scenarios"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(catalog_names())
    assert all(line.split()[0] in catalog_names() for line in lines)


def test_run_writes_a_summary(tmp_path, capsys):
    scenario = write_scenario(tmp_path, duration=3.0)  # a head-on crash of two others at ~1.8 s
    out = tmp_path / "run"
    code = main(["run", scenario, "--planner", "standard", "--seed", "4", "--out", str(out)])
    assert code == 0
    run = run_id(scenario, "standard", 4)
    assert run.startswith("short-") and run.endswith("__standard__s4")  # a file: stem and path hash
    assert sorted(p.name for p in out.iterdir()) == ["index.jsonl", run]
    summary = json.loads((out / run / "summary.json").read_text())
    assert summary["format"] == "etp-run-record" and summary["run_id"] == run
    assert summary["scenario"] == "short"
    assert summary["planner"] == "standard" and summary["seed"] == 4
    assert summary["outcome"] != "crash" and not summary["ego_collided"]  # others collided, not the ego
    for key in ("duration", "collisions", "max_risk", "min_distance", "timings", "tracking_rms"):
        assert key in summary
    collision = summary["collisions"][0]
    assert {"measurement", "a", "b"} <= set(collision)  # the measurement, the prediction per body
    assert {"dv_measured", "dv_predicted", "harm_measured", "harm_predicted"} <= set(collision["a"])
    assert "wrote" in capsys.readouterr().out


def test_run_rejects_bad_input(capsys):
    assert main(["run", "no_such_scenario"]) == 2
    assert "unknown scenario 'no_such_scenario'" in capsys.readouterr().err
    assert main(["run", "oncoming_drift", "--planner", "reckless"]) == 2
    err = capsys.readouterr().err
    assert "unknown planner 'reckless'; allowed: ethical, selfish, standard" in err
    assert "keep_lane" in err
    assert main(["demo", "--scenarios", "nope"]) == 2


def test_demo_runs_on_two_workers_and_resumes(tmp_path, capsys):
    out = tmp_path / "demo"
    args = [
        "demo",
        "--scenarios",
        "oncoming_drift,red_light_runner",
        "--planners",
        "standard",
        "--out",
        str(out),
        "--workers",
        "2",
        "--no-progress",
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "oncoming_drift" in text and "per planner" in text
    runs = sorted(p.name for p in out.iterdir() if p.is_dir())
    assert runs == ["oncoming_drift__standard__s0", "red_light_runner__standard__s0"]
    aggregate = json.loads((out / "aggregate.json").read_text())
    assert len(aggregate["runs"]) == 2
    assert (out / "table.txt").exists()
    # A second call resumes: nothing is run again.
    assert main(args) == 0
    assert "2 resumed" in capsys.readouterr().out
    # A run in a spawned worker equals the same run in this process.
    written = read_record(out / "oncoming_drift__standard__s0")
    assert written.recording.endswith("oncoming_drift__standard__s0/recording.rrd")
    here = run_scenario(get_scenario("oncoming_drift"), "standard", seed=0)
    assert written.summary.comparable_dict() == here.comparable_dict()


def test_demo_runs_random_variants(tmp_path, capsys):
    out = tmp_path / "random"
    args = [
        "demo",
        "--random",
        "2",
        "--scenario-seed",
        "5",
        "--scenarios",
        "red_light_runner",
        "--planners",
        "standard",
        "--out",
        str(out),
        "--workers",
        "1",
        "--no-progress",
    ]
    assert main(args) == 0
    runs = sorted(p.name for p in out.iterdir() if p.is_dir())
    assert runs == ["red_light_runner-s5-0__standard__s0", "red_light_runner-s5-1__standard__s0"]


def test_a_failing_run_is_recorded_and_the_batch_goes_on(tmp_path):
    tasks = [
        RunTask(str(tmp_path / "missing.toml"), "ethical", 0, str(tmp_path)),
        RunTask("red_light_runner", "standard", 0, str(tmp_path)),
    ]
    results = run_batch(tasks, workers=1, progress=False)
    first, second = (r.record.summary for r in results)
    assert first.outcome == "failed" and "cannot read scenario file" in first.reason
    assert second.outcome in ("goal", "timeout", "crash")
    assert read_record(tasks[0].record_path).summary.outcome == "failed"
    assert "failed 1" in comparison_table(r.record for r in results)
    assert [r.run_id for r in read_index(tmp_path)] == [tasks[0].run_id, tasks[1].run_id]


EXPECTING = """
name = "{name}"
duration = {duration}
[road]
length = 100.0
[ego]
s0 = 10.0
speed = 5.0
[expect]
collision = false
min_progress = 90.0
"""


def test_run_reports_expectations_and_exits_1_when_one_fails(tmp_path, capsys):
    scenario = write_scenario(tmp_path, template=EXPECTING, name="expecting", duration=0.5)
    code = main(["run", scenario, "--planner", "keep_lane", "--out", str(tmp_path / "r"), "--no-record"])
    out = capsys.readouterr().out
    assert code == 1
    assert "expectations: FAIL" in out
    assert "pass  collision: expected false, got false" in out
    assert "FAIL  min_progress: expected >= 90, got 12.5" in out


def test_scenarios_json_lists_expectations(capsys):
    assert main(["scenarios", "--json"]) == 0
    entries = {e["name"]: e for e in json.loads(capsys.readouterr().out)}
    assert entries["child_between_parked"]["expect"] == {"ego_collision": False, "max_vulnerable_harm": 0.0}
    assert entries["oncoming_drift"]["expect"] == {}
    both = {"max_rule_violations": 0, "ego_collision": False, "reach_goal": True}
    assert entries["no_overtaking_zone"]["expect"] == both and entries["stop_sign"]["expect"] == both


def test_comparison_table_shows_the_test_suite(tmp_path):
    scenario = write_scenario(tmp_path, template=EXPECTING, name="expecting", duration=0.3)
    (result,) = run_batch([RunTask(scenario, "keep_lane", 0, str(tmp_path / "b"), record=False)], workers=1)
    table = comparison_table([result.record])
    assert "FAIL" in table.splitlines()[2]
    assert "keep_lane   0 pass   1 fail   0 none  | failing: expecting" in table
