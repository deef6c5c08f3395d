"""Validation and calibration of the harm model against simulated impacts."""
