import math

import numpy as np
import pytest

from harm_calibration.calibration import CalibratedDeltaV, calibrate, fit_calibrated_delta_v


def test_fit_recovers_factors_and_reduces_test_error(tmp_path):
    rng = np.random.default_rng(1)
    n = 2000
    angle = rng.uniform(0, 180, n)
    pred = rng.uniform(1, 20, n)
    truth = np.where(angle < 60, 1.1, np.where(angle < 120, 0.7, 1.0))
    meas = pred * truth * rng.normal(1.0, 0.02, n)
    cls = np.where(np.abs(angle - 90) > 80, "central_collinear", "oblique")
    result = calibrate(pred, meas, angle, cls, np.random.default_rng(7), edges_deg=(0, 60, 120, 180))
    assert result.correction.factors == pytest.approx((1.1, 0.7, 1.0), rel=0.01)
    assert result.after["all"]["median_abs"] < 0.25 * result.before["all"]["median_abs"]
    assert result.seed == 7
    path = tmp_path / "cal.json"
    result.correction.save(path)
    assert CalibratedDeltaV.load(path) == result.correction


def test_call_is_vectorised_and_folds_angles():
    cal = CalibratedDeltaV((0.0, 90.0, 180.0), (2.0, 0.5))
    dv = np.full((3, 4), 10.0)
    angle = np.array([0.1, -0.1, math.pi - 0.1, 2 * math.pi + 0.1])
    out = cal(dv, angle)
    assert out.shape == (3, 4)
    np.testing.assert_allclose(out[0], [20.0, 20.0, 5.0, 20.0])
    assert float(cal(10.0, math.pi)) == 5.0


def test_empty_bins_keep_factor_one():
    cal = fit_calibrated_delta_v([10.0, 10.0], [12.0, 12.0], [10.0, 20.0], (0, 90, 180))
    assert cal.factors == (1.2, 1.0) and cal.n_train == (2, 0)


@pytest.mark.parametrize(
    ("edges", "factors", "match"),
    [((0, 90), (1.0,), "180"), ((0, 90, 180), (1.0,), "one per bin"), ((0, 90, 180), (1.0, -1.0), "> 0")],
)
def test_invalid_correction(edges, factors, match):
    with pytest.raises(ValueError, match=match):
        CalibratedDeltaV(edges, factors)


def test_from_dict_rejects_unknown_keys():
    with pytest.raises(ValueError, match="unknown keys"):
        CalibratedDeltaV.from_dict({"edges_deg": [0, 180], "factors": [1], "scale": 2})
