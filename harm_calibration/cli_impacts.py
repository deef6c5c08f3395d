"""Subcommands of the ``harm_calibration`` layer (impact sweeps, calibration)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add this layer's subcommands to ``etp``."""
