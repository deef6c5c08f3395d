"""Run records: the typed file of one run, and the one rule for run ids and folders."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from mujoco_world.loop.runner import RunConfig, run_scenario
from mujoco_world.loop.summary import BodyRecord, RunSummary
from mujoco_world.loop.world import ObservationNoise
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.scenario.spec import scenario_from_dict
from mujoco_world.storage.run_folder import run_dir, run_id, source_key
from mujoco_world.storage.run_record import (
    RECORD_FILE,
    RECORD_VERSION,
    NotARunRecord,
    RunRecord,
    iter_records,
    read_record,
    write_record,
)


@pytest.fixture(scope="module")
def crash_summary():
    """Two cars meet head-on beside the ego at t ~ 1.8 s: a measured collision."""
    car = {"type": "car", "behaviour": {"kind": "scripted", "speed": 10.0}}
    scenario = scenario_from_dict(
        {
            "name": "head_on",
            "road": {"length": 300.0},
            "ego": {"s0": 10.0, "speed": 10.0},
            "duration": 3.0,
            "road_users": [
                {"name": "east", "s0": 100.0, "route": {"lane": 1, "wrong_way": True}, **car},
                {"name": "west", "s0": 160.0, "route": {"lane": 0, "direction": -1}, **car},
            ],
        }
    )
    return run_scenario(scenario, "standard", seed=0)


def test_a_record_reads_back_equal(tmp_path, crash_summary):
    assert crash_summary.collisions
    config = RunConfig(noise=ObservationNoise(position=0.1))
    record = RunRecord("x__standard__s0", crash_summary, "x", "standard", config, None)
    path = write_record(tmp_path / "x", record)
    assert path == tmp_path / "x" / RECORD_FILE
    back = read_record(path)
    assert back.to_dict() == record.to_dict()
    assert back.config == config
    assert back.summary.collisions[0].measurement == crash_summary.collisions[0].measurement
    assert read_record(tmp_path / "x").run_id == "x__standard__s0"  # the folder works too


def test_non_finite_numbers_survive(tmp_path):
    summary = RunSummary("s", "p", 0, "timeout", "", min_distance=math.nan, min_ttc=math.inf)
    write_record(tmp_path, RunRecord("r", summary))
    data = json.loads((tmp_path / RECORD_FILE).read_text())
    assert data["min_ttc"] == "inf" and data["min_distance"] == "nan"
    back = read_record(tmp_path).summary
    assert back.min_ttc == math.inf and math.isnan(back.min_distance)


def test_bodies_carry_the_simulated_shapes_and_masses(tmp_path):
    scenario = dataclasses.replace(get_scenario("pedestrian_behind_parked"), duration=0.2)
    summary = run_scenario(scenario, "standard", seed=0)
    van = next(b for b in summary.bodies if b.name == "parked_van")
    assert (van.length, van.width) == (5.5, 2.1)
    assert van.mass == pytest.approx(-1333.5 + 526.9 * (5.5 * 2.1) ** 0.8)  # SPEC car-mass regression
    assert summary.bodies[0] == BodyRecord(
        0, "ego", scenario.ego.type, scenario.ego.length, scenario.ego.width, scenario.ego.mass
    )
    assert [b.id for b in summary.bodies] == list(range(len(scenario.road_users) + 1))
    # How each road user moved (a parked van, a walking pedestrian), read back from the record.
    behaviours = [u.behaviour.kind.value for u in scenario.road_users]
    assert [b.behaviour for b in summary.bodies] == [None, *behaviours]
    assert van.behaviour == "parked"
    write_record(tmp_path, RunRecord("r", summary))
    assert read_record(tmp_path).summary.bodies == summary.bodies


@pytest.mark.parametrize(
    ("content", "error", "match"),
    [
        ("[1, 2]", NotARunRecord, "not a run record"),
        ('{"format": "other"}', NotARunRecord, "not a run record"),
        ("{not json", ValueError, "not valid JSON"),
        ('{"scenario": "s", "planner": "p", "outcome": "goal"}', ValueError, "before run records carried"),
        ('{"format": "etp-run-record", "version": 99}', ValueError, "version 99 is not supported"),
        ('{"format": "etp-run-record", "version": 1, "run_id": "r"}', ValueError, "scenario"),
        (
            '{"format": "etp-run-record", "version": 1, "run_id": "r", "scenario": "s", "planner": "p",'
            ' "seed": 0, "outcome": "goal", "reason": "", "bodies": [{"id": 0}]}',
            ValueError,
            "bodies",
        ),
        (
            '{"format": "etp-run-record", "version": 1, "run_id": "r", "scenario": "s", "planner": "p",'
            ' "seed": 0, "outcome": "goal", "reason": "", "colour": 3}',
            ValueError,
            "unknown key 'colour'",
        ),
    ],
)
def test_what_is_not_a_readable_record_is_named(tmp_path, content, error, match):
    path = tmp_path / RECORD_FILE
    path.write_text(content)
    with pytest.raises(error, match=match) as info:
        read_record(path)
    assert str(path) in str(info.value)


def test_a_missing_record_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="cannot read run record"):
        read_record(tmp_path / "nothing")


def test_iter_records_skips_other_summaries(tmp_path):
    write_record(tmp_path / "a", RunRecord("a", RunSummary("s", "p", 0, "goal", "")))
    (tmp_path / "sweep").mkdir()
    (tmp_path / "sweep" / RECORD_FILE).write_text('{"overall": {}}')
    assert [r.run_id for _, r in iter_records(tmp_path)] == ["a"]
    assert RECORD_VERSION == 1


def test_run_ids_of_names_are_readable():
    assert run_id("oncoming_drift", "ethical", 0) == "oncoming_drift__ethical__s0"
    assert run_id("dense_urban-s3-17", "standard", 12) == "dense_urban-s3-17__standard__s12"
    assert run_dir("logs/demo", "a__b__s0").as_posix() == "logs/demo/a__b__s0"


def test_same_stem_in_two_folders_gives_two_run_folders(tmp_path, monkeypatch):
    for folder in ("dirA", "dirB"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "s.toml").write_text("")
    a = run_id(str(tmp_path / "dirA" / "s.toml"), "ethical", 0)
    b = run_id(str(tmp_path / "dirB" / "s.toml"), "ethical", 0)
    assert a != b and a.startswith("s-") and b.startswith("s-")
    monkeypatch.chdir(tmp_path)
    assert run_id("dirA/s.toml", "ethical", 0) == a  # the same file from another directory
    assert source_key("dirA/s.toml") != "dirA/s.toml"
    # A planner configuration file is keyed the same way (not its preset's name).
    assert run_id("oncoming_drift", "dirA/s.toml", 0).split("__")[1].startswith("s-")


@pytest.mark.parametrize("bad", ["a__b", "a b", "", "ä"])
def test_names_that_cannot_name_a_run(bad):
    with pytest.raises(ValueError, match="cannot name a run"):
        run_id(bad, "ethical", 0)
    with pytest.raises(ValueError, match="planner"):
        run_id("s", bad, 0)


def test_seed_must_be_an_integer():
    with pytest.raises(ValueError, match="seed"):
        run_id("s", "ethical", 1.5)


def test_a_configured_planner_never_shares_a_preset_folder():
    from ethical_planner.config import preset

    ethical = preset("ethical")
    assert run_id("s", "ethical", 0, ethical) == "s__ethical__s0"  # the preset itself
    cautious = ethical.with_overrides({"name": "ethical+c", "risk": {"max_acceptable_risk": 0.01}})
    bolder = ethical.with_overrides({"name": "ethical+c", "risk": {"max_acceptable_risk": 0.2}})
    a, b = run_id("s", "ethical+c", 0, cautious), run_id("s", "ethical+c", 0, bolder)
    assert a != b and a.startswith("s__ethical+c-") and b.startswith("s__ethical+c-")
    assert run_id("s", "ethical+c", 0, cautious) == a  # the same configuration resumes
    changed = ethical.with_overrides({"risk": {"max_acceptable_risk": 0.01}})  # still named "ethical"
    assert run_id("s", "ethical", 0, changed) != "s__ethical__s0"
