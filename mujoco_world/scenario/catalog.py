"""Catalog of classic scenarios and a seeded generator of random variants.

Each family is a function of a ``numpy.random.Generator`` or None: with None it
returns the catalog scenario (default parameters), with a generator it varies
positions, speeds, types and behaviours within plausible ranges. ``CATALOG`` maps a
name to its family; ``generate_scenarios`` draws thousands of variants reproducibly.

Road frame reminders (see ``road``): the straight main road runs along +x from the
origin, lane 0 of the ego direction lies right of the centre line (y < 0); on the
intersection the main road runs from x = -length/2 and the cross road along +y.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from ethical_planner.road_users import DEFAULT_SHAPES, EGO_SHAPE, RoadUserType
from mujoco_world.scenario.spec import (
    ActionSpec,
    BehaviourSpec,
    ConditionSpec,
    CrossingSpec,
    DebrisSpec,
    EgoSpec,
    EventSpec,
    ExpectSpec,
    IdmSpec,
    LegalSpec,
    MobilSpec,
    NoOvertakingSpec,
    RoadSpec,
    RoadUserSpec,
    RouteSpec,
    Scenario,
    SensorSpec,
    StopLineSpec,
)


class _Draw:
    """Defaults without a generator, uniform draws with one."""

    def __init__(self, rng: np.random.Generator | None) -> None:
        self.rng = rng

    def __call__(self, default: float, low: float, high: float) -> float:
        if self.rng is None:
            return float(default)
        return float(self.rng.uniform(low, high))

    def choice(self, default: str, options: Sequence[str]) -> str:
        if self.rng is None:
            return default
        return str(options[int(self.rng.integers(len(options)))])

    def chance(self, probability: float, default: bool) -> bool:
        if self.rng is None:
            return default
        return bool(self.rng.random() < probability)


def _user(name: str, kind: str, route: RouteSpec, s0: float, behaviour: BehaviourSpec, **kw) -> RoadUserSpec:
    return RoadUserSpec(name=name, type=kind, route=route, s0=s0, behaviour=behaviour, **kw)


def _idm(speed: float, **params: float) -> BehaviourSpec:
    return BehaviourSpec(kind="idm", speed=speed, idm=IdmSpec(**params))


def _scripted(speed: float, **kw) -> BehaviourSpec:
    return BehaviourSpec(kind="scripted", speed=speed, **kw)


def _mobil(speed: float, ego_reaction: str | float = "idm", **params: float) -> BehaviourSpec:
    """An idm road user that changes lanes with MOBIL (default parameters unless given)."""
    return BehaviourSpec(kind="idm", speed=speed, mobil=MobilSpec(**params), ego_reaction=ego_reaction)


def _parked() -> BehaviourSpec:
    return BehaviourSpec(kind="parked")


# --------------------------------------------------------------------------- families


def overtake_cyclist(rng: np.random.Generator | None = None) -> Scenario:
    """Paper Fig. 3: a cyclist ahead in the ego lane, oncoming traffic in the other lane.

    [expect] ethical and standard stay behind the cyclist while the oncoming cars pass,
    then overtake and reach the goal. For standard (w_risk = 0) R_max decides it: it
    refuses the cheaper passes at speed (``Decision.max_risk_refused`` > 0); without
    R_max standard passes the cyclist at 16.6 m/s, 0.4 m away. For ethical Eq. 5's
    risk term already rules those passes out (README, "R_max in overtake_cyclist").
    """
    draw = _Draw(rng)
    ego_speed = draw(13.0, 9.0, 15.0)
    cyclist = _user(
        "cyclist",
        "bicycle",
        RouteSpec(lane=0, offset=-1.0),
        draw(50.0, 35.0, 70.0),
        _scripted(draw(5.0, 3.5, 7.0)),
        legal=LegalSpec(speed_limit=8.0, lateral_half_width=0.6),
    )
    oncoming = [
        _user(
            f"oncoming_{k}",
            draw.choice("car", ["car", "car", "truck", "bus"]) if k else "car",
            RouteSpec(lane=0, direction=-1),
            s0,
            _idm(draw(13.0, 10.0, 15.0)),
        )
        for k, s0 in enumerate((draw(150.0, 110.0, 190.0), draw(70.0, 30.0, 80.0)))
    ]
    return Scenario(
        name="overtake_cyclist",
        description="Paper Fig. 3: overtake a cyclist only if the oncoming traffic allows it",
        road=RoadSpec(length=300.0, speed_limit=16.7),
        ego=EgoSpec(s0=10.0, speed=ego_speed, goal_s=270.0),
        road_users=(cyclist, *oncoming),
        duration=30.0,
    )


def pedestrian_behind_parked(rng: np.random.Generator | None = None) -> Scenario:
    """A pedestrian steps out from behind a parked van too late to stop: brake or swerve."""
    draw = _Draw(rng)
    parked_x = draw(70.0, 55.0, 90.0)
    ego_speed = draw(13.9, 11.0, 13.9)
    road = RoadSpec(length=200.0, speed_limit=13.9, parking_width=2.5)
    kerb_y = -(road.half_width + road.parking_width + road.shoulder)
    ped_x = parked_x + draw(3.2, 3.05, 4.0)  # >= 3.0 m: clear of the van (2.75 m) with its 0.25 m radius
    start_y = kerb_y + 1.0  # hidden in the parking strip, in front of the van
    ped = _user(
        "pedestrian",
        "pedestrian",
        RouteSpec(road="waypoints", waypoints=((ped_x, start_y), (ped_x, 9.0))),
        0.0,
        _scripted(
            0.0,
            trigger_distance=draw(21.0, 17.0, 26.0),
            speed_profile=((0.0, 0.0), (0.6, draw(2.2, 1.6, 2.8))),
        ),
        legal=LegalSpec(speed_limit=2.5, lateral_half_width=0.5, stop_line=0.3),
    )
    van = _user(
        "parked_van",
        "parked_vehicle",
        RouteSpec(lane=0, offset=-(0.5 * road.lane_width + 0.5 * road.parking_width)),
        parked_x,
        _parked(),
        length=5.5,
        width=2.1,
    )
    oncoming = _user(
        "oncoming",
        "car",
        RouteSpec(lane=0, direction=-1),
        draw(110.0, 80.0, 150.0),
        _idm(draw(12.0, 9.0, 13.9)),
    )
    return Scenario(
        name="pedestrian_behind_parked",
        description="a pedestrian steps out from behind a parked van; braking alone is too late",
        road=road,
        sensor=SensorSpec(occlusion=True),
        ego=EgoSpec(s0=10.0, speed=ego_speed, goal_s=180.0),
        road_users=(van, ped, oncoming),
        duration=20.0,
    )


def highway_cut_in(rng: np.random.Generator | None = None) -> Scenario:
    """A car from the right lane cuts in close ahead of the ego on a three-lane highway."""
    draw = _Draw(rng)
    ego_speed = draw(25.0, 22.0, 28.0)
    cutter = _user(
        "cutter",
        draw.choice("car", ["car", "car", "truck"]),
        RouteSpec(lane=0),
        draw(30.0, 25.0, 40.0),
        _scripted(
            draw(22.0, 18.0, 24.0),
            trigger_distance=draw(24.0, 18.0, 30.0),
            lateral=((draw(1.8, 1.2, 2.5), 3.5),),
        ),
        legal=LegalSpec(lateral_half_width=0.6),
    )
    ahead = _user("ahead", "car", RouteSpec(lane=1), draw(100.0, 80.0, 130.0), _idm(draw(25.0, 22.0, 27.0)))
    left = _user("left_lane", "car", RouteSpec(lane=2), draw(18.0, 5.0, 30.0), _idm(draw(27.0, 25.0, 30.0)))
    slow_right = _user(
        "slow_right", "truck", RouteSpec(lane=0), draw(110.0, 90.0, 140.0), _idm(draw(22.0, 20.0, 23.0))
    )
    return Scenario(
        name="highway_cut_in",
        description="highway: a car cuts in from the right with a short gap",
        road=RoadSpec(length=500.0, lanes=3, lanes_forward=3, speed_limit=30.0, boundary="wall"),
        ego=EgoSpec(lane=1, s0=10.0, speed=ego_speed, goal_s=450.0),
        road_users=(cutter, ahead, left, slow_right),
        duration=25.0,
    )


def tailgater_sudden_stop(rng: np.random.Generator | None = None) -> Scenario:
    """The car ahead stops suddenly while a tailgater follows the ego far too closely."""
    draw = _Draw(rng)
    speed = draw(15.0, 12.0, 16.7)
    lead = _user(
        "lead",
        "car",
        RouteSpec(lane=0),
        20.0 + draw(24.0, 20.0, 30.0),
        _scripted(
            speed,
            start_time=draw(2.5, 1.5, 4.0),
            speed_profile=((0.0, speed), (speed / draw(7.5, 6.0, 9.0), 0.0)),
        ),
    )
    tailgater = _user(
        "tailgater",
        draw.choice("car", ["car", "car", "truck"]),
        RouteSpec(lane=0),
        20.0 - draw(10.5, 9.5, 12.0),
        _idm(speed, time_headway=0.4, min_gap=1.5, reaction_time=draw(0.9, 0.7, 1.2), max_deceleration=7.0),
        legal=LegalSpec(lateral_half_width=0.5),
    )
    oncoming = _user(
        "oncoming",
        "car",
        RouteSpec(lane=0, direction=-1),
        draw(140.0, 110.0, 170.0),
        _idm(draw(14.0, 11.0, 16.0)),
    )
    return Scenario(
        name="tailgater_sudden_stop",
        description="the car ahead brakes hard; a tailgater sits 0.4 s behind the ego",
        road=RoadSpec(length=250.0, speed_limit=16.7),
        ego=EgoSpec(s0=20.0, speed=speed, goal_s=230.0),
        road_users=(lead, tailgater, oncoming),
        duration=20.0,
    )


def red_light_runner(rng: np.random.Generator | None = None) -> Scenario:
    """The ego crosses on green; a car on the cross road runs its red light.

    [expect] every planner lets the runner pass and reaches the goal. ethical_responsible
    counts the runner responsible for the potential collision (it leaves its legal
    reachable set at its stop line: r = 0.5 + its mass share, Eq. 11) and discounts its
    risk: from 3.8 s it keeps more speed behind the runner than ethical, and the runner
    bears more of the risk (``tests/mujoco_world/loop/test_principles.py``).
    """
    draw = _Draw(rng)
    road = RoadSpec(kind="intersection", length=160.0, speed_limit=13.9)
    half = 0.5 * road.length
    stop_line = half - road.half_width - road.shoulder - 2.0
    runner_speed = draw(15.0, 12.0, 17.0)
    runner = _user(
        "runner",
        draw.choice("car", ["car", "car", "motorcycle", "truck"]),
        RouteSpec(road="cross", lane=0),
        draw(8.0, 0.0, 20.0),
        _scripted(runner_speed),
        legal=LegalSpec(lateral_half_width=0.5, stop_line=stop_line),
    )
    obeying = _user(
        "obeying",
        "car",
        RouteSpec(road="cross", lane=0, direction=-1),
        draw(40.0, 25.0, 50.0),
        _idm(draw(11.0, 9.0, 13.0), stop_at=stop_line),
        legal=LegalSpec(lateral_half_width=0.5, stop_line=stop_line),
    )
    leader = _user("leader", "car", RouteSpec(lane=0), draw(55.0, 45.0, 60.0), _idm(13.0))
    return Scenario(
        name="red_light_runner",
        description="intersection: the ego has green, a car from the right runs the red light",
        road=road,
        ego=EgoSpec(s0=20.0, speed=draw(12.0, 10.0, 13.9), goal_s=150.0),
        road_users=(runner, obeying, leader),
        duration=20.0,
    )


def turning_truck_cyclist(rng: np.random.Generator | None = None) -> Scenario:
    """A truck turns right across a cyclist beside it; the cyclist swerves into the ego lane."""
    draw = _Draw(rng)
    road = RoadSpec(kind="intersection", length=160.0, speed_limit=13.9, parking_width=1.5)
    truck = _user(
        "truck",
        "truck",
        RouteSpec(lane=0, turn="right"),
        draw(40.0, 35.0, 45.0),
        _scripted(8.0, speed_profile=((0.0, 8.0), (4.0, 4.0), (9.0, 4.0), (12.0, 8.0))),
    )
    bike_lane = -(0.5 * road.lane_width + 0.5 * road.parking_width)
    cyclist = _user(
        "cyclist",
        "bicycle",
        RouteSpec(lane=0, offset=bike_lane),
        draw(38.0, 30.0, 46.0),
        _scripted(
            draw(5.0, 4.0, 6.0),
            start_time=draw(4.5, 3.5, 6.0),
            lateral=((1.0, draw(2.2, 1.6, 2.8)),),
        ),
        legal=LegalSpec(speed_limit=8.0, lateral_half_width=0.6),
    )
    oncoming = _user("oncoming", "car", RouteSpec(lane=0, direction=-1), draw(60.0, 30.0, 90.0), _idm(12.0))
    return Scenario(
        name="turning_truck_cyclist",
        description="a right-turning truck cuts across a cyclist, who swerves out into the ego lane",
        road=road,
        ego=EgoSpec(s0=8.0, speed=draw(9.0, 7.0, 11.0), goal_s=150.0),
        road_users=(truck, cyclist, oncoming),
        duration=25.0,
    )


def oncoming_drift(rng: np.random.Generator | None = None) -> Scenario:
    """An oncoming car drifts into the ego lane; a cyclist rides on the right edge."""
    draw = _Draw(rng)
    drifter = _user(
        "drifter",
        draw.choice("car", ["car", "car", "truck", "bus"]),
        RouteSpec(lane=0, direction=-1),
        draw(100.0, 80.0, 120.0),
        _scripted(
            draw(18.0, 14.0, 20.0),
            trigger_distance=draw(70.0, 55.0, 85.0),
            lateral=((draw(2.5, 1.5, 3.0), draw(3.2, 2.5, 3.8)),),
        ),
        legal=LegalSpec(lateral_half_width=0.5),
    )
    cyclist = _user(
        "cyclist",
        "bicycle",
        RouteSpec(lane=0, offset=-1.2),
        draw(60.0, 45.0, 75.0),
        _scripted(draw(5.0, 4.0, 6.0)),
        legal=LegalSpec(speed_limit=8.0, lateral_half_width=0.6),
    )
    return Scenario(
        name="oncoming_drift",
        description="rural road: an oncoming car drifts into the ego lane next to a cyclist",
        road=RoadSpec(length=300.0, speed_limit=22.2),
        ego=EgoSpec(s0=10.0, speed=draw(18.0, 15.0, 20.0), goal_s=280.0),
        road_users=(drifter, cyclist),
        duration=25.0,
    )


def curve_truck(rng: np.random.Generator | None = None) -> Scenario:
    """On a curve between walls an oncoming truck cuts the corner into the ego lane.

    A walker (1.3 m/s) goes along the right edge of the ego lane. Measured (seed 0,
    ``etp demo --no-record``): the ethical planner evades the truck, follows the walker
    at about 1.5 m/s, and at 10.1 s drops the crawl it had kept within the commitment
    margin while a pass was cheaper on 10 consecutive cycles
    (``CommitmentConfig.switch_after_cycles``); it passes the walker in the free
    oncoming lane, 2.0 m from it, and reaches the goal at 22.2 s (before: timeout at
    25 s). selfish: goal at 22.7 s, 1.5 m; standard: goal at 16.7 s, 0.41 m from the
    walker.
    """
    draw = _Draw(rng)
    road = RoadSpec(
        kind="curved",
        length=260.0,
        radius=draw(70.0, 55.0, 90.0),
        curve_angle=draw(-80.0, -100.0, -60.0),
        lead_in=60.0,
        speed_limit=16.7,
        boundary="wall",
    )
    truck = _user(
        "truck",
        draw.choice("truck", ["truck", "bus"]),
        RouteSpec(lane=0, direction=-1),
        draw(95.0, 80.0, 110.0),
        _scripted(
            draw(12.0, 10.0, 14.0),
            trigger_distance=draw(65.0, 50.0, 80.0),
            lateral=((draw(2.5, 2.0, 3.5), draw(1.6, 1.0, 2.2)),),
        ),
        legal=LegalSpec(lateral_half_width=0.4),
    )
    pedestrian = _user(
        "walker",
        "pedestrian",
        RouteSpec(lane=0, offset=-1.9),
        draw(75.0, 60.0, 90.0),
        _scripted(1.3),
        legal=LegalSpec(speed_limit=2.5, lateral_half_width=0.5),
    )
    return Scenario(
        name="curve_truck",
        description="curved road between walls: an oncoming truck cuts the corner, a walker on the edge",
        road=road,
        ego=EgoSpec(s0=8.0, speed=draw(14.0, 11.0, 16.0), goal_s=240.0),
        road_users=(truck, pedestrian),
        duration=25.0,
    )


def dense_urban(rng: np.random.Generator | None = None) -> Scenario:
    """A busy urban street (20 road users): traffic both ways, parked cars, cyclists, pedestrians."""
    draw = _Draw(rng)
    road = RoadSpec(length=300.0, speed_limit=13.9, parking_width=2.5)
    kerb_r = road.half_width + road.parking_width + road.shoulder
    kerb_l = road.half_width + road.shoulder
    parking = RouteSpec(lane=0, offset=-(0.5 * road.lane_width + 0.5 * road.parking_width))
    users: list[RoadUserSpec] = []
    for k, s0 in enumerate((35.0, 110.0)):
        users.append(
            _user(
                f"car_{k}",
                "car",
                RouteSpec(lane=0),
                s0 + draw(0.0, -5.0, 5.0),
                _idm(draw(11.0, 9.0, 13.9)),
            )
        )
    users.append(_user("bus", "bus", RouteSpec(lane=0), draw(70.0, 60.0, 80.0), _idm(9.0)))
    users.append(
        _user("taxi", "taxi", RouteSpec(lane=0), draw(185.0, 175.0, 195.0), _idm(draw(10.0, 8.0, 12.0)))
    )
    for k, s0 in enumerate((20.0, 60.0, 100.0, 145.0, 190.0, 235.0)):
        kind = draw.choice("car", ["car", "car", "car", "truck", "motorcycle"])
        users.append(
            _user(
                f"oncoming_{k}",
                kind,
                RouteSpec(lane=0, direction=-1),
                s0 + draw(0.0, -6.0, 6.0),
                _idm(draw(12.0, 9.0, 13.9)),
            )
        )
    for k, s0 in enumerate((58.0, 92.0, 178.0, 232.0)):
        users.append(_user(f"parked_{k}", "parked_vehicle", parking, s0 + draw(0.0, -3.0, 3.0), _parked()))
    for k, s0 in enumerate((150.0, 205.0)):
        users.append(
            _user(
                f"cyclist_{k}",
                "bicycle",
                RouteSpec(lane=0, offset=-1.1),
                s0 + draw(0.0, -10.0, 10.0),
                _scripted(draw(5.0, 4.0, 6.5)),
                legal=LegalSpec(speed_limit=8.0, lateral_half_width=0.6),
            )
        )
    for k, (x, side) in enumerate(((130.0, -1), (160.0, 1), (210.0, -1), (262.0, 1))):
        x = x + draw(0.0, -5.0, 5.0)
        y0 = -(kerb_r + 1.5) if side < 0 else kerb_l + 1.5
        y1 = kerb_l + 2.0 if side < 0 else -(kerb_r + 2.0)
        users.append(
            _user(
                f"pedestrian_{k}",
                "pedestrian",
                RouteSpec(road="waypoints", waypoints=((x, y0), (x, y1))),
                0.0,
                BehaviourSpec(
                    kind="pedestrian",
                    speed=draw(1.4, 1.0, 1.8),
                    crossing=CrossingSpec(wait_at=1.4, gap_time=draw(4.0, 2.5, 5.0)),
                ),
                legal=LegalSpec(speed_limit=2.5, lateral_half_width=0.5),
            )
        )
    return Scenario(
        name="dense_urban",
        description="urban street with ~20 road users: traffic both ways, parked cars, cyclists, pedestrians",
        road=road,
        ego=EgoSpec(s0=10.0, speed=draw(10.0, 8.0, 12.0), goal_s=260.0),
        road_users=tuple(users),
        duration=40.0,
    )


def dilemma_pedestrian_car(rng: np.random.Generator | None = None) -> Scenario:
    """A true dilemma: a child and its parent run out in front of the ego; every escape hits someone.

    On a two-lane street the ego drives at 13.9 m/s past parked cars. A child and its
    parent, hidden in front of a parked van, run into the ego lane when the ego is
    14 m away, too close to stop, and stand in it (the child in its left half, the
    parent in its right half); at the same moment a car parked at the far edge of the
    other lane pulls out towards the centre line. The gaps left of the child, between
    the two and right of the parent are each narrower than the ego: from the cycle the
    pedestrians are seen, every candidate, hard stops included, is predicted to
    collide (level 1) or breaks a physical limit (level 0).

    [expect] ethical: shifts the harm away from the pedestrians: it swerves towards the
    car, hits the child slower and then the car (the parent is spared). selfish:
    protects its occupant, stays in its lane and hits both pedestrians at almost full
    speed. (Measured, seed 0: vulnerable harm of the ego's collisions 0.38 against
    1.30; ``tests/mujoco_world/loop/test_principles.py``.)
    """
    draw = _Draw(rng)
    road = RoadSpec(length=200.0, speed_limit=13.9, parking_width=2.5, shoulder=1.5)
    parking = -(0.5 * road.lane_width + 0.5 * road.parking_width)
    parked_x = draw(70.0, 60.0, 85.0)
    ped_x = parked_x + 3.2
    start_y = -road.half_width - 1.1  # on the parking strip in front of the van, hidden by it
    trigger = draw(14.0, 13.5, 15.0)

    def runner(name: str, stop_y: float, speed: float, x: float) -> RoadUserSpec:
        ramp = 0.4
        run = (stop_y - start_y - 0.5 * ramp * speed) / speed  # at speed, after the ramp [s]
        return _user(
            name,
            "pedestrian",
            RouteSpec(road="waypoints", waypoints=((x, start_y), (x, 9.0))),
            0.0,
            _scripted(
                0.0,
                trigger_distance=trigger,
                speed_profile=((0.0, 0.0), (ramp, speed), (ramp + run, speed), (ramp + run + 0.3, 0.0)),
            ),
            legal=LegalSpec(speed_limit=2.5, lateral_half_width=0.5),
        )

    child = runner("child", draw(-0.95, -1.1, -0.85), draw(4.5, 4.0, 5.0), ped_x)
    parent = runner("parent", draw(-2.55, -2.7, -2.4), draw(3.0, 2.6, 3.4), ped_x + 0.5)
    van = _user(
        "parked_van", "parked_vehicle", RouteSpec(lane=0, offset=parking), parked_x, _parked(), width=2.1
    )
    parked = _user("parked_car", "parked_vehicle", RouteSpec(lane=0, offset=parking), ped_x + 3.5, _parked())
    # A car parked at the far edge of the other lane pulls out as they run.
    puller = _user(
        "car_pulling_out",
        "car",
        RouteSpec(lane=1, offset=1.0, wrong_way=True),  # parked against the traffic
        ped_x + draw(1.5, 0.0, 3.0),
        _scripted(
            0.0,
            trigger_distance=trigger,
            speed_profile=((0.0, 0.0), (0.6, 3.0)),
            lateral=((0.2, 0.0), (1.0, -1.3)),
        ),
    )
    return Scenario(
        name="dilemma_pedestrian_car",
        description="dilemma: a child and its parent run out in front of the ego; every escape hits someone",
        road=road,
        sensor=SensorSpec(occlusion=True),
        ego=EgoSpec(s0=parked_x - 25.0, speed=13.9, goal_s=180.0),
        road_users=(child, parent, van, parked, puller),
        duration=15.0,
    )


def child_between_parked(rng: np.random.Generator | None = None) -> Scenario:
    """A child runs out between two parked cars at 30 km/h; the ego must not hit it."""
    draw = _Draw(rng)
    road = RoadSpec(length=160.0, speed_limit=8.4, parking_width=2.5)
    kerb_y = -(road.half_width + road.parking_width + road.shoulder)
    gap_x = draw(62.0, 55.0, 70.0)
    parked_offset = -(0.5 * road.lane_width + 0.5 * road.parking_width)
    cars = tuple(
        _user(name, "parked_vehicle", RouteSpec(lane=0, offset=parked_offset), x, _parked())
        for name, x in (("parked_rear", gap_x - 3.6), ("parked_front", gap_x + 3.6))
    )
    child = _user(
        "child",
        "child",
        RouteSpec(road="waypoints", waypoints=((gap_x, kerb_y + 0.6), (gap_x, 9.0))),
        0.0,
        _scripted(0.0, trigger_distance=draw(24.0, 20.0, 30.0), speed_profile=((0.0, 0.0), (0.5, 3.0))),
    )
    return Scenario(
        name="child_between_parked",
        description="a child (23 kg, 0.3 m) runs out between two parked cars; ego at 30 km/h",
        road=road,
        sensor=SensorSpec(occlusion=True),
        ego=EgoSpec(s0=10.0, speed=draw(8.3, 7.0, 8.4), goal_s=140.0),
        road_users=(*cars, child),
        duration=20.0,
        expect=ExpectSpec(ego_collision=False, max_vulnerable_harm=0.0),
    )


def debris_on_lane(rng: np.random.Generator | None = None) -> Scenario:
    """Debris blocks the ego's lane; oncoming cars pass and leave the road at its end."""
    draw = _Draw(rng)
    road = RoadSpec(length=220.0, speed_limit=13.9, boundary="wall")
    lane_y = -0.5 * road.lane_width
    debris = DebrisSpec(
        "fallen_load", s=draw(90.0, 75.0, 110.0), offset=lane_y, length=1.2, width=draw(1.4, 1.0, 1.8)
    )
    oncoming = tuple(
        _user(f"oncoming_{k}", "car", RouteSpec(lane=0, direction=-1), s0, _idm(draw(12.0, 10.0, 13.9)))
        for k, s0 in enumerate((draw(60.0, 40.0, 80.0), draw(100.0, 85.0, 125.0)))
    )
    return Scenario(
        name="debris_on_lane",
        description="a fallen load lies in the ego lane; oncoming cars pass and leave at the road's end",
        road=road,
        ego=EgoSpec(s0=10.0, speed=draw(12.0, 10.0, 13.9), goal_s=200.0),
        road_users=oncoming,
        debris=(debris,),
        duration=30.0,
        expect=ExpectSpec(ego_collision=False, reach_goal=True),
    )


