import dataclasses
import json
import math
import time

import numpy as np
import pytest

from ethical_planner.collision_probability import collision_probability
from ethical_planner.config import preset
from ethical_planner.environment import RoadEnvironment
from ethical_planner.harm import collision_harm
from ethical_planner.planner import Planner
from ethical_planner.prediction import make_predictor
from ethical_planner.road_users import DEFAULT_SHAPES, EGO_SHAPE, KinematicState, RoadUser, RoadUserType
from ethical_planner.situations import oncoming_in_ego_lane_with_pedestrian, overtaking_cyclist
from ethical_planner.validity import UNASSESSED, Validity


def test_maximum_acceptable_risk_forbids_the_risky_overtake():
    """Paper Fig. 3: without R_max the risk-blind planner passes the cyclist; with R_max it stays behind."""
    situation = overtaking_cyclist()
    r_max = 0.01
    base = preset("standard").with_overrides({"sampling": {"horizons": [3.0]}})
    cyclist_end_x = situation.road_users[0].state.x + 4.0 * 3.0

    free = Planner(base.with_overrides({"risk": {"max_acceptable_risk": 1.0}}), situation.environment)
    risky = free.plan(situation.ego, situation.road_users)
    assert risky.trajectory.x[-1] > cyclist_end_x  # it passes the cyclist
    assert risky.road_users[0].risk > r_max

    bounded = Planner(base.with_overrides({"risk": {"max_acceptable_risk": r_max}}), situation.environment)
    safe = bounded.plan(situation.ego, situation.road_users)
    assert safe.level == Validity.VALID
    assert safe.level_counts[int(Validity.ABOVE_MAX_RISK)] > 0  # overtakes were there, and refused
    assert safe.trajectory.x[-1] < cyclist_end_x - 2.0  # stays behind
    assert max(u.risk for u in safe.road_users) <= r_max and safe.ego_combined_risk <= r_max


def test_selfish_shifts_risk_to_the_pedestrian_where_ethical_does_not():
    situation = oncoming_in_ego_lane_with_pedestrian()
    decisions = {
        name: Planner(preset(name), situation.environment).plan(situation.ego, situation.road_users)
        for name in ("ethical", "selfish")
    }
    pedestrian = {name: d.road_users[0] for name, d in decisions.items()}
    assert pedestrian["selfish"].risk > 10 * pedestrian["ethical"].risk
    assert decisions["selfish"].ego_combined_risk < decisions["ethical"].ego_combined_risk
    assert decisions["selfish"].trajectory.y.min() < -2.0  # swerves onto the shoulder


def test_best_candidate_of_each_level_is_the_cheapest_of_that_level():
    """Decision.best_by_level against a plain loop over the candidates the planner evaluated."""
    situation = overtaking_cyclist()
    config = preset("standard").with_overrides(
        {"sampling": {"horizons": [3.0]}, "risk": {"max_acceptable_risk": 0.01}}
    )
    planner = Planner(config, situation.environment)
    grids = []
    evaluate = planner._evaluate

    def keep(*args, **kwargs):
        grids.append(evaluate(*args, **kwargs))
        return grids[-1]

    planner._evaluate = keep
    decision = planner.plan(situation.ego, situation.road_users)
    grid = grids[0]
    # Costed: the candidates of the best level possible without integrals (risk.rows)
    # that the branch and bound evaluated; those it left out may be above R_max, so
    # that level has no entry (its cheapest candidate is unknown).
    left_out = grid.levels == UNASSESSED
    assert left_out.any()
    costed = {int(v) for v in grid.levels[grid.risk.rows]} - {int(Validity.ABOVE_MAX_RISK)}
    assert np.isnan(np.delete(grid.costs.total, grid.risk.rows)).all()
    assert set(decision.best_by_level) == costed
    assert int(Validity.VALID) in decision.best_by_level
    for level, best in decision.best_by_level.items():
        cheapest, key = None, None
        for i in grid.risk.rows:
            if grid.levels[i] != level:
                continue
            k = (grid.costs.total[i], grid.costs.comfort[i] + grid.costs.mobility[i])
            if key is None or k < key:
                cheapest, key = i, k
        assert best.index == cheapest
        assert best.cost == pytest.approx(grid.costs.total[cheapest])
        assert best.candidate.end_offset == pytest.approx(grid.candidates.end_offset[cheapest])
    # The first cycle has no plan to keep: the chosen plan is the best valid one.
    assert decision.best_by_level[int(Validity.VALID)].index == decision.chosen_index
    assert decision.best_by_level[int(Validity.VALID)].cost == pytest.approx(decision.costs["total"])
    # Fig. 3: candidates R_max refused that Eq. 5 preferred pass the cyclist; the chosen
    # one stays behind. All of them were evaluated (their cost is below the chosen's).
    cyclist_end_x = situation.road_users[0].state.x + 4.0 * 3.0
    costs = grid.costs
    eq5 = config.weights.risk * costs.risk + costs.comfort + costs.mobility
    refused = np.flatnonzero((grid.levels == Validity.ABOVE_MAX_RISK) & (eq5 < decision.costs["total"]))
    assert refused.size == decision.max_risk_refused > 0
    assert (decision.candidate_x[refused, -1] > cyclist_end_x).any()
    assert decision.trajectory.x[-1] < cyclist_end_x
    record = json.loads(json.dumps(decision.to_dict()))
    assert set(record["best_by_level"]) == {str(k) for k in costed}


