"""Planning-cycle benchmark (same as ``etp bench``): prints a table, optionally JSON.

python benchmarks/planning_cycle.py [--repetitions 20] [--json out.json]
"""

import sys

from harm_calibration.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
