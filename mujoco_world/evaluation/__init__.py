"""Evaluation.

A measured impact held against the harm model's prediction (``compare``).
"""
