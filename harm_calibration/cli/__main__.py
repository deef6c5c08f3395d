"""``python -m harm_calibration.cli``: the same as the ``etp`` command."""

import sys

from harm_calibration.cli import main

if __name__ == "__main__":
    sys.exit(main())
