"""Physics.

The MuJoCo scene of planar body proxies (``scene``), impact measurement from
contact forces (``impact``), the force controllers that drive bodies (``control``) and the
constant-velocity time to collision of two rectangles (``safety``), which both
scripted road users and the loop's metrics read.
"""
