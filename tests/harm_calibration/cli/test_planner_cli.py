import json

import pytest

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
    text = capsys.readouterr().out
    assert "frenetix" in text
    # The per-stage CPU breakdown is printed for every row and adds up to at most its total.
    for r in rows:
        stages = {k: v for k, v in r["stages_ms"].items() if k not in ("total", "wall")}
        assert {"sampling", "prediction", "risk", "record"} <= set(stages)
        assert sum(stages.values()) <= r["stages_ms"]["total"] + 1e-3 * len(stages)
        assert f"225 candidates, {r['road_users']} road users: sampling" in text


def test_bench_lists_the_benchmarks_candidate_sets():
    from benchmarks import planning_cycle
    from harm_calibration.cli import bench

    assert bench.GRID_NAMES == planning_cycle.GRID_NAMES


def test_bench_default_set_is_the_presets_candidates_without_continuation():
    from benchmarks.planning_cycle import grid_config
    from ethical_planner.config import preset

    config = grid_config("default")
    assert config.sampling == preset("ethical").sampling and not config.commitment.enabled
    assert grid_config("225").sampling.horizons == (2.0,) and not grid_config("225").sampling.brake_candidates


def test_bench_peer_plans_every_horizon_of_the_default_set():
    pytest.importorskip("frenetix")
    from benchmarks.planning_cycle import grid_config, time_peer

    sampling = grid_config("default").sampling
    timing = time_peer("default", 0, repetitions=1)
    assert timing["n_trajectories"] == len(sampling.horizons) * sampling.n_speeds * sampling.n_offsets


@pytest.mark.slow
def test_first_call_compiles_then_loads_every_kernel_from_the_disk_cache():
    from benchmarks.planning_cycle import first_call_times

    empty, warm = first_call_times("225", 5)
    assert empty["compiled"] > 0 and empty["loaded"] == 0
    # The warm process loads the kernels the cycle calls from Python; the kernels they call
    # are inside that machine code (compiled, in the first process, as part of their callers).
    assert warm["compiled"] == 0 and 0 < warm["loaded"] <= empty["compiled"]