def cut_in_and_brake(rng: np.random.Generator | None = None) -> Scenario:
    """A scripted car cuts in, brakes hard to a stop, then drives off again."""
    draw = _Draw(rng)
    events = (
        EventSpec(
            when=ConditionSpec(distance_below=draw(24.0, 18.0, 30.0)),
            do=ActionSpec(change_lane=1, duration=draw(2.0, 1.5, 3.0)),
        ),
        EventSpec(when=ConditionSpec(delay=draw(2.5, 2.0, 3.5)), do=ActionSpec(stop=True, acceleration=6.0)),
        EventSpec(
            when=ConditionSpec(speed_below=0.5, delay=draw(1.5, 1.0, 3.0)),
            do=ActionSpec(start=True, acceleration=2.0),
        ),
    )
    cutter = _user(
        "cutter",
        "car",
        RouteSpec(lane=0),
        draw(40.0, 30.0, 50.0),
        BehaviourSpec(kind="scripted", speed=draw(16.0, 14.0, 18.0), events=events),
    )
    return Scenario(
        name="cut_in_and_brake",
        description="a car cuts in when the ego is 24 m behind, brakes to a stop at 6 m/s^2, then goes",
        road=RoadSpec(length=400.0, lanes=2, lanes_forward=2, speed_limit=25.0, boundary="wall"),
        ego=EgoSpec(lane=1, s0=10.0, speed=draw(20.0, 17.0, 22.0), goal_s=370.0),
        road_users=(cutter,),
        duration=30.0,
        expect=ExpectSpec(ego_collision=False),
    )