def test_empty_road_has_zero_risk_and_a_valid_plan():
    env = RoadEnvironment.along_path([[-20, 0], [300, 0]], lanes_left=1)
    decision = Planner(preset("ethical"), env).plan(KinematicState(0, 0, 0, 10), [])
    assert decision.level == Validity.VALID
    assert decision.ego_combined_risk == 0.0 and decision.road_users == ()
    assert all(math.isfinite(v) for v in decision.costs.values())
    assert decision.costs["bayes"] == 0.0 and decision.costs["equality"] == 0.0


def test_never_returns_nothing_emergency_braking_when_everything_is_invalid():
    env = RoadEnvironment.along_path([[-20, 0], [300, 0]], lanes_left=1)
    config = preset("ethical").with_overrides({"vehicle": {"v_max": 5.0}})  # ego already faster
    decision = Planner(config, env).plan(KinematicState(0, 0, 0, 10), [])
    assert decision.emergency and decision.chosen_index == -1
    assert "emergency braking" in decision.reason
    assert decision.trajectory.v[-1] < decision.trajectory.v[0]


def test_decision_record_is_complete_and_json_able():
    situation = overtaking_cyclist()
    decision = Planner(preset("ethical"), situation.environment).plan(situation.ego, situation.road_users)
    config = preset("ethical").sampling
    # The grid (15 x 15 x 4 horizons), the braking family (4 decelerations x 15 offsets, the
    # current one among them, x 2 lateral fractions); no continuation in a first cycle.
    n_brake = 4 * config.n_offsets * len(config.brake_lateral_fractions)
    assert sum(decision.level_counts.values()) == len(decision.candidate_levels)
    assert len(decision.candidate_levels) == config.n_trajectories + n_brake == 900 + 120
    record = json.loads(json.dumps(decision.to_dict()))
    assert record["candidate"]["kind"] in ("grid", "brake") and record["continued"] is False
    assert set(record["candidate"]) == {"kind", "horizon", "end_speed", "end_offset", "deceleration"}
    assert {"bayes", "equality", "maximin", "responsibility", "risk", "comfort", "mobility", "total"} <= set(
        record["costs"]
    )
    assert [u["id"] for u in record["road_users"]] == [1, 2]
    assert record["timings_ms"]["total"] > 0
    assert "level" in decision.summary()


class _SlowPredictor:
    """The ethical preset's predictor, sleeping ``seconds`` first (no CPU time spent)."""

    name = "slow"

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.inner = make_predictor(preset("ethical").prediction)

    def predict(self, road_users, times):
        time.sleep(self.seconds)
        return self.inner.predict(road_users, times)


