"""Planar contact geometry of the force modes against hand cases and shapely."""

import math

import numpy as np
import pytest
import shapely
from shapely import affinity

from ethical_planner.road_users import KinematicState
from mujoco_world.physics.collide2d import STATIC, Box2D, Collider, disc_disc, rect_disc, rect_rect
from mujoco_world.physics.impact import measure_impact

CAR = (2.254, 0.805)
BUS = (6.0, 1.25)


def test_face_to_face_gives_two_points_at_the_overlap_ends():
    # b 4.4 m ahead of a, both heading +x: faces overlap by 0.108 m along x.
    rows = rect_rect((0, 0), 0.0, CAR, (4.4, 0.3), 0.0, CAR, 0.1)
    assert len(rows) == 2
    for dist, px, _, nx, ny in rows:
        assert dist == pytest.approx(4.4 - 2 * CAR[0])
        assert (nx, ny) == pytest.approx((1.0, 0.0))
        assert px == pytest.approx(2.2, abs=1e-12)
    # clipped to a's face: y from 0.3 - 0.805 to a's edge at 0.805
    assert sorted(r[2] for r in rows) == pytest.approx([0.3 - 0.805, 0.805])


def test_corner_into_face_is_one_point_with_the_corners_depth():
    # b turned 45 deg; its corner (-l, +w) lies at (-(l + w), -(l - w)) / sqrt(2) from its
    # centre: placed 2 cm into the middle of a's front face.
    r = math.sqrt(0.5)
    centre = (CAR[0] - 0.02 + (CAR[0] + CAR[1]) * r, (CAR[0] - CAR[1]) * r)
    rows = rect_rect((0, 0), 0.0, CAR, centre, math.pi / 4, CAR, 0.1)
    assert len(rows) == 1
    dist, px, py, nx, ny = rows[0]
    assert dist == pytest.approx(-0.02)
    assert (nx, ny) == pytest.approx((1.0, 0.0))
    assert (px, py) == pytest.approx((CAR[0] - 0.01, 0.0), abs=1e-12)  # midway between the surfaces


def test_separated_beyond_margin_is_nothing_and_within_it_is_reported():
    assert rect_rect((0, 0), 0.0, CAR, (4.7, 0.0), 0.0, CAR, 0.1) == []
    rows = rect_rect((0, 0), 0.0, CAR, (4.55, 0.0), 0.0, CAR, 0.1)
    assert [r[0] for r in rows] == pytest.approx([4.55 - 2 * CAR[0]] * 2)


def _poly(centre, yaw, half):
    box = shapely.geometry.box(-half[0], -half[1], half[0], half[1])
    return affinity.translate(affinity.rotate(box, yaw, use_radians=True, origin=(0, 0)), *centre)


def _mtd(pa, pb_centre, yaw, half, directions=720):
    """Brute-force penetration depth: the shortest translation of b that separates it."""
    best = math.inf
    for th in np.linspace(0, 2 * math.pi, directions, endpoint=False):
        u = np.array([math.cos(th), math.sin(th)])
        lo, hi = 0.0, 2.0
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            if _poly(tuple(np.array(pb_centre) + mid * u), yaw, half).intersects(pa):
                lo = mid
            else:
                hi = mid
        best = min(best, hi)
    return best


@pytest.mark.parametrize("seed", range(4))
def test_penetration_is_the_minimum_translation_distance(seed):
    """The deepest point's depth is the exact penetration depth (MuJoCo's box-box collider
    reports centimetres more in some of these configurations)."""
    rng = np.random.default_rng(seed)
    pa = _poly((0, 0), 0.0, CAR)
    yaw, ang = rng.uniform(-math.pi, math.pi), rng.uniform(0, 2 * math.pi)
    u = np.array([math.cos(ang), math.sin(ang)])
    lo, hi = 0.0, 20.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _poly(tuple(mid * u), yaw, BUS).intersects(pa) else (lo, mid)
    centre = tuple((lo - rng.uniform(0.01, 0.2)) * u)
    rows = rect_rect((0, 0), 0.0, CAR, centre, yaw, BUS, 0.1)
    assert -min(r[0] for r in rows) == pytest.approx(_mtd(pa, centre, yaw, BUS), abs=2e-3)


def test_disc_cases():
    # disc 0.3 m radius 0.2 m into a's side face
    ((dist, px, py, nx, ny),) = rect_disc((0, 0), 0.0, CAR, (0.0, CAR[1] + 0.1), 0.3, 0.1)
    assert (dist, nx, ny) == pytest.approx((-0.2, 0.0, 1.0))
    assert (px, py) == pytest.approx((0.0, CAR[1] - 0.1))
    # outside a corner: distance to the corner
    ((dist, *_),) = rect_disc((0, 0), 0.0, CAR, (CAR[0] + 0.3, CAR[1] + 0.4), 0.3, 1.0)
    assert dist == pytest.approx(0.5 - 0.3)
    ((dist, _, _, nx, ny),) = disc_disc((0, 0), 0.3, (0.5, 0.0), 0.3, 0.1)
    assert (dist, nx, ny) == pytest.approx((-0.1, 1.0, 0.0))


def test_collider_filters_kerbs_and_orders_pairs():
    kerb = Box2D(0.0, 1.7, 0.0, 10.0, 0.1, kerb=True)
    collider = Collider([CAR, (0.3, 0.3)], [False, True], [True, False], [kerb])
    # car and pedestrian both over the kerb, the pedestrian touching the car's side
    qpos = np.array([[0.0, 1.0, 0.0], [1.0, 2.0, 0.0]])
    found = collider.contacts(qpos)
    pairs = set(zip(found.a.tolist(), found.b.tolist(), strict=True))
    assert pairs == {(0, 1), (0, STATIC)}  # the pedestrian does not touch the kerb
    assert np.all(found.dist < 0)
    assert found.static[found.b == STATIC].tolist() == [0] * int(np.sum(found.b == STATIC))


def test_a_car_into_a_bus_side_at_30_mps_keeps_restitution():
    """The configuration MuJoCo's box-box collider missed until 3.6 cm deep (e = 2.6 then)."""
    from harm_calibration.geometry import Footprint, launch_geometry, speeds_for_closing

    alpha = math.radians(135.0)
    sa, sb = speeds_for_closing(30.0, alpha, 15.0)
    launch = launch_geometry(
        Footprint(*(2 * h for h in CAR)), Footprint(*(2 * h for h in BUS)), sa, sb, alpha, 0.25
    )
    m = measure_impact(
        "car",
        KinematicState(0, 0, 0, sa),
        "bus",
        KinematicState(*launch.position_b, launch.yaw_b, sb),
        shape_a=(2 * CAR[0], 2 * CAR[1]),
        shape_b=(2 * BUS[0], 2 * BUS[1]),
    )
    assert 0.09 < m.restitution < 0.12
    assert m.max_penetration < 0.02
