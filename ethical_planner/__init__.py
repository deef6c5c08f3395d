"""Ethical trajectory planning after Geisslinger et al. (Nature Machine Intelligence 2023)."""