def test_stage_timers_are_cpu_time_and_add_up_to_the_cycle():
    """Every stage is reported, the stages add up to at most ``total`` (CPU), ``wall`` is wall time.

    The predictor sleeps 0.3 s: wall time counts the sleep, CPU time does not (a mutant
    timing the stages with ``time.perf_counter`` goes red). No speed is asserted.
    """
    situation = overtaking_cyclist()
    planner = Planner(preset("ethical"), situation.environment, predictor=_SlowPredictor(0.3))
    timings = planner.plan(situation.ego, situation.road_users).timings_ms
    stages = ("sampling", "prediction", "validity", "risk", "responsibility", "cost", "selection", "record")
    assert set(timings) == {*stages, "total", "wall"}
    assert all(timings[k] >= 0 for k in timings)
    # Consecutive intervals of one clock, each rounded to 1 us.
    assert sum(timings[k] for k in stages) <= timings["total"] + 1e-3 * len(stages)
    assert timings["wall"] >= 300.0
    assert timings["prediction"] < 150.0 and timings["total"] < timings["wall"]


def test_risk_of_the_chosen_plan_matches_a_scalar_recomputation():
    """Vectorised risk (Eq. 3) against a loop over steps with single-triple calls."""
    situation = overtaking_cyclist(cyclist_ahead=8.0)
    planner = Planner(preset("standard"), situation.environment)
    decision = planner.plan(situation.ego, situation.road_users)
    traj, pred = decision.trajectory, decision.prediction
    for k, user in enumerate(situation.road_users):
        best = 0.0
        for t in range(len(traj.t)):
            p = collision_probability(
                traj.x[None, [t]],
                traj.y[None, [t]],
                traj.yaw[None, [t]],
                EGO_SHAPE.length,
                EGO_SHAPE.width,
                pred.mean[[k]][:, [t]],
                pred.cov[[k]][:, [t]],
                pred.heading[[k]][:, [t]],
                pred.length[[k]],
                pred.width[[k]],
            ).probability[0, 0, 0]
            if p == 0.0:
                continue
            harm = collision_harm(
                1475.0,
                [traj.v[t] * math.cos(traj.yaw[t]), traj.v[t] * math.sin(traj.yaw[t])],
                [traj.x[t], traj.y[t]],
                traj.yaw[t],
                user.mass,
                [
                    pred.speed[k, t] * math.cos(pred.heading[k, t]),
                    pred.speed[k, t] * math.sin(pred.heading[k, t]),
                ],
                pred.mean[k, t],
                pred.heading[k, t],
                np.array(user.is_vulnerable),
            ).harm_obs
            best = max(best, float(p * harm))
        assert decision.road_users[k].risk == pytest.approx(best, rel=1e-9, abs=1e-15)


@pytest.mark.parametrize("field,value", [("x", math.nan), ("v", math.inf)])
def test_bad_ego_state_is_rejected(field, value):
    kwargs = {"x": 0.0, "y": 0.0, "yaw": 0.0, "v": 5.0, field: value}
    with pytest.raises(ValueError, match=f"KinematicState.{field}"):
        KinematicState(**kwargs)


def test_reference_path_shorter_than_the_horizon_is_extended_straight():
    env = RoadEnvironment.along_path([[-5, 0], [10, 0]], lanes_left=1)
    car = RoadUser(
        1, RoadUserType.CAR, KinematicState(40, 3.5, math.pi, 10), DEFAULT_SHAPES[RoadUserType.CAR]
    )
    decision = Planner(preset("ethical"), env).plan(KinematicState(0, 0, 0, 12), [car])
    assert np.all(np.isfinite(decision.trajectory.x)) and decision.trajectory.x[-1] > 10
    assert all(math.isfinite(v) for v in decision.costs.values())
    # Beyond the mapped road the footprint leaves the drivable area: a defined level, not a crash.
    assert decision.level in {int(level) for level in Validity}


def test_bad_planner_arguments():
    env = RoadEnvironment.along_path([[0, 0], [10, 0]])
    with pytest.raises(ValueError, match="ego_mass"):
        Planner(preset("ethical"), env, ego_mass=0.0)
    with pytest.raises(ValueError, match="config"):
        Planner({"weights": {}}, env)


