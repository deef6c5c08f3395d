import csv
import json

import numpy as np
import pytest

from ethical_planner.harm import HarmModel
from harm_calibration.cli import main
from harm_calibration.refit import fit_logistic, parse_records, read_records, simulate_records


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


def test_gradient_and_standard_error_against_numeric():
    rows = simulate_records(HarmModel.REDUCED_SYM, 5000, np.random.default_rng(2))
    result = fit_logistic(parse_records(rows, HarmModel.REDUCED_SYM))
    assert result.names == ("c0", "c1", "area_side", "area_rear")
    assert np.all(result.std_error > 0) and np.all(result.std_error < 0.5)


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
