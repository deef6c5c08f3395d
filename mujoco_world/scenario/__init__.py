"""Scenario specification.

Frozen scenario records and TOML loading (``spec``), road
geometry built from a spec (``road``), the built-in catalog and its random variants
(``catalog``), and the validation helpers of these records (``fields``).
"""