def test_planar_delta_v_model_changes_the_harm_the_planner_computes():
    """Overtaking a cyclist: a brush at the cyclist's side transfers less than Eq. 1's
    common velocity, and the planar model's harm follows its delta-v (pedestrian-style
    harm of the cyclist is monotone in delta-v)."""
    from ethical_planner.harm import collision_harm
    from ethical_planner.impulse import planar_impulse

    situation = overtaking_cyclist(cyclist_ahead=8.0)
    # Risk-blind and without R_max, so both plans are the same candidate.
    base = preset("standard").with_overrides({"risk": {"max_acceptable_risk": 1.0}})
    plain = Planner(base, situation.environment).plan(situation.ego, situation.road_users)
    planar_config = base.with_overrides({"risk": {"delta_v_model": "planar_impulse"}})
    planar = Planner(planar_config, situation.environment).plan(situation.ego, situation.road_users)
    assert planar.chosen_index == plain.chosen_index
    cyclist_plain, cyclist_planar = plain.road_users[0], planar.road_users[0]
    assert cyclist_plain.collision_probability == pytest.approx(cyclist_planar.collision_probability)
    assert cyclist_planar.harm != pytest.approx(cyclist_plain.harm, rel=1e-3)
    # The harm is the planar model's at the same states (checked on one pair of states).
    ego, cyclist = situation.ego, situation.road_users[0]
    other = cyclist.state
    args = dict(ego_mass=1475.0, ego_vel=ego.velocity, ego_pos=(ego.x, ego.y), ego_yaw=ego.yaw,
                obs_mass=cyclist.mass, obs_vel=other.velocity, obs_pos=(other.x, other.y),
                obs_yaw=other.yaw, obs_unprotected=np.array(True))  # fmt: skip
    result = collision_harm(**args, delta_v_model="planar_impulse", ego_shape=(4.508, 1.61),
                            obs_shape=(cyclist.shape.length, cyclist.shape.width))  # fmt: skip
    direct = planar_impulse(1475.0, (ego.x, ego.y), ego.yaw, 4.508, 1.61, ego.velocity, cyclist.mass,
                            (cyclist.state.x, cyclist.state.y), cyclist.state.yaw, cyclist.shape.length,
                            cyclist.shape.width, cyclist.state.velocity, friction=0.3)  # fmt: skip
    assert float(result.dv_obs) == pytest.approx(float(direct.dv_b))


def test_principles_of_the_chosen_plan_use_the_papers_risk_set():
    """J_B and J_E of the decision recomputed by hand from its per-road-user risks:
    S_R = {R_k} + {R_ego,k}, 2k entries for a plan on the road (no road-edge entry)."""
    import itertools

    situation = oncoming_in_ego_lane_with_pedestrian()
    decision = Planner(preset("ethical"), situation.environment).plan(situation.ego, situation.road_users)
    assert decision.boundary_risk == 0.0
    values = [u.risk for u in decision.road_users] + [u.ego_risk for u in decision.road_users]
    assert len(values) == 6 and max(values) > 0
    pairs = list(itertools.combinations(values, 2))
    assert decision.costs["bayes"] == pytest.approx(sum(values) / 6, rel=1e-12)
    assert decision.costs["equality"] == pytest.approx(sum(abs(a - b) for a, b in pairs) / 15, rel=1e-12)


def test_a_user_predictor_is_used_by_the_planner():
    from ethical_planner.prediction import predict_constant_turn_rate

    calls = []

    class Recording:
        name = "recording"

        def predict(self, road_users, times):
            calls.append(len(times))
            return predict_constant_turn_rate(road_users, times, preset("ethical").prediction)

    situation = overtaking_cyclist()
    Planner(preset("ethical"), situation.environment, predictor=Recording()).plan(
        situation.ego, situation.road_users
    )
    assert calls == [int(round(max(preset("ethical").sampling.horizons) / 0.1)) + 1]
    with pytest.raises(ValueError, match="Predictor protocol"):
        Planner(preset("ethical"), situation.environment, predictor=object())


