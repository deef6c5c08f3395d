import csv
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from ethical_planner.harm import HarmModel, harm
from harm_calibration import refit
from harm_calibration.cli import main
from harm_calibration.refit import fit_logistic, parse_records, read_records, simulate_records
from harm_calibration.sweep import GridSpec, run_sweep


@pytest.mark.parametrize(
    ("model", "seed"),
    [(HarmModel.REDUCED_SYM, 3), (HarmModel.IGNORE_ANGLE, 4), (HarmModel.PEDESTRIAN_MAIS3, 5)],
)
def test_recovers_shipped_coefficients_within_two_se(model, seed):
    rows = simulate_records(model, 20000, np.random.default_rng(seed))
    result = fit_logistic(parse_records(rows, model), model)
    assert result.converged
    z = (result.estimate - result.shipped) / result.std_error
    assert np.all(np.abs(z) < 2.0), result.table()


def test_weights_equal_duplicated_records():
    rows = simulate_records(HarmModel.IGNORE_ANGLE, 3000, np.random.default_rng(0))
    weighted = [dict(r, weight="2") for r in rows]
    a = fit_logistic(parse_records(rows + rows, HarmModel.IGNORE_ANGLE), HarmModel.IGNORE_ANGLE)
    b = fit_logistic(parse_records(weighted, HarmModel.IGNORE_ANGLE), HarmModel.IGNORE_ANGLE)
    np.testing.assert_allclose(a.estimate, b.estimate, rtol=1e-6)
    np.testing.assert_allclose(a.std_error, b.std_error, rtol=1e-6)


def _scalar_log_likelihood(beta, rows):
    """Log-likelihood of LR4S records written out record by record (independent of refit.py)."""
    total = 0.0
    for r in rows:
        area = {"front": 0.0, "side": beta[2], "rear": beta[3]}[r["area"]]
        p = 1.0 / (1.0 + math.exp(-(beta[0] + beta[1] * float(r["dv"]) + area)))
        total += math.log(p) if r["mais3"] == "1" else math.log(1.0 - p)
    return total


def test_estimate_maximises_and_standard_errors_invert_the_numeric_hessian():
    rows = simulate_records(HarmModel.REDUCED_SYM, 2000, np.random.default_rng(2))
    result = fit_logistic(parse_records(rows, HarmModel.REDUCED_SYM))
    assert result.names == ("c0", "c1", "area_side", "area_rear")
    beta, h = result.estimate, 1e-3
    assert result.log_likelihood == pytest.approx(_scalar_log_likelihood(beta, rows), rel=1e-10)
    hessian = np.zeros((4, 4))
    for i in range(4):
        for j in range(4):
            e_i, e_j = np.eye(4)[i] * h, np.eye(4)[j] * h
            hessian[i, j] = (
                _scalar_log_likelihood(beta + e_i + e_j, rows)
                - _scalar_log_likelihood(beta + e_i - e_j, rows)
                - _scalar_log_likelihood(beta - e_i + e_j, rows)
                + _scalar_log_likelihood(beta - e_i - e_j, rows)
            ) / (4 * h * h)
    gradient = [
        (
            _scalar_log_likelihood(beta + np.eye(4)[i] * 1e-6, rows)
            - _scalar_log_likelihood(beta - np.eye(4)[i] * 1e-6, rows)
        )
        / 2e-6
        for i in range(4)
    ]
    np.testing.assert_allclose(gradient, 0.0, atol=1e-5)  # a maximum
    np.testing.assert_allclose(result.std_error, np.sqrt(np.diag(np.linalg.inv(-hessian))), rtol=1e-4)


def test_converged_means_the_summed_log_likelihood_has_converged(monkeypatch):
    rows = simulate_records(HarmModel.IGNORE_ANGLE, 3000, np.random.default_rng(7))
    records = parse_records(rows, HarmModel.IGNORE_ANGLE)
    heavy = replace(records, weight=records.weight * 1e6)  # a million times each record
    a, b = fit_logistic(records, "ignore_angle"), fit_logistic(heavy, "ignore_angle")
    assert a.converged and b.converged
    assert a.newton_decrement < 1e-10 and b.newton_decrement < 1e-10  # on the sum, not the mean
    np.testing.assert_allclose(b.estimate, a.estimate, rtol=1e-9)
    np.testing.assert_allclose(b.std_error, a.std_error * 1e-3, rtol=1e-6)
    monkeypatch.setattr(refit, "MAX_ITERATIONS", 1)  # one Newton step from the shipped values
    stopped = fit_logistic(records, "ignore_angle")
    assert not stopped.converged and stopped.newton_decrement > 1e-10
    assert "NOT converged" in stopped.table()


def _rows(dv, labels, area="front"):
    return [{"dv": str(v), "mais3": str(y), "area": area} for v, y in zip(dv, labels, strict=True)]


