import json
import math

import pytest

from ethical_planner.road_users import KinematicState
from harm_calibration.cli import main
from harm_calibration.closed_loop import rows_from_runs
from mujoco_world.evaluation.compare import compare_impact
from mujoco_world.physics.impact import measure_impact


def _record(angle: float, dy: float) -> dict:
    m = measure_impact(
        "car",
        KinematicState(0.0, 0.0, 0.0, 10.0),
        "car",
        KinematicState(6.0, dy, angle, 3.0 if angle else 0.0),
    )
    return compare_impact(m).to_dict()


def _summary(collisions: list[dict]) -> dict:
    # shaped like mujoco_world.runner.RunSummary.to_dict
    return {
        "scenario": "s",
        "planner": "p",
        "seed": 0,
        "outcome": "crash",
        "reason": "collision",
        "collisions": collisions,
        "ego_collided": bool(collisions),
    }


@pytest.fixture()
def runs(tmp_path):
    root = tmp_path / "runs"
    (root / "a" / "seed0").mkdir(parents=True)
    (root / "b").mkdir()
    (root / "a" / "seed0" / "summary.json").write_text(json.dumps(_summary([_record(math.pi, 0.0)])))
    (root / "b" / "summary.json").write_text(json.dumps(_summary([_record(0.0, 0.0), _record(math.pi, 1.2)])))
    (root / "other.json").write_text("{}")
    return root


def test_rows_from_runs(runs):
    rows = rows_from_runs(runs)
    assert len(rows) == 3
    head_on = next(r for r in rows if r["source"].startswith("a/seed0"))
    assert head_on["partner"] == "car"
    assert head_on["angle_deg"] == pytest.approx(180.0)
    assert head_on["closing_speed"] == pytest.approx(13.0)
    assert head_on["class"] == "central_collinear"
    assert head_on["dv_measured_a"] == pytest.approx(head_on["dv_predicted_a"], rel=0.05)
    assert {r["class"] for r in rows} == {"central_collinear", "offset"}


def test_cli_from_runs(runs, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["impacts", "--from-runs", str(runs), "--out", str(out), "--no-plots"]) == 0
    assert (out / "impacts.csv").exists() and (out / "report.md").exists()
    assert "central_collinear" in capsys.readouterr().out


def test_cli_from_runs_without_collisions(tmp_path, capsys):
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "summary.json").write_text(json.dumps(_summary([])))
    assert main(["impacts", "--from-runs", str(tmp_path / "r"), "--out", str(tmp_path / "o")]) == 2
    assert "no collisions" in capsys.readouterr().err


def test_malformed_collision_names_file(tmp_path):
    (tmp_path / "summary.json").write_text(json.dumps(_summary([{"time": 0.0}])))
    with pytest.raises(ValueError, match="measurement"):
        rows_from_runs(tmp_path)
