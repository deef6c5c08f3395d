"""Subcommands of the ``ethical_planner`` layer: ``harm``, ``bench``, ``plan``."""

from __future__ import annotations

import argparse

from . import harm_cli


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add this layer's subcommands to ``etp``."""
    harm_cli.register(subparsers)
