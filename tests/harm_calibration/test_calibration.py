import math

import numpy as np
import pytest

from harm_calibration.calibration import (
    BinCorrection,
    bin_index,
    done_checks,
    error_stats,
    held_back_evaluation,
    relative_error,
    scored,
    speed_independence,
)


def synthetic_rows(rng, n_cells=60, speeds=(5.0, 10.0, 20.0, 30.0)):
    """Rows of a sweep whose measurement is a known function of the geometry cell.

    measured = Eq. 1 x factor(angle, offset) x noise; the planar model predicts the
    measurement within 2 %.
    """
    rows = []
    for k in range(n_cells):
        partner = ("car", "truck", "pedestrian")[k % 3]
        angle = float(rng.choice([0.0, 45.0, 90.0, 135.0, 180.0]))
        offset = float(rng.choice([0.0, 0.5, 0.9]))
        factor = 1.1 if offset == 0.0 else (0.6 if angle == 90.0 else 0.8)
        for v in speeds:
            eq1 = 0.5 * v
            meas = eq1 * factor * rng.normal(1.0, 0.02)
            rows.append(
                {
                    "cell": f"{partner}|a{angle:g}|o{offset:g}|{k}",
                    "partner": partner,
                    "class": "offset" if offset > 0.15 else "oblique",
                    "angle_deg": angle,
                    "offset": offset,
                    "closing_speed": v,
                    "restitution_set": "default",
                    "dv_measured_a": meas,
                    "dv_measured_b": meas,
                    "dv_first_a": meas,
                    "dv_predicted_a": eq1,
                    "dv_planar_a": meas * rng.normal(1.0, 0.01),
                    "multi_impact": "no",
                }
            )
    return rows


def test_error_stats_relative_error_and_touches():
    s = error_stats(np.array([-0.5, 0.1, 1.0, np.nan]))
    assert s["n"] == 3 and s["median_abs"] == pytest.approx(0.5) and s["median"] == pytest.approx(0.1)
    assert s["p95_abs"] == pytest.approx(np.percentile([0.5, 0.1, 1.0], 95))
    # A model predicting (almost) nothing for a real impact is a large error, not a skipped row.
    err = relative_error(np.array([2.0, 1.0, 1.0]), np.array([1.0, 0.0, np.nan]))
    assert err[0] == pytest.approx(1.0) and err[1] == pytest.approx(1.0 / 0.05) and np.isnan(err[2])
    rows = [{"dv_measured_a": 0.02, "dv_measured_b": 0.4}, {"dv_measured_a": 0.03, "dv_measured_b": 0.6}]
    assert scored(rows).tolist() == [False, True]


def test_bins_cover_the_grid_values_one_per_bin():
    angles = np.arange(0.0, 181.0, 15.0)
    offsets = np.array([0.0, 0.25, 0.5, 0.75, 0.9])
    a, o = np.meshgrid(angles, offsets)
    bins = bin_index(a.ravel(), o.ravel())
    assert len(set(bins.tolist())) == bins.size == 13 * 5


def test_bin_correction_marks_unseen_bins_instead_of_falling_back():
    eq1 = np.array([10.0, 10.0, 10.0, 10.0])
    meas = np.array([8.0, 9.0, 10.0, 5.0])
    bins = np.array([0, 0, 0, 1])
    corr = BinCorrection.fit(eq1, meas, bins, min_count=3)
    assert corr.factors[0] == pytest.approx(0.9)
    assert np.isnan(corr.factors[1]) and corr.counts[1] == 1
    predicted = corr(np.array([20.0, 20.0]), np.array([0, 1]))
    assert predicted[0] == pytest.approx(18.0) and np.isnan(predicted[1])


