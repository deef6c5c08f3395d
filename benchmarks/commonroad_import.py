"""Import every CommonRoad file below a folder and build its MuJoCo world; count what runs.

For each ``*.xml`` (sorted): ``import_commonroad`` then ``World(scenario)``; one JSON line
per file (status ok / rejected / error, the rejection reason, recorded duration, road
users, seconds). Resumes: files already in OUT are skipped. At the end a summary by
status and reason.

Run: python benchmarks/commonroad_import.py ../shared/commonroad logs/import_check.jsonl
"""

from __future__ import annotations

import collections
import json
import sys
import time
from pathlib import Path

from mujoco_world.loop.world import World
from mujoco_world.scenario.commonroad import CommonRoadImportError, import_commonroad


def check_file(path: Path) -> dict:
    """Import one file and build its world."""
    start = time.perf_counter()
    row: dict = {}
    try:
        scenario = import_commonroad(path)
        World(scenario)
        row.update(status="ok", duration=scenario.duration, users=len(scenario.road_users))
    except CommonRoadImportError as error:
        row.update(status="rejected", reason=error.reason, message=str(error)[-200:])
    except Exception as error:  # noqa: BLE001 - an importer bug: reported, the loop goes on
        row.update(status="error", error=f"{type(error).__name__}: {error}"[:400])
    row["seconds"] = round(time.perf_counter() - start, 2)
    return row


def main(root: str, out: str) -> None:
    """Check every file below ``root`` into the JSON lines file ``out`` and print a summary."""
    base, target = Path(root), Path(out)
    done = set()
    if target.exists():
        done = {json.loads(line)["file"] for line in target.read_text().splitlines() if line.strip()}
    with target.open("a") as handle:
        for path in sorted(base.rglob("*.xml")):
            name = str(path.relative_to(base))
            if name not in done:
                handle.write(json.dumps({"file": name, **check_file(path)}) + "\n")
                handle.flush()
    rows = [json.loads(line) for line in target.read_text().splitlines() if line.strip()]
    counts = collections.Counter((r["status"], r.get("reason", "")) for r in rows)
    for (status, reason), n in sorted(counts.items()):
        print(f"{status:<9} {reason:<20} {n:>4}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
