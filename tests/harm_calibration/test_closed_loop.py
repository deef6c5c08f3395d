import json
import math

import pytest

from ethical_planner.road_users import KinematicState
from harm_calibration.cli import main
from harm_calibration.closed_loop import rows_from_runs
from mujoco_world.evaluation.compare import compare_impact
from mujoco_world.loop.summary import BodyRecord, RunSummary
from mujoco_world.physics.impact import measure_impact
from mujoco_world.storage.run_record import RunRecord, write_record

CAR = (4.5, 1.8)
VAN = (5.5, 2.1)  # the catalog's parked van, wider than the default parked vehicle (1.8 m)


def _impact(angle: float, dy: float, partner: str = "car", shape=CAR):
    m = measure_impact(
        "car",
        KinematicState(0.0, 0.0, 0.0, 10.0),
        partner,
        KinematicState(6.0, dy, angle, 3.0 if angle else 0.0),
        shape_a=CAR,
        shape_b=shape,
    )
    return compare_impact(m)


def _record(impacts, partner="car", shape=CAR) -> RunRecord:
    bodies = (
        BodyRecord(0, "ego", "car", *CAR, 1500.0),
        BodyRecord(1, "b", partner, *shape, 2000.0),
    )
    summary = RunSummary("s", "p", 0, "crash", "collision", bodies=bodies, collisions=tuple(impacts))
    return RunRecord("s__p__s0", summary)


@pytest.fixture()
def runs(tmp_path):
    root = tmp_path / "runs"
    write_record(root / "a" / "seed0", _record([_impact(math.pi, 0.0)]))
    write_record(root / "b", _record([_impact(0.0, 0.0), _impact(math.pi, 1.2)]))
    (root / "other.json").write_text("{}")
    (root / "sweep").mkdir()
    (root / "sweep" / "summary.json").write_text(json.dumps({"by_partner": {}}))  # not a run record
    return root


def test_rows_from_runs(runs):
    rows = rows_from_runs(runs)
    assert len(rows) == 3
    head_on = next(r for r in rows if r["source"].startswith("a/seed0"))
    assert head_on["partner"] == "car"
    assert head_on["angle_deg"] == pytest.approx(180.0)
    assert head_on["closing_speed"] == pytest.approx(13.0)
    assert head_on["class"] == "central_collinear"
    e = head_on["restitution"]
    assert head_on["dv_measured_a"] == pytest.approx(head_on["dv_predicted_a"] * (1 + e), rel=0.01)
    assert head_on["dv_measured_a"] == pytest.approx(head_on["dv_planar_a"], rel=0.02)
    assert {r["class"] for r in rows} == {"central_collinear", "offset"}


def test_offset_uses_the_shapes_the_run_simulated(tmp_path):
    # A car hits a parked 5.5 x 2.1 m van 1.2 m off centre, both aligned. The contact
    # region of the centres is a rectangle: the edge offset is (w_a + w_b) / 2.
    impact = _impact(0.0, 1.2, "parked_vehicle", VAN)
    write_record(tmp_path / "r", _record([impact], "parked_vehicle", VAN))
    (row,) = rows_from_runs(tmp_path)
    assert row["offset"] == pytest.approx(1.2 / ((1.8 + 2.1) / 2), rel=1e-6)
    assert row["offset"] != pytest.approx(1.2 / 1.8, rel=1e-3)  # the default parked vehicle's


def test_a_record_without_the_colliding_body_is_an_error(tmp_path):
    record = _record([_impact(0.0, 1.2)])
    summary = RunSummary(
        "s", "p", 0, "crash", "x", bodies=record.summary.bodies[:1], collisions=record.summary.collisions
    )
    write_record(tmp_path / "r", RunRecord("r", summary))
    with pytest.raises(ValueError, match="lack b"):
        rows_from_runs(tmp_path)


def test_cli_from_runs(runs, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["impacts", "--from-runs", str(runs), "--out", str(out), "--no-plots"]) == 0
    assert (out / "impacts.csv").exists() and (out / "report.md").exists()
    assert "central_collinear" in capsys.readouterr().out
    report = (out / "report.md").read_text()
    # One line per collision with measured delta-v and harm against both models.
    assert "## Collisions" in report and report.count("| a/seed0[0] |") == 1
    assert "harm planar a / b" in report


def test_cli_from_runs_without_collisions(tmp_path, capsys):
    write_record(tmp_path / "r", _record([]))
    assert main(["impacts", "--from-runs", str(tmp_path / "r"), "--out", str(tmp_path / "o")]) == 2
    assert "no collisions" in capsys.readouterr().err


def test_an_old_summary_is_a_clear_error(tmp_path, capsys):
    old = {"scenario": "s", "planner": "p", "seed": 0, "outcome": "crash", "collisions": []}
    (tmp_path / "summary.json").write_text(json.dumps(old))
    with pytest.raises(ValueError, match="before run records carried a format"):
        rows_from_runs(tmp_path)
    assert main(["impacts", "--from-runs", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "summary.json" in capsys.readouterr().err