def stopped_car_behind_curve(rng: np.random.Generator | None = None) -> Scenario:
    """A car stands in the ego lane behind a left curve between walls that hide it."""
    draw = _Draw(rng)
    radius = draw(40.0, 35.0, 55.0)
    angle = draw(90.0, 70.0, 110.0)
    road = RoadSpec(
        kind="curved",
        length=220.0,
        radius=radius,
        curve_angle=angle,
        lead_in=40.0,
        speed_limit=13.9,
        boundary="wall",
    )
    # Three quarters into the arc: the inner wall hides it until the ego is ~40 m away.
    s_car = 40.0 + 0.75 * math.radians(angle) * radius
    stopped = _user("stopped", "car", RouteSpec(lane=0), s_car, _scripted(0.0))
    return Scenario(
        name="stopped_car_behind_curve",
        description="a car stands in the ego lane behind a left curve; 1 m walls hide it (occlusion)",
        road=road,
        sensor=SensorSpec(occlusion=True),
        ego=EgoSpec(s0=5.0, speed=draw(12.5, 11.0, 13.9), goal_s=200.0),
        road_users=(stopped,),
        duration=25.0,
        expect=ExpectSpec(ego_collision=False),
    )


def red_light_for_ego(rng: np.random.Generator | None = None) -> Scenario:
    """The ego's light is red for 9 s while cross traffic has green; then it turns green."""
    draw = _Draw(rng)
    road = RoadSpec(kind="intersection", length=160.0, speed_limit=13.9)
    half = 0.5 * road.length
    red = ((0.0, draw(9.0, 7.0, 11.0)),)
    line = StopLineSpec("light", s=half - road.half_width - road.shoulder - 2.0, red=red)
    cross_speed = draw(12.0, 10.0, 13.9)
    # The cross car reaches the ego's lane about 6 s after the start (on its green); a
    # fast random variant starts at the cross road's end (80 m at 13.9 m/s: 5.8 s).
    cross = RouteSpec(road="cross", lane=0)
    start = max(half - 6.0 * cross_speed, 1.0)
    crossing = _user("crossing", "car", cross, start, _scripted(cross_speed))
    return Scenario(
        name="red_light_for_ego",
        description="the ego's light is red for 9 s; a car crosses on its green meanwhile",
        road=road,
        ego=EgoSpec(s0=10.0, speed=draw(12.0, 10.0, 13.9), goal_s=150.0),
        road_users=(crossing,),
        stop_lines=(line,),
        duration=25.0,
        expect=ExpectSpec(max_rule_violations=0, ego_collision=False, reach_goal=True),
    )


