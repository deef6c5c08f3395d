"""``python -m harm_calibration.cli``: the same as the ``etp`` command."""

import sys

from harm_calibration.cli import main

sys.exit(main())
