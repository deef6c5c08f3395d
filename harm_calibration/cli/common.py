"""What every ``etp`` command shares: output folders, JSON output, progress, planner configs.

* ``--out``: ``output_dir`` creates the folder and writes a probe file into it before
  any simulation, so a read-only, full or misnamed folder fails at once (exit 2).
* ``--json``: ``print_json`` prints one JSON document to stdout instead of the
  human-readable text (non-finite numbers become null); messages go to stderr.
* progress bars: ``show_progress`` is false with ``--no-progress`` or when stderr is
  not a terminal.
* ``--config FILE.toml``: ``planner_configs`` turns preset names and a planner TOML
  into the configurations that ``etp run`` and ``etp demo`` run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ethical_planner.validation import check

#: Bytes written by the probe of an output folder (a full disk fails here, not after a run).
PROBE_BYTES = 64 * 1024


def output_dir(path: str | Path, option: str = "--out") -> Path:
    """Create ``path`` if needed and check that files can be written into it.

    Args:
        path: the output folder.
        option: the command-line option that named it (for messages).

    Returns:
        The folder.

    Raises:
        ValueError: ``path`` is a file, cannot be created, or cannot take a file of
            ``PROBE_BYTES`` (read-only, full disk); the message names ``option``.
    """
    folder = Path(path)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{option} {folder} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ValueError(f"{option} {folder}: cannot create the folder: {error.strerror}") from None
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".etp-probe-") as probe:
            probe.write(b"\0" * PROBE_BYTES)
            probe.flush()
            os.fsync(probe.fileno())
    except OSError as error:
        raise ValueError(f"{option} {folder} is not writable: {error.strerror}") from None
    return folder


def output_file(path: str | Path, option: str) -> Path:
    """Check that ``path`` can be written (its folder is created and probed).

    Raises:
        ValueError: ``path`` is a folder or its folder is not writable.
    """
    file = Path(path)
    if file.is_dir():
        raise ValueError(f"{option} {file} is a folder, not a file")
    output_dir(file.parent, option)
    return file


def _plain(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return _plain(value.tolist())
    return value


def print_json(data: Any) -> None:
    """Print ``data`` as one JSON document on stdout (non-finite numbers as null)."""
    print(json.dumps(_plain(data), indent=2, allow_nan=False))


def say(args: argparse.Namespace, message: str) -> None:
    """Print a human-readable message: stdout normally, stderr under ``--json``."""
    print(message, file=sys.stderr if getattr(args, "json", False) else sys.stdout)


def show_progress(args: argparse.Namespace) -> bool:
    """True unless ``--no-progress`` was given or stderr is not a terminal."""
    return not getattr(args, "no_progress", False) and sys.stderr.isatty()


def split_items(text: str, what: str) -> list[str]:
    """Comma-separated items of option ``what``, each once.

    Raises:
        ValueError: no item, or an item given twice (named).
    """
    items = [item.strip() for item in text.split(",") if item.strip()]
    check(bool(items), f"{what} must name at least one item")
    twice = sorted({item for item in items if items.count(item) > 1})
    check(not twice, f"{what} lists {', '.join(twice)} more than once")
    return items


def non_negative(value: int, option: str) -> None:
    """Raise a ValueError naming ``option`` unless ``value`` >= 0."""
    check(value >= 0, f"{option} must be an integer >= 0, got {value}")


def parse_seeds(text: str, option: str = "--seeds") -> list[int]:
    """Comma-separated run seeds, each an integer >= 0, each once."""
    try:
        seeds = [int(s) for s in split_items(text, option)]
    except ValueError as error:
        if "more than once" in str(error) or "at least one" in str(error):
            raise
        raise ValueError(f"{option} must be comma-separated integers, got {text!r}") from None
    for seed in seeds:
        non_negative(seed, option)
    return seeds


def add_json(parser: argparse.ArgumentParser) -> None:
    """The ``--json`` flag, with the same meaning on every command."""
    parser.add_argument(
        "--json", action="store_true", help="print the result as JSON on stdout instead of text"
    )


def add_config(parser: argparse.ArgumentParser) -> None:
    """The ``--config FILE.toml`` option of the commands that run planners."""
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        metavar="FILE.toml",
        help="planner TOML: overrides applied on top of each planner preset (see the README)",
    )


def planner_configs(names: Sequence[str], config: Path | None) -> list:
    """Planner configurations for preset ``names`` with the overrides of ``config`` applied.

    Without ``config`` the presets themselves, and the other registered planners
    (``mujoco_world.agents.EGO_PLANNERS``: the scripted manoeuvres) by name. With it,
    each preset gets the file's
    overrides and is named ``<preset>+<file stem>`` unless the file sets ``name`` (a
    file's ``preset`` key is allowed when one planner is asked for and chooses it).

    Raises:
        ValueError: an unknown preset, or a config file that cannot be read or holds
            an invalid value; the message names the file and the key.
    """
    import dataclasses

    from ethical_planner.config import PRESETS, load_config, preset
    from ethical_planner.records import read_toml
    from mujoco_world.agents import EGO_PLANNERS

    for name in names:
        EGO_PLANNERS.get(name)  # an unknown name lists every planner
    if config is None:
        return [preset(name) if name in PRESETS else name for name in names]
    scripted = [name for name in names if name not in PRESETS]
    if scripted:
        raise ValueError(f"--config {config} applies to planner presets, not to {', '.join(scripted)}")
    keys = read_toml(config, "planner configuration")
    if "preset" in keys and len(names) > 1:
        raise ValueError(
            f"--config {config}: the key 'preset' chooses one planner, but {len(names)} are asked "
            "for (--planners); remove the key to apply the file to each of them"
        )
    configs = []
    for name in names:
        loaded = load_config(config, base=name)
        if "name" not in keys:
            loaded = dataclasses.replace(loaded, name=f"{loaded.name}+{Path(config).stem}")
        _check_planner_name(loaded.name, config)
        configs.append(loaded)
    return configs


def _check_planner_name(name: str, config: Path) -> None:
    """A planner name becomes part of run folders: letters, digits and _ - + . only."""
    if not name or not all(c.isalnum() or c in "_-+." for c in name):
        raise ValueError(
            f"--config {config}: name must consist of letters, digits and _ - + . (it names run "
            f"folders), got {name!r}"
        )
