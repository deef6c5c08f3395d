"""``etp scenarios``, ``etp run`` and ``etp demo`` (batch, resume, failures)."""

import json

from harm_calibration.cli import main
from mujoco_world.loop.batch import RunTask, comparison_table, run_batch
from mujoco_world.loop.runner import run_scenario
from mujoco_world.scenario.catalog import catalog_names, get_scenario
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
    summary = json.loads((out / "short__standard__s4" / "summary.json").read_text())
    assert summary["scenario"] == "short"
    assert summary["planner"] == "standard" and summary["seed"] == 4
    assert summary["outcome"] == "crash" and not summary["ego_collided"]
    for key in ("duration", "collisions", "max_risk", "min_distance", "timings", "tracking_rms"):
        assert key in summary
    collision = summary["collisions"][0]
    assert {"measurement", "comparison"} <= set(collision)
    assert {"dv_measured", "dv_predicted", "harm_measured", "harm_predicted"} <= set(
        collision["comparison"]["a"]
    )
    assert "wrote" in capsys.readouterr().out


def test_run_rejects_bad_input(capsys):
    assert main(["run", "no_such_scenario"]) == 2
    assert "unknown scenario 'no_such_scenario'" in capsys.readouterr().err
    assert main(["run", "oncoming_drift", "--planner", "reckless"]) == 2
    assert "unknown planner preset 'reckless'" in capsys.readouterr().err
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
    written = json.loads((out / "oncoming_drift__standard__s0" / "summary.json").read_text())
    written.pop("timings")
    assert written.pop("recording").endswith("oncoming_drift__standard__s0/recording.rrd")
    here = run_scenario(get_scenario("oncoming_drift"), "standard", seed=0).comparable_dict()
    assert json.loads(json.dumps(here)) == written


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
    rows = run_batch(tasks, workers=1, progress=False)
    assert rows[0]["outcome"] == "failed" and "cannot read scenario file" in rows[0]["reason"]
    assert rows[1]["outcome"] in ("goal", "timeout", "crash")
    failed = json.loads(tasks[0].summary_path.read_text())
    assert failed["outcome"] == "failed"
    assert "failed 1" in comparison_table(rows)
