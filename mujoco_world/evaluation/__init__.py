"""Evaluation: a measured impact held against the harm model's prediction (``compare``)."""
