"""The extension example of mujoco_world/README.md runs as written and does what it says."""

import re
from pathlib import Path

import pytest

from mujoco_world.agents import EGO_PLANNERS
from mujoco_world.scenario.sources import SCENARIO_SOURCES, resolve_scenario

README = Path(__file__).resolve().parents[3] / "mujoco_world" / "README.md"


def test_the_readme_extension_example_runs(monkeypatch, capsys):
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Extension points") :]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    for registry in (SCENARIO_SOURCES, EGO_PLANNERS):  # the registrations are undone after the test
        monkeypatch.setattr(registry, "_entries", dict(registry._entries))
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)  # noqa: S102 - our own README
    summary = namespace["summary"]
    # the new source: the catalog's scenario, 5 s long; an unknown name lists it
    assert summary.scenario == "overtake_cyclist"
    with pytest.raises(ValueError, match="; first5:<catalog name>"):
        resolve_scenario("warp_drive")
    # the registered planner by name: 13 m/s, braking at 6 m/s^2 from t = 1 s, stops at
    # t = 1 + 13 / 6 = 3.17 s; the new rule ends the run 0.5 s later, the new metric saw 13 m/s
    assert summary.planner == "brake_at_1s"
    assert summary.outcome == "timeout" and summary.reason.startswith("the ego stood still from t = ")
    stopped = float(summary.reason.split("= ")[1].split(" s")[0])
    assert stopped == pytest.approx(1.0 + 13.0 / 6.0, abs=0.1)
    assert summary.duration == pytest.approx(stopped + 0.5, abs=0.011)
    assert summary.extra_metrics["top_speed"] == pytest.approx(13.0, abs=0.05)
    assert capsys.readouterr().out.startswith("timeout the ego stood still")
