"""Run index, near-crash ranking, TTC, and the near-crash/replay commands."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math

import numpy as np
import pytest

from harm_calibration.cli.runs import register
from mujoco_world.loop.summary import RunSummary
from mujoco_world.physics.safety import time_to_collision
from mujoco_world.storage.run_folder import store_run
from mujoco_world.storage.run_index import (
    INDEX_FILE,
    IndexRow,
    NearCrashThresholds,
    append_row,
    near_crashes,
    read_index,
    severity,
)


def summary(min_distance=10.0, collisions=(), scenario="s", seed=0):
    return RunSummary(
        scenario=scenario,
        planner="ethical",
        seed=seed,
        outcome="timeout",
        reason="",
        duration=1.0,
        steps=1000,
        cycles=10,
        collisions=tuple(collisions),
        ego_collided=bool(collisions),
        max_risk={"ego": 0.01, "third_party": 0.02, "vulnerable": 0.0},
        top_risks={},
        harm={},
        min_distance=min_distance,
        min_distance_vulnerable=math.nan,
        tracking_rms=0.0,
        tracking_max=0.0,
        progress=0.0,
        levels={},
        timings={},
    )


def row(run_id, near, score, collisions=0, distance=5.0):
    return IndexRow(
        run_id=run_id,
        scenario="s",
        planner="ethical",
        seed=0,
        outcome="timeout",
        collisions=collisions,
        max_harm_measured=0.0,
        max_harm_predicted=0.0,
        min_distance=distance,
        min_ttc=math.inf,
        max_collision_probability=0.0,
        near_crash=near,
        severity=score,
    )


def test_index_survives_truncated_last_line(tmp_path):
    append_row(tmp_path, row("a", False, 0.0))
    append_row(tmp_path, row("b", True, 0.5))
    with (tmp_path / INDEX_FILE).open("ab") as handle:
        handle.write(row("c", True, 0.9).to_json().encode()[:40])  # writer killed mid-line
    assert [r.run_id for r in read_index(tmp_path)] == ["a", "b"]
    append_row(tmp_path, row("d", True, 0.7))  # the next writer starts a fresh line
    rows = read_index(tmp_path)
    assert [r.run_id for r in rows] == ["a", "b", "d"]
    assert rows[0].min_ttc == math.inf


def test_a_run_indexed_twice_is_listed_once_with_its_latest_row(tmp_path):
    # an interrupted attempt (failed), another run, then the rerun of the first
    append_row(tmp_path, dataclasses.replace(row("a", True, 0.9), outcome="failed"))
    append_row(tmp_path, row("b", False, 0.0))
    append_row(tmp_path, row("a", False, 0.1))
    rows = read_index(tmp_path)
    assert [(r.run_id, r.outcome) for r in rows] == [("a", "timeout"), ("b", "timeout")]
    assert near_crashes(rows) == []


def test_near_crash_ranking_worst_first():
    rows = [
        row("far", False, 0.0),
        row("close", True, 0.3, distance=0.3),
        row("crash", True, 1.2, collisions=1, distance=-0.1),
        row("closer", True, 0.8, distance=0.1),
    ]
    assert [r.run_id for r in near_crashes(rows)] == ["crash", "closer", "close"]
    assert [r.run_id for r in near_crashes(rows, top=1)] == ["crash"]


def test_severity_thresholds():
    th = NearCrashThresholds(min_distance=0.5, min_ttc=1.0, collision_probability=0.1)
    assert severity(0, 0.0, 5.0, math.inf, 0.0, th) == (False, 0.0)
    near, score = severity(0, 0.0, 0.25, math.inf, 0.0, th)
    assert near and score == pytest.approx(0.5)
    near, score = severity(0, 0.0, 5.0, 0.2, 0.0, th)
    assert near and score == pytest.approx(0.8)
    assert severity(0, 0.0, 5.0, math.inf, 0.1, th)[0]
    assert severity(1, 0.3, 5.0, math.inf, 0.0, th) == (True, pytest.approx(2.3))  # the ego's crash
    third = severity(0, 0.3, 5.0, math.inf, 0.0, th, third_party_collisions=2)
    assert third == (True, pytest.approx(1.3))  # others' collision: listed, after every crash
    assert severity(0, 0.0, math.nan, math.nan, math.nan, th) == (False, 0.0)


def test_a_close_pass_of_a_vulnerable_road_user_is_a_near_crash():
    th = NearCrashThresholds(vulnerable_clearance=1.0)
    # 0.06 m from a cyclist: 2 m from everything else would be no near crash
    near, score = severity(0, 0.0, 2.0, math.inf, 0.0, th, min_distance_vulnerable=0.06)
    assert near and score == pytest.approx(0.94)
    assert severity(0, 0.0, 2.0, math.inf, 0.0, th, min_distance_vulnerable=1.2) == (False, 0.0)


@pytest.mark.parametrize("name", ["min_distance", "min_ttc", "collision_probability", "vulnerable_clearance"])
def test_thresholds_reject_bad_values(name):
    with pytest.raises(ValueError, match=name):
        NearCrashThresholds(**{name: -1.0})


def test_ttc_head_on_and_parallel():
    ego = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 4.0, 2.0])
    others = np.array(
        [
            [30.0, 0.0, math.pi, -5.0, 0.0, 4.0, 2.0],  # head-on: gap 26 m at 15 m/s
            [0.0, 5.0, 0.0, 10.0, 0.0, 4.0, 2.0],  # parallel, same speed: never
            [1.0, 0.5, 0.3, 0.0, 0.0, 4.0, 2.0],  # overlapping now
        ]
    )
    ttc = time_to_collision(ego, others, horizon=10.0)
    assert ttc[0] == pytest.approx(26.0 / 15.0)
    assert ttc[1] == math.inf
    assert ttc[2] == 0.0


def test_store_run_keeps_only_near_crash_recordings(tmp_path):
    for name, dist, kept in (("calm", 10.0, False), ("close", 0.1, True)):
        rrd = tmp_path / name / "recording.rrd"
        rrd.parent.mkdir(parents=True)
        rrd.write_bytes(b"rrd")  # stands in for a recording
        record = store_run(
            summary(min_distance=dist, scenario=name), tmp_path, name, recording=rrd, keep="near-crash"
        )
        assert rrd.exists() is kept
        assert (record.recording is not None) is kept
    rows = read_index(tmp_path)
    assert [r.run_id for r in rows] == ["calm", "close"]
    assert rows[1].near_crash and not rows[0].near_crash
    assert rows[1].recording == str(tmp_path / "close" / "recording.rrd") and rows[0].recording is None


def test_store_run_rejects_bad_keep(tmp_path):
    with pytest.raises(ValueError, match="keep"):
        store_run(summary(), tmp_path, "x", keep="some")


def parser():
    p = argparse.ArgumentParser()
    register(p.add_subparsers(dest="command"))
    return p


def test_near_crash_command_json(tmp_path, capsys):
    store_run(summary(min_distance=0.2, scenario="a"), tmp_path, "a")
    store_run(summary(min_distance=5.0, scenario="b"), tmp_path, "b")
    args = parser().parse_args(["near-crash", str(tmp_path), "--json", "--top", "5"])
    assert args.handler(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert [r["run_id"] for r in out] == ["a"]


def test_replay_prints_command_without_display(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    rrd = tmp_path / "run" / "run1" / "recording.rrd"  # etp run: logs/run/<id>, index in logs/run
    rrd.parent.mkdir(parents=True)
    rrd.write_bytes(b"rrd")
    store_run(summary(), tmp_path / "run", "run1", recording=rrd)
    args = parser().parse_args(["replay", "run1", "--root", str(tmp_path)])
    assert args.handler(args) == 0
    assert capsys.readouterr().out.strip() == f"rerun {rrd.resolve()}"


def test_replay_unknown_run(tmp_path):
    append_row(tmp_path, row("a", False, 0.0))
    args = parser().parse_args(["replay", "nope", "--root", str(tmp_path)])
    with pytest.raises(ValueError, match="RUN_ID_OR_PATH"):
        args.handler(args)


def test_index_row_of_a_real_run_counts_third_party_collisions_apart(tmp_path):
    from mujoco_world.loop.runner import run_scenario
    from mujoco_world.scenario.spec import scenario_from_dict

    car = {"type": "car", "behaviour": {"kind": "scripted", "speed": 10.0}}
    scenario = scenario_from_dict(
        {
            "name": "others_collide",
            "road": {"length": 300.0},
            "ego": {"s0": 10.0, "speed": 10.0, "goal_s": 60.0},
            "duration": 6.0,
            "road_users": [
                {"name": "east", "s0": 100.0, "route": {"lane": 1, "wrong_way": True}, **car},
                {"name": "west", "s0": 160.0, "route": {"lane": 0, "direction": -1}, **car},
            ],
        }
    )
    record = store_run(run_scenario(scenario, "keep_lane"), tmp_path, "others")
    (r,) = read_index(tmp_path)
    assert record.summary.outcome == r.outcome == "goal"
    assert (r.collisions, r.ego_collisions, r.third_party_collisions) == (1, 0, 1)
    assert r.max_harm_ego_involved == 0.0 and r.max_harm_measured > 0
    assert r.near_crash and 1.0 < r.severity < 2.0
