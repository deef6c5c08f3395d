"""Crash attribution on collisions the MuJoCo impact rig produced: who drove into whom."""

import dataclasses
import math

import pytest

from ethical_planner.road_users import KinematicState
from harm_calibration.study.analysis import analyse
from harm_calibration.study.attribution import approach_speed, attribute
from harm_calibration.study.runner import study_run
from mujoco_world.evaluation.compare import compare_impact
from mujoco_world.loop.summary import BodyRecord, RunSummary
from mujoco_world.physics.impact import measure_impact
from mujoco_world.physics.scene import STATIC
from mujoco_world.storage.run_record import RunRecord

CAR = (4.5, 1.8)


def _collision(ego: KinematicState, other: KinematicState):
    """A real two-body impact: the ego (entity 0, a car) and another car (entity 1)."""
    m = measure_impact("car", ego, "car", other, shape_a=CAR, shape_b=CAR)
    assert m is not None and m.a.entity == 0
    return compare_impact(m)


@pytest.fixture(scope="module")
def rear_end():
    # The ego drives at 2 m/s; a car 6 m behind it (1.5 m gap) at 10 m/s drives into its rear.
    return _collision(KinematicState(0.0, 0.0, 0.0, 2.0), KinematicState(-6.0, 0.0, 0.0, 10.0))


def test_a_follower_driving_into_the_ego_is_struck_from_behind(rear_end):
    m = rear_end.measurement
    assert m.a.reduced_area == "rear" and m.b.reduced_area == "front"
    # By hand: the contact lies on the x axis between the two; the ego moves away from it
    # at its 2 m/s, the follower towards it at its 10 m/s.
    assert approach_speed(m.a, m.contact_position) == pytest.approx(-2.0, abs=0.05)
    assert approach_speed(m.b, m.contact_position) == pytest.approx(10.0, abs=0.05)
    assert attribute(rear_end, {0: None, 1: "recorded"}) == "struck_from_behind_by_replay"
    assert attribute(rear_end, {0: None, 1: "idm"}) == "struck_from_behind"


def test_the_ego_driving_into_a_slower_car_or_a_kerb_is_its_own():
    # The ego at 10 m/s into a replayed car 6 m ahead at 3 m/s: the ego strikes, replay or not.
    ahead = _collision(KinematicState(0.0, 0.0, 0.0, 10.0), KinematicState(6.0, 0.0, 0.0, 3.0))
    assert ahead.measurement.a.reduced_area == "front"
    assert attribute(ahead, {1: "recorded"}) == "ego_strikes"
    kerb = dataclasses.replace(
        ahead.measurement.b, entity=STATIC, type="kerb", velocity=(0.0, 0.0), position=(0.0, 0.0)
    )
    into_kerb = dataclasses.replace(ahead, measurement=dataclasses.replace(ahead.measurement, b=kerb))
    assert attribute(into_kerb, {}) == "ego_into_static"


def test_a_replay_crossing_into_a_standing_ego_strikes_its_side():
    # The ego stands; a replayed car comes from its left (4 m off, heading -y) at 8 m/s.
    side = _collision(KinematicState(0.0, 0.0, 0.0, 0.0), KinematicState(0.0, 3.5, -math.pi / 2, 8.0))
    assert side.measurement.a.reduced_area == "driver_side"
    assert attribute(side, {1: "recorded"}) == "struck_by_replay"
    assert attribute(side, {1: "pedestrian"}) == "struck"


def test_a_collision_without_the_ego_is_refused(rear_end):
    swapped = dataclasses.replace(
        rear_end.measurement,
        a=dataclasses.replace(rear_end.measurement.a, entity=3),
    )
    with pytest.raises(ValueError, match="ego-involved"):
        attribute(dataclasses.replace(rear_end, measurement=swapped), {})


