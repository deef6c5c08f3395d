"""Scenario sources: how a name on the command line becomes a ``Scenario``.

Each source is one object registered in ``SCENARIO_SOURCES``; ``resolve_scenario``
asks them in registration order and the first that accepts the reference loads it.
Built in: scenario files (``*.toml``), CommonRoad files (``*.xml``, imported by
``scenario/commonroad.py``), generated names (``dense_urban-s3-17``) and the catalog
(``dense_urban``). A new source is one module with a class like these, registered at
import, plus its import at the end of this file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from ethical_planner.registry import Registry
from mujoco_world.scenario.catalog import CATALOG, GENERATED_NAME, generated_scenario, get_scenario
from mujoco_world.scenario.spec import Scenario, load_scenario


class ScenarioSource(Protocol):
    """Turns references it accepts into scenarios."""

    def accepts(self, reference: str) -> bool:
        """True if this source reads ``reference`` (it may still fail to load it)."""
        ...

    def load(self, reference: str) -> Scenario:
        """The scenario ``reference`` names.

        Raises:
            ValueError: it cannot be loaded; the message names the reference and why.
        """
        ...

    def describe(self) -> str:
        """What references this source accepts, for error messages and help."""
        ...


#: Scenario sources, asked in registration order.
SCENARIO_SOURCES: Registry[ScenarioSource] = Registry("scenario source")


class _TomlFileSource:
    """A scenario file in TOML (``mujoco_world/data/example_scenario.toml``)."""

    def accepts(self, reference: str) -> bool:
        return Path(reference).suffix.lower() == ".toml"

    def load(self, reference: str) -> Scenario:
        return load_scenario(reference)

    def describe(self) -> str:
        return "a scenario file *.toml"


class _GeneratedSource:
    """A random variant of a catalog family: ``<family>-s<seed>-<index>``."""

    def accepts(self, reference: str) -> bool:
        return GENERATED_NAME.match(reference) is not None

    def load(self, reference: str) -> Scenario:
        return generated_scenario(reference)

    def describe(self) -> str:
        return "a generated name <family>-s<seed>-<index> such as dense_urban-s3-17"


class _CatalogSource:
    """A built-in catalog scenario with its default parameters."""

    def accepts(self, reference: str) -> bool:
        return reference in CATALOG

    def load(self, reference: str) -> Scenario:
        return get_scenario(reference)

    def describe(self) -> str:
        return f"a catalog name ({', '.join(CATALOG)})"


class _CommonRoadSource:
    """A CommonRoad scenario file ``*.xml``, optionally ``FILE.xml#PLANNING_PROBLEM_ID``."""

    def accepts(self, reference: str) -> bool:
        from mujoco_world.scenario.commonroad import is_commonroad_reference

        return is_commonroad_reference(reference)

    def load(self, reference: str) -> Scenario:
        from mujoco_world.scenario.commonroad import load_commonroad

        return load_commonroad(reference)

    def describe(self) -> str:
        return "a CommonRoad file *.xml (or FILE.xml#PLANNING_PROBLEM_ID)"


SCENARIO_SOURCES.register("toml", _TomlFileSource())
SCENARIO_SOURCES.register("commonroad", _CommonRoadSource())
SCENARIO_SOURCES.register("generated", _GeneratedSource())
SCENARIO_SOURCES.register("catalog", _CatalogSource())


def resolve_scenario(reference: str) -> Scenario:
    """The scenario named by ``reference``: the first source that accepts it loads it.

    Raises:
        ValueError: no source accepts it (the message lists what each source accepts),
            or the accepting source cannot load it.
    """
    sources = [SCENARIO_SOURCES.get(name) for name in SCENARIO_SOURCES]
    for source in sources:
        if source.accepts(reference):
            return source.load(reference)
    allowed = "; ".join(source.describe() for source in sources)
    raise ValueError(f"unknown scenario {reference!r}; allowed: {allowed}")


__all__ = [
    "SCENARIO_SOURCES",
    "ScenarioSource",
    "resolve_scenario",
]
