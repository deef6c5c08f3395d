"""What a study runs: catalog names, scenario files, folders and globs, expanded to references."""

from __future__ import annotations

import glob
from collections.abc import Sequence
from pathlib import Path

from mujoco_world.scenario.sources import SCENARIO_SOURCES

#: File suffixes a folder contributes (CommonRoad files may end in ``.cr.xml``).
SCENARIO_SUFFIXES = (".xml", ".toml")
_GLOB_CHARS = set("*?[")


def _accepted(reference: str) -> bool:
    return any(SCENARIO_SOURCES.get(name).accepts(reference) for name in SCENARIO_SOURCES)


def expand_scenarios(items: Sequence[str]) -> list[str]:
    """Scenario references of a study, in a stable order, each once.

    Args:
        items: catalog or generated names, ``*.toml`` and ``*.xml`` files (``FILE.xml#ID``
            names a planning problem), folders (every ``*.xml`` and ``*.toml`` below,
            recursively, sorted) and globs (``logs/**/*.xml``).

    Returns:
        References a scenario source accepts: names as given, files as resolved paths.

    Raises:
        ValueError: an item that names nothing (a missing file, an empty folder or glob,
            an unknown name), naming the item and what is allowed.
    """
    out: list[str] = []
    for item in items:
        found = _expand(item)
        out += found
    seen: set[str] = set()
    unique = []
    for ref in out:
        if ref not in seen:
            seen.add(ref)
            unique.append(ref)
    if not unique:
        raise ValueError("no scenarios given")
    return unique


def _expand(item: str) -> list[str]:
    if _GLOB_CHARS & set(item):
        matches = sorted(glob.glob(item, recursive=True))
        files = [m for m in matches if _is_scenario_file(Path(m))]
        dirs = [m for m in matches if Path(m).is_dir()]
        found = [str(Path(f).resolve()) for f in files] + [r for d in dirs for r in _folder(Path(d))]
        if not found:
            raise ValueError(f"scenario glob {item!r} matches no *.xml or *.toml file")
        return found
    path = Path(item.split("#", 1)[0])
    if path.is_dir():
        found = _folder(path)
        if not found:
            raise ValueError(f"scenario folder {item!r} holds no *.xml or *.toml file")
        return found
    if path.suffix.lower() in SCENARIO_SUFFIXES:
        if not path.is_file():
            raise ValueError(f"scenario file {item!r} does not exist")
        suffix = item[len(str(path)) :] if item.startswith(str(path)) else ""
        return [str(path.resolve()) + suffix]
    if not _accepted(item):
        allowed = "; ".join(SCENARIO_SOURCES.get(n).describe() for n in SCENARIO_SOURCES)
        raise ValueError(f"unknown scenario {item!r}; allowed: {allowed}; a folder; a glob")
    return [item]


def _is_scenario_file(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() in SCENARIO_SUFFIXES


def _folder(folder: Path) -> list[str]:
    files = [
        p
        for p in folder.rglob("*")
        if _is_scenario_file(p) and not any(part.startswith(".") for part in p.relative_to(folder).parts)
    ]
    return [str(p.resolve()) for p in sorted(files)]


__all__ = ["SCENARIO_SUFFIXES", "expand_scenarios"]