@pytest.mark.parametrize(
    ("rows", "model", "match"),
    [
        (
            _rows([5.0] * 6, [0, 1] * 3),
            "ignore_angle",
            r"cannot tell parameters \['c0', 'c1'\] apart.*dv = 5",
        ),
        (_rows(range(10), [0] * 10), "ignore_angle", "every record has mais3 = 0"),
        (_rows(range(10), [1] * 10), "ignore_angle", "every record has mais3 = 1"),
        (_rows(range(10), [0] * 5 + [1] * 5), "ignore_angle", "separable"),
        (_rows([1, 2, 5, 5, 8, 9], [0, 0, 0, 1, 1, 1]), "ignore_angle", "separable"),  # a tie at 5
        (_rows(range(6), [0, 1] * 3) + _rows([3.0], [1], "rear"), "reduced_sym", r"\['area_side'\]"),
        (
            _rows(range(8), [0, 1] * 4)
            + _rows([2.0, 4.0], [1, 1], "side")
            + _rows([3.0, 5.0], [0, 1], "rear"),
            "reduced_sym",
            "separable",  # every side record is MAIS3+: area_side runs off to infinity
        ),
    ],
)
def test_records_without_a_finite_estimate_are_refused(rows, model, match):
    with pytest.raises(ValueError, match=match):
        fit_logistic(parse_records(rows, model), model)


def test_overlapping_records_fit_without_complaint():
    result = fit_logistic(
        parse_records(_rows([1, 2, 5, 5, 8, 9], [0, 1, 0, 1, 0, 1]), "ignore_angle"), "ignore_angle"
    )
    assert result.converged and np.all(np.isfinite(result.std_error))


def test_table_columns_never_run_together():
    result = refit.RefitResult(
        model="ignore_angle",
        names=("c0", "c1"),
        estimate=np.array([-123456.789, 98765.4321]),
        std_error=np.array([1.0e6, 0.5]),
        shipped=np.array([-4.591, 0.185]),
        log_likelihood=-1.0,
        n_records=10,
        weight_sum=10.0,
        converged=True,
    )
    lines = result.table().splitlines()
    assert lines[1].split() == ["parameter", "estimate", "std.err", "shipped", "z"]
    assert lines[2].split() == ["c0", "-123456.7890", "1000000.0000", "-4.5910", "-0.12"]
    assert lines[3].split() == ["c1", "98765.4321", "0.5000", "0.1850", "197530.49"]


IMPACT_HEADER = ["status"] + [
    f"{name}_{side}"
    for side in ("a", "b")
    for name in ("model", "harm_measured", "dv_measured", "dv_predicted", "area_measured", "area_predicted")
]


def _impact_table(path, rng, n=400, scale=1.25):
    """An impact table whose predicted delta-v is ``scale`` times the measured one, areas alike."""
    rows = []
    for _ in range(n):
        row = {"status": "ok"}
        for side in ("a", "b"):
            dv = rng.uniform(0.0, 40.0)
            area = ["front", "driver_side", "right_side", "rear"][rng.integers(4)]
            row |= {
                f"model_{side}": "reduced_sym",
                f"dv_measured_{side}": repr(dv),
                f"dv_predicted_{side}": repr(scale * dv),
                f"area_measured_{side}": area,
                f"area_predicted_{side}": area,
                f"harm_measured_{side}": repr(float(harm(HarmModel.REDUCED_SYM, dv, _ANGLE[area]))),
            }
        rows.append(row)
    rows.append({k: "" for k in IMPACT_HEADER} | {"status": "failed"})  # no measurement: left out
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=IMPACT_HEADER)
        writer.writeheader()
        writer.writerows(rows)
    return path


_ANGLE = {"front": 0.0, "driver_side": math.pi / 2, "right_side": -math.pi / 2, "rear": math.pi}


def test_refit_of_an_impact_table_finds_the_coefficients_of_the_predicted_inputs(tmp_path):
    # H = s(c0 + c1 dv_measured + c_area) = s(c0 + (c1 / 1.25) dv_predicted + c_area): exact by hand
    path = _impact_table(tmp_path / "impacts.csv", np.random.default_rng(4))
    predicted = fit_logistic(read_records(path, "reduced_sym"), "reduced_sym")
    assert predicted.n_records == 800 and predicted.std_error_kind == "sandwich"
    np.testing.assert_allclose(predicted.estimate, [-4.457, 0.177 / 1.25, 0.244, -0.431], atol=1e-7)
    measured = fit_logistic(read_records(path, "reduced_sym", "measured"), "reduced_sym")
    np.testing.assert_allclose(measured.estimate, [-4.457, 0.177, 0.244, -0.431], atol=1e-7)
    with pytest.raises(ValueError, match="no measured body was assessed with model 'ignore_angle'"):
        read_records(path, "ignore_angle")