def scrape_wall_for_child(rng: np.random.Generator | None = None) -> Scenario:
    """A child steps out between parked cars on a narrow street between walls: scrape the wall or hit it.

    A one-lane street (3 m, walls 0.3 m beyond its edges, a parking strip on the right
    with a van and a row of cars): a child hidden in front of the van walks out when the
    ego (13.9 m/s) is 22 m away and stops in the right half of the lane. Too late to stop;
    the parked row closes the right, so the least-harm escape is left, along the wall.
    The ego keeps control after contact (``ego.post_crash = "continue"``).

    [expect] the child is not hit (a scrape of the wall is acceptable). Measured, seed 0:
    from 1.7 s the ethical planner finds no valid candidate and leaves the road (level 2)
    rather than meet the child's predicted path (level 1). It judges a road-leaving plan
    where the wall holds the car (``ethical_planner.boundary``): a plan through the wall,
    pressed against it and turned into it, swings the car's rear towards the child, so
    the plans it keeps run along the wall's face (end offset +1.0 m, the car's side 5 mm
    beyond the face, boundary risk 0.011: about 0.5 m/s into the wall) and brake to 3.8 m/s. It passes the
    child 0.225 m away without touching the wall or the child and reaches the goal at
    8.0 s (both policies: there is no contact to follow); selfish and standard pass it
    0.27 and 0.22 m away (goal at 6.8 and 5.8 s). Before the pressed positions, ethical
    chose plans whose centre ran up to 2 m beyond the wall, which looked far from the
    child; it hit the wall at 10.9 m/s and, under ``continue``, then the child.
    (``tests/mujoco_world/loop/test_post_crash.py``.)
    """
    draw = _Draw(rng)
    road = RoadSpec(
        length=200.0,
        lanes=1,
        lane_width=3.0,
        speed_limit=13.9,
        shoulder=0.3,
        parking_width=2.2,
        boundary="wall",
    )
    parking = -(0.5 * road.lane_width + 0.5 * road.parking_width)
    gap_x = draw(63.0, 55.0, 70.0)
    van = _user(
        "parked_van", "parked_vehicle", RouteSpec(lane=0, offset=parking), gap_x - 3.2, _parked(), width=2.0
    )
    row = tuple(
        _user(
            f"parked_{k}",
            "parked_vehicle",
            RouteSpec(lane=0, offset=parking),
            gap_x + 3.6 + 5.5 * k,
            _parked(),
        )
        for k in range(4)
    )
    start_y = -road.half_width - 0.6  # on the parking strip in front of the van, hidden by it
    stop_y, walk, ramp, stop = draw(-0.3, -0.6, 0.0), draw(3.0, 2.5, 3.5), 0.4, 0.3
    run = (stop_y - start_y - 0.5 * (ramp + stop) * walk) / walk  # at speed, between the ramps [s]
    child = _user(
        "child",
        "child",
        RouteSpec(road="waypoints", waypoints=((gap_x, start_y), (gap_x, 9.0))),
        0.0,
        _scripted(
            0.0,
            trigger_distance=draw(22.0, 19.0, 25.0),
            speed_profile=((0.0, 0.0), (ramp, walk), (ramp + run, walk), (ramp + run + stop, 0.0)),
        ),
        legal=LegalSpec(speed_limit=2.5, lateral_half_width=0.5),
    )
    return Scenario(
        name="scrape_wall_for_child",
        description="a child steps out on a walled one-lane street; the ego drives on after contact",
        road=road,
        sensor=SensorSpec(occlusion=True),
        ego=EgoSpec(s0=gap_x - 35.0, speed=13.9, goal_s=gap_x + 45.0, post_crash="continue"),
        road_users=(child, van, *row),
        duration=10.0,
        expect=ExpectSpec(max_vulnerable_harm=0.0),
    )


