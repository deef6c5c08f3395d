"""Recordings read back with ``rerun.chunk.RrdReader``: content, not bytes."""

from __future__ import annotations

import dataclasses
from collections import defaultdict

import numpy as np
import pytest
from rerun.chunk import RrdReader

from ethical_planner.config import preset
from ethical_planner.sampling import CandidateKind
from ethical_planner.validity import LIMITS
from mujoco_world.loop.runner import ObserverGroup, RunObserver, run_scenario
from mujoco_world.loop.world import World
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.storage.recording import RecorderConfig, RerunRecorder, ellipse_strips

#: Rejected candidates per validity level: entity name -> level.
REJECTED = {
    "physically_invalid": 0,
    "collision": 1,
    "leaves_road": 2,
    "above_max_risk": 3,
    "breaks_traffic_rule": 4,
}


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
        ("ttc_horizon", {"ttc_horizon": 0.0}),
        ("ttc_horizon", {"ttc_horizon": float("inf")}),
        ("follow_height", {"follow_height": -5.0}),
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


# ---------------------------------------------------------------- recordings explain the decision


class Probe(RunObserver):
    """Keeps every decision and the ego's true position at the recorder's frames."""

    step_interval = 50  # 20 Hz at dt = 1 ms, the recorder's interval

    def __init__(self):
        self.decisions, self.cycle_times, self.frames = [], [], []

    def on_start(self, world, scenario, planner, seed):
        self.world = world
        self.frames.append((world.time, world.positions[0].copy(), world.yaws[0]))

    def on_step(self, world, time):
        self.frames.append((time, world.positions[0].copy(), world.yaws[0]))

    def on_cycle(self, plan, time):
        self.decisions.append(plan.decision)
        self.cycle_times.append(time)


def _recorded_ethical_run(tmp_path_factory, scenario_name, duration):
    """(summary, probe, chunks) of an ethical run of ``duration`` [s], recorded without candidates."""
    out = tmp_path_factory.mktemp("runs") / scenario_name
    scenario = dataclasses.replace(get_scenario(scenario_name), duration=duration)
    recorder = RerunRecorder(out, RecorderConfig(candidates=0))
    probe = Probe()
    summary = run_scenario(scenario, "ethical", 0, observer=ObserverGroup([recorder, probe]))
    return summary, probe, read_chunks(recorder.path)


@pytest.fixture(scope="module")
def hidden_pedestrian_run(tmp_path_factory):
    # The pedestrian stays hidden behind the parked van (occlusion on) until about 4.1 s.
    return _recorded_ethical_run(tmp_path_factory, "pedestrian_behind_parked", 5.0)


def per_cycle(chunks, path):
    """Values of a per-cycle series, one per planning cycle (the static style row has none)."""
    _, values = column(chunks[path], "Scalars:scalars")
    return np.array([v[0] for v in values if v])


def test_rejected_candidates_per_level_add_up_to_every_candidate(hidden_pedestrian_run):
    _, probe, chunks = hidden_pedestrian_run
    levels = {name: per_cycle(chunks, f"/series/rejected/{name}") for name in REJECTED}
    valid = per_cycle(chunks, "/series/candidates/valid")
    unassessed = per_cycle(chunks, "/series/candidates/unassessed")
    total = per_cycle(chunks, "/series/candidates/total")
    assert len(total) == len(probe.decisions) > 10
    assert np.array_equal(sum(levels.values()) + valid + unassessed, total)
    for c, decision in enumerate(probe.decisions):
        # Row v + 1 counts level v; row 0 the candidates the planner left unassessed.
        by_level = np.bincount(np.asarray(decision.candidate_levels) + 1, minlength=12)[1:]
        assert unassessed[c] == np.sum(np.asarray(decision.candidate_levels) == -1)
        assert total[c] == len(decision.candidate_levels)
        assert valid[c] == by_level[10]
        for name, level in REJECTED.items():
            assert levels[name][c] == by_level[level], (name, c)
    limits = {name: per_cycle(chunks, f"/series/rejected/limit/{name}") for name in LIMITS}
    # A candidate may break several limits: each limit's count is at most the level-0 count,
    # and together they cover it.
    assert all(np.all(v <= levels["physically_invalid"]) for v in limits.values())
    assert np.all(sum(limits.values()) >= levels["physically_invalid"])
    assert levels["physically_invalid"].max() > 0
    refused = per_cycle(chunks, "/series/rejected/max_risk_refused")
    assert np.array_equal(refused, [d.max_risk_refused for d in probe.decisions])