def test_sandwich_standard_errors_against_a_direct_computation(tmp_path):
    rng = np.random.default_rng(5)
    dv = rng.uniform(0, 30, 300)
    y = np.clip(1 / (1 + np.exp(4.0 - 0.2 * dv)) + rng.normal(0, 0.05, dv.size), 0, 1)
    records = refit.CrashRecords(dv, y, ("",) * dv.size, np.ones(dv.size))
    result = fit_logistic(records, "ignore_angle")
    x = np.column_stack([np.ones_like(dv), dv])
    p = 1 / (1 + np.exp(-(x @ result.estimate)))
    bread = np.linalg.inv(x.T @ (x * (p * (1 - p))[:, None]))
    meat = (x * (y - p)[:, None]).T @ (x * (y - p)[:, None])
    np.testing.assert_allclose(result.std_error, np.sqrt(np.diag(bread @ meat @ bread)), rtol=1e-8)
    assert result.std_error_kind == "sandwich"


def test_refit_reads_the_csv_that_etp_impacts_writes(tmp_path, capsys):
    # Offset 0.5 gives side hits (rigid contact: at offset 0 and 90 deg the front corners meet).
    grid = GridSpec((6.0, 12.0, 18.0), (0.0, 90.0, 180.0), (0.0, 0.5), ("car",), ("default",))
    run_sweep(grid.cases(), tmp_path / "impacts.csv", workers=1, progress=False)
    assert main(["refit-harm", str(tmp_path / "impacts.csv"), "--inputs", "measured", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["n_records"] == 36 and data["converged"]
    for name, value in {"c0": -4.457, "c1": 0.177, "area_side": 0.244, "area_rear": -0.431}.items():
        assert data["parameters"][name]["estimate"] == pytest.approx(value, abs=1e-6)
    assert main(["refit-harm", str(tmp_path / "impacts.csv")]) == 0
    assert "std.err: sandwich" in capsys.readouterr().out


GOOD = {"dv": "5.0", "mais3": "1", "area": "front"}


@pytest.mark.parametrize(
    ("rows", "match"),
    [
        ([{"dv": "5.0", "area": "front"}], r"missing columns \['mais3'\]"),
        ([GOOD, {"dv": "-1", "mais3": "0", "area": "front"}], "row 2: dv must be finite and >= 0"),
        ([GOOD, GOOD, {"dv": "x", "mais3": "0", "area": "front"}], "row 3: dv must be a number"),
        ([{"dv": "5", "mais3": "2", "area": "front"}], "row 1: mais3 must be 0 or 1"),
        ([{"dv": "5", "mais3": "1", "area": "roof"}], "row 1: area 'roof'"),
        (
            [{"dv": "5", "mais3": "1", "area": "front", "weight": "-2"}],
            "row 1: weight must be finite and >= 0",
        ),
    ],
)
def test_bad_records_name_the_row(rows, match):
    with pytest.raises(ValueError, match=match):
        parse_records(rows, HarmModel.REDUCED_SYM)


def test_area_aliases():
    rec = parse_records([{"dv": "1", "mais3": "0", "area": "driver_side"}], HarmModel.REDUCED_SYM)
    assert rec.area == ("side",)
    rec = parse_records([{"dv": "1", "mais3": "0", "area": "4"}], HarmModel.COMPLETE_SYM)
    assert rec.area == ("4_8",)


def test_reference_speed_model_is_rejected():
    with pytest.raises(ValueError, match="not logistic"):
        parse_records([GOOD], HarmModel.REF_SPEED_IGNORE_ANGLE)


def _write(path, rows):
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_cli_refit(tmp_path, capsys):
    path = tmp_path / "crashes.csv"
    _write(path, simulate_records(HarmModel.REDUCED_SYM, 4000, np.random.default_rng(9)))
    assert main(["refit-harm", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data["parameters"]) == {"c0", "c1", "area_side", "area_rear"}
    assert main(["refit-harm", str(path), "--model", "ignore_angle"]) == 0
    assert "c1" in capsys.readouterr().out
    assert read_records(path, "reduced_sym").dv.size == 4000


def test_cli_refit_bad_file(tmp_path, capsys):
    path = tmp_path / "bad.csv"
    _write(path, [GOOD, {"dv": "3", "mais3": "yes", "area": "rear"}])
    assert main(["refit-harm", str(path)]) == 2
    assert "row 2: mais3 must be 0 or 1" in capsys.readouterr().err
    path.write_bytes(b"dv,mais3\n5,\xff\n")
    assert main(["refit-harm", str(path), "--model", "ignore_angle"]) == 2
    assert f"{path}: not UTF-8 text" in capsys.readouterr().err
    path.write_text("a,b\n1,2\n")
    assert main(["refit-harm", str(path)]) == 2
    assert "neither crash records" in capsys.readouterr().err
