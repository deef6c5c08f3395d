"""What every ``etp`` command shares: --version, descriptions, --json, --out, --config, progress."""

import argparse
import json
import os
import sys
from importlib import metadata
from pathlib import Path

import pytest

from harm_calibration.cli import build_parser, main
from mujoco_world.storage.run_folder import run_id
from mujoco_world.storage.run_index import read_index
from tests.harm_calibration.cli.conftest import FOLLOW, write_scenario


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    """Every leaf command by its full name ("predictor train" for a command group)."""

    def leaves(parser: argparse.ArgumentParser, prefix: str) -> dict[str, argparse.ArgumentParser]:
        groups = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not groups:
            return {prefix: parser}
        out = {}
        for name, sub in groups[0].choices.items():
            out |= leaves(sub, f"{prefix} {name}".strip())
        return out

    return leaves(build_parser(), "")


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"etp {metadata.version('ethical-trajectory-planning')}"


@pytest.mark.parametrize("name", sorted(_subcommands()))
def test_every_subcommand_has_a_description_and_the_same_json_flag(name):
    sub = _subcommands()[name]
    assert sub.description and len(sub.description) > 40, name
    (json_flag,) = [a for a in sub._actions if "--json" in a.option_strings]
    assert isinstance(json_flag, argparse._StoreTrueAction), f"{name}: --json takes no value"
    assert json_flag.help == "print the result as JSON on stdout instead of text"


def _json_out(capsys, argv):
    code = main(argv)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)  # stdout holds exactly one JSON document


def test_json_is_machine_readable_on_every_cheap_command(tmp_path, capsys, short_scenario):
    assert _json_out(capsys, ["harm", "--dv", "10", "--area", "front", "--json"])["probability"] > 0
    assert _json_out(capsys, ["plan", "--cycles", "1", "--json"])[0]["planner"] == "ethical"
    assert len(_json_out(capsys, ["scenarios", "--json"])) >= 9
    summary = _json_out(
        capsys, ["run", short_scenario, "--out", str(tmp_path / "r"), "--no-record", "--json"]
    )
    assert summary["scenario"] == "short" and summary["outcome"] in ("goal", "timeout", "crash")
    demo = ["demo", "--scenarios", short_scenario, "--planners", "standard", "--out", str(tmp_path / "d")]
    batch = _json_out(capsys, [*demo, "--no-record", "--workers", "1", "--json"])
    assert [r["scenario"] for r in batch["runs"]] == ["short"]
    rows = _json_out(capsys, ["near-crash", str(tmp_path / "r"), "--json"])
    assert [r["run_id"] for r in rows] == [run_id(short_scenario, "ethical", 0)]  # the head-on crash nearby


def test_output_stays_inside_out(tmp_path, short_scenario):
    out = tmp_path / "nest" / "D"
    assert main(["run", short_scenario, "--out", str(out), "--no-record"]) == 0
    assert sorted(p.name for p in (tmp_path / "nest").iterdir()) == ["D"]
    run = run_id(short_scenario, "ethical", 0)  # short-<hash of the file's path>__ethical__s0
    assert sorted(p.name for p in out.iterdir()) == ["index.jsonl", run]
    assert [r.run_id for r in read_index(out)] == [run]


def _never(*args, **kwargs):
    raise AssertionError("simulated although the output folder is unusable")


@pytest.mark.parametrize("command", ["run", "demo"])
def test_unusable_out_fails_before_simulating(tmp_path, capsys, monkeypatch, short_scenario, command):
    import mujoco_world.experiments.batch as batch

    monkeypatch.setattr(batch, "run_scenario", _never)
    monkeypatch.setattr(batch, "run_batch", _never)
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    argv = [command, short_scenario] if command == "run" else [command, "--scenarios", short_scenario]
    for out, message in (
        (a_file, f"--out {a_file} is a file, not a folder"),
        (a_file / "below", "cannot create the folder"),
        (Path("/proc/self/etp-out"), "cannot create the folder"),
    ):
        assert main([*argv, "--out", str(out)]) == 2
        assert message in capsys.readouterr().err


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_out_fails_before_simulating(tmp_path, capsys, short_scenario):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        assert main(["run", short_scenario, "--out", str(folder)]) == 2
        assert "is not writable" in capsys.readouterr().err
    finally:
        folder.chmod(0o755)