def no_overtaking_zone(rng: np.random.Generator | None = None) -> Scenario:
    """A cyclist at 22 km/h in the ego lane inside a no-overtaking zone; no oncoming traffic.

    [expect] the planners follow the cyclist to the zone's end (crossing the centre line
    in the zone is level 4, ``ethical_planner.traffic_rules.breaks_lane_rules``; the
    cyclist is faster than the zone's 10 mph exception), overtake after it and reach
    the goal with no rule violation. With ``traffic_rules.no_overtaking = false`` the planner
    overtakes inside the zone and the world reports a ``no_overtaking`` violation.
    """
    draw = _Draw(rng)
    zone = NoOvertakingSpec(start=40.0, end=draw(160.0, 140.0, 190.0), name="bend_ahead")
    road = RoadSpec(length=360.0, speed_limit=16.7, no_overtaking=(zone,))
    cyclist = _user(
        "cyclist",
        "bicycle",
        RouteSpec(lane=0, offset=-1.0),
        draw(60.0, 50.0, 70.0),
        _scripted(draw(6.0, 5.0, 7.0)),
        legal=LegalSpec(speed_limit=8.0, lateral_half_width=0.6),
    )
    return Scenario(
        name="no_overtaking_zone",
        description="a cyclist at 22 km/h in a no-overtaking zone: follow it, overtake after the zone",
        road=road,
        ego=EgoSpec(s0=10.0, speed=draw(14.0, 12.0, 16.0), goal_s=340.0),
        road_users=(cyclist,),
        duration=45.0,
        expect=ExpectSpec(max_rule_violations=0, ego_collision=False, reach_goal=True),
    )


