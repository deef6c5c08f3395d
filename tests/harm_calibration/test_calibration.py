import math
import time

import numpy as np
import pytest

from ethical_planner.dv_correction import DeltaVCorrection as PlannerCorrection
from ethical_planner.geometry import impact_offset_fraction
from ethical_planner.road_users import DEFAULT_SHAPES, EGO_SHAPE, RoadUserType
from harm_calibration.analysis import summarize, write_report
from harm_calibration.calibration import (
    DeltaVCorrection,
    calibrate,
    error_stats,
    fit_delta_v_correction,
    row_offset_fractions,
)
from harm_calibration.geometry import (
    Footprint,
    configuration_space,
    edge_offset,
    launch_geometry,
    speeds_for_closing,
)
from harm_calibration.sweep import GRIDS, PARTNER_SPEED_CAP, Grid, run_sweep

EDGES = (0.0, 60.0, 120.0, 180.0)
OFFSETS = (0.0, 0.25, 1.0)


def synthetic(n, rng):
    """Ratio measured / Eq. 1 driven by the offset (glancing hits fall short), a little by angle."""
    angle = rng.uniform(0, 180, n)
    off = rng.uniform(0, 1, n)
    pred = rng.uniform(1, 20, n)
    truth = np.where(off < 0.25, np.where(angle < 60, 1.1, 1.0), np.where(angle < 120, 0.4, 0.6))
    meas = pred * truth * rng.normal(1.0, 0.02, n)
    cls = np.where(off > 0.15, "offset", "oblique")
    return pred, meas, angle, off, cls, truth


def test_fit_recovers_factors_per_angle_and_offset_bin():
    pred, meas, angle, off, _, _ = synthetic(3000, np.random.default_rng(1))
    corr = fit_delta_v_correction(pred, meas, angle, off, EDGES, OFFSETS)
    np.testing.assert_allclose(corr.factors, [[1.1, 0.4], [1.0, 0.4], [1.0, 0.6]], rtol=0.01)
    assert sum(map(sum, corr.n_train)) == 3000


def test_a_saved_calibration_corrects_the_planners_delta_v(tmp_path):
    # Fitted here, written as calibration.json, read by the planner through its config:
    # the planner scales Eq. 1 by the synthetic truth of the bin (0.4 for a glancing
    # 100 deg impact, 1.1 for a central 30 deg one).
    from ethical_planner.config import preset
    from ethical_planner.planner import Planner
    from ethical_planner.situations import overtaking_cyclist

    pred, meas, angle, off, _, _ = synthetic(3000, np.random.default_rng(1))
    fit_delta_v_correction(pred, meas, angle, off, EDGES, OFFSETS).save(tmp_path / "calibration.json")
    config = preset("ethical").with_overrides(
        {"risk": {"delta_v_correction": str(tmp_path / "calibration.json")}}
    )
    planner = Planner(config, overtaking_cyclist().environment)
    assert isinstance(planner.dv_correction, PlannerCorrection)
    corrected = planner.dv_correction([10.0, 10.0], np.radians([100.0, 30.0]), [0.5, 0.1])
    np.testing.assert_allclose(corrected, [4.0, 11.0], rtol=0.01)


def test_sparse_bins_fall_back_to_angle_only_then_one():
    # angle bin 0: two central rows (sparse 2D bin) and four glancing rows; angle bin 1 too sparse
    pred = [10.0] * 8
    meas = [12.0, 12.0, 5.0, 5.0, 5.0, 6.0, 9.0, 9.0]
    angle = [10.0, 20.0, 10.0, 20.0, 30.0, 40.0, 100.0, 110.0]
    off = [0.0, 0.1, 0.5, 0.6, 0.7, 0.8, 0.5, 0.5]
    corr = fit_delta_v_correction(pred, meas, angle, off, (0, 90, 180), (0.0, 0.25, 1.0), min_count=3)
    assert corr.n_train == ((2, 4), (0, 2))
    angle_only = float(np.median(np.divide(meas[:6], 10.0)))
    assert corr.factors == ((angle_only, 0.5), (1.0, 1.0))


def test_fit_ignores_tiny_and_non_finite_rows_and_checks_shapes():
    corr = fit_delta_v_correction([0.01, 10.0, 10.0], [5.0, 8.0, math.nan], [0, 0, 0], [0, 0, 0],
                                  (0, 180), (0, 1), min_count=1)  # fmt: skip
    assert corr.factors == ((0.8,),) and corr.n_train == ((1,),)
    with pytest.raises(ValueError, match="shapes differ"):
        fit_delta_v_correction([1.0], [1.0, 2.0], [0.0], [0.0])


def test_calibrate_reports_held_back_median_and_p95(tmp_path):
    pred, meas, angle, off, cls, _ = synthetic(2000, np.random.default_rng(2))
    result = calibrate(pred, meas, angle, off, cls, np.random.default_rng(7),
                       angle_edges_deg=EDGES, offset_edges=OFFSETS)  # fmt: skip
    assert result.seed == 7
    n_test = 600
    assert result.before["all"]["n"] == result.after["all"]["n"] == n_test
    # the offset-driven truth: angle-only cannot fix it, angle x offset can
    assert result.after["all"]["median_abs"] < 0.1 * result.before["all"]["median_abs"]
    assert result.after["all"]["p95_abs"] < 0.1 * result.after_angle_only["all"]["p95_abs"]
    assert result.after_angle_only["all"]["p95_abs"] > 0.3
    data = result.to_dict()
    assert set(data["test_error_calibrated"]) == {"all", "oblique", "offset"}
    assert DeltaVCorrection.from_dict(data["correction"]) == result.correction
    path = tmp_path / "cal.json"
    result.correction.save(path)
    assert DeltaVCorrection.load(path) == result.correction


