"""``etp predictor train`` / ``calibrate`` / ``eval``: bad input exits 2 with a message; a small real run."""

import json

import pytest

pytest.importorskip("torch")
pytest.importorskip("commonroad")

from harm_calibration.cli import main  # noqa: E402
from mujoco_world.scenario.commonroad_tracks import shared_commonroad  # noqa: E402

SHARED = shared_commonroad()


@pytest.mark.parametrize(
    "argv,message",
    [
        (
            ["predictor", "train", "--data", "/nonexistent", "--out", "x.pt"],
            "--data /nonexistent: not a folder",
        ),
        (["predictor", "train", "--stride", "0", "--out", "x.pt"], "--stride must be >= 1"),
        (["predictor", "train", "--max-files", "0", "--out", "x.pt"], "--max-files must be >= 1"),
        (["predictor", "eval", "--weights", "/nonexistent.pt"], "no such file"),
        (
            ["predictor", "train", "--components", "0", "--out", "x.pt"],
            "--components must be between 1 and 4",
        ),
        (
            ["predictor", "calibrate", "--components", "5", "--out", "x.pt"],
            "--components must be between 1 and 4",
        ),
        (["predictor", "calibrate", "--stride", "0", "--out", "x.pt"], "--stride must be >= 1"),
    ],
)
def test_bad_input_exits_2_with_a_message(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_corrupted_weights_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a torch file")
    assert main(["predictor", "eval", "--weights", str(bad), "--data", str(tmp_path)]) == 2
    assert "not a readable weights file" in capsys.readouterr().err


@pytest.mark.skipif(SHARED is None, reason="../shared/commonroad is absent")
def test_small_training_and_evaluation_on_real_files(tmp_path, capsys):
    """One file per SinD recording: train 1 epoch, refit a 3-Gaussian mixture, evaluate the held-out one."""
    data = str(SHARED / "drivability-checker-datasets" / "SinD")
    weights = tmp_path / "tiny.pt"
    common = ["--data", data, "--max-files", "1", "--workers", "1", "--no-cache"]
    assert main(["predictor", "train", *common, "--out", str(weights), "--epochs", "1"]) == 0
    out = capsys.readouterr().out
    assert "SinD declared 0.1 s, recorded velocities say 0.5 s" in out and weights.is_file()
    three = tmp_path / "three.pt"
    assert (
        main(
            [
                "predictor",
                "calibrate",
                *common,
                "--weights",
                str(weights),
                "--out",
                str(three),
                "--components",
                "3",
                "--json",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert summary["components"] == 3 and summary["validation_windows"] > 0
    assert len(summary["calibration"]["pedestrian moving"]["2"]["weight"]) == 3
    report = tmp_path / "eval"
    assert main(["predictor", "eval", *common, "--weights", str(three), "--out", str(report)]) == 0
    metrics = json.loads((report / "metrics.json").read_text())
    assert metrics["recordings"] == ["SinD-851"]
    assert {"learned (3-Gaussian mixture)", "learned, one Gaussian", "constant_velocity", "ctra"} <= set(
        metrics["metrics"]
    )
    assert (report / "reliability.png").stat().st_size > 10_000


def test_closed_loop_commands_reject_an_unknown_predictor(capsys, tmp_path):
    assert (
        main(["run", "highway_cut_in", "--predictor", "psychic", "--out", str(tmp_path), "--no-record"]) == 2
    )
    err = capsys.readouterr().err
    assert "psychic" in err and "learned" in err
