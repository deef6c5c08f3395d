"""The ``[expect]`` table of a scenario, checked against a finished run.

Each item of ``ExpectSpec`` is one entry of ``EXPECTATIONS``: how it is measured from
the run's ``RunSummary`` and what passes. ``check_expectations`` returns one
``ExpectationResult`` per item the scenario gives; ``RunSummary.verdict`` is ``pass``
when all are met, ``fail`` otherwise (``none`` without expectations). A run that
failed (``outcome = failed``) fails every item except an ``outcome`` that lists
``failed``: its numbers were not measured to the end.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ethical_planner.registry import Registry
from mujoco_world.evaluation.compare import ego_strikes
from mujoco_world.loop.summary import ExpectationResult, RunSummary
from mujoco_world.scenario.spec import ExpectSpec


@dataclass(frozen=True, slots=True)
class Expectation:
    """How one ``[expect]`` item is checked.

    Attributes:
        measure: the run's value of the item.
        compare: ``==`` (equal), ``<=`` (at most the expected value), ``>=`` (at
            least), ``in`` (one of the expected values).
        description: one line for the documentation.
    """

    measure: Callable[[RunSummary], Any]
    compare: str
    description: str


#: Every ``[expect]`` item by its key in the table.
EXPECTATIONS: Registry[Expectation] = Registry("expectation")


def _harm(group: str) -> Callable[[RunSummary], float]:
    return lambda s: float(s.harm.get(group, 0.0))


for _name, _item in {
    "outcome": Expectation(lambda s: s.outcome, "in", "the run's outcome is one of these"),
    "reach_goal": Expectation(lambda s: s.outcome == "goal", "==", "the ego reaches its goal"),
    "ego_collision": Expectation(lambda s: s.ego_collided, "==", "the ego takes part in a collision"),
    "ego_strikes": Expectation(
        lambda s: any(ego_strikes(c) for c in s.ego_collisions),
        "==",
        "the ego drives into a body itself (a fixed one, or a road user approaching the contact no faster)",
    ),
    "collision": Expectation(lambda s: bool(s.collisions), "==", "any collision happens"),
    "max_collisions": Expectation(lambda s: len(s.collisions), "<=", "measured collisions, at most"),
    "max_ego_collisions": Expectation(
        lambda s: len(s.ego_collisions), "<=", "measured collisions of the ego, at most"
    ),
    "max_ego_harm": Expectation(_harm("ego"), "<=", "measured harm of the ego, at most"),
    "max_third_party_harm": Expectation(
        _harm("third_party"), "<=", "measured harm of third parties (summed), at most"
    ),
    "max_vulnerable_harm": Expectation(
        _harm("vulnerable"), "<=", "measured harm of vulnerable road users (summed), at most"
    ),
    "min_distance": Expectation(lambda s: s.min_distance, ">=", "ego-to-road-user distance [m], at least"),
    "min_distance_vulnerable": Expectation(
        lambda s: s.min_distance_vulnerable, ">=", "ego-to-vulnerable distance [m], at least"
    ),
    "min_ttc": Expectation(lambda s: s.min_ttc, ">=", "ego time-to-collision [s], at least"),
    "min_progress": Expectation(lambda s: s.progress, ">=", "ego arc length along its route [m], at least"),
    "max_rule_violations": Expectation(
        lambda s: len(s.rule_violations),
        "<=",
        "ego traffic-rule violations, at most",
    ),
}.items():
    EXPECTATIONS.register(_name, _item)


def _text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, tuple):
        return " or ".join(str(v) for v in value)
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _passes(compare: str, measured: Any, expected: Any) -> bool:
    if compare == "in":
        return measured in expected
    if compare == "==":
        return measured == expected
    if isinstance(measured, float) and math.isnan(measured):
        return compare == ">="  # nothing to measure (no road user): a lower bound holds
    return measured <= expected if compare == "<=" else measured >= expected


def check_expectations(expect: ExpectSpec | None, summary: RunSummary) -> tuple[ExpectationResult, ...]:
    """Check every item ``expect`` gives against the run ``summary``.

    Args:
        expect: the scenario's expectations (None: nothing expected).
        summary: the finished run.

    Returns:
        One result per given item, in the order of ``ExpectSpec``'s fields.
    """
    if expect is None:
        return ()
    out = []
    failed_run = summary.outcome == "failed"
    for name in EXPECTATIONS.names():
        expected = getattr(expect, name)
        if expected is None or expected == ():
            continue
        item = EXPECTATIONS.get(name)
        measured = item.measure(summary)
        passed = _passes(item.compare, measured, expected)
        if failed_run and name != "outcome":
            passed = False
        prefix = "" if item.compare in ("==", "in") else f"{item.compare} "
        out.append(ExpectationResult(name, prefix + _text(expected), _text(measured), bool(passed)))
    return tuple(out)
