"""Recordings read back with ``rerun.chunk.RrdReader``: content, not bytes."""

from __future__ import annotations

import dataclasses
from collections import defaultdict

import numpy as np
import pytest
from rerun.chunk import RrdReader

from mujoco_world.loop.runner import ObserverGroup, RunObserver, run_scenario
from mujoco_world.loop.world import World
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.storage.recording import RecorderConfig, RerunRecorder, ellipse_strips


def read_chunks(path):
    """entity path -> list of record batches."""
    out = defaultdict(list)
    for chunk in RrdReader(str(path)).stream().to_chunks():
        out[str(chunk.entity_path)].append(chunk.to_record_batch())
    return out


def column(batches, name):
    """(sim_time [s], values) of one component over all batches, in time order (static: -inf)."""
    times, values = [], []
    for rb in batches:
        if name not in rb.schema.names:
            continue
        if "sim_time" in rb.schema.names:
            t = rb.column("sim_time").cast("int64").to_numpy() * 1e-9
        else:  # static data
            t = np.full(rb.num_rows, -np.inf)
        times.extend(t)
        values.extend(rb.column(name).to_pylist())
    order = np.argsort(times, kind="stable")
    return np.asarray(times)[order], [values[i] for i in order]


class StateCopy(RunObserver):
    """Keeps the simulated ego position at the recorder's steps."""

    def __init__(self, interval):
        self.step_interval = interval
        self.states = []

    def on_start(self, world, scenario, planner, seed):
        self.states.append((world.time, world.positions[0].copy()))

    def on_step(self, world, time):
        self.states.append((time, world.positions[0].copy()))


@pytest.fixture(scope="module")
def crash_run(tmp_path_factory):
    # The truck hits the cyclist at 4.9 s whatever the ego does: an impact that does not
    # depend on the planner's competence.
    out = tmp_path_factory.mktemp("runs") / "turning-truck-run"
    scenario = dataclasses.replace(get_scenario("turning_truck_cyclist"), duration=6.0)
    recorder = RerunRecorder(out, RecorderConfig(frame_rate=20.0, candidates=50))
    copy = StateCopy(50)  # 20 Hz at dt = 1 ms, the recorder's interval
    summary = run_scenario(scenario, "ethical", 0, observer=ObserverGroup([recorder, copy]))
    return summary, recorder.path, copy.states, read_chunks(recorder.path)


def test_logged_ego_positions_equal_simulated(crash_run):
    _, _, states, chunks = crash_run
    times, centers = column(chunks["/world/ego"], "Boxes3D:centers")
    logged = {round(t, 6): c[0][:2] for t, c in zip(times, centers, strict=True)}
    assert len(logged) >= 0.9 * len(states)
    for t, xy in states:
        assert logged[round(t, 6)] == pytest.approx(xy, abs=1e-5)


def test_logged_impact_delta_v_equals_summary(crash_run):
    summary, _, _, chunks = crash_run
    assert summary.collisions, "the scenario must crash within its time limit"
    for k, rec in enumerate(summary.collisions):
        m = rec.measurement
        t, dv = column(chunks[f"/impacts/{k}/{m.a.name}/dv_measured"], "Scalars:scalars")
        assert t[0] == pytest.approx(m.time, abs=1e-6)
        assert dv[0][0] == pytest.approx(rec.a.dv_measured, rel=1e-6)
        _, dv_pred = column(chunks[f"/impacts/{k}/{m.a.name}/dv_predicted"], "Scalars:scalars")
        assert dv_pred[0][0] == pytest.approx(rec.a.dv_predicted, rel=1e-6)
        assert f"/world/impacts/{k}/force" in chunks


def test_recording_has_expected_entities(crash_run):
    summary, _, _, chunks = crash_run
    expected = {
        "/world/road/surface",
        "/world/road/boundary",
        "/world/road/lanes",
        "/world/ego",
        "/world/road_users/boxes",
        "/world/ego_path",
        "/world/plan/chosen",
        "/world/plan/candidates",
        "/world/prediction/means",
        "/world/prediction/sigma1",
        "/world/prediction/sigma2",
        "/decision",
        "/impacts",
        "/series/ego/risk",
        "/series/ego/max_acceptable_risk",
        "/series/planning_ms",
        "/series/cost/total",
        "/series/risk/user_1",
        "/series/collision_probability/user_1",
        "/series/harm/user_1",
    }
    assert expected <= set(chunks)
    # One planning cycle per cycle-timeline entry, candidates capped by the config.
    _, risk = column(chunks["/series/ego/risk"], "Scalars:scalars")
    assert len(risk) == summary.cycles
    _, strips = column(chunks["/world/plan/candidates"], "LineStrips3D:strips")
    assert all(len(s) <= 50 for s in strips)
    _, texts = column(chunks["/decision"], "TextLog:text")
    assert any("level" in text[0] and "costs:" in text[0] for text in texts)


