"""Benchmarks and peer timings (application layer): each module prints a table.

``planning_cycle`` (``etp bench``) times our full ethical cycle beside frenetix's
(``peer_frenetix``); ``world_speed``, ``recording_overhead`` and
``collision_probability`` time the world, the recorder and the kernel alone.
"""
