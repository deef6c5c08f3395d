"""Tests of ``etp harm`` through the top-level command line."""

from __future__ import annotations

import json
import math
import re

import pytest

from ethical_planner.harm import HarmModel, harm
from harm_calibration.cli import main


def _json(capsys, *argv: str) -> dict:
    assert main(["harm", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_default_model_side_impact_human_line(capsys):
    assert main(["harm", "--dv", "12", "--area", "side"]) == 0
    out = capsys.readouterr().out.strip()
    # LR4S: 1 / (1 + exp(4.457 - 0.177 * 12 - 0.244)) = 0.110
    assert out.startswith("reduced_sym (LR4S): car dv 12.00 m/s, area side")
    assert "P(MAIS3+) = 0.110" in out
    assert len(out.splitlines()) == 1


def test_json_output(capsys):
    record = _json(capsys, "--dv", "12", "--area", "side")
    assert record["model"] == "reduced_sym"
    assert record["label"] == "LR4S"
    assert record["partner"] == "car"
    assert record["unprotected"] is False
    assert record["probability"] == pytest.approx(1 / (1 + math.exp(4.457 - 0.177 * 12 - 0.244)))
    assert record["angle_rad"] == pytest.approx(math.pi / 2)
    # Eq. 1: the ego's delta-v times its mass equals the partner's.
    assert record["ego_dv_mps"] * record["ego_mass_kg"] == pytest.approx(
        record["dv_mps"] * record["partner_mass_kg"]
    )
    assert record["closing_speed_mps"] == pytest.approx(record["dv_mps"] + record["ego_dv_mps"])


@pytest.mark.parametrize("partner", ["pedestrian", "bicycle", "motorcycle"])
def test_unprotected_partners_use_the_pedestrian_model(capsys, partner):
    record = _json(capsys, "--dv", "8", "--partner", partner)
    assert record["model"] == "pedestrian_mais3"
    assert record["unprotected"] is True
    assert record["probability"] == pytest.approx(1 / (1 + math.exp(3.164 - 0.288 * 8)))


def test_pedestrian_mais2_and_ignored_area(capsys):
    assert main(["harm", "--dv", "8", "--partner", "pedestrian", "--model", "pedestrian_mais2",
                 "--area", "front"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "P(MAIS2+)" in out
    assert "not used by this model" in out


@pytest.mark.parametrize(
    ("area", "model", "degrees"),
    [
        ("3", "complete", -90.0),
        ("9", "complete", 90.0),
        ("12", "complete_sym", 0.0),
        ("6", "reduced", 180.0),
        ("driver_side", "reduced", 90.0),
        ("right_side", "complete", -90.0),
        ("rear", "ref_speed_reduced_sym", 180.0),
        ("5", "reduced_sym", -150.0),
    ],
)
def test_areas_map_to_the_model(capsys, area, model, degrees):
    record = _json(capsys, "--dv", "20", "--area", area, "--model", model)
    expected = float(harm(model, 20.0, math.radians(degrees)))
    assert record["probability"] == pytest.approx(expected)


@pytest.mark.parametrize("model", [m.value for m in HarmModel if not m.startswith("pedestrian")])
def test_every_vehicle_model_answers(capsys, model):
    record = _json(capsys, "--dv", "15", "--area", "front", "--model", model)
    assert 0.0 <= record["probability"] <= 1.0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--dv", "12", "--area", "middle"], "unknown area 'middle'; allowed: front, side"),
        (["--dv", "12", "--area", "13"], "clock position 1..12"),
        (["--dv", "12"], "model reduced_sym needs --area"),
        (["--dv", "12", "--area", "side", "--model", "complete"], "'side' is ambiguous"),
        (["--dv", "-3", "--area", "front"], r"--dv must lie in \[0, 100\] m/s"),
        (["--dv", "nan", "--area", "front"], r"--dv must lie in \[0, 100\] m/s, got nan"),
        (["--dv", "12", "--model", "lr4"], "unknown harm model 'lr4'; allowed: ignore_angle"),
        (["--dv", "12", "--partner", "dog"], "unknown road-user type 'dog'; allowed: car"),
        (["--dv", "12", "--partner", "pedestrian", "--model", "reduced_sym"],
         "allowed: pedestrian_mais3, pedestrian_mais2"),
        (["--dv", "12", "--model", "pedestrian_mais3"], "partner car is protected"),
        (["--dv", "12", "--area", "rear", "--ego-mass", "0"], "--ego-mass must lie in"),
    ],
)  # fmt: skip
def test_bad_values_exit_2_with_allowed_values(capsys, argv, message):
    assert main(["harm", *argv]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "etp harm: error:" in captured.err
    assert re.search(message, captured.err), captured.err
