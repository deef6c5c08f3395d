import json
import math

import numpy as np
import pytest

from harm_calibration.analysis import analyse, summarize
from harm_calibration.geometry import CENTRAL_COLLINEAR, OBLIQUE, OFFSET, Footprint, classify, launch_geometry
from harm_calibration.rows import read_rows
from harm_calibration.sweep import GRIDS, Grid, GridSpec, ImpactCase, run_case, run_sweep

FEW = GridSpec(
    closing_speeds=(10.0,),
    angles_deg=(0.0, 90.0, 180.0),
    offsets=(0.0, 0.5),
    partners=("car", "pedestrian"),
    restitution_sets=("plastic",),
)


def test_head_on_car_matches_plastic_formula():
    row = run_case(ImpactCase("car", 10.0, 180.0, 0.0, "plastic"))
    assert row["status"] == "ok"
    assert row["class"] == CENTRAL_COLLINEAR
    assert row["dv_measured_a"] == pytest.approx(row["dv_predicted_a"], rel=0.03)
    assert row["mass_a"] * row["dv_measured_a"] == pytest.approx(
        row["mass_b"] * row["dv_measured_b"], rel=1e-6
    )
    assert row["area_measured_a"] == row["area_predicted_a"] == "front"


def test_restitution_raises_delta_v():
    plastic = run_case(ImpactCase("car", 10.0, 180.0, 0.0, "plastic"))
    bouncy = run_case(ImpactCase("car", 10.0, 180.0, 0.0, "e0.4"))
    assert bouncy["dv_measured_a"] / plastic["dv_measured_a"] == pytest.approx(1.4 / 1.01, rel=0.08)


def test_launch_geometry_touches_after_the_gap():
    ego, car = Footprint(4.5, 1.8), Footprint(4.5, 1.8)
    launch = launch_geometry(ego, car, 10.0, 0.0, 0.0, 0.0)
    assert launch.position_b == pytest.approx((4.5 + 0.05, 0.0))
    with pytest.raises(ValueError, match="offset"):
        launch_geometry(ego, car, 10.0, 0.0, 0.0, 1.0)


def test_classify():
    assert classify(180.0, 0.0) == CENTRAL_COLLINEAR
    assert classify(90.0, 0.0) == OBLIQUE
    assert classify(0.0, 0.5) == OFFSET


def test_grid_spec_rejects_unknown_partner():
    with pytest.raises(ValueError, match="partners"):
        GridSpec((10.0,), (0.0,), (0.0,), ("tram",), ("plastic",))


def test_small_grid_size():
    assert 100 <= len(GRIDS[Grid.SMALL].cases()) <= 1000
    ids = [c.id for c in GRIDS[Grid.FULL].cases()]
    assert len(ids) == len(set(ids))


def test_sweep_resumes_and_reports(tmp_path):
    cases = FEW.cases()
    csv_path = tmp_path / "impacts.csv"
    seen = []
    rows = run_sweep(cases[:5], csv_path, workers=1, progress=False)
    rows = run_sweep(cases, csv_path, workers=1, progress=False, on_row=seen.append)
    assert len(seen) == len(cases) - 5  # the first five were skipped
    assert len(read_rows(csv_path)) == len(cases)
    assert all(r["status"] == "ok" for r in rows)
    summary = analyse(tmp_path, rows, "test", plots=False)
    assert set(summary["by_partner"]) == {"car", "pedestrian"}
    assert summary["by_class"][CENTRAL_COLLINEAR]["dv_median_abs_rel_error"] < 0.05
    report = (tmp_path / "report.md").read_text()
    assert "Literature check" in report and "| car |" in report
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["n_impacts"] == len(cases)


def test_summary_pools_areas_of_both_bodies():
    rows = [run_case(c) for c in FEW.cases() if c.partner == "car"]
    s = summarize(rows)
    assert 0.0 <= s["overall"]["area_agreement"] <= 1.0
    assert np.isfinite(s["overall"]["harm_mean_abs_error"])
    assert "calibration" not in s  # no rng given


@pytest.mark.slow
def test_small_grid_runs_in_parallel(tmp_path):
    rows = run_sweep(GRIDS[Grid.SMALL].cases(), tmp_path / "impacts.csv", workers=2, progress=False)
    assert sum(r["status"] == "ok" for r in rows) >= 0.95 * len(rows)
    assert math.isfinite(summarize(rows)["overall"]["dv_median_abs_rel_error"])