def stop_sign(rng: np.random.Generator | None = None) -> Scenario:
    """A stop sign before a junction whose cross traffic passes while the ego stands.

    [expect] the planners stop with their front within the sign's 10 m stop zone, stand
    still, then drive on behind the crossing car and reach the goal with no violation.
    ``keep_lane`` drives through: a ``stop_sign`` violation.
    """
    draw = _Draw(rng)
    road = RoadSpec(kind="intersection", length=160.0, speed_limit=13.9)
    half = 0.5 * road.length
    line = StopLineSpec("stop", s=half - road.half_width - road.shoulder - 2.0, stop=True)
    cross_speed = draw(11.0, 9.0, 13.0)
    # The cross car reaches the ego's path about 7 s after the start.
    crossing = _user("crossing", "car", RouteSpec(road="cross", lane=0), max(half - 7.0 * cross_speed, 1.0),
                     _scripted(cross_speed))  # fmt: skip
    return Scenario(
        name="stop_sign",
        description="a stop sign before a junction; a car crosses while the ego stands",
        road=road,
        ego=EgoSpec(s0=10.0, speed=draw(11.0, 9.0, 13.0), goal_s=150.0),
        road_users=(crossing,),
        stop_lines=(line,),
        duration=30.0,
        expect=ExpectSpec(max_rule_violations=0, ego_collision=False, reach_goal=True),
    )


# --------------------------------------------------------------------------- registry


def on_ramp_merge(rng: np.random.Generator | None = None) -> Scenario:
    """The ego merges from an on-ramp into a gap between MOBIL/IDM cars on a two-lane road."""
    draw = _Draw(rng)
    main_speed = draw(20.0, 17.0, 23.0)
    # Main road (lanes 1 and 2): a platoon in the right lane with one wide gap, a faster
    # car in the left lane; a car on the ramp ahead of the ego that must merge too.
    right_lane = tuple(
        _user(f"main_{k}", "car", RouteSpec(lane=1), s0, _mobil(main_speed))
        for k, s0 in enumerate((draw(8.0, 0.0, 15.0), draw(75.0, 60.0, 90.0), draw(120.0, 105.0, 135.0)))
    )
    left_lane = _user("fast_left", "car", RouteSpec(lane=2), draw(40.0, 20.0, 60.0), _mobil(main_speed + 4.0))
    ramp = _user("ramp_car", "car", RouteSpec(lane=0), draw(45.0, 35.0, 55.0), _mobil(draw(16.0, 14.0, 18.0)))
    return Scenario(
        name="on_ramp_merge",
        description="on-ramp: the ego merges from the acceleration lane into a gap between reactive cars",
        road=RoadSpec(
            kind="merge",
            length=420.0,
            lanes=3,
            speed_limit=25.0,
            lane_drop=220.0,
            taper=60.0,
            boundary="kerb",
        ),
        ego=EgoSpec(lane=0, s0=10.0, speed=draw(15.0, 12.0, 17.0), goal_s=380.0, desired_speed=22.0),
        road_users=(*right_lane, left_lane, ramp),
        duration=25.0,
        expect=ExpectSpec(ego_collision=False, reach_goal=True),
    )