def test_calibrate_rejects_bad_fraction():
    with pytest.raises(ValueError, match="test_fraction"):
        calibrate([1.0], [1.0], [0.0], [0.0], ["oblique"], np.random.default_rng(0), test_fraction=1.0)


def test_error_stats():
    s = error_stats(np.array([-0.5, 0.1, 1.0, np.nan]))
    assert s["n"] == 3 and s["median_abs"] == pytest.approx(0.5)
    assert s["p95_abs_log"] == pytest.approx(np.percentile(np.abs(np.log([0.5, 1.1, 2.0])), 95))


# ------------------------------------------------------------------ sweep geometry


def _launches(grid):
    ego = Footprint(EGO_SHAPE.length, EGO_SHAPE.width)
    spec = GRIDS[grid]
    for case in spec.cases():
        if case.restitution_set != spec.restitution_sets[0]:
            continue  # restitution does not change the launch
        shape = DEFAULT_SHAPES[RoadUserType(case.partner)]
        partner = Footprint(shape.length, shape.width, case.partner == "pedestrian")
        alpha = math.radians(case.angle_deg)
        cap = PARTNER_SPEED_CAP.get(case.partner, math.inf)
        speed_a, speed_b = speeds_for_closing(case.closing_speed, alpha, min(0.5 * case.closing_speed, cap))
        launch = launch_geometry(ego, partner, speed_a, speed_b, alpha, case.offset)
        yield case, ego, partner, shape, speed_a, speed_b, launch


@pytest.mark.parametrize("grid", [Grid.SMALL, Grid.FULL])
def test_sweep_offset_agrees_with_the_planners(grid):
    """The sweep's Minkowski-sum offset equals the planner's on rectangles; the round
    pedestrian proxy of the sweep differs a little from the planner's square pedestrian."""
    worst: dict[bool, float] = {True: 0.0, False: 0.0}
    for case, ego, partner, shape, _, _, launch in _launches(grid):
        rel_vel = np.subtract(launch.velocity_b, launch.velocity_a)
        w = rel_vel / np.hypot(*rel_vel)
        # perpendicular distance of b's centre from the approach line through a's centre,
        # over the largest one that still touches (the sweep's own hull, round pedestrians)
        hull = configuration_space(ego, 0.0, partner, launch.yaw_b)
        sweep = abs(float(np.dot(launch.position_b, [-w[1], w[0]]))) / edge_offset(hull, w)
        planner = impact_offset_fraction(
            (0.0, 0.0), launch.velocity_a, 0.0, ego.length, ego.width,
            launch.position_b, launch.velocity_b, launch.yaw_b, shape.length, shape.width,
        )  # fmt: skip
        assert sweep == pytest.approx(case.offset, abs=1e-9)
        worst[partner.round] = max(worst[partner.round], abs(float(planner) - sweep))
    assert worst[False] < 1e-9
    assert worst[True] < 0.07


def test_row_offsets_are_the_planners():
    rows, expected = [], []
    for case, ego, _, shape, speed_a, speed_b, launch in _launches(Grid.SMALL):
        rows.append(case.design() | {"source": "sweep", "speed_a": speed_a, "speed_b": speed_b})
        expected.append(float(impact_offset_fraction(
            (0.0, 0.0), launch.velocity_a, 0.0, ego.length, ego.width,
            launch.position_b, launch.velocity_b, launch.yaw_b, shape.length, shape.width,
        )))  # fmt: skip
    rows.append({"source": "run-1", "offset": 0.3})
    np.testing.assert_allclose(row_offset_fractions(rows), [*expected, 0.3], atol=1e-12)


# ------------------------------------------------------------------ the real small grid


def test_small_grid_reports_held_back_median_and_p95(tmp_path):
    start = time.perf_counter()
    rows = run_sweep(GRIDS[Grid.SMALL].cases(), tmp_path / "impacts.csv", workers=2, progress=False)
    summary = summarize(rows, np.random.default_rng(0))
    cal = summary["calibration"]
    for key in ("test_error_eq1", "test_error_angle_only", "test_error_calibrated"):
        stats = cal[key]["all"]
        assert stats["n"] > 150
        assert math.isfinite(stats["median_abs"]) and math.isfinite(stats["p95_abs"])
    before, after = cal["test_error_eq1"]["all"], cal["test_error_calibrated"]["all"]
    print(
        f"held-back median {before['median_abs']:.1%} -> {after['median_abs']:.1%}, "
        f"p95 {before['p95_abs']:.1%} -> {after['p95_abs']:.1%} ({time.perf_counter() - start:.1f} s)"
    )
    assert after["median_abs"] < before["median_abs"]
    # the p95 is reported, not asserted to improve: it does not (see the report)
    report = write_report(tmp_path, summary, "small", [])
    text = report.read_text()
    assert "angle x offset p95" in text and "offset-fraction bin" in text