class _NobodyNearPredictor:
    """A predictor written for the test: every road user is predicted 300 m away."""

    name = "nobody_near"

    def __init__(self, config):
        self.inner = make_predictor(config)
        self.calls = 0

    def predict(self, road_users, times):
        self.calls += 1
        base = self.inner.predict(road_users, times)
        return dataclasses.replace(base, mean=base.mean + np.array([300.0, 0.0]))


def test_a_custom_predictor_changes_the_decision():
    """The planner takes any Predictor: one that sees the road clear lets it overtake."""
    situation = overtaking_cyclist()
    config = preset("standard").with_overrides(
        {"sampling": {"horizons": [3.0]}, "risk": {"max_acceptable_risk": 0.01}}
    )
    cyclist_end_x = situation.road_users[0].state.x + 4.0 * 3.0
    default = Planner(config, situation.environment)
    assert default.predictor.name == config.prediction.model
    behind = default.plan(situation.ego, situation.road_users)
    assert behind.trajectory.x[-1] < cyclist_end_x - 2.0  # stays behind the cyclist

    predictor = _NobodyNearPredictor(config.prediction)
    custom = Planner(config, situation.environment, predictor=predictor)
    past = custom.plan(situation.ego, situation.road_users)
    assert predictor.calls == 1
    assert past.prediction.mean[0, 0, 0] == pytest.approx(situation.road_users[0].state.x + 300.0)
    assert past.trajectory.x[-1] > behind.trajectory.x[-1] + 5.0  # keeps its speed
    assert past.road_users[0].risk == 0.0


def test_predictor_is_checked_and_named_by_the_registry():
    env = overtaking_cyclist().environment
    with pytest.raises(ValueError, match="Predictor protocol"):
        Planner(preset("ethical"), env, predictor=object())
    unknown = preset("ethical").with_overrides({"prediction": {"model": "walenet"}})
    with pytest.raises(ValueError, match="unknown predictor 'walenet'; allowed: .*constant_turn_rate"):
        Planner(unknown, env)


def _stopped_truck_ahead(gap):
    """A single-lane road between walls, the ego at 14 m/s, a stopped truck ``gap`` m ahead."""
    env = RoadEnvironment.along_path([[-30, 0], [300, 0]], lanes_left=0, margin=0.3)
    truck_x = 0.5 * EGO_SHAPE.length + gap + 0.5 * DEFAULT_SHAPES[RoadUserType.TRUCK].length
    truck = RoadUser(
        1, RoadUserType.TRUCK, KinematicState(truck_x, 0, 0, 0), DEFAULT_SHAPES[RoadUserType.TRUCK]
    )
    return env, KinematicState(0, 0, 0, 14.0), [truck], truck_x


def test_cause_1_a_hard_stop_that_stays_stopped_saves_the_ego():
    """Issue 9, cause 1: the hardest braking candidate of the old grid stopped exactly at
    T = 2 s (10.5 m/s^2 peak, invalid), so the ego rolled into a stopped truck. A braking
    candidate at the emergency deceleration (8 m/s^2 after a 30 m/s^3 ramp) stops in
    14.1 m from 14 m/s and stays stopped: with a 16 m gap it is the plan."""
    env, ego, users, truck_x = _stopped_truck_ahead(gap=16.0)
    old = preset("ethical").with_overrides(
        {"sampling": {"horizons": [2.0], "brake_candidates": False}, "commitment": {"enabled": False}}
    )
    before = Planner(old, env).plan(ego, users)
    decision = Planner(preset("ethical"), env).plan(ego, users)
    # Without a way to stop, the old grid's best was to scrape past the truck off the road.
    assert before.level <= Validity.LEAVES_ROAD and before.trajectory.v[-1] > 0
    assert decision.level > Validity.LEAVES_ROAD
    plan = decision.trajectory
    assert plan.v[-1] == 0.0 and np.all(plan.v[np.argmax(plan.v == 0) :] == 0)  # stops and stays
    assert plan.x.max() + 0.5 * EGO_SHAPE.length < truck_x - 5.0  # before the truck's rear