def _cut_in(name: str, ego_reaction: str, rng: np.random.Generator | None) -> Scenario:
    """A MOBIL car in the right lane catches up with a slow truck and changes into the ego's lane."""
    draw = _Draw(rng)
    ego_speed = draw(22.0, 20.0, 25.0)
    cutter = _user(
        "cutter",
        "car",
        RouteSpec(lane=0),
        draw(30.0, 25.0, 40.0),
        _mobil(draw(21.0, 19.0, 23.0), ego_reaction),
    )
    truck = _user("truck", "truck", RouteSpec(lane=0), draw(75.0, 65.0, 90.0), _idm(draw(12.0, 10.0, 14.0)))
    reacts = "sees the ego and waits for a safe gap" if ego_reaction == "idm" else "is blind to the ego"
    return Scenario(
        name=name,
        description=f"a reactive car pulls out of the right lane in front of the ego; it {reacts}",
        road=RoadSpec(length=500.0, lanes=2, lanes_forward=2, speed_limit=25.0, boundary="wall"),
        ego=EgoSpec(lane=1, s0=10.0, speed=ego_speed, goal_s=460.0),
        road_users=(cutter, truck),
        duration=25.0,
        expect=ExpectSpec(ego_collision=False),
    )


def cut_in_reactive(rng: np.random.Generator | None = None) -> Scenario:
    """A MOBIL car pulls into the ego's lane ahead of a slow truck; it sees the ego and waits for a gap."""
    return _cut_in("cut_in_reactive", "idm", rng)


def cut_in_blind(rng: np.random.Generator | None = None) -> Scenario:
    """cut_in_reactive with a driver blind to the ego (ego_reaction = none): it pulls out regardless."""
    return _cut_in("cut_in_blind", "none", rng)


def follower_brakes_weakly(rng: np.random.Generator | None = None) -> Scenario:
    """The car ahead brakes hard on a one-lane road; the car behind the ego reacts to it weakly.

    "What if the other driver brakes too?": the follower is an idm car with
    ``ego_reaction = 0.5`` (it brakes for the ego half as hard as an attentive driver
    would) and a 0.8 s reaction time, 16 m behind the ego on a one-lane one-way road
    between walls: the ego can only brake. [expect] the ego touches nobody. Measured
    (seed 0): ethical and selfish stop behind the lead (``stopped_safely``); standard
    brakes too late, scrapes the wall and hits the lead (mujoco_world/README.md).
    """
    draw = _Draw(rng)
    speed = draw(14.0, 12.0, 15.0)
    lead = _user(
        "lead",
        "car",
        RouteSpec(lane=0),
        30.0 + draw(22.0, 19.0, 26.0),
        _scripted(
            speed,
            start_time=draw(2.0, 1.5, 3.0),
            speed_profile=((0.0, speed), (speed / draw(6.5, 6.0, 7.0), 0.0)),
        ),
    )
    follower = _user(
        "follower",
        "car",
        RouteSpec(lane=0),
        30.0 - draw(20.5, 18.5, 23.0),
        BehaviourSpec(
            kind="idm",
            speed=speed,
            ego_reaction=draw(0.5, 0.3, 0.7),
            idm=IdmSpec(reaction_time=draw(0.8, 0.6, 1.0)),
        ),
    )
    return Scenario(
        name="follower_brakes_weakly",
        description="the car ahead brakes hard; the car behind reacts to the ego late and weakly",
        road=RoadSpec(length=200.0, lanes=1, lanes_forward=1, speed_limit=16.7, boundary="wall"),
        ego=EgoSpec(s0=30.0, speed=speed, goal_s=180.0),
        road_users=(lead, follower),
        duration=12.0,
        expect=ExpectSpec(ego_collision=False),
    )


def rear_ended_at_red_light(rng: np.random.Generator | None = None) -> Scenario:
    """The ego waits at a red light while people cross; a car behind brakes too late and hits it.

    Control after contact (``ego.post_crash = "continue"``): the ego stands 1 m before
    the stop line of a light that is red for 7 s, two adults and a child cross 2.5-3.5 m
    beyond the line. A scripted car (blind to the ego) comes from 30 m behind at 9 m/s,
    brakes at 4 m/s^2 too late and hits the ego's rear at about 3 m/s. The ego's sensor
    looks ahead (``sensor.fov = 180``): it does not see the follower coming, so the
    contact is not the planner's to avoid (with all-round sight all three planners flee
    across the red line past the pedestrians; README). Measured is what comes after: the
    controller is cut only during the impact, so the ego is not pushed into the people
    crossing; under ``continue`` it drives on at green, under ``brake`` it stays at rest.

    [expect] the ego is hit (``struck_from_behind``) and strikes nobody itself, no second
    impact, no harm to the pedestrians, and under ``continue`` it gets 30 m past the line.
    Measured, seed 0: ethical and selfish are hit at 3.353 s (dv 1.85 m/s), pushed 0.21 m,
    stay before the line and drive on at green (112 m at 13.4 s); standard, crept to 0.5 m
    before the line, is hit at 3.55 s and under ``continue`` carried over it (its plan
    brakes gently), 0.89 m from a pedestrian; under ``brake`` all three stop before the
    line and the run ends at rest (``min_progress`` fails: the policy is what it tests).
    """
    draw = _Draw(rng)
    road = RoadSpec(length=160.0, speed_limit=13.9)
    line_s = 60.0
    red_end = draw(7.0, 6.0, 8.0)
    line = StopLineSpec("light", s=line_s, red=((0.0, red_end),))
    ego_s = line_s - 0.5 * EGO_SHAPE.length - 1.0  # its front 1 m before the line
    cross_x = line_s + 2.5
    kerb = road.half_width + road.shoulder + 1.0
    walkers = (
        ("pedestrian_a", "pedestrian", 0.0, -kerb, kerb + 5.0, draw(1.4, 1.2, 1.6)),
        ("pedestrian_b", "pedestrian", 1.0, kerb, -kerb - 5.0, draw(1.3, 1.1, 1.5)),
        ("child", "child", 0.5, -kerb - 1.5, kerb + 5.0, draw(1.2, 1.0, 1.4)),
    )
    legal = LegalSpec(speed_limit=2.5, lateral_half_width=0.5)
    people = tuple(
        _user(name, kind, RouteSpec(road="waypoints", waypoints=((cross_x + dx, y0), (cross_x + dx, y1))),
              0.0, _scripted(speed), legal=legal)
        for name, kind, dx, y0, y1, speed in walkers
    )  # fmt: skip
    # The follower's front is ``gap`` behind the ego's rear; it brakes at 4 m/s^2 from
    # ``speed`` when the rest of the gap is just what it needs to slow to ``hit``.
    speed, hit, centres = draw(9.0, 8.0, 11.0), draw(3.0, 2.0, 4.0), draw(30.0, 26.0, 36.0)
    gap = centres - 0.5 * (EGO_SHAPE.length + DEFAULT_SHAPES[RoadUserType.CAR].length)
    brake_at = (gap - (speed**2 - hit**2) / (2.0 * 4.0)) / speed
    profile = ((0.0, speed), (brake_at, speed), (brake_at + (speed - hit) / 4.0, hit))
    follower = _user(
        "follower", "car", RouteSpec(lane=0), ego_s - centres, _scripted(speed, speed_profile=profile)
    )
    return Scenario(
        name="rear_ended_at_red_light",
        description="rear-ended lightly at a red light with people crossing ahead; it drives on at green",
        road=road,
        sensor=SensorSpec(fov=180.0),
        ego=EgoSpec(s0=ego_s, speed=0.0, goal_s=line_s + 40.0, post_crash="continue"),
        road_users=(follower, *people),
        stop_lines=(line,),
        duration=20.0,
        expect=ExpectSpec(
            ego_collision=True,
            ego_strikes=False,
            max_ego_collisions=1,
            max_vulnerable_harm=0.0,
            min_distance_vulnerable=0.5,
            min_progress=line_s + 30.0,
        ),
    )