def test_held_back_evaluation_splits_by_cell_and_reports_every_split():
    rows = synthetic_rows(np.random.default_rng(0))
    result = held_back_evaluation(rows, seeds=range(10))
    groups = result["groups"]
    assert len(result["seeds"]) == 10 and result["n_cells"] == 60
    # Whole cells are held back: every split tests a multiple of the 4 speeds.
    assert all(u["test_impacts"] % 4 == 0 for u in result["unseen"])
    eq1, planar, corr = (groups["all"][m]["median_abs"]["median"] for m in ("eq1", "planar", "correction"))
    assert planar < corr < 0.03 < 0.1 < eq1  # eq1 misses the factors, the correction fits them
    assert groups["all"]["eq1"]["median_abs"]["min"] <= groups["all"]["eq1"]["median_abs"]["max"]
    assert {"class:offset", "class:oblique", "partner:truck"} <= set(groups)
    assert not result["decision"]["correction_beats_planar"]
    checks = {c["group"]: c for c in done_checks(result)}
    assert checks["all"]["median_halved"] and checks["all"]["p95_no_worse"]


def test_held_back_groups_split_each_partner_by_sequence_type():
    rows = synthetic_rows(np.random.default_rng(3))
    # Every truck impact at 30 m/s is a multi-impact sequence whose measurement doubles.
    for r in rows:
        if r["partner"] == "truck" and r["closing_speed"] == 30.0:
            r["multi_impact"] = "yes"
            r["dv_measured_a"] *= 2.0
    groups = held_back_evaluation(rows, seeds=range(5))["groups"]
    single, multi = (
        groups["partner and sequence:truck, single impulse"],
        groups["partner and sequence:truck, multi-impact"],
    )
    # Whole cells are held back: a quarter of a truck's held-back impacts are its 30 m/s ones.
    assert multi["planar"]["n"]["median"] * 3 == single["planar"]["n"]["median"]
    assert multi["planar"]["median_abs"]["median"] == pytest.approx(1.0, abs=0.05)
    assert single["planar"]["median_abs"]["median"] < 0.03
    assert groups["partner and sequence:car, multi-impact"]["planar"]["n"]["median"] == 0


def test_held_back_evaluation_reports_unseen_bins():
    rows = synthetic_rows(np.random.default_rng(1))
    # One bin that exists in a single cell only: whenever that cell is held back it is unseen.
    rows += [
        dict(
            rows[0],
            cell="lonely",
            angle_deg=30.0,
            offset=0.25,
            closing_speed=v,
            dv_measured_a=1.0,
            dv_measured_b=1.0,
        )
        for v in (5.0, 10.0)
    ]
    result = held_back_evaluation(rows, seeds=range(20))
    lonely = [u for u in result["unseen"] if any("angle 22.5-37.5" in b for b in u["unseen_bins"])]
    assert lonely and all(u["unseen_impacts"] >= 2 for u in lonely)


def test_held_back_evaluation_rejects_bad_input():
    with pytest.raises(ValueError, match="test_fraction"):
        held_back_evaluation(synthetic_rows(np.random.default_rng(0)), test_fraction=1.0)
    with pytest.raises(ValueError, match="geometry cells"):
        held_back_evaluation(synthetic_rows(np.random.default_rng(0), n_cells=1))