def test_best_cost_of_each_level_is_logged_and_bounds_the_chosen_plan(hidden_pedestrian_run):
    _, probe, chunks = hidden_pedestrian_run
    for name, level in {**REJECTED, "valid": 10}.items():
        best = per_cycle(chunks, f"/series/best_cost/{name}")
        assert len(best) == len(probe.decisions)
        for c, decision in enumerate(probe.decisions):
            levels = np.asarray(decision.candidate_levels)
            # Costed (risk assessed): the levels of the best level possible without
            # integrals, always including the highest level present.
            costed = level in decision.best_by_level
            assert np.isfinite(best[c]) == costed, (name, c)
            assert not costed or np.any(levels == level), (name, c)
            assert int(levels.max()) in decision.best_by_level
            if decision.level == level and decision.chosen_index >= 0:
                # The chosen plan is a candidate of its level: the best of the level is no dearer.
                assert best[c] <= decision.costs["total"] + 1e-9
                if not decision.continued:
                    assert best[c] == pytest.approx(decision.costs["total"])
    # The paths: one strip per level present, labelled with the level.
    _, strips = column(chunks["/world/plan/best"], "LineStrips3D:strips")
    _, labels = column(chunks["/world/plan/best"], "LineStrips3D:labels")
    assert len(strips) == len(probe.decisions)
    for decision, cycle_strips, cycle_labels in zip(probe.decisions, strips, labels, strict=True):
        assert len(cycle_strips) == len(decision.best_by_level)
        for strip, label in zip(cycle_strips, cycle_labels, strict=True):
            level = {**REJECTED, "valid": 10}[label.split(":")[0]]
            index = decision.best_by_level[level].index
            assert np.asarray(strip)[:, 0] == pytest.approx(decision.candidate_x[index])
            assert np.asarray(strip)[:, 1] == pytest.approx(decision.candidate_y[index])


@pytest.fixture(scope="module")
def braking_run(tmp_path_factory):
    # The car ahead brakes hard; the ethical planner chooses a braking candidate at 2.1 s
    # (measured on main 0cad004; the hidden-pedestrian run chooses none since the
    # commitment's persistence rule).
    return _recorded_ethical_run(tmp_path_factory, "follower_brakes_weakly", 2.5)


def _check_chosen_candidate_parameters(probe, chunks):
    """The recorded chosen-candidate series against each cycle's decision and executed plan."""
    end_speed = per_cycle(chunks, "/series/chosen/end_speed")
    end_offset = per_cycle(chunks, "/series/chosen/end_offset")
    horizon = per_cycle(chunks, "/series/chosen/horizon")
    family = per_cycle(chunks, "/series/chosen/family")
    path = probe.world.ego_path
    for c, decision in enumerate(probe.decisions):
        plan = decision.trajectory
        # The chosen candidate's parameters; for a grid candidate they are also the plan's
        # last speed and where it ends across the ego's route (a braking candidate's, or the
        # continuation of one, are its targets at its stop, which may lie past the horizon).
        _, d_end = path.to_frenet(plan.x[-1], plan.y[-1])
        chosen = decision.candidate
        assert (end_speed[c], end_offset[c], horizon[c]) == (
            chosen.end_speed,
            chosen.end_offset,
            chosen.horizon,
        )
        if chosen.kind == CandidateKind.GRID:
            assert end_speed[c] == pytest.approx(plan.v[-1], abs=1e-6)
            assert end_offset[c] == pytest.approx(d_end, abs=0.02)
            assert 0.0 < horizon[c] <= plan.t[-1] + 1e-9
        if chosen.kind == CandidateKind.BRAKE:
            # A braking candidate targets a stop and never ends faster than it starts
            # (continuations and grid candidates may speed up).
            assert end_speed[c] == 0.0 and plan.v[-1] <= plan.v[0] + 1e-6
        assert family[c] == int(decision.candidate.kind)


def test_chosen_candidate_parameters_match_the_executed_plan(hidden_pedestrian_run):
    _, probe, chunks = hidden_pedestrian_run
    _check_chosen_candidate_parameters(probe, chunks)
    kinds = {d.candidate.kind for d in probe.decisions}
    assert {CandidateKind.GRID, CandidateKind.CONTINUATION} <= kinds


def test_chosen_braking_candidate_parameters_match_the_executed_plan(braking_run):
    _, probe, chunks = braking_run
    # The run chooses a braking candidate, so the braking branch of the check is exercised.
    assert any(d.candidate.kind == CandidateKind.BRAKE for d in probe.decisions)
    _check_chosen_candidate_parameters(probe, chunks)


def test_plan_switch_flags_a_plan_that_does_not_continue_the_previous_one(hidden_pedestrian_run):
    _, probe, chunks = hidden_pedestrian_run
    switch = per_cycle(chunks, "/series/plan_switch")
    assert switch[0] == 0.0  # nothing to switch from
    assert 0 < switch.sum() < len(switch)
    for c in range(1, len(switch)):
        before, now = probe.decisions[c - 1].candidate, probe.decisions[c].candidate
        if switch[c] == 0.0:  # kept: the same end state, continued
            assert now.kind == CandidateKind.CONTINUATION
            assert (now.end_speed, now.end_offset) == pytest.approx((before.end_speed, before.end_offset))
        else:
            assert now.kind != CandidateKind.CONTINUATION


