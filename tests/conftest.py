"""Test-suite settings shared by every test module."""

from hypothesis import settings

# Hypothesis' default 200 ms deadline per example is a timed assertion: on a loaded
# machine it fails correct code (seen at 260-313 ms under load). Timing belongs in
# benchmarks/, never in tests.
settings.register_profile("no_deadline", deadline=None)
settings.load_profile("no_deadline")
