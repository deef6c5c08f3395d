"""``etp avoidability`` and ``etp demo --avoidability``: the verdict lands in the record, index and table."""

import json

from harm_calibration.cli import main
from mujoco_world.storage.run_folder import run_id
from mujoco_world.storage.run_index import near_crashes, read_index
from mujoco_world.storage.run_record import read_record
from tests.harm_calibration.cli.conftest import write_scenario

#: The ego keeps its lane at 10 m/s into a car parked 50 m ahead (contact at ~4.5 s).
PARKED = """
name = "{name}"
duration = {duration}
[road]
length = 200.0
[ego]
s0 = 10.0
speed = 10.0
[[road_users]]
name = "parked"
type = "car"
s0 = 60.0
behaviour = {{ kind = "parked" }}
"""


def test_avoidability_stores_the_verdict_in_record_index_and_listing(tmp_path, capsys):
    scenario = write_scenario(tmp_path, PARKED, name="parked", duration=6.0)
    out = tmp_path / "runs"
    assert main(["run", scenario, "--planner", "keep_lane", "--out", str(out), "--no-record"]) == 0
    run = out / run_id(scenario, "keep_lane", 0)
    (row,) = read_index(out)
    assert row.ego_collisions == 1 and row.avoidable is None
    capsys.readouterr()
    assert main(["avoidability", str(run), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "AVOIDABLE" in text and "brake" in text
    verdict = read_record(run).avoidability
    assert verdict.avoidable and not verdict.best.ego_collided
    (row,) = read_index(out)  # the latest row of the run replaces the first
    assert row.avoidable is True
    assert near_crashes([row])[0].avoidable is True
    assert main(["near-crash", str(out)]) == 0
    assert " yes " in capsys.readouterr().out
    # an output root searches every ego collision below it; JSON on request
    assert main(["avoidability", str(out), "--json", "--workers", "1"]) == 0
    (entry,) = json.loads(capsys.readouterr().out)
    assert entry["avoidability"]["avoidable"] is True


def test_avoidability_bad_input_exits_2(tmp_path, capsys):
    assert main(["avoidability", str(tmp_path / "nothing")]) == 2
    assert "RUN_DIR" in capsys.readouterr().err
    assert main(["avoidability", str(tmp_path), "--lookback", "0"]) == 2
    assert "--lookback" in capsys.readouterr().err
