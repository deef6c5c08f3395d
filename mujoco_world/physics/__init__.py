"""Physics.

The MuJoCo scene of planar body proxies (``scene``), impact measurement from
contact forces (``impact``) and the force controllers that drive bodies (``control``).
"""