def test_config_overrides_apply_to_run_and_demo(tmp_path, capsys):
    scenario = write_scenario(tmp_path, FOLLOW, "follow", duration=0.5)
    config = tmp_path / "calibrated.toml"
    # the planar impulse model with e = 0.4: a rear-end delta-v 1.4 times Eq. 1's
    config.write_text(
        '[risk]\ndelta_v_model = "planar_impulse"\nrestitution_law = {e_high = 0.4, e_low = 0.4}\n',
        encoding="utf-8",
    )
    slow = tmp_path / "slow.toml"
    slow.write_text('name = "crawl"\ndesired_speed = 2.0\n', encoding="utf-8")

    def run(*extra, scenario=scenario):
        argv = ["run", scenario, "--out", str(tmp_path / "out"), "--no-record", "--json", *extra]
        return _json_out(capsys, argv)

    plain, calibrated = run(), run("--config", str(config))
    free_road = write_scenario(tmp_path, duration=2.0)  # ego starts at s = 10 m with 10 m/s
    free, crawl = run(scenario=free_road), run("--config", str(slow), scenario=free_road)
    assert (free["planner"], calibrated["planner"], crawl["planner"]) == (
        "ethical",
        "ethical+calibrated",
        "crawl",
    )
    # another delta-v model plans with other harms (and trajectories); a 2 m/s target slows the ego
    assert 0 < plain["max_risk"]["ego"] != calibrated["max_risk"]["ego"] > 0
    assert free["progress"] - 10.0 > 20.0 > 18.0 > crawl["progress"] - 10.0  # 13.9 vs 2 m/s wanted
    demo = ["demo", "--scenarios", scenario, "--planners", "ethical,standard", "--config", str(config)]
    batch = _json_out(
        capsys, [*demo, "--out", str(tmp_path / "d"), "--no-record", "--workers", "1", "--json"]
    )
    assert sorted(r["planner"] for r in batch["runs"]) == ["ethical+calibrated", "standard+calibrated"]
    # the configured planner's folder carries a hash of its configuration (never a preset's folder)
    (folder,) = (tmp_path / "d").glob("follow-*__ethical+calibrated-*__s0")
    assert (folder / "summary.json").is_file()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('[risk]\ndelta_v_model = "bogus"\n', "risk.delta_v_model"),
        ("[risk]\nmax_acceptable_risk = 2.0\n", "max_acceptable_risk must lie in [0, 1]"),
        ("[weights]\nbogus = 1\n", "weights.bogus"),
        ("[risk\n", "not valid TOML"),
        ('preset = "ethical"\n', "the key 'preset' chooses one planner"),
    ],
)
def test_bad_config_is_exit_2_naming_the_file(tmp_path, capsys, monkeypatch, short_scenario, text, message):
    import mujoco_world.experiments.batch as batch

    monkeypatch.setattr(batch, "run_batch", _never)
    config = tmp_path / "bad.toml"
    config.write_text(text, encoding="utf-8")
    assert main(["demo", "--scenarios", short_scenario, "--config", str(config), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert str(config) in err and message in err


def test_run_shows_progress_on_a_terminal_only(tmp_path, capsys, monkeypatch):
    argv = ["run", write_scenario(tmp_path, duration=0.5), "--out", str(tmp_path), "--no-record"]
    assert main(argv) == 0
    assert "simulated" not in capsys.readouterr().err  # stderr is not a terminal here
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(argv) == 0
    assert "0.5/0.5 s simulated" in capsys.readouterr().err
    assert main([*argv, "--no-progress"]) == 0
    assert "simulated" not in capsys.readouterr().err


def test_near_crash_prints_whole_run_ids_that_replay_accepts(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    long_name = "a_scenario_name_well_beyond_thirty_two_characters"
    scenario = write_scenario(tmp_path, name=long_name, duration=2.0)
    assert main(["run", scenario, "--planner", "standard", "--out", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    assert main(["near-crash", str(tmp_path / "out")]) == 0
    text = capsys.readouterr().out
    assert "harm meas / harm pred: highest MAIS3+ probability of any body" in text
    run = run_id(scenario, "standard", 0)
    assert run.startswith(long_name)
    (line,) = [line for line in text.splitlines() if run in line]
    assert line.split()[1] == run
    assert main(["replay", run, "--root", str(tmp_path / "out"), "--json"]) == 0
    replay = json.loads(capsys.readouterr().out)
    assert replay["recording"].endswith(f"{run}/recording.rrd") and replay["opened"] is False


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["refit-harm", "{tmp}/missing.csv"], "missing.csv: cannot read: No such file or directory"),
        (["refit-harm", "{tmp}"], "is a folder, not a CSV file"),
        (["near-crash", "{tmp}/nowhere"], "no run index at"),
        (["replay", "nothing", "--root", "{tmp}"], "no recording for 'nothing'"),
        (["impacts", "--from-runs", "{tmp}/nowhere", "--out", "{tmp}/o"], "--from-runs"),
        (["run", "{tmp}/missing.toml"], "cannot read scenario file"),
        (["demo", "--scenarios", "{tmp}/missing.toml", "--out", "{tmp}/o"], "cannot read scenario file"),
        (["bench", "--out", "{tmp}", "--grid", "225"], "is a folder, not a file"),
    ],
)
def test_missing_files_are_exit_2_not_a_traceback(tmp_path, capsys, argv, message):
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