def test_cause_1_when_everything_collides_the_least_expected_harm_is_chosen_hard_stops_included():
    env, ego, users, _ = _stopped_truck_ahead(gap=7.0)
    planner = Planner(preset("ethical"), env)
    decision = planner.plan(ego, users)
    assert decision.level == Validity.COLLISION
    assert "every candidate is predicted to collide" in decision.reason
    assert "hard stops included" in decision.reason
    # The choice is a hard stop: the lowest impact speed, the least harm.
    assert decision.candidate.kind.name == "BRAKE" and decision.candidate.deceleration >= 6.0


def test_cause_1_the_plan_is_kept_unless_another_is_clearly_better():
    """Commitment: replanning from a state on the previous plan keeps it (hysteresis);
    an obstacle appearing on it makes the planner switch at once."""
    situation = overtaking_cyclist()
    planner = Planner(preset("ethical"), situation.environment)
    first = planner.plan(situation.ego, situation.road_users)
    t = first.trajectory
    on_plan = KinematicState(t.x[1], t.y[1], t.yaw[1], t.v[1], t.a[1])
    moved = [
        RoadUser(
            u.id,
            u.type,
            KinematicState(
                u.state.x + 0.1 * u.state.v * math.cos(u.state.yaw),
                u.state.y + 0.1 * u.state.v * math.sin(u.state.yaw),
                u.state.yaw,
                u.state.v,
            ),
            u.shape,
        )
        for u in situation.road_users
    ]
    second = planner.plan(on_plan, moved)
    assert second.continued and second.candidate.kind.name == "CONTINUATION"
    assert second.trajectory.x[:-1] == pytest.approx(t.x[1:], abs=1e-6)
    # A parked car appears on the continued plan: it is dropped.
    blocker = RoadUser(
        9,
        RoadUserType.PARKED_VEHICLE,
        KinematicState(t.x[25], t.y[25], 0, 0),
        DEFAULT_SHAPES[RoadUserType.CAR],
    )
    third = planner.plan(on_plan, [*moved, blocker])
    assert not third.continued


def test_cause_4_an_overtake_on_a_clear_road_is_not_punished():
    """Staying behind a 4 m/s cyclist on an empty two-lane road costs mobility for the
    whole horizon; measured against the lane it drives in, the overtake wins. The
    reference weights (path term against the route, weight 10) stay behind."""
    situation = overtaking_cyclist()
    cyclist = situation.road_users[0]
    ethical = Planner(preset("ethical"), situation.environment).plan(situation.ego, [cyclist])
    reference = Planner(preset("reference"), situation.environment).plan(situation.ego, [cyclist])
    assert ethical.level == Validity.VALID
    assert ethical.trajectory.y.max() > 2.5  # into the free lane
    assert reference.trajectory.y.max() < 1.0  # behind the cyclist


def test_the_readme_predictor_example_runs_and_its_registration_works(monkeypatch):
    """README "The planner in five lines": the planner, then a predictor of one's own."""
    import re
    from pathlib import Path

    from ethical_planner.prediction import PREDICTORS, ConstantTurnRatePredictor

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("## The planner in five lines") :]
    section = section[: section.index("\n## ", 1)]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert len(blocks) == 2
    monkeypatch.setattr(PREDICTORS, "_entries", dict(PREDICTORS._entries))  # undone after the test
    namespace: dict = {}
    for code in blocks:
        exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102 - our own README
    assert namespace["decision"].trajectory.t.size > 1
    planner, situation = namespace["planner"], namespace["situation"]
    assert planner.predictor.name == "cautious"
    times = np.linspace(0.0, 3.0, 31)
    base = ConstantTurnRatePredictor(namespace["config"].prediction).predict(situation.road_users, times)
    doubled = planner.predictor.predict(situation.road_users, times)
    np.testing.assert_array_equal(doubled.cov, 2.0 * base.cov)
    np.testing.assert_array_equal(doubled.mean, base.mean)
    # registered under its name, a TOML's [prediction] model = "cautious" chooses it
    by_name = Planner(
        preset("ethical").with_overrides({"prediction": {"model": "cautious"}}), situation.environment
    )
    assert by_name.predictor.name == "cautious"
    assert "cautious" in PREDICTORS


