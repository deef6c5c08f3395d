"""Closed-loop MuJoCo world in which the ethical planner drives an ego body."""
