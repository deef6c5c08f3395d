import json

from harm_calibration.cli import main


def test_plan_prints_decision_records(capsys):
    assert main(["plan", "--cycles", "2"]) == 0
    out = capsys.readouterr().out
    assert out.count("[ethical] level") == 2 and "bicycle" in out


def test_plan_json(capsys):
    assert main(["plan", "--cycles", "1", "--planner", "selfish", "--json"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert records[0]["planner"] == "selfish"


def test_plan_unknown_preset_is_a_clear_error(capsys):
    assert main(["plan", "--planner", "greedy"]) == 2
    assert "allowed: ethical" in capsys.readouterr().err


def test_bench_small_grid_writes_json(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(["bench", "--grid", "225", "--repetitions", "1", "--no-peer", "--out", str(out)]) == 0
    rows = json.loads(out.read_text())
    assert [r["road_users"] for r in rows] == [0, 5, 20]
    assert all(r["n_trajectories"] == 225 and r["ours_median_ms"] > 0 for r in rows)
    assert "frenetix" in capsys.readouterr().out
