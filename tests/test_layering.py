"""Each layer imports nothing above it (STYLE: one-way layers), checked for every module.

Layers, bottom to top: ``ethical_planner`` (algorithm) < ``mujoco_world`` (world) <
``harm_calibration`` (validation, and the application shell in ``harm_calibration.cli``)
< ``benchmarks`` (timing scripts and the frenetix peer). Two checks:

* static: every ``import`` statement of every module, including those inside functions,
  is read from the source and held against the layer table;
* dynamic: importing every module of a package in a fresh interpreter pulls in nothing
  above it (catches imports hidden behind ``importlib``).

Rerun is imported by one module only, ``mujoco_world.storage.recording``.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ethical_planner", "mujoco_world", "harm_calibration", "benchmarks")
#: What each package may not import (project packages above it, and foreign extras).
FORBIDDEN = {
    "ethical_planner": {"mujoco", "rerun", "mujoco_world", "harm_calibration", "benchmarks", "frenetix"},
    "mujoco_world": {"rerun", "harm_calibration", "benchmarks", "frenetix"},
    "harm_calibration": {"rerun", "benchmarks", "frenetix"},
    "benchmarks": {"rerun"},
}
#: Modules allowed to import a name their package otherwise may not.
EXCEPTIONS = {
    "rerun": {"mujoco_world.storage.recording"},
    "frenetix": {"benchmarks.peer_frenetix"},
    # ``etp bench`` runs the planning-cycle benchmark; the rest of harm_calibration stays below it.
    "benchmarks": {"harm_calibration.cli.bench"},
}
#: Inside ``harm_calibration``, only the application shell may import the shell.
APPLICATION = "harm_calibration.cli"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> list[tuple[str, Path]]:
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            found.append((_module_name(path), path))
    return found


def _imports(module: str, path: Path) -> list[tuple[int, str]]:
    """Every imported module name (absolute) with its line, functions included."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_package = path.name == "__init__.py"
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            out.append((node.lineno, name))
    return out


def _violations(module: str, path: Path) -> list[str]:
    package = module.split(".")[0]
    bad = []
    for line, name in _imports(module, path):
        top = name.split(".")[0]
        allowed = module in EXCEPTIONS.get(top, set())
        if top in FORBIDDEN[package] and not allowed:
            bad.append(f"{module}:{line} imports {name}")
        if (
            package == "harm_calibration"
            and not module.startswith(APPLICATION)
            and (name == APPLICATION or name.startswith(APPLICATION + "."))
        ):
            bad.append(f"{module}:{line} imports the application shell {name}")
    return bad


def test_every_module_is_checked():
    names = [m for m, _ in _modules()]
    # The shell, the world's loop and storage, and the benchmarks are all covered.
    for expected in ("harm_calibration.cli", "mujoco_world.loop.runner", "benchmarks.peer_frenetix"):
        assert expected in names


@pytest.mark.parametrize(("module", "path"), _modules(), ids=[m for m, _ in _modules()])
def test_module_imports_nothing_above_its_layer(module, path):
    assert _violations(module, path) == []


def test_the_static_check_sees_imports_inside_functions(tmp_path):
    fake = tmp_path / "mod.py"
    fake.write_text("def f():\n    from harm_calibration.cli import main\n    return main\n")
    assert _violations("mujoco_world.fake", fake) == ["mujoco_world.fake:2 imports harm_calibration.cli"]
    fake.write_text("def f():\n    from ...harm_calibration import rows\n")
    assert _violations("mujoco_world.loop.fake", fake)  # relative imports resolve too
    fake.write_text("def f():\n    from benchmarks.planning_cycle import run_benchmark\n")
    assert _violations("harm_calibration.calibration", fake) == [
        "harm_calibration.calibration:2 imports benchmarks.planning_cycle"
    ]
    assert _violations("harm_calibration.cli.bench", fake) == []  # the one module that may


@pytest.mark.parametrize("package", ["ethical_planner", "mujoco_world", "harm_calibration"])
def test_importing_every_module_pulls_in_nothing_above(package):
    forbidden = sorted(FORBIDDEN[package] - {"frenetix"})
    exempt = sorted(set().union(*EXCEPTIONS.values()))
    code = (
        "import sys, importlib, pkgutil\n"
        f"pkg = importlib.import_module('{package}')\n"
        "for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):\n"
        f"    if m.name not in {exempt!r}:\n"
        "        importlib.import_module(m.name)\n"
        f"bad = [n for n in {forbidden!r} if n in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "", f"{package} imports {out.stdout.strip()}"


#: The world's concern groups, bottom to top: each imports only groups before it.
WORLD_GROUPS = ("scenario", "physics", "agents", "evaluation", "loop", "storage", "experiments")


def test_world_groups_cover_every_subpackage():
    found = {p.name for p in (ROOT / "mujoco_world").iterdir() if (p / "__init__.py").is_file()}
    assert found - {"data"} == set(WORLD_GROUPS)


#: Every module of a world group, the group's ``__init__`` included.
_GROUPED = [(m, p) for m, p in _modules() if m.split(".")[0] == "mujoco_world" and m.count(".") >= 1]


@pytest.mark.parametrize(("module", "path"), _GROUPED, ids=[m for m, _ in _GROUPED])
def test_world_groups_import_only_groups_below(module, path):
    rank = {group: k for k, group in enumerate(WORLD_GROUPS)}
    own = rank[module.split(".")[1]]
    above = [
        f"{module}:{line} imports {name}"
        for line, name in _imports(module, path)
        if name.startswith("mujoco_world.") and rank.get(name.split(".")[1], -1) > own
    ]
    assert above == []