def test_speed_independence_flags_cells_and_names_the_cause():
    rows = synthetic_rows(np.random.default_rng(2), n_cells=12)
    steady = speed_independence(rows, partners=("car", "truck"))
    assert steady["n_cells"] == 8 and not steady["flagged"] and steady["max_variation"] < 0.1
    assert {c["verdict"] for c in steady["cells"]} == {"steady"}
    cells = sorted({r["cell"] for r in rows if r["partner"] == "car"})
    cells.append(sorted({r["cell"] for r in rows if r["partner"] == "truck"})[0])
    for r in rows:
        v = r["closing_speed"]
        if r["cell"] == cells[0]:  # a measurement artefact: the ratio grows with speed
            r["dv_measured_a"] = r["dv_predicted_a"] * (1.0 + 0.02 * v)
        if r["cell"] == cells[1]:  # grows only where a second hit joins the sequence
            r["multi_impact"] = "yes" if v >= 20.0 else "no"
            r["dv_measured_a"] *= 1.5 if v >= 20.0 else 1.0
        if r["cell"] == cells[2]:  # grows at speeds 5-20 without a second hit: not explained
            r["multi_impact"] = "yes" if v == 30.0 else "no"
            r["dv_measured_a"] *= 1.0 + 0.01 * v
        if r["cell"] == cells[3]:  # restitution falling with speed, which the planar model takes too
            e = 0.1 + 0.5 * math.exp(-v / 6.0)
            r["dv_measured_a"] = r["dv_predicted_a"] * (1.0 + e)
            r["dv_planar_a"] = r["dv_measured_a"] * 0.97
        if r["cell"] == cells[4]:  # multi-impact at every speed, the first impulse moving too
            r["multi_impact"] = "yes"
            r["dv_measured_a"] *= 1.0 + 0.02 * v
            r["dv_first_a"] *= 1.0 + 0.02 * v
    check = speed_independence(rows, partners=("car", "truck"))
    verdicts = {c["cell"]: c["verdict"] for c in check["cells"]}
    # cells[4]: no single-impulse speed to compare, and the first impulse does not agree
    # with the planar model across speeds: no evidence that later hits explain it.
    expected = ["unexplained", "multi-impact", "unexplained", "restitution law", "unexplained"]
    assert [verdicts[c] for c in cells[:5]] == expected
    assert {c["cell"] for c in check["flagged"]} == set(cells[:5])
    assert {c["cell"] for c in check["unexplained"]} == {cells[0], cells[2], cells[4]}
    first = next(c for c in check["cells"] if c["cell"] == cells[0])
    assert first["variation"] == pytest.approx(1.6 / 1.1 - 1, rel=0.05)
    assert first["ratio"]["5"] == pytest.approx(1.1, rel=0.01) and first["ratio"]["30"] == pytest.approx(1.6)
    # The multi-impact cell's first impulse (dv_first_a, untouched above) stays with the planar model.
    second = next(c for c in check["cells"] if c["cell"] == cells[1])
    assert second["variation_first"] < 0.1 < second["variation_planar"]
    counts = check["by_restitution_set"]["default"]
    assert (counts["flagged"], counts["unexplained"], counts["multi-impact"], counts["restitution law"]) == (
        5, 3, 1, 1,
    )  # fmt: skip


def test_the_sequence_model_is_held_back_checked_and_explains_speed_variation():
    """A model that follows the whole sequence: in the held-back table, the checks, the speed verdicts."""
    rows = synthetic_rows(np.random.default_rng(4), n_cells=12)
    truck = sorted({r["cell"] for r in rows if r["partner"] == "truck"})[0]
    for r in rows:
        r["dv_planar_seq_a"] = r["dv_measured_a"] * 1.01
        if r["cell"] == truck:  # later hits grow with speed; only the sequence model has them
            r["multi_impact"] = "yes"
            r["dv_measured_a"] *= 1.0 + 0.03 * r["closing_speed"]
            r["dv_first_a"] *= 1.0 + 0.03 * r["closing_speed"]
            r["dv_planar_seq_a"] = r["dv_measured_a"] * 0.98
    result = held_back_evaluation(rows, seeds=range(5))
    seq = result["groups"]["all"]["planar_seq"]["median_abs"]["median"]
    assert seq == pytest.approx(0.01 / 1.01, rel=0.05)
    checks = {c["group"]: c for c in done_checks(result, "planar_seq")}
    assert checks["all"]["model"] == "planar_seq" and checks["all"]["p95_no_worse"]
    with pytest.raises(ValueError, match="model must be one of"):
        done_checks(result, "correction")
    verdicts = {c["cell"]: c for c in speed_independence(rows, partners=("truck",))["cells"]}
    assert verdicts[truck]["verdict"] == "sequence model"
    assert verdicts[truck]["variation_seq"] < 0.01
    # A table without the sequence model's column (an older impacts.csv): nan, never an error.
    for r in rows:
        del r["dv_planar_seq_a"]
    old = held_back_evaluation(rows, seeds=range(2))
    assert math.isnan(old["groups"]["all"]["planar_seq"]["median_abs"]["median"])
    without = {c["cell"]: c["verdict"] for c in speed_independence(rows, partners=("truck",))["cells"]}
    assert without[truck] == "unexplained"
