"""Small scenarios for command-line tests (a few simulated seconds each)."""

import pytest

#: Two cars meet head-on in the oncoming lane at t ~ 1.8 s while the ego drives by.
HEAD_ON = """
name = "{name}"
duration = {duration}
[road]
length = 300.0
[ego]
s0 = 10.0
speed = 10.0
[[road_users]]
name = "east"
type = "car"
s0 = 100.0
route = {{ lane = 1, wrong_way = true }}
behaviour = {{ kind = "scripted", speed = 10.0 }}
[[road_users]]
name = "west"
type = "car"
s0 = 160.0
route = {{ lane = 0, direction = -1 }}
behaviour = {{ kind = "scripted", speed = 10.0 }}
"""

#: The ego closes on a slower car in its lane (planned risk, no crash in 2 s).
FOLLOW = """
name = "{name}"
duration = {duration}
[road]
length = 300.0
lanes = 1
[ego]
s0 = 10.0
speed = 14.0
[[road_users]]
name = "slow"
type = "car"
s0 = 32.0
behaviour = {{ kind = "scripted", speed = 3.0 }}
"""


def write_scenario(folder, template=HEAD_ON, name="short", duration=2.0):
    """Write a scenario TOML into ``folder`` and return its path as a string."""
    path = folder / f"{name}.toml"
    path.write_text(template.format(name=name, duration=duration), encoding="utf-8")
    return str(path)


@pytest.fixture
def short_scenario(tmp_path):
    """A 2 s head-on scenario file (no ego collision)."""
    return write_scenario(tmp_path)
