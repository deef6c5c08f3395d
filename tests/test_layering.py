"""Each layer imports nothing above it (STYLE: one-way layers).

Rerun is imported by one module only (``mujoco_world.recording``); the CLI modules and
the optional frenetix peer are left out, since they are the places that attach extras.
"""

import subprocess
import sys

import pytest

FORBIDDEN = {
    "ethical_planner": ["mujoco", "rerun", "mujoco_world", "harm_calibration", "frenetix"],
    "mujoco_world": ["rerun", "harm_calibration"],
}


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_pulls_in_nothing_above_it(package):
    code = (
        "import sys, importlib, pkgutil\n"
        f"pkg = importlib.import_module('{package}')\n"
        "for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):\n"
        "    if not m.name.endswith(('cli', 'cli_recording', 'recording', 'peer_frenetix')):\n"
        "        importlib.import_module(m.name)\n"
        f"bad = [n for n in {FORBIDDEN[package]!r} if n in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"{package} imports {out.stdout.strip()}"
