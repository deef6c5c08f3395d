"""Agents.

The behaviours of the other road users (scripted, car following, crossing
pedestrians, rule violators).
"""