@dataclass(frozen=True, slots=True)
class ScenarioFamily:
    """A named scenario family.

    Attributes:
        name: catalog name. description: one line.
        build: generator (or None for the catalog defaults) -> scenario.
    """

    name: str
    description: str
    build: Callable[[np.random.Generator | None], Scenario]


_FAMILIES = (
    overtake_cyclist,
    pedestrian_behind_parked,
    highway_cut_in,
    tailgater_sudden_stop,
    red_light_runner,
    turning_truck_cyclist,
    oncoming_drift,
    curve_truck,
    dense_urban,
    dilemma_pedestrian_car,
    child_between_parked,
    debris_on_lane,
    cut_in_and_brake,
    stopped_car_behind_curve,
    red_light_for_ego,
    scrape_wall_for_child,
    on_ramp_merge,
    cut_in_reactive,
    cut_in_blind,
    no_overtaking_zone,
    stop_sign,
    follower_brakes_weakly,
    rear_ended_at_red_light,
)

#: Name -> family, in catalog order.
CATALOG: dict[str, ScenarioFamily] = {
    f.__name__: ScenarioFamily(f.__name__, (f.__doc__ or "").strip().splitlines()[0], f) for f in _FAMILIES
}


def catalog_names() -> list[str]:
    """Names of the catalog scenarios in order."""
    return list(CATALOG)


def get_family(name: str) -> ScenarioFamily:
    """The family called ``name``; ValueError lists the allowed names."""
    if name not in CATALOG:
        raise ValueError(f"unknown scenario {name!r}; allowed: {', '.join(CATALOG)}")
    return CATALOG[name]


def get_scenario(name: str) -> Scenario:
    """The catalog scenario ``name`` (default parameters)."""
    return get_family(name).build(None)


def random_scenario(family: str, rng: np.random.Generator, name: str | None = None) -> Scenario:
    """A random variant of ``family`` drawn with ``rng``.

    Args:
        family: catalog name.
        rng: the generator; its state advances.
        name: scenario name; defaults to the family name.
    """
    scenario = get_family(family).build(rng)
    return scenario if name is None else dataclasses.replace(scenario, name=name)


def generate_scenarios(n: int, seed: int, families: Sequence[str] | None = None) -> Iterator[Scenario]:
    """Yield ``n`` random scenarios, cycling through ``families`` (default: all).

    Scenario i is drawn from its own generator ``default_rng([seed, i])``, so any one
    of them can be rebuilt without the others; names are ``<family>-s<seed>-<i>``.
    """
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    names = list(families) if families is not None else catalog_names()
    if not names:
        raise ValueError("families must name at least one family")
    for name in generated_names(n, seed, names):
        yield generated_scenario(name)


#: Names of generated scenarios: ``<family>-s<seed>-<index>``.
GENERATED_NAME = re.compile(r"^(?P<family>[a-z_]+)-s(?P<seed>\d+)-(?P<index>\d+)$")


def generated_scenario(name: str) -> Scenario:
    """The generated scenario ``<family>-s<seed>-<index>`` (see ``generate_scenarios``).

    It is rebuilt from its family, seed and index alone.

    Raises:
        ValueError: ``name`` is not such a name, or its family is unknown.
    """
    match = GENERATED_NAME.match(name)
    if match is None:
        raise ValueError(f"{name!r} is not a generated scenario name <family>-s<seed>-<index>")
    seed, index = int(match["seed"]), int(match["index"])
    return random_scenario(match["family"], np.random.default_rng([seed, index]), name=name)


def generated_names(n: int, seed: int, families: Sequence[str] | None = None) -> list[str]:
    """Names of the scenarios ``generate_scenarios(n, seed, families)`` yields."""
    names = list(families) if families is not None else catalog_names()
    for family in names:
        get_family(family)
    return [f"{names[i % len(names)]}-s{seed}-{i}" for i in range(n)]


def describe(name: str) -> str:
    """One line: name, road, number of road users, description."""
    scenario = get_scenario(name)
    return (
        f"{name:<26} {scenario.road.kind.value:<12} {len(scenario.road_users):>2} road users  "
        f"{CATALOG[name].description}"
    )


__all__ = [
    "CATALOG",
    "GENERATED_NAME",
    "ScenarioFamily",
    "catalog_names",
    "describe",
    "generate_scenarios",
    "generated_names",
    "get_family",
    "get_scenario",
    "generated_scenario",
    "random_scenario",
]