def test_pedestrians_are_round_bodies(tmp_path):
    scenario = dataclasses.replace(get_scenario("pedestrian_behind_parked"), duration=0.5)
    recorder = RerunRecorder(tmp_path / "ped", RecorderConfig(candidates=0))
    run_scenario(scenario, "ethical", 0, observer=recorder)
    chunks = read_chunks(recorder.path)
    _, labels = column(chunks["/world/road_users/round"], "Cylinders3D:labels")
    assert all("pedestrian" in label for label in labels[0])


@pytest.mark.filterwarnings("ignore:RRD file has no footer")
def test_interrupted_recording_is_readable(tmp_path):
    scenario = dataclasses.replace(get_scenario("tailgater_sudden_stop"), duration=1.0)
    world = World(scenario)
    recorder = RerunRecorder(tmp_path / "cut", RecorderConfig(flush_interval=0.1))
    recorder.on_start(world, scenario, "ethical", 0)
    for _ in range(200):
        world.step()
        if world.scene.data.time * 1000 % recorder.step_interval < 0.5:
            recorder.on_step(world, world.time)
    # No on_end, no close: the process could die here. Only the partial file exists.
    assert not recorder.path.exists()
    chunks = read_chunks(recorder.partial_path)
    times, _ = column(chunks["/world/ego"], "Boxes3D:centers")
    assert times.max() >= 0.1
    recorder.close()  # the complete file takes the final name
    assert recorder.path.is_file() and not recorder.partial_path.exists()
    times, _ = column(read_chunks(recorder.path)["/world/ego"], "Boxes3D:centers")
    assert times.max() >= 0.1


def test_ellipse_strips_axes():
    cov = np.array([[[4.0, 0.0], [0.0, 1.0]]])
    pts = ellipse_strips(np.zeros((1, 2)), cov, 2.0, n=9)
    assert np.abs(pts[0, :, 0]).max() == pytest.approx(4.0)
    assert np.abs(pts[0, :, 1]).max() == pytest.approx(2.0)


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("frame_rate", {"frame_rate": 0}),
        ("candidates", {"candidates": -1}),
        ("prediction_stride", {"prediction_stride": 0}),
        ("flush_interval", {"flush_interval": 0}),
    ],
)
def test_config_rejects_bad_values(field, kwargs):
    with pytest.raises(ValueError, match=field):
        RecorderConfig(**kwargs)


class Interrupt(RunObserver):
    """Presses Ctrl-C at the given planning cycle."""

    def __init__(self, at_cycle):
        self.at_cycle = at_cycle
        self.cycles = 0

    def on_cycle(self, plan, time):
        self.cycles += 1
        if self.cycles == self.at_cycle:
            raise KeyboardInterrupt


def test_interrupted_run_leaves_a_recording_and_a_failed_index_row(tmp_path, monkeypatch):
    from mujoco_world.experiments import batch
    from mujoco_world.experiments.batch import RunTask, TaskInterrupted, run_task
    from mujoco_world.storage.run_index import read_index

    scenario = dataclasses.replace(get_scenario("tailgater_sudden_stop"), duration=4.0)
    monkeypatch.setattr(batch, "resolve_scenario", lambda name: scenario)
    task = RunTask("tailgater_sudden_stop", "ethical", 0, str(tmp_path))
    with pytest.raises(TaskInterrupted) as stop:
        run_task(task, observers=[Interrupt(5)])
    summary = stop.value.result.record.summary
    assert isinstance(stop.value, KeyboardInterrupt) and summary.outcome == "failed"
    assert summary.reason.startswith("interrupted at t = ")
    (row,) = read_index(tmp_path)
    assert row.outcome == "failed" and row.run_id == "tailgater_sudden_stop__ethical__s0"
    assert not task.record_path.exists()  # no record: rerunning the batch runs it again
    assert row.recording == str(task.run_dir / "recording.rrd")  # closed: the final name
    times, _ = column(read_chunks(row.recording)["/world/ego"], "Boxes3D:centers")
    assert 0.3 <= times.max() < 1.0  # what happened up to the interrupt, no more


def test_a_planner_without_decisions_is_recorded_with_its_plans(tmp_path):
    scenario = dataclasses.replace(get_scenario("tailgater_sudden_stop"), duration=1.0)
    recorder = RerunRecorder(tmp_path / "keep-lane")
    summary = run_scenario(scenario, "keep_lane", 0, observer=recorder)
    chunks = read_chunks(recorder.path)
    times, _ = column(chunks["/world/plan/chosen"], "LineStrips3D:strips")
    assert len(times) == summary.cycles == 10
    assert "/world/plan/candidates" not in chunks and "/world/prediction/means" not in chunks
