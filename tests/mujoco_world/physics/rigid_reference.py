"""Independent 2-D rigid-body impact computation, the reference of the named-case tests.

Written without MuJoCo and without ``ethical_planner.impulse``: bodies are rectangles or
discs with 3 planar degrees of freedom; every corner of one rectangle inside the other
(or a disc overlapping a rectangle) is a contact point with a stiff hysteretic normal
spring (loading stiffness k, unloading k / e^2, so a one-point impact returns e^2 of its
energy, i.e. restitution e) or a Hunt-Crossley spring-damper (F = k x (1 + lambda x'),
lambda solved here for restitution e at the corner's closing speed), and regularised
Coulomb friction. It is integrated with
symplectic Euler at a 2 us step until the bodies have been apart for 1 ms (the first
impulse); as k grows this tends to the rigid-body impact, and a flat contact distributes
its force between the corners by itself.
"""

import math

import numpy as np
from scipy.optimize import brentq


def hunt_crossley_lambda(e: float, speed: float) -> float:
    """lambda [s/m] with restitution e at closing speed: u - ln(1 + u) = -w - ln(1 - w), w = e u."""
    if speed <= 0:
        return 0.0
    u = brentq(lambda u: u - math.log1p(u) + e * u + math.log1p(-e * u), 1e-9, (1 - 1e-12) / e)
    return u / speed


class Body:
    def __init__(self, mass, length, width, x, y, yaw, vx, vy, omega=0.0, disc=False):
        self.m = float(mass)
        self.hl, self.hw = 0.5 * length, 0.5 * width
        self.disc = disc
        self.r = 0.5 * min(length, width)
        self.inertia = 0.5 * mass * self.r**2 if disc else mass * (length**2 + width**2) / 12.0
        self.p = np.array([x, y], float)
        self.yaw = float(yaw)
        self.v = np.array([vx, vy], float)
        self.w = float(omega)

    def corners(self):
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        local = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * [self.hl, self.hw]
        return self.p + local @ np.array([[c, s], [-s, c]])

    def to_local(self, q):
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        d = q - self.p
        return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])

    def to_world_dir(self, d):
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])

    def point_velocity(self, q):
        r = q - self.p
        return self.v + self.w * np.array([-r[1], r[0]])


def _inside_rect(body, q):
    """Penetration depth and outward normal (world) of a point q inside rectangle body, or None."""
    loc = body.to_local(q)
    dx, dy = body.hl - abs(loc[0]), body.hw - abs(loc[1])
    if dx <= 0 or dy <= 0:
        return None
    if dx < dy:
        return dx, body.to_world_dir(np.array([math.copysign(1.0, loc[0]), 0.0]))
    return dy, body.to_world_dir(np.array([0.0, math.copysign(1.0, loc[1])]))


def contacts(a, b):
    """List of (key, point, normal from a to b, depth)."""
    out = []
    if not a.disc and not b.disc:
        for i, q in enumerate(a.corners()):
            hit = _inside_rect(b, q)
            if hit:
                depth, n_out_b = hit
                out.append((("a", i), q, -n_out_b, depth))
        for i, q in enumerate(b.corners()):
            hit = _inside_rect(a, q)
            if hit:
                depth, n_out_a = hit
                out.append((("b", i), q, n_out_a, depth))
        return out
    rect, disc, sign = (a, b, 1.0) if b.disc else (b, a, -1.0)
    loc = rect.to_local(disc.p)
    clamped = np.clip(loc, [-rect.hl, -rect.hw], [rect.hl, rect.hw])
    d = loc - clamped
    dist = float(np.hypot(*d))
    if dist > 0:
        if dist >= disc.r:
            return out
        n_local = d / dist
        depth = disc.r - dist
    else:  # centre inside the rectangle
        dx, dy = rect.hl - abs(loc[0]), rect.hw - abs(loc[1])
        n_local = (
            np.array([math.copysign(1, loc[0]), 0.0])
            if dx < dy
            else np.array([0.0, math.copysign(1, loc[1])])
        )
        depth = disc.r + min(dx, dy)
    n = rect.to_world_dir(n_local)  # from rect to disc
    point = disc.p - n * disc.r
    out.append((("d", 0), point, sign * n, depth))
    return out


def collide(
    a, b, e_of_speed, mu, k=8e8, dt=2e-6, t_max=0.05, v_eps=0.02, law="hysteretic", apart=0.001, dt_free=None
):
    """Integrate until the bodies have separated; return the total impulse on b.

    Args:
        e_of_speed: restitution as a function of the normal closing speed at first touch.
        mu: Coulomb friction coefficient.
        apart: time without contact that ends the integration [s] (0.001: the first
            impulse; longer: later hits of the free bodies join, the whole sequence).
        dt_free: step while no point touches [s] (default ``dt``).
    """
    state = {}
    impulse_b = np.zeros(2)
    t = 0.0
    touched = False
    quiet = 0.0
    step = dt
    while t < t_max:
        fa, fb = np.zeros(2), np.zeros(2)
        ta = tb = 0.0
        active = contacts(a, b)
        keys = set()
        for key, q, n, depth in active:
            keys.add(key)
            u = b.point_velocity(q) - a.point_velocity(q)
            un = float(u @ n)
            if key not in state:
                e = float(e_of_speed(max(-un, 0.0)))
                state[key] = {"dmax": 0.0, "e": e, "lam": hunt_crossley_lambda(e, max(-un, 0.0))}
            st = state[key]
            if law == "hunt_crossley":
                fn = max(0.0, k * depth * (1.0 - st["lam"] * un))
            elif depth >= st["dmax"]:
                st["dmax"] = depth
                fn = k * depth
            else:
                dp = st["dmax"] * (1.0 - max(st["e"], 1e-3) ** 2)
                fn = max(0.0, k * st["dmax"] * (depth - dp) / (st["dmax"] - dp))
            tang = u - un * n
            speed_t = float(np.hypot(*tang))
            ft = -mu * fn * math.tanh(speed_t / v_eps) * (tang / speed_t) if speed_t > 0 else np.zeros(2)
            f = fn * n + ft  # on b
            fb += f
            fa -= f
            rb, ra = q - b.p, q - a.p
            tb += rb[0] * f[1] - rb[1] * f[0]
            ta -= ra[0] * f[1] - ra[1] * f[0]
        for key in list(state):
            if key not in keys:
                del state[key]
        step = dt if active or dt_free is None else dt_free
        if active:
            touched = True
            quiet = 0.0
        elif touched:
            quiet += step
            if quiet > apart:
                break  # apart long enough: the first impulse (or the sequence) is over
        impulse_b += fb * step
        for body, f, tq in ((a, fa, ta), (b, fb, tb)):
            body.v = body.v + f / body.m * step
            body.w = body.w + tq / body.inertia * step
            body.p = body.p + body.v * step
            body.yaw += body.w * step
        t += step
    return impulse_b
