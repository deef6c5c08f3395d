"""Route tables: bodies on the same route share one row; lookups equal those of a table per body."""

import numpy as np

from mujoco_world.agents.behaviour import RouteTable
from mujoco_world.loop.world import World
from mujoco_world.scenario.spec import scenario_from_dict


def _lane(y: float, length: float = 400.0) -> np.ndarray:
    return np.column_stack([np.linspace(0.0, length, 9), np.full(9, y)])


def test_bodies_on_one_route_share_a_row_and_look_up_the_same_poses():
    polylines = [_lane(0.0), _lane(3.5), _lane(0.0), _lane(3.5), _lane(0.0, 200.0)]
    table = RouteTable(polylines)
    assert table.x.shape[0] == 3  # three distinct routes for five bodies
    assert table.paths[0] is table.paths[2] and table.paths[1] is table.paths[3]
    s = np.array([[5.0, 120.5], [399.0, 0.0], [17.25, 80.0], [3.0, 3.0], [150.0, 250.0]])
    rows = np.arange(5)[:, None].repeat(2, axis=1)
    together = table.lookup(rows, s)
    for body, polyline in enumerate(polylines):
        alone = RouteTable([polyline]).lookup(np.zeros(2, dtype=int), s[body])
        for a, b in zip(together, alone, strict=True):
            np.testing.assert_allclose(a[body], b, atol=1e-12)


def test_a_crowded_scenario_builds_one_route_per_lane():
    # 400 cars in 8 lanes used to smooth 400 paths (seconds, gigabytes at 2000); now 8.
    users = [
        {"name": f"u{i}", "type": "car", "s0": 40.0 + 8.0 * (i // 8), "route": {"lane": i % 8},
         "behaviour": {"kind": "scripted", "speed": 10.0}}
        for i in range(400)
    ]  # fmt: skip
    road = {"length": 600.0, "lanes": 8, "lanes_forward": 8}
    scenario = scenario_from_dict({"name": "crowd", "duration": 1.0, "road": road, "road_users": users})
    world = World(scenario)
    routes = world.fleet.routes
    assert routes.x.shape[0] == 8
    x, y, _, _ = routes.lookup(np.array([0, 8, 16]), np.array([40.0, 48.0, 56.0]))
    np.testing.assert_allclose(y, y[0])  # one lane, one lateral position