def test_old_correction_option_is_rejected_by_name():
    with pytest.raises(ValueError, match="unknown key 'risk.delta_v_correction'"):
        preset("ethical").with_overrides({"risk": {"delta_v_correction": "calibration.json"}})


def test_the_oncoming_lane_costs_more_than_a_lane_of_the_own_direction():
    """A plan in the oncoming lane pays ``weights.oncoming_lane`` (here 2) per lane across the centre line.

    The same two-lane road once as a one-way road (no centre line: the left lane is one
    of the ego's own direction) and once as a two-way road (centre line between the
    lanes: the left lane is the oncoming traffic's). No one else on the road, the ego at
    10 m/s in the left lane: both choose the same return to the right lane; on the
    two-way road its mobility cost is higher by 2 x the fraction of steps the ego's
    centre spends across the centre line (d > 1.75 m: in the oncoming lane's half).
    """
    one_way = RoadEnvironment.along_path([[-30, 0], [300, 0]], lanes_left=1)
    two_way = dataclasses.replace(one_way, centre_line=1.75)
    ego = KinematicState(0.0, 3.5, 0.0, 10.0)
    config = preset("ethical").with_overrides(
        {"commitment": {"enabled": False}, "weights": {"oncoming_lane": 2.0}}
    )
    one, two = (Planner(config, env).plan(ego, []) for env in (one_way, two_way))
    np.testing.assert_allclose(two.trajectory.y, one.trajectory.y)  # the same plan
    y = two.trajectory.y
    assert y[0] == pytest.approx(3.5) and y[-1] < 1.75  # back on its side
    across = float(np.mean(y > 1.75))
    assert 0.0 < across < 1.0
    extra = two.costs["mobility"] - one.costs["mobility"]
    assert extra == pytest.approx(2.0 * across, abs=1e-9)  # weights.oncoming_lane = 2
    # Off by default (SPEC's mobility term knows no lanes): the same cost on both roads.
    default = preset("ethical").with_overrides({"commitment": {"enabled": False}})
    one, two = (Planner(default, env).plan(ego, []) for env in (one_way, two_way))
    assert two.costs["mobility"] == one.costs["mobility"]


@pytest.mark.parametrize("share", [0.3, 0.7, 1.0])
def test_risk_free_terms_of_some_rows_are_those_of_the_rows_alone(share):
    """Comfort's and mobility's inputs of a subset of the candidates, computed over every row
    and then picked (at least half of them) or over the subset, equal the expressions
    evaluated on the subset's own arrays, to the bit."""
    from ethical_planner.cost import path_deviation
    from ethical_planner.sampling import frenet_state, sample_candidates

    env = RoadEnvironment.along_path([[-20, 0], [200, 0]], lanes_left=1, lanes_right=1, margin=0.5)
    planner = Planner(preset("ethical"), env)
    path = env.reference_path
    start = frenet_state(KinematicState(0.0, 0.8, 0.05, 9.0, 0.4), path)
    config = planner.config
    candidates = sample_candidates(start, path, config.sampling, config.vehicle)
    n = candidates.n_traj
    rng = np.random.default_rng(5)
    rows = np.sort(rng.choice(n, int(share * n), replace=False))
    got = planner._risk_free_terms(candidates, rows)
    d = candidates.d[rows].copy()
    expected = (
        candidates.jerk_lon[rows],
        candidates.jerk_lat[rows],
        np.abs(candidates.v[rows].copy() - planner.desired_speed).mean(axis=1),
        *path_deviation(d, env.lane_offsets, env.lane_width, config.weights.path_reference),
    )
    assert len(got) == len(expected)
    for value, reference in zip(got, expected, strict=True):
        np.testing.assert_array_equal(value, reference)