def _record(collisions, behaviour, source="ZAM_X-1_1.xml", outcome="crash", scenario="s"):
    bodies = (
        BodyRecord(0, "ego", "car", *CAR, 1500.0),
        BodyRecord(1, "car_7", "car", *CAR, 1500.0, behaviour=behaviour),
    )
    summary = RunSummary(
        scenario,
        "ethical",
        0,
        outcome,
        "",
        bodies=bodies,
        collisions=tuple(collisions),
        ego_collided=bool(collisions),
    )
    return RunRecord(f"{scenario}-0123456789__ethical__s0", summary, scenario_source=source)


def test_the_run_record_gives_the_crash_and_older_commonroad_records_count_as_replays(rear_end):
    ahead = _collision(KinematicState(0.0, 0.0, 0.0, 10.0), KinematicState(6.0, 0.0, 0.0, 3.0))
    later = dataclasses.replace(ahead, measurement=dataclasses.replace(ahead.measurement, time=9.0))
    # The first ego collision decides: rear-ended by the replay at t = 0, pushed into a car later.
    assert study_run(_record([later, rear_end], "recorded")).crash == "struck_from_behind_by_replay"
    assert study_run(_record([rear_end], "idm")).crash == "struck_from_behind"
    # Written before bodies carried their behaviour: every road user of a CommonRoad file
    # replays its recording; elsewhere nothing is assumed.
    assert study_run(_record([rear_end], None)).crash == "struck_from_behind_by_replay"
    assert study_run(_record([rear_end], None, source="cut_in")).crash == "struck_from_behind"
    assert study_run(_record([], "recorded", outcome="goal")).crash is None


def test_crash_counts_rates_and_harm_with_and_without_the_replays_rear_ends(rear_end):
    ahead = _collision(KinematicState(0.0, 0.0, 0.0, 10.0), KinematicState(6.0, 0.0, 0.0, 3.0))
    runs = [
        study_run(_record([rear_end], "recorded", scenario="a")),
        study_run(_record([ahead], "recorded", scenario="b")),
        study_run(_record([], "recorded", outcome="goal", scenario="c")),
    ]
    runs = [dataclasses.replace(r, distance=500.0) for r in runs]  # 1.5 km in all
    analysis = analyse(runs, ["ethical"], resamples=100)
    table = analysis.table["ethical"]
    assert table.ego_crashes == 2 and table.ego_crashes_excluding == 1
    assert table.crash_classes["struck_from_behind_by_replay"] == 1
    assert table.crash_classes["ego_strikes"] == 1
    assert table.crashes_per_1000km.value == pytest.approx(2 / 1.5 * 1000)
    assert table.crashes_per_1000km_excluding.value == pytest.approx(1 / 1.5 * 1000)
    # Harm: the excluded run's measured harm leaves the "excluding" sums, the other stays.
    harm_a = rear_end.a.harm_measured + rear_end.b.harm_measured
    harm_b = ahead.a.harm_measured + ahead.b.harm_measured
    assert harm_a > 0 and harm_b > 0
    ego, third = analysis.summaries[("ego", "ethical")], analysis.summaries[("third_party", "ethical")]
    assert ego.harm.value + third.harm.value == pytest.approx(harm_a + harm_b)
    assert ego.harm_excluding.value + third.harm_excluding.value == pytest.approx(harm_b)
    assert ego.harm_ego_collisions_excluding == pytest.approx(ahead.a.harm_measured)


def test_two_files_with_one_benchmark_id_stay_two_scenarios():
    # ZAM_Tutorial-1_1_T-1.xml and ZAM_Tutorial-1_2_T-1.xml both call their scenario
    # ZAM_Tutorial-1_1_T-1: the run id's scenario part (file name and hash) keeps them apart.
    summary = RunSummary("ZAM_Tutorial-1_1_T-1", "ethical", 0, "goal", "")
    runs = [
        study_run(RunRecord(f"ZAM_Tutorial-1_{k}_T-1-{k}a{k}b{k}c{k}d{k}e__ethical__s0", summary))
        for k in (1, 2)
    ]
    keys = ["ZAM_Tutorial-1_1_T-1-1a1b1c1d1e", "ZAM_Tutorial-1_2_T-1-2a2b2c2d2e"]
    assert [r.scenario for r in runs] == keys
    assert len(analyse(runs, ["ethical"], resamples=10).scenarios) == 2