def test_ego_speed_equals_the_speed_of_the_stored_path(hidden_pedestrian_run):
    _, probe, chunks = hidden_pedestrian_run
    times, speed = column(chunks["/series/motion/speed"], "Scalars:scalars")
    speed = np.array([v[0] for v in speed])
    t = np.array([f[0] for f in probe.frames])
    xy = np.array([f[1] for f in probe.frames])
    assert times == pytest.approx(t, abs=1e-6)
    # Central differences of the true positions, projected on the heading.
    velocity = (xy[2:] - xy[:-2]) / (t[2:] - t[:-2])[:, None]
    yaw = np.array([f[2] for f in probe.frames])[1:-1]
    along = velocity[:, 0] * np.cos(yaw) + velocity[:, 1] * np.sin(yaw)
    assert speed[1:-1] == pytest.approx(along, abs=0.05)


def test_ego_acceleration_follows_a_scripted_brake(tmp_path):
    from mujoco_world.agents import ScriptedPlanner, brake
    from mujoco_world.agents.ego_planner import EGO_PLANNERS

    EGO_PLANNERS.register("test_brake_4", lambda setup: ScriptedPlanner(brake(4.0, start=0.5), setup))
    scenario = dataclasses.replace(get_scenario("overtake_cyclist"), duration=2.0)
    recorder = RerunRecorder(tmp_path / "brake", RecorderConfig(candidates=0))
    run_scenario(scenario, "test_brake_4", 0, observer=recorder)
    times, accel = column(read_chunks(recorder.path)["/series/motion/acceleration"], "Scalars:scalars")
    accel = np.array([v[0] for v in accel])
    assert accel[times < 0.4] == pytest.approx(0.0, abs=0.3)  # cruising
    assert np.median(accel[times > 1.0]) == pytest.approx(-4.0, abs=0.3)  # braking at 4 m/s^2


def test_ttc_and_distance_per_road_user_equal_a_hand_computed_case(tmp_path):
    """Ego at 10 m/s on y = 0; a car stopped 30 m ahead; a car coming the other way 3.5 m to the left."""
    import mujoco

    scenario = get_scenario("tailgater_sudden_stop")
    world = World(scenario)
    assert world.n >= 3 and not any(b.is_round for b in world.scene.bodies[:3])
    qpos, qvel = world.scene.qpos, world.scene.qvel
    qvel[:] = 0.0
    qpos[:, 0] = 2000.0 + 30.0 * np.arange(world.n)  # everyone else far away
    qpos[:, 1] = 500.0
    qpos[:, 2] = 0.0
    qpos[0] = (0.0, 0.0, 0.0)
    qvel[0, 0] = 10.0
    qpos[1] = (30.0, 0.0, 0.0)
    qpos[2] = (40.0, 3.5, np.pi)
    qvel[2, 0] = -5.0
    mujoco.mj_forward(world.scene.model, world.scene.data)
    length, width = world.lengths, world.widths
    recorder = RerunRecorder(tmp_path / "ttc", RecorderConfig(candidates=0))
    recorder.on_start(world, scenario, "test", 0)
    recorder.close()
    chunks = read_chunks(recorder.path)

    def first(path):
        """The value at t = 0; nan if none was logged (a road user without a value is left out)."""
        values = [v[0] for v in column(chunks.get(path, []), "Scalars:scalars")[1] if v]
        return values[0] if values else np.nan

    gap_ahead = 30.0 - 0.5 * (length[0] + length[1])
    assert first("/series/ttc/user_1") == pytest.approx(gap_ahead / 10.0, rel=1e-9)
    assert first("/series/distance/user_1") == pytest.approx(gap_ahead, abs=1e-3)
    # The oncoming car passes beside the ego: no collision, so no time to collision.
    assert np.isnan(first("/series/ttc/user_2"))
    dx = 40.0 - 0.5 * (length[0] + length[2])
    dy = 3.5 - 0.5 * (width[0] + width[2])
    assert first("/series/distance/user_2") == pytest.approx(np.hypot(dx, dy), abs=1e-3)
    # Far away (beyond the 50 m the distance resolves, no approach): not logged at all.
    assert np.isnan(first("/series/distance/user_3")) and np.isnan(first("/series/ttc/user_3"))


def test_visibility_per_road_user_matches_what_the_planner_saw(hidden_pedestrian_run):
    _, probe, chunks = hidden_pedestrian_run
    names = probe.world.scene.names
    pedestrian = names.index("pedestrian")
    times, visible = column(chunks[f"/series/visible/user_{pedestrian}"], "Scalars:scalars")
    visible = np.array([v[0] if v else np.nan for v in visible])
    assert visible[times < 3.0].max() == 0.0 and visible[times > 4.5].min() == 1.0
    # In the scene, a ring surrounds the pedestrian while it is hidden, and nobody after.
    ring_times, rings = column(chunks["/world/hidden"], "LineStrips3D:strips")
    hidden_then = [r for t, r in zip(ring_times, rings, strict=True) if 1.0 < t < 3.0]
    assert hidden_then and all(len(r) == 1 for r in hidden_then)
    assert rings[-1] == [] and ring_times[-1] < 4.5
    round_times, round_centers = column(chunks["/world/road_users/round"], "Cylinders3D:centers")
    pedestrian_at = {
        round(float(t), 6): c[0][:2] for t, c in zip(round_times, round_centers, strict=True) if c
    }
    for t, r in zip(ring_times, rings, strict=True):
        if r:
            centre = np.asarray(r[0])[:-1, :2].mean(axis=0)  # the closing point repeats the first
            assert centre == pytest.approx(pedestrian_at[round(float(t), 6)], abs=1e-5)
    # At every planning cycle, a road user is logged visible iff the planner was given it.
    logged = {}
    for i in range(1, probe.world.n):
        t, v = column(chunks[f"/series/visible/user_{i}"], "Scalars:scalars")
        logged[i] = {round(float(a), 6): b[0] for a, b in zip(t, v, strict=True) if b}
    for time, decision in zip(probe.cycle_times, probe.decisions, strict=True):
        seen = {u.id for u in decision.road_users}
        for i in range(1, probe.world.n):
            value = logged[i].get(round(time, 6))
            if value is not None:
                assert (value == 1.0) == (i in seen), (time, i)


def test_recording_shows_when_r_max_decides(tmp_path):
    """With a tight R_max, cheaper candidates above it are refused: the count is recorded per cycle."""
    config = preset("ethical").with_overrides({"risk": {"max_acceptable_risk": 1e-5}})
    scenario = dataclasses.replace(get_scenario("overtake_cyclist"), duration=1.0)
    recorder = RerunRecorder(tmp_path / "r-max", RecorderConfig(candidates=0))
    probe = Probe()
    run_scenario(scenario, config, 0, observer=ObserverGroup([recorder, probe]))
    chunks = read_chunks(recorder.path)
    refused = per_cycle(chunks, "/series/rejected/max_risk_refused")
    above = per_cycle(chunks, "/series/rejected/above_max_risk")
    assert np.array_equal(refused, [d.max_risk_refused for d in probe.decisions])
    assert refused.max() > 0 and np.all(refused <= above)


def test_ttc_is_a_time_within_the_horizon_or_nan(hidden_pedestrian_run):
    _, probe, chunks = hidden_pedestrian_run
    values = []
    for i in range(1, probe.world.n):
        path = f"/series/ttc/user_{i}"
        values += [v[0] for v in column(chunks.get(path, []), "Scalars:scalars")[1] if v]
    values = np.array(values)
    finite = np.isfinite(values)
    assert finite.any() and (~finite).any()  # approaching and not, in this run
    assert np.all(np.isnan(values[~finite]))  # "none within the horizon" is nan, never inf
    assert np.all((values[finite] >= 0.0) & (values[finite] <= RecorderConfig().ttc_horizon))


def test_a_stop_line_is_drawn_across_the_road_red_while_its_light_is_red(tmp_path):
    scenario = dataclasses.replace(get_scenario("red_light_for_ego"), duration=1.0)
    (line,) = scenario.stop_lines
    assert line.red == ((0.0, 9.0),)
    recorder = RerunRecorder(tmp_path / "light", RecorderConfig(candidates=0))
    run_scenario(scenario, "keep_lane", 0, observer=recorder)
    batches = read_chunks(recorder.path)["/world/stop_lines/light"]
    times, colors = column(batches, "LineStrips3D:colors")
    assert list(times) == [0.0, 9.0]  # red from the start, green at 9 s
    red, green = 0xE62828FF, 0x3CC85AFF  # RGBA of (230, 40, 40) and (60, 200, 90)
    assert [c[0] for c in colors] == [red, green]
    _, strips = column(batches, "LineStrips3D:strips")
    ends = np.array(strips[0][0])
    # Across the straight road along +x, line.s - ego.s0 ahead of the ego's start (its
    # logged centre), over both lanes (3.5 m each, the ego in the right one).
    _, centers = column(read_chunks(recorder.path)["/world/ego"], "Boxes3D:centers")
    start_x, start_y = centers[0][0][:2]
    assert ends[:, 0] == pytest.approx(np.full(2, start_x + line.s - scenario.ego.s0), abs=0.05)
    assert sorted(ends[:, 1] - start_y) == pytest.approx([-1.75, 5.25], abs=0.05)
