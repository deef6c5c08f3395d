"""Planar impulse-momentum delta-v of a collision (Brach; Ishikawa), closed form.

Paper Eq. 1 is the perfectly plastic, common-velocity result: both bodies end with one
velocity, sideways too, and nothing rotates. Crash reconstruction instead treats an
impact as one instantaneous impulse at a contact point (R. M. Brach, *Mechanical Impact
Dynamics*, 1991; H. Ishikawa, SAE 931654, 1993):

1. **Contact.** The two footprints are moved back along their relative velocity to the
   moment they first touch (``contact_geometry``): the states of a prediction step
   (0.1 s) overlap by up to 2 m at 20 m/s, and the face of least penetration of such an
   overlap is often the wrong one. The face entered gives the normal; the touching
   features give the contact, a point (a corner on a face) or a segment (two parallel
   faces). Vehicles are rectangles; pedestrians (``round``) discs of diameter
   min(length, width). An approach that would miss under constant velocities (the
   prediction is uncertain) is shifted sideways onto the nearest grazing line.
2. **Effective mass.** With lever arms r_a, r_b from the centres to the contact point,
   masses m and yaw inertias I (rectangle m (l^2 + w^2) / 12, disc m r^2 / 2), an
   impulse P on b (-P on a) changes the relative velocity of the contact points by K P,
   in the normal / tangent basis (n, t)

       K_nn = 1/m_a + 1/m_b + r_at^2/I_a + r_bt^2/I_b,
       K_tt = 1/m_a + 1/m_b + r_an^2/I_a + r_bn^2/I_b,
       K_nt = -(r_an r_at / I_a + r_bn r_bt / I_b).

3. **Impulse.** The normal relative velocity at the contact point reverses with
   restitution e (``RestitutionLaw`` of the normal closing speed); tangentially the
   contact points reach a common velocity (full stick), P = K^-1 (-(1 + e) u_n, -u_t).
   If that needs a tangential impulse above ``friction`` times the normal one (Brach's
   impulse ratio), the bodies slide: P_t = +-friction P_n, with P_n from the normal
   condition. ``friction = inf`` is full stick.
4. **Flat contacts.** Two parallel faces touch along a segment. The impulse acts at the
   end of the segment where, with the whole impulse there, the other end separates at
   least as fast (a T-bone at a car's rear axle: the end nearer the struck car's centre;
   as the car spins, the far end swings away). If neither end qualifies (symmetric
   cases such as an offset head-on of equal cars), both ends share the normal impulse
   (both reaching the restitution velocity) and the impulse acts at their
   impulse-weighted mean. A rigid simulation (``mujoco_world`` rigid mode) concentrates
   the force the same way.
5. **Delta-v.** dv_a = |P| / m_a, dv_b = |P| / m_b (centre-of-mass velocity changes).

A central collinear impact gives Eq. 1 times (1 + e). Pre-impact yaw rates are taken as
zero, as in Eq. 1. Everything is vectorised over any broadcast shape, e.g. the planner's
(candidate, road user, step) triples; nothing is fitted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numpy.typing import ArrayLike

from ethical_planner.validation import parse_enum


class DeltaVModel(StrEnum):
    """How the planner predicts a collision's delta-v (``[risk] delta_v_model``)."""

    EQ1 = "eq1"  # paper Eq. 1: perfectly plastic, common velocity
    PLANAR_IMPULSE = "planar_impulse"  # this module: impulse at the first contact

    @classmethod
    def parse(cls, value: str | DeltaVModel) -> DeltaVModel:
        """Return the model named by ``value`` or raise a ValueError listing the allowed names."""
        return parse_enum(cls, value, "delta-v model")


#: Relative speed below which two bodies do not approach [m/s].
MIN_RELATIVE_SPEED = 1e-9
#: |cos| below which a direction counts as parallel to a rectangle's face.
_PARALLEL = 1e-6
#: Contact segments shorter than this are points [m].
_POINT = 1e-6


@dataclass(frozen=True, slots=True)
class RestitutionLaw:
    """Coefficient of restitution against the normal closing speed.

    e(v) = e_high + (e_low - e_high) exp(-v / speed_scale): about e_high at medium and
    high speed, rising towards e_low for gentle contacts (car-to-car tests: ~0.1 above
    ~10 m/s, 0.2-0.4 below ~2 m/s of delta-v). ``e_low == e_high`` is a constant.

    Attributes:
        e_high: restitution at high closing speed, in [0, 1].
        e_low: restitution as the closing speed goes to 0, in [0, 1].
        speed_scale: closing speed over which e falls from e_low towards e_high [m/s], > 0.
    """

    e_high: float = 0.1
    e_low: float = 0.4
    speed_scale: float = 4.0

    def __post_init__(self) -> None:
        for name in ("e_high", "e_low", "speed_scale"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"restitution_law.{name} must be a finite number, got {value!r}")
        for name in ("e_high", "e_low"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"restitution_law.{name} must lie in [0, 1], got {getattr(self, name)}")
        if self.speed_scale <= 0:
            raise ValueError(f"restitution_law.speed_scale must be > 0 m/s, got {self.speed_scale}")

    @classmethod
    def constant(cls, e: float) -> RestitutionLaw:
        """A speed-independent restitution ``e``."""
        return cls(e_high=e, e_low=e)

    def __call__(self, closing_speed: ArrayLike) -> np.ndarray:
        """Restitution at normal closing speeds [m/s] (any shape; the sign is ignored)."""
        v = np.abs(np.asarray(closing_speed, dtype=float))
        return self.e_high + (self.e_low - self.e_high) * np.exp(-v / self.speed_scale)


@dataclass(frozen=True, slots=True, eq=False)
class ContactGeometry:
    """Where two footprints first touch (arrays of one broadcast shape S).

    Attributes:
        point: middle of the contact, relative to a's centre [m], shape S + (2,).
        normal: unit contact normal from a to b, shape S + (2,).
        half_length: half-length of the contact segment along the tangent (-n_y, n_x)
            [m], shape S (0 for a point).
        offset_b: b's centre relative to a's centre at first touch [m], shape S + (2,).
        approaching: False where the relative speed is below ``MIN_RELATIVE_SPEED``, shape S.
        grazing: the approach line missed and was shifted onto the nearest grazing line, shape S.
    """

    point: np.ndarray
    normal: np.ndarray
    half_length: np.ndarray
    offset_b: np.ndarray
    approaching: np.ndarray
    grazing: np.ndarray


@dataclass(frozen=True, slots=True, eq=False)
class PlanarImpulse:
    """Result of the planar impulse model (arrays of one broadcast shape S).

    Attributes:
        dv_a, dv_b: |delta-v| of a and b [m/s], shape S.
        impulse: impulse on b (minus the one on a) [N s], world frame, shape S + (2,).
        point: where it acts, relative to a's centre [m], shape S + (2,).
        restitution: e used, shape S.
        closing_speed: normal closing speed at the contact [m/s], shape S.
        impulse_ratio: |P_t| / P_n, shape S (nan where P_n = 0).
        sliding: the friction limit was reached, shape S.
        geometry: the contact.
    """

    dv_a: np.ndarray
    dv_b: np.ndarray
    impulse: np.ndarray
    point: np.ndarray
    restitution: np.ndarray
    closing_speed: np.ndarray
    impulse_ratio: np.ndarray
    sliding: np.ndarray
    geometry: ContactGeometry


def yaw_inertia(
    mass: ArrayLike, length: ArrayLike, width: ArrayLike, round_: ArrayLike = False
) -> np.ndarray:
    """Yaw inertia [kg m^2]: m (l^2 + w^2) / 12 for a rectangle, m r^2 / 2 for a disc (r = min(l, w) / 2)."""
    m, length, width = (np.asarray(x, dtype=float) for x in (mass, length, width))
    radius = 0.5 * np.minimum(length, width)
    return np.where(
        np.asarray(round_, dtype=bool), 0.5 * m * radius * radius, m * (length**2 + width**2) / 12.0
    )


def _support_size(c, s, hl, hw, dx, dy):
    """Support h(d) = hl |d.u| + hw |d.v| of a centred rectangle with axes u=(c,s), v=(-s,c).

    ``geometry.rectangle_half_extent`` with the trigonometry hoisted out of the loop over
    the octagon's eight faces (this runs on every planner triple).
    """
    return hl * np.abs(c * dx + s * dy) + hw * np.abs(c * dy - s * dx)


def _support_feature(c, s, hl, hw, dx, dy, tx, ty):
    """Support feature of a centred rectangle in direction d: centre (x, y) and half-length along t."""
    du = c * dx + s * dy
    dv = c * dy - s * dx
    su = np.where(np.abs(du) < _PARALLEL, 0.0, np.sign(du))
    sv = np.where(np.abs(dv) < _PARALLEL, 0.0, np.sign(dv))
    x = hl * su * c - hw * sv * s
    y = hl * su * s + hw * sv * c
    half = hl * (su == 0) * np.abs(c * tx + s * ty) + hw * (sv == 0) * np.abs(c * ty - s * tx)
    return x, y, half


def _rect_rect(ca, sa, hla, hwa, cb, sb, hlb, hwb, rx, ry, ux, uy):
    """First touch of two rectangles: point, normal, half-length, b's offset (tuples of arrays)."""
    # The octagon has the face normals +-u_a, +-v_a, +-u_b, +-v_b; opposite faces share
    # their support h, a sum of the two rectangles' extents along the axis (Delta = the
    # angle between the rectangles). On each axis only the face the line enters counts,
    # normal m = sign axis with sign = -sign(axis . u): lambda = (sign axis . r - h) / |axis . u|.
    cd = np.abs(ca * cb + sa * sb)  # |cos(yaw_b - yaw_a)|
    sd = np.abs(ca * sb - sa * cb)  # |sin(yaw_b - yaw_a)|
    axes = (
        (ca, sa, hla + hlb * cd + hwb * sd),
        (-sa, ca, hwa + hlb * sd + hwb * cd),
        (cb, sb, hlb + hla * cd + hwa * sd),
        (-sb, cb, hwb + hla * sd + hwa * cd),
    )
    lams, nxs, nys = [], [], []
    for axis_x, axis_y, h in axes:
        au = axis_x * ux + axis_y * uy
        sign = -np.sign(au)
        along = np.abs(au)
        safe = np.where(along > 1e-12, along, 1.0)
        lam = np.where(along > 1e-12, (sign * (axis_x * rx + axis_y * ry) - h) / safe, -np.inf)
        lams.append(lam)
        nxs.append(sign * axis_x)
        nys.append(sign * axis_y)
    entry = np.argmax(np.stack(lams), axis=0)[None]
    lam_in = np.take_along_axis(np.stack(lams), entry, 0)[0]
    nx_in = np.take_along_axis(np.stack(np.broadcast_arrays(*nxs)), entry, 0)[0]
    ny_in = np.take_along_axis(np.stack(np.broadcast_arrays(*nys)), entry, 0)[0]
    cx, cy = rx + lam_in * ux, ry + lam_in * uy
    tx, ty = -ny_in, nx_in
    ax_, ay_, a_half = _support_feature(ca, sa, hla, hwa, nx_in, ny_in, tx, ty)
    bx_, by_, b_half = _support_feature(cb, sb, hlb, hwb, -nx_in, -ny_in, tx, ty)
    a_t, b_t = ax_ * tx + ay_ * ty, (bx_ + cx) * tx + (by_ + cy) * ty
    lo = np.maximum(a_t - a_half, b_t - b_half)
    hi = np.minimum(a_t + a_half, b_t + b_half)
    mid = 0.5 * (lo + hi)
    along_n = ax_ * nx_in + ay_ * ny_in
    px, py = along_n * nx_in + mid * tx, along_n * ny_in + mid * ty
    return px, py, nx_in, ny_in, np.maximum(0.5 * (hi - lo), 0.0), cx, cy


def _rect_disc(c, s, hl, hw, rho, rx, ry, ux, uy):
    """First touch of a rectangle (at the origin) and a disc of radius rho centred at r + lambda u."""
    # In the rectangle's frame.
    qx, qy = c * rx + s * ry, -s * rx + c * ry
    dx, dy = c * ux + s * uy, -s * ux + c * uy
    ex, ey = hl + rho, hw + rho
    lam_in = np.full(qx.shape, -np.inf)
    face_x = np.zeros(qx.shape, dtype=bool)
    for q, d, e, is_x in ((qx, dx, ex, True), (qy, dy, ey, False)):
        for sign in (1.0, -1.0):
            nu = sign * d
            entering = nu < -1e-12
            lam = np.where(entering, (e - sign * q) / np.where(entering, nu, -1.0), -np.inf)
            better = lam > lam_in
            lam_in = np.where(better, lam, lam_in)
            if is_x:
                face_x = np.where(better, True, face_x)
            else:
                face_x = np.where(better, False, face_x)
    hx, hy = qx + lam_in * dx, qy + lam_in * dy
    # Face region: the disc centre lies beside a face; corner region: on a corner's arc.
    in_face = np.where(face_x, np.abs(hy) <= hw, np.abs(hx) <= hl)
    kx, ky = np.sign(hx) * hl, np.sign(hy) * hw  # nearest corner
    fx, fy = qx - kx, qy - ky
    b = fx * dx + fy * dy
    disc = np.maximum(b * b - (fx * fx + fy * fy - rho * rho), 0.0)
    lam_corner = -b - np.sqrt(disc)
    lam = np.where(in_face, lam_in, lam_corner)
    ox, oy = qx + lam * dx, qy + lam * dy
    face_nx = np.where(face_x, np.sign(hx), 0.0)
    face_ny = np.where(face_x, 0.0, np.sign(hy))
    corner_nx, corner_ny = (ox - kx) / rho, (oy - ky) / rho
    nx = np.where(in_face, face_nx, corner_nx)
    ny = np.where(in_face, face_ny, corner_ny)
    norm = np.hypot(nx, ny)
    nx, ny = nx / np.where(norm > 0, norm, 1.0), ny / np.where(norm > 0, norm, 1.0)
    px, py = ox - rho * nx, oy - rho * ny
    # Back to the world frame.
    return (
        c * px - s * py, s * px + c * py, c * nx - s * ny, s * nx + c * ny,
        c * ox - s * oy, s * ox + c * oy,
    )  # fmt: skip


def contact_geometry(
    pos_a: ArrayLike,
    yaw_a: ArrayLike,
    length_a: ArrayLike,
    width_a: ArrayLike,
    vel_a: ArrayLike,
    pos_b: ArrayLike,
    yaw_b: ArrayLike,
    length_b: ArrayLike,
    width_b: ArrayLike,
    vel_b: ArrayLike,
    round_a: ArrayLike = False,
    round_b: ArrayLike = False,
) -> ContactGeometry:
    """First touch of two footprints moving at constant velocities (see the module docstring).

    Two rectangles: the entry of the approach line r + lambda w (r = b's centre minus
    a's, w = b's velocity minus a's) into the Minkowski sum of a and -b (an octagon with
    the face normals of both) is found by clipping the line against its faces; the face
    entered is the normal. With a disc, the sum is a rounded rectangle (or a disc).
    States may overlap (the first touch then lies behind).

    Args:
        pos_a: a's centre [m], shape (..., 2). yaw_a: heading [rad]. length_a, width_a: [m], > 0.
        vel_a: a's velocity [m/s], shape (..., 2).
        pos_b, yaw_b, length_b, width_b, vel_b: the same for b.
        round_a, round_b: bool, the body is a disc of diameter min(length, width).

    Returns:
        ``ContactGeometry`` of the broadcast shape.
    """
    pa, pb = np.asarray(pos_a, dtype=float), np.asarray(pos_b, dtype=float)
    va, vb = np.asarray(vel_a, dtype=float), np.asarray(vel_b, dtype=float)
    rx, ry = pb[..., 0] - pa[..., 0], pb[..., 1] - pa[..., 1]
    wx, wy = vb[..., 0] - va[..., 0], vb[..., 1] - va[..., 1]
    ya, yb = np.asarray(yaw_a, dtype=float), np.asarray(yaw_b, dtype=float)
    la, wa = np.asarray(length_a, dtype=float), np.asarray(width_a, dtype=float)
    lb, wb = np.asarray(length_b, dtype=float), np.asarray(width_b, dtype=float)
    rnd_a, rnd_b = np.asarray(round_a, dtype=bool), np.asarray(round_b, dtype=bool)
    shape = np.broadcast_shapes(
        rx.shape,
        wx.shape,
        ya.shape,
        yb.shape,
        la.shape,
        wa.shape,
        lb.shape,
        wb.shape,
        rnd_a.shape,
        rnd_b.shape,
    )
    ca, sa, cb, sb = np.cos(ya), np.sin(ya), np.cos(yb), np.sin(yb)
    rho_a, rho_b = 0.5 * np.minimum(la, wa), 0.5 * np.minimum(lb, wb)
    # A disc is a rectangle of half-extents 0 grown by its radius.
    hla, hwa = np.where(rnd_a, 0.0, 0.5 * la), np.where(rnd_a, 0.0, 0.5 * wa)
    hlb, hwb = np.where(rnd_b, 0.0, 0.5 * lb), np.where(rnd_b, 0.0, 0.5 * wb)
    grow = np.where(rnd_a, rho_a, 0.0) + np.where(rnd_b, rho_b, 0.0)
    speed = np.hypot(wx, wy)
    approaching = speed > MIN_RELATIVE_SPEED
    safe = np.where(approaching, speed, 1.0)
    # Approach direction; without relative motion, along the line of centres (or -x).
    dist = np.hypot(rx, ry)
    dsafe = np.where(dist > 0, dist, 1.0)
    ux = np.where(approaching, wx / safe, np.where(dist > 0, -rx / dsafe, -1.0))
    uy = np.where(approaching, wy / safe, np.where(dist > 0, -ry / dsafe, 0.0))
    # Shift a missing approach line sideways onto the nearest grazing line.
    qx, qy = -uy, ux
    offset = rx * qx + ry * qy
    reach = _support_size(ca, sa, hla, hwa, qx, qy) + _support_size(cb, sb, hlb, hwb, qx, qy) + grow
    excess = np.maximum(np.abs(offset) - reach * (1.0 - 1e-9), 0.0)
    grazing = excess > 0
    rx = rx - np.sign(offset) * excess * qx
    ry = ry - np.sign(offset) * excess * qy
    outputs = _rect_rect(ca, sa, hla, hwa, cb, sb, hlb, hwb, rx, ry, ux, uy)
    # Own flat writable outputs (never 0-d); discs overwrite their entries below.
    px, py, nx, ny, half, cx, cy = (_writable_flat(v, shape) for v in outputs)
    approaching, grazing = np.broadcast_to(approaching, shape), np.broadcast_to(grazing, shape)
    rnd_a, rnd_b = np.broadcast_to(rnd_a, shape), np.broadcast_to(rnd_b, shape)
    one_round = (rnd_a ^ rnd_b).reshape(-1)
    if one_round.any():
        # Put the rectangle first: a disc a is handled as b seen from a rectangle b.
        sel = np.flatnonzero(one_round)
        where = np.unravel_index(sel, shape) if shape else ()

        def at(x):  # noqa: ANN001, ANN202
            return np.broadcast_to(x, shape)[where].reshape(-1)

        flip = at(rnd_a)
        sign = np.where(flip, -1.0, 1.0)

        def pick(x_a, x_b):  # noqa: ANN001, ANN202
            return np.where(flip, at(x_b), at(x_a))

        rect = (pick(ca, cb), pick(sa, sb), pick(hla, hlb), pick(hwa, hwb))
        rho = pick(rho_b, rho_a)
        out = _rect_disc(*rect, rho, sign * at(rx), sign * at(ry), sign * at(ux), sign * at(uy))
        ppx, ppy, nnx, nny, oox, ooy = out
        # Seen from a rectangle b: the normal points from b to a; offsets and points are relative to b.
        nnx, nny = sign * nnx, sign * nny
        oox, ooy = sign * oox, sign * ooy
        ppx = np.where(flip, ppx + oox, ppx)
        ppy = np.where(flip, ppy + ooy, ppy)
        for target, value in ((px, ppx), (py, ppy), (nx, nnx), (ny, nny), (cx, oox), (cy, ooy)):
            target[sel] = value
        half[sel] = 0.0
    both_round = (rnd_a & rnd_b).reshape(-1)
    if both_round.any():
        sel = np.flatnonzero(both_round)
        where = np.unravel_index(sel, shape) if shape else ()

        def at(x):  # noqa: ANN001, ANN202
            return np.broadcast_to(x, shape)[where].reshape(-1)

        big = at(rho_a + rho_b)
        x0, y0 = at(rx), at(ry)
        dx, dy = at(ux), at(uy)
        b = x0 * dx + y0 * dy
        lam = -b - np.sqrt(np.maximum(b * b - (x0 * x0 + y0 * y0 - big * big), 0.0))
        ox, oy = x0 + lam * dx, y0 + lam * dy
        norm = np.hypot(ox, oy)
        norm = np.where(norm > 0, norm, 1.0)
        for target, value in (
            (nx, ox / norm), (ny, oy / norm), (cx, ox), (cy, oy),
            (px, at(rho_a) * ox / norm), (py, at(rho_a) * oy / norm),
        ):  # fmt: skip
            target[sel] = value
        half[sel] = 0.0
    vector = (*shape, 2)
    return ContactGeometry(
        point=np.stack([px, py], axis=-1).reshape(vector),
        normal=np.stack([nx, ny], axis=-1).reshape(vector),
        half_length=half.reshape(shape),
        offset_b=np.stack([cx, cy], axis=-1).reshape(vector),
        approaching=approaching.reshape(shape),
        grazing=grazing.reshape(shape),
    )


def _writable_flat(value: ArrayLike, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` broadcast to ``shape`` as a flat array this module may overwrite (a view if it can)."""
    array = np.asarray(value, dtype=float)
    if array.shape == shape and shape and array.flags.writeable and array.flags.c_contiguous:
        return array.reshape(-1)
    return np.array(np.broadcast_to(array, shape), dtype=float).reshape(-1)


def _impulse_at(inv_m, i_a, i_b, ra_n, ra_t, rb_n, rb_t, u_n, u_t, e, friction):
    """Normal and tangential impulse at one contact point (stick, else slide at the ratio)."""
    k_nn = inv_m + ra_t * ra_t / i_a + rb_t * rb_t / i_b
    k_tt = inv_m + ra_n * ra_n / i_a + rb_n * rb_n / i_b
    k_nt = -(ra_n * ra_t / i_a + rb_n * rb_t / i_b)
    target_n = -(1.0 + e) * np.minimum(u_n, 0.0)
    target_t = np.where(u_n < 0.0, -u_t, 0.0)
    det = k_nn * k_tt - k_nt * k_nt
    p_n = (k_tt * target_n - k_nt * target_t) / det
    p_t = (k_nn * target_t - k_nt * target_n) / det
    approaching = target_n > 0.0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # Stick is impossible where it needs more tangential impulse than friction allows,
        # or a pulling normal impulse (a fast tangential slip coupled through rotation).
        sliding = approaching & ((p_n <= 0.0) | (np.abs(p_t) > friction * p_n))
    if np.any(sliding):
        # The friction impulse opposes the slip (or, with p_n > 0, keeps the stick direction).
        direction = np.where(p_n > 0.0, np.sign(p_t), -np.sign(u_t))
        ratio = friction if math.isfinite(friction) else 0.0  # infinite friction and no stick: no P_t
        denominator = k_nn + direction * ratio * k_nt
        usable = sliding & (denominator > 1e-12 * inv_m)
        slide_n = target_n / np.where(usable, denominator, 1.0)
        p_n = np.where(usable, slide_n, p_n)
        p_t = np.where(usable, direction * ratio * slide_n, p_t)
        sliding = usable
    p_n = np.maximum(p_n, 0.0)
    p_t = np.where(p_n > 0, p_t, 0.0)
    return p_n, p_t, sliding


def planar_impulse(
    mass_a: ArrayLike,
    pos_a: ArrayLike,
    yaw_a: ArrayLike,
    length_a: ArrayLike,
    width_a: ArrayLike,
    vel_a: ArrayLike,
    mass_b: ArrayLike,
    pos_b: ArrayLike,
    yaw_b: ArrayLike,
    length_b: ArrayLike,
    width_b: ArrayLike,
    vel_b: ArrayLike,
    restitution: RestitutionLaw | None = None,
    friction: float = math.inf,
    round_a: ArrayLike = False,
    round_b: ArrayLike = False,
) -> PlanarImpulse:
    """Delta-v of both bodies from one planar impulse at their first contact.

    Args:
        mass_a: a's mass [kg], > 0, broadcastable.
        pos_a: a's centre [m], shape (..., 2). yaw_a: heading [rad].
        length_a, width_a: a's footprint [m], > 0.
        vel_a: a's velocity [m/s], shape (..., 2).
        mass_b, pos_b, yaw_b, length_b, width_b, vel_b: the same for b.
        restitution: normal restitution against the closing speed (default ``RestitutionLaw()``).
        friction: largest impulse ratio |P_t| / P_n (inf: full stick, common tangential
            velocity of the contact points).
        round_a, round_b: bool, the body is a disc (pedestrians).

    Returns:
        ``PlanarImpulse``; where the bodies do not approach, dv = 0.

    Raises:
        ValueError: a mass, length or width is not finite and > 0, or friction < 0.
    """
    law = restitution if restitution is not None else RestitutionLaw()
    if not friction >= 0:
        raise ValueError(f"friction (largest impulse ratio) must be >= 0, got {friction}")
    m_a, m_b = np.asarray(mass_a, dtype=float), np.asarray(mass_b, dtype=float)
    for name, value in (
        ("mass_a", m_a), ("mass_b", m_b), ("length_a", length_a), ("width_a", width_a),
        ("length_b", length_b), ("width_b", width_b),
    ):  # fmt: skip
        array = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(array) & (array > 0)):
            raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    geo = contact_geometry(
        pos_a, yaw_a, length_a, width_a, vel_a, pos_b, yaw_b, length_b, width_b, vel_b, round_a, round_b
    )
    nx, ny = geo.normal[..., 0], geo.normal[..., 1]
    tx, ty = -ny, nx
    mx, my = geo.point[..., 0], geo.point[..., 1]
    ox, oy = geo.offset_b[..., 0], geo.offset_b[..., 1]
    i_a = yaw_inertia(m_a, length_a, width_a, round_a)
    i_b = yaw_inertia(m_b, length_b, width_b, round_b)
    inv_m = 1.0 / m_a + 1.0 / m_b
    va, vb = np.asarray(vel_a, dtype=float), np.asarray(vel_b, dtype=float)
    ux, uy = vb[..., 0] - va[..., 0], vb[..., 1] - va[..., 1]
    u_n = ux * nx + uy * ny  # < 0 while approaching
    u_t = ux * tx + uy * ty
    closing = np.maximum(-u_n, 0.0)
    e = law(closing)
    # Lever arms in (n, t) of the middle of the contact; a segment's ends are +-half along t.
    ra_n, ra_t0 = mx * nx + my * ny, mx * tx + my * ty
    rb_n, rb_t0 = (mx - ox) * nx + (my - oy) * ny, (mx - ox) * tx + (my - oy) * ty
    half = geo.half_length
    shape = np.shape(half)
    p_n, p_t, sliding = _impulse_at(inv_m, i_a, i_b, ra_n, ra_t0, rb_n, rb_t0, u_n, u_t, e, friction)
    shift = np.zeros(shape)
    segment = (half > _POINT).reshape(-1)
    if segment.any():
        # Flat contacts only (parallel faces): where along the segment the impulse acts.
        where = np.unravel_index(np.flatnonzero(segment), shape) if shape else ()

        def at(x):  # noqa: ANN001, ANN202
            return np.broadcast_to(x, shape)[where].reshape(-1)

        args = (at(inv_m), at(i_a), at(i_b), at(ra_n))
        local = (at(ra_t0), at(rb_n), at(rb_t0))
        flow = (at(u_n), at(u_t), at(e))
        moved = _segment_shift(args, *local, at(half), *flow, friction)
        q_n, q_t, q_slide = _impulse_at(*args, local[0] + moved, local[1], local[2] + moved, *flow, friction)
        p_n, p_t, sliding = (_writable_flat(x, shape) for x in (p_n, p_t, sliding))
        shift = shift.reshape(-1)
        index = np.flatnonzero(segment)
        p_n[index], p_t[index], sliding[index], shift[index] = q_n, q_t, q_slide, moved
        p_n, p_t, shift = p_n.reshape(shape), p_t.reshape(shape), shift.reshape(shape)
        sliding = sliding.reshape(shape) > 0.5
    px, py = p_n * nx + p_t * tx, p_n * ny + p_t * ty
    magnitude = np.hypot(px, py)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(p_n > 0, np.abs(p_t) / p_n, np.nan)
    point = np.stack([mx + shift * tx, my + shift * ty], axis=-1)
    return PlanarImpulse(
        dv_a=magnitude / m_a,
        dv_b=magnitude / m_b,
        impulse=np.stack([px, py], axis=-1),
        point=point,
        restitution=e,
        closing_speed=closing,
        impulse_ratio=ratio,
        sliding=np.asarray(sliding, dtype=bool),
        geometry=geo,
    )


def _segment_shift(args, ra_t0, rb_n, rb_t0, half, u_n, u_t, e, friction):
    """Where along a contact segment the impulse acts: offset from its middle along t [m].

    An end carries the whole impulse if the other end then separates at least as fast;
    otherwise both ends share the normal impulse (both reach -e u_n) and it acts at
    their impulse-weighted mean.
    """
    inv_m, i_a, i_b, ra_n = args
    shifts = []
    for sign in (-1.0, 1.0):
        end = sign * half
        p_n, p_t, _ = _impulse_at(*args, ra_t0 + end, rb_n, rb_t0 + end, u_n, u_t, e, friction)
        # Normal velocity change at the other end (lever arms there) from this impulse.
        other = -end
        ra_i, rb_i = ra_t0 + other, rb_t0 + other
        ra_j, rb_j = ra_t0 + end, rb_t0 + end
        k_nn = inv_m + ra_i * ra_j / i_a + rb_i * rb_j / i_b
        k_nt = -(ra_i * ra_n / i_a + rb_i * rb_n / i_b)
        k_jj_nn = inv_m + ra_j * ra_j / i_a + rb_j * rb_j / i_b
        k_jj_nt = -(ra_j * ra_n / i_a + rb_j * rb_n / i_b)
        u_other = u_n + k_nn * p_n + k_nt * p_t
        u_self = u_n + k_jj_nn * p_n + k_jj_nt * p_t
        shifts.append((end, u_other >= u_self - 1e-9 * np.abs(u_n)))
    (end_lo, ok_lo), (end_hi, ok_hi) = shifts
    # Both ends: normal-only 2 x 2 system with the same target at both ends.
    ra_lo, rb_lo, ra_hi, rb_hi = ra_t0 - half, rb_t0 - half, ra_t0 + half, rb_t0 + half
    k11 = inv_m + ra_lo * ra_lo / i_a + rb_lo * rb_lo / i_b
    k22 = inv_m + ra_hi * ra_hi / i_a + rb_hi * rb_hi / i_b
    k12 = inv_m + ra_lo * ra_hi / i_a + rb_lo * rb_hi / i_b
    # P = K^-1 (1, 1) up to a common factor; weights of the two ends.
    w_lo, w_hi = np.maximum(k22 - k12, 0.0), np.maximum(k11 - k12, 0.0)
    total = w_lo + w_hi
    shared = np.where(total > 0, (w_hi - w_lo) / np.where(total > 0, total, 1.0), 0.0) * half
    pick_lo = ok_lo & ~(ok_hi & (k22 < k11))
    pick_hi = ok_hi & ~pick_lo
    return np.where(pick_lo, end_lo, np.where(pick_hi, end_hi, shared))


# --------------------------------------------------------------------------------------
# The impact sequence: later hits of the bodies the first impulse set moving and spinning.


@dataclass(frozen=True, slots=True)
class SkidModel:
    """Tyre forces on crashed bodies between impulses: both skid to rest at the friction limit.

    The world's crashed bodies brake (``mujoco_world.physics.control.brake_forces``): the
    centre of mass decelerates at min(deceleration, speed / time_constant) against its
    velocity, the yaw rate at min(yaw_deceleration, |yaw rate| / time_constant); the
    impact rig switches braking off inside a pulse and for ``delay`` (its pulse gap)
    after it.

    Attributes:
        deceleration: largest deceleration of the centre of mass [m/s^2] (mu g), >= 0.
        yaw_deceleration: largest yaw deceleration [rad/s^2], >= 0.
        time_constant: below speed / this the deceleration scales down smoothly [s], > 0.
        delay: no braking for this long after an impulse [s], >= 0.
    """

    deceleration: float = 0.9 * 9.81
    yaw_deceleration: float = 40.0
    time_constant: float = 0.05
    delay: float = 0.01

    def __post_init__(self) -> None:
        for name in ("deceleration", "yaw_deceleration", "time_constant", "delay"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"skid.{name} must be a finite number, got {value!r}")
            if value < 0 or (name == "time_constant" and value == 0):
                bound = "> 0 s" if name == "time_constant" else ">= 0"
                raise ValueError(f"skid.{name} must be {bound}, got {value}")


@dataclass(frozen=True, slots=True, eq=False)
class ImpactSequence:
    """Result of ``planar_impulse_sequence`` (arrays of one broadcast shape S; K = max_pulses).

    Impulses closer in time than ``pulse_gap`` form one *pulse* (the measurement's
    impulse); a sustained contact is a train of small impulses, one pulse.

    Attributes:
        dv_a, dv_b: |sum of the impulses| / m of a and b over the sequence [m/s], shape S.
        impulse: sum of the impulses on b (minus the one on a) [N s], world, shape S + (2,).
        n_pulses: pulses with a non-zero impulse, shape S (int).
        n_impulses: impulses, shape S (int).
        pulses: impulse on b of each pulse [N s], shape S + (K, 2) (zero after the last;
            pulses beyond K are added to the last).
        points: where each pulse's first impulse acted [m], world frame (a's centre
            starts at ``pos_a``), shape S + (K, 2).
        times: when each pulse began, after the first contact [s], shape S + (K,) (nan after the last).
        energy_before, energy_after: kinetic energy of both bodies before and after each
            pulse [J] (no tyre forces act inside a pulse), shape S + (K,) (nan after the last).
        velocity_a, velocity_b: velocities when the sequence ended [m/s], shape S + (2,).
        yaw_rate_a, yaw_rate_b: yaw rates when the sequence ended [rad/s], shape S.
        duration: first to last impulse [s], shape S.
        in_contact: the sequence reached ``max_duration`` with the bodies still
            touching, shape S.
        first: the first impulse (``planar_impulse`` of the same inputs).
    """

    dv_a: np.ndarray
    dv_b: np.ndarray
    impulse: np.ndarray
    n_pulses: np.ndarray
    n_impulses: np.ndarray
    pulses: np.ndarray
    points: np.ndarray
    times: np.ndarray
    energy_before: np.ndarray
    energy_after: np.ndarray
    velocity_a: np.ndarray
    velocity_b: np.ndarray
    yaw_rate_a: np.ndarray
    yaw_rate_b: np.ndarray
    duration: np.ndarray
    in_contact: np.ndarray
    first: PlanarImpulse


#: Overlap beyond which two footprints touch again [m].
_TOUCH_DEPTH = 1e-6
#: Bisection steps that locate a new contact inside a time step (step / 2^12).
_BISECTIONS = 12
#: Gauss-Seidel sweeps of a two-point (flat) contact.
_SWEEPS = 40


def _advance(q, v, h, brake, skid):
    """One semi-implicit Euler step of both bodies of every pair.

    Args:
        q: (n, 2, 3) x, y [m], yaw [rad] of a and b. v: (n, 2, 3) their velocities.
        h: step [s], scalar or (n,). brake: (n,) bool, tyre forces act. skid: ``SkidModel`` or None.

    Returns:
        New (q, v), shapes (n, 2, 3).
    """
    h = np.broadcast_to(np.asarray(h, dtype=float), (q.shape[0],))[:, None, None]
    if skid is None or not np.any(brake):
        v_new = v
    else:
        speed = np.hypot(v[..., 0], v[..., 1])
        decel = np.minimum(skid.deceleration, speed / skid.time_constant)
        on = brake[:, None]
        scale = np.where(on, decel / np.maximum(speed, 1e-9), 0.0)
        spin = np.clip(v[..., 2] / skid.time_constant, -skid.yaw_deceleration, skid.yaw_deceleration)
        acc = np.stack([-scale * v[..., 0], -scale * v[..., 1], np.where(on, -spin, 0.0)], axis=-1)
        v_new = v + h * acc
    return q + h * v_new, v_new


def _contact(q, hl, hw, rnd, rho):
    """Overlap of the footprints of each pair: depth, contact feature and normal.

    Rectangles: the separating-axis test over the four face normals; the depth is the
    smallest overlap of the projections, its axis the normal (from a to b). Just after
    first touch that is the axis that separated the bodies until then. The contact is
    the overlap of the two support features along it: a corner, or a segment of two
    parallel faces (its middle and half-length). A disc: its overlap with the rectangle
    or the other disc.

    Args:
        q: (n, 2, 3) poses of a and b. hl, hw: (n, 2) half-length and half-width [m].
        rnd: (n, 2) bool, the body is a disc of radius ``rho`` (n, 2) [m].

    Returns:
        depth (n,) [m] (> 0 overlapping), point (n, 2) world [m] (middle of the contact),
        normal (n, 2) from a to b, half (n,) half-length of the contact segment [m].
    """
    c, s = np.cos(q[..., 2]), np.sin(q[..., 2])  # (n, 2)
    dx, dy = q[:, 1, 0] - q[:, 0, 0], q[:, 1, 1] - q[:, 0, 1]
    ca, sa, cb, sb = c[:, 0], s[:, 0], c[:, 1], s[:, 1]
    hla, hwa, hlb, hwb = hl[:, 0], hw[:, 0], hl[:, 1], hw[:, 1]
    best = np.full(q.shape[0], np.inf)
    nx, ny = np.zeros(q.shape[0]), np.zeros(q.shape[0])
    for ax, ay in ((ca, sa), (-sa, ca), (cb, sb), (-sb, cb)):
        along = ax * dx + ay * dy
        overlap = (
            _support_size(ca, sa, hla, hwa, ax, ay) + _support_size(cb, sb, hlb, hwb, ax, ay) - np.abs(along)
        )
        better = overlap < best
        best = np.where(better, overlap, best)
        sign = np.where(along >= 0.0, 1.0, -1.0)
        nx, ny = np.where(better, sign * ax, nx), np.where(better, sign * ay, ny)
    tx, ty = -ny, nx
    # Support features: a's towards b (+n), b's towards a (-n), relative to a's centre.
    ax_, ay_, a_half = _support_feature(ca, sa, hla, hwa, nx, ny, tx, ty)
    bx_, by_, b_half = _support_feature(cb, sb, hlb, hwb, -nx, -ny, tx, ty)
    a_t, b_t = ax_ * tx + ay_ * ty, (bx_ + dx) * tx + (by_ + dy) * ty
    lo = np.maximum(a_t - a_half, b_t - b_half)
    hi = np.minimum(a_t + a_half, b_t + b_half)
    mid = 0.5 * (lo + hi)
    # The middle of the contact, halfway between the two features along n.
    along_n = 0.5 * (ax_ * nx + ay_ * ny + (bx_ + dx) * nx + (by_ + dy) * ny)
    point = np.stack([q[:, 0, 0] + along_n * nx + mid * tx, q[:, 0, 1] + along_n * ny + mid * ty], -1)
    normal = np.stack([nx, ny], -1)
    half = np.maximum(0.5 * (hi - lo), 0.0)
    if rnd.any():
        best, point, normal = _disc_contact(q, c, s, hl, hw, rnd, rho, best, point, normal)
        half = np.where(rnd.any(axis=1), 0.0, half)
    return best, point, normal, half


def _disc_contact(q, c, s, hl, hw, rnd, rho, depth, point, normal):
    """``_contact`` where a body is a disc (overwrites those pairs)."""
    depth, point, normal = depth.copy(), point.copy(), normal.copy()
    both = rnd[:, 0] & rnd[:, 1]
    one = rnd[:, 0] ^ rnd[:, 1]
    if both.any():
        d = q[both, 1, :2] - q[both, 0, :2]
        dist = np.hypot(d[:, 0], d[:, 1])
        n_ab = d / np.where(dist > 0, dist, 1.0)[:, None]
        n_ab[dist <= 0] = (1.0, 0.0)
        depth[both] = rho[both, 0] + rho[both, 1] - dist
        normal[both] = n_ab
        point[both] = q[both, 0, :2] + rho[both, 0, None] * n_ab
    if one.any():
        disc = np.where(rnd[one, 0], 0, 1)  # index of the disc in the pair
        rect = 1 - disc
        rows = np.flatnonzero(one)
        cr, sr = c[rows, rect], s[rows, rect]
        d = q[rows, disc, :2] - q[rows, rect, :2]
        lx, ly = cr * d[:, 0] + sr * d[:, 1], -sr * d[:, 0] + cr * d[:, 1]
        ex, ey = hl[rows, rect], hw[rows, rect]
        kx, ky = np.clip(lx, -ex, ex), np.clip(ly, -ey, ey)
        gx, gy = lx - kx, ly - ky
        dist = np.hypot(gx, gy)
        outside = dist > 0
        inside_x = (ex - np.abs(lx)) < (ey - np.abs(ly))
        nlx = np.where(outside, gx / np.where(outside, dist, 1.0), np.where(inside_x, np.sign(lx), 0.0))
        nly = np.where(outside, gy / np.where(outside, dist, 1.0), np.where(inside_x, 0.0, np.sign(ly)))
        r = rho[rows, disc]
        depth[rows] = np.where(outside, r - dist, r + np.minimum(ex - np.abs(lx), ey - np.abs(ly)))
        # Normal from the rectangle to the disc; from a to b it flips when the disc is a.
        wnx, wny = cr * nlx - sr * nly, sr * nlx + cr * nly
        sign = np.where(disc == 1, 1.0, -1.0)
        normal[rows] = np.stack([sign * wnx, sign * wny], -1)
        point[rows] = q[rows, disc, :2] - r[:, None] * np.stack([wnx, wny], -1)
    return depth, point, normal


def _rotating_impulse(q, v, point, normal, inv_m, inertia, law, friction):
    """Impulse on b at a point contact of moving, spinning bodies (yaw rates in the point velocities).

    Args:
        q, v: (n, 2, 3) poses and velocities. point: (n, 2) world [m]. normal: (n, 2) from a to b.
        inv_m: (n,) 1/m_a + 1/m_b. inertia: (n, 2) yaw inertias [kg m^2].

    Returns:
        impulse on b (n, 2) [N s] and whether the point approached, (n,).
    """
    nx, ny = normal[:, 0], normal[:, 1]
    tx, ty = -ny, nx
    ra = point - q[:, 0, :2]
    rb = point - q[:, 1, :2]
    ua = v[:, 0, :2] + v[:, 0, 2, None] * np.stack([-ra[:, 1], ra[:, 0]], -1)
    ub = v[:, 1, :2] + v[:, 1, 2, None] * np.stack([-rb[:, 1], rb[:, 0]], -1)
    ux, uy = ub[:, 0] - ua[:, 0], ub[:, 1] - ua[:, 1]
    u_n, u_t = ux * nx + uy * ny, ux * tx + uy * ty
    e = law(np.maximum(-u_n, 0.0))
    p_n, p_t, _ = _impulse_at(
        inv_m, inertia[:, 0], inertia[:, 1],
        ra[:, 0] * nx + ra[:, 1] * ny, ra[:, 0] * tx + ra[:, 1] * ty,
        rb[:, 0] * nx + rb[:, 1] * ny, rb[:, 0] * tx + rb[:, 1] * ty,
        u_n, u_t, e, friction,
    )  # fmt: skip
    return np.stack([p_n * nx + p_t * tx, p_n * ny + p_t * ty], -1), u_n < 0.0


def _point_velocity_nt(q, v, point, nx, ny):
    """Relative velocity of b's material point at ``point`` to a's, along n and t = (-n_y, n_x)."""
    ra = point - q[:, 0, :2]
    rb = point - q[:, 1, :2]
    ux = v[:, 1, 0] - v[:, 1, 2] * rb[:, 1] - v[:, 0, 0] + v[:, 0, 2] * ra[:, 1]
    uy = v[:, 1, 1] + v[:, 1, 2] * rb[:, 0] - v[:, 0, 1] - v[:, 0, 2] * ra[:, 0]
    return ux * nx + uy * ny, -ux * ny + uy * nx


def _two_point_impulse(q, v, ends, normal, inv_m, inertia, restitution, friction, sweeps=_SWEEPS):
    """Impulses at the two ends of a flat contact, solved together (projected Gauss-Seidel).

    Each end i gets a normal impulse p_n,i >= 0 that makes it leave at no less than its
    restitution velocity -e_i u_n,i (0 where it did not approach; complementary: an end
    with p_n,i > 0 leaves at exactly that), and a tangential one towards stick, bounded by
    ``friction`` p_n,i. The ends are coupled through both bodies' rotation (the 2 x 2
    blocks K_ij of the relative-velocity change at i per unit impulse at j). Yaw rates
    enter the end velocities.

    Args:
        q, v: (m, 2, 3). ends: two (m, 2) world points [m]. normal: (m, 2) from a to b.
        inv_m: (m,). inertia: (m, 2). restitution: closing speed -> e. friction: impulse ratio.

    Returns:
        Two (m, 2) impulses on b [N s], one per end.
    """
    nx, ny = normal[:, 0], normal[:, 1]
    tx, ty = -ny, nx
    arms = []
    for p in ends:
        ra, rb = p - q[:, 0, :2], p - q[:, 1, :2]
        arms.append((ra[:, 0] * nx + ra[:, 1] * ny, ra[:, 0] * tx + ra[:, 1] * ty,
                     rb[:, 0] * nx + rb[:, 1] * ny, rb[:, 0] * tx + rb[:, 1] * ty))  # fmt: skip
    i_a, i_b = inertia[:, 0], inertia[:, 1]

    def block(i, j):  # noqa: ANN001, ANN202
        an_i, at_i, bn_i, bt_i = arms[i]
        an_j, at_j, bn_j, bt_j = arms[j]
        return (
            inv_m + at_i * at_j / i_a + bt_i * bt_j / i_b,  # n at i per P_n at j
            -(an_j * at_i / i_a + bn_j * bt_i / i_b),  # n at i per P_t at j
            -(at_j * an_i / i_a + bt_j * bn_i / i_b),  # t at i per P_n at j
            inv_m + an_i * an_j / i_a + bn_i * bn_j / i_b,  # t at i per P_t at j
        )

    k = {(i, j): block(i, j) for i in (0, 1) for j in (0, 1)}
    u0 = [_point_velocity_nt(q, v, p, nx, ny) for p in ends]
    target = [-restitution(np.maximum(-un, 0.0)) * np.minimum(un, 0.0) for un, _ in u0]
    pn = [np.zeros(nx.shape), np.zeros(nx.shape)]
    pt = [np.zeros(nx.shape), np.zeros(nx.shape)]
    bound = friction if math.isfinite(friction) else np.inf

    def velocity(i):  # noqa: ANN001, ANN202
        un, ut = u0[i]
        for j in (0, 1):
            knn, knt, ktn, ktt = k[(i, j)]
            un = un + knn * pn[j] + knt * pt[j]
            ut = ut + ktn * pn[j] + ktt * pt[j]
        return un, ut

    for _ in range(sweeps):
        for i in (0, 1):
            un, _ = velocity(i)
            pn[i] = np.maximum(pn[i] + (target[i] - un) / k[(i, i)][0], 0.0)
            _, ut = velocity(i)
            pt[i] = np.clip(pt[i] - ut / k[(i, i)][3], -bound * pn[i], bound * pn[i])
    return [np.stack([pn[i] * nx + pt[i] * tx, pn[i] * ny + pt[i] * ty], -1) for i in (0, 1)]


def _apply(v, impulse, point, q, mass, inertia):
    """Velocities after an impulse on b (minus it on a) at ``point``; returns a new (n, 2, 3)."""
    out = v.copy()
    ra = point - q[:, 0, :2]
    rb = point - q[:, 1, :2]
    px, py = impulse[:, 0], impulse[:, 1]
    out[:, 0, 0] -= px / mass[:, 0]
    out[:, 0, 1] -= py / mass[:, 0]
    out[:, 1, 0] += px / mass[:, 1]
    out[:, 1, 1] += py / mass[:, 1]
    out[:, 0, 2] -= (ra[:, 0] * py - ra[:, 1] * px) / inertia[:, 0]
    out[:, 1, 2] += (rb[:, 0] * py - rb[:, 1] * px) / inertia[:, 1]
    return out


def _energy(v, mass, inertia):
    """Kinetic energy of both bodies of each pair [J], shape (n,)."""
    return 0.5 * (mass * (v[..., 0] ** 2 + v[..., 1] ** 2) + inertia * v[..., 2] ** 2).sum(axis=1)


def planar_impulse_sequence(
    mass_a: ArrayLike,
    pos_a: ArrayLike,
    yaw_a: ArrayLike,
    length_a: ArrayLike,
    width_a: ArrayLike,
    vel_a: ArrayLike,
    mass_b: ArrayLike,
    pos_b: ArrayLike,
    yaw_b: ArrayLike,
    length_b: ArrayLike,
    width_b: ArrayLike,
    vel_b: ArrayLike,
    restitution: RestitutionLaw | None = None,
    friction: float = math.inf,
    round_a: ArrayLike = False,
    round_b: ArrayLike = False,
    yaw_rate_a: ArrayLike = 0.0,
    yaw_rate_b: ArrayLike = 0.0,
    skid: SkidModel | None = None,
    step: float = 1e-3,
    pulse_gap: float = 0.01,
    separation_time: float = 0.5,
    max_duration: float = 2.0,
    max_pulses: int = 16,
) -> ImpactSequence:
    """Delta-v of both bodies over their whole impact sequence: impulse, motion, next contact, ...

    1. The first impulse is ``planar_impulse`` at the first contact of the footprints
       (where yaw rates are given, its impulse is recomputed at that point with the
       rotating point velocities).
    2. Both bodies move on rigidly with their new velocities and yaw rates
       (semi-implicit Euler, ``step``), skidding at the tyre limit from ``skid.delay``
       after the last impulse (``skid``; None: they coast), until the footprints overlap
       again. The moment of contact is bisected inside the step. The contact
       (``_contact``): the separating axis just lost gives the normal, the touching
       features a corner or a segment of two parallel faces (``_two_point_impulse``).
    3. Its impulse takes the yaw rates into the contact-point velocity, the restitution
       law at the normal closing speed (0 below ``RESTING_SPEED``: a sustained contact,
       e.g. a truck front carrying a spun car, is a train of plastic impulses, one per
       step, the time-stepped contact force) and the impulse ratio ``friction``, as the
       first impulse does (``_impulse_at``).
    4. Repeat. A pair's sequence ends when its bounding circles are apart and separating
       (braking only slows them), after ``separation_time`` without an impulse, or
       ``max_duration`` after the first contact: the impact rig's rules.

    Total delta-v = |sum of the impulses| / m, the measurement's definition (|J| / m).
    Vectorised over any broadcast shape: the loop runs over time steps, with the pairs
    still in their sequence as arrays.

    Args:
        mass_a ... round_b: as ``planar_impulse``.
        yaw_rate_a, yaw_rate_b: pre-impact yaw rates [rad/s], broadcastable.
        skid: tyre forces between impulses; None: the bodies coast.
        step: time step of the motion between impulses [s], > 0.
        pulse_gap: impulses closer than this form one pulse [s], > 0.
        separation_time: a sequence ends after this long without an impulse [s], > 0.
        max_duration: a sequence ends this long after its first contact [s], > 0.
        max_pulses: pulses kept separately in the result, >= 1.

    Returns:
        ``ImpactSequence``.

    Raises:
        ValueError: as ``planar_impulse``, or a setting out of range.
    """
    if isinstance(max_pulses, bool) or not isinstance(max_pulses, int) or max_pulses < 1:
        raise ValueError(f"max_pulses must be an integer >= 1, got {max_pulses!r}")
    for name, value in (
        ("step", step), ("pulse_gap", pulse_gap), ("separation_time", separation_time),
        ("max_duration", max_duration),
    ):  # fmt: skip
        if isinstance(value, bool) or not (
            isinstance(value, int | float) and math.isfinite(value) and value > 0
        ):
            raise ValueError(f"{name} must be a finite number > 0 [s], got {value!r}")
    if skid is not None and not isinstance(skid, SkidModel):
        raise ValueError(f"skid must be a SkidModel or None, got {skid!r}")
    law = restitution if restitution is not None else RestitutionLaw()
    first = planar_impulse(
        mass_a, pos_a, yaw_a, length_a, width_a, vel_a, mass_b, pos_b, yaw_b, length_b, width_b, vel_b,
        law, friction, round_a, round_b,
    )  # fmt: skip
    shape = first.dv_a.shape
    n = int(np.prod(shape, dtype=int))

    def flat(x):  # noqa: ANN001, ANN202
        return np.broadcast_to(np.asarray(x, dtype=float), shape).reshape(n)

    def flat2(x):  # noqa: ANN001, ANN202
        return np.broadcast_to(np.asarray(x, dtype=float), (*shape, 2)).reshape(n, 2)

    rnd = np.stack([flat(round_a) > 0.5, flat(round_b) > 0.5], -1)
    length = np.stack([flat(length_a), flat(length_b)], -1)
    width = np.stack([flat(width_a), flat(width_b)], -1)
    mass = np.stack([flat(mass_a), flat(mass_b)], -1)
    inertia = yaw_inertia(mass, length, width, rnd)
    rho = 0.5 * np.minimum(length, width)
    bodies = _Bodies(
        mass=mass,
        inertia=inertia,
        inv_m=1.0 / mass[:, 0] + 1.0 / mass[:, 1],
        hl=np.where(rnd, rho, 0.5 * length),
        hw=np.where(rnd, rho, 0.5 * width),
        rnd=rnd,
        rho=rho,
        reach=0.5 * np.hypot(length, width).sum(axis=1) + 0.05,
    )
    # The state at the first contact: a at pos_a, b at a + the touching offset.
    q = np.zeros((n, 2, 3))
    q[:, 0, :2] = flat2(pos_a)
    q[:, 1, :2] = q[:, 0, :2] + first.geometry.offset_b.reshape(n, 2)
    q[:, 0, 2], q[:, 1, 2] = flat(yaw_a), flat(yaw_b)
    v = np.zeros((n, 2, 3))
    v[:, 0, :2], v[:, 1, :2] = flat2(vel_a), flat2(vel_b)
    v[:, 0, 2], v[:, 1, 2] = flat(yaw_rate_a), flat(yaw_rate_b)
    point = q[:, 0, :2] + first.point.reshape(n, 2)
    impulse = first.impulse.reshape(n, 2).copy()
    spinning = (v[:, 0, 2] != 0.0) | (v[:, 1, 2] != 0.0)
    if spinning.any():
        impulse[spinning], _ = _rotating_impulse(
            q[spinning], v[spinning], point[spinning], first.geometry.normal.reshape(n, 2)[spinning],
            bodies.inv_m[spinning], inertia[spinning], law, friction,
        )  # fmt: skip
    hit = np.hypot(impulse[:, 0], impulse[:, 1]) > 0.0
    log = _PulseLog(n, max_pulses, pulse_gap)
    log.add(np.flatnonzero(hit), np.zeros(int(hit.sum())), impulse[hit], point[hit],
            _energy(v[hit], mass[hit], inertia[hit]), None)  # fmt: skip
    v = _apply(v, np.where(hit[:, None], impulse, 0.0), point, q, mass, inertia)
    log.energy_after[hit, 0] = _energy(v[hit], mass[hit], inertia[hit])
    in_contact = _follow(q, v, np.flatnonzero(hit), bodies, law, friction, skid, step, separation_time,
                         max_duration, log)  # fmt: skip
    total = log.total
    size = np.hypot(total[:, 0], total[:, 1])
    k_max = max_pulses
    return ImpactSequence(
        dv_a=(size / mass[:, 0]).reshape(shape),
        dv_b=(size / mass[:, 1]).reshape(shape),
        impulse=total.reshape(*shape, 2),
        n_pulses=log.n_pulses.reshape(shape),
        n_impulses=log.n_impulses.reshape(shape),
        pulses=log.pulses.reshape(*shape, k_max, 2),
        points=log.points.reshape(*shape, k_max, 2),
        times=log.times.reshape(*shape, k_max),
        energy_before=log.energy_before.reshape(*shape, k_max),
        energy_after=log.energy_after.reshape(*shape, k_max),
        velocity_a=v[:, 0, :2].reshape(*shape, 2),
        velocity_b=v[:, 1, :2].reshape(*shape, 2),
        yaw_rate_a=v[:, 0, 2].reshape(shape),
        yaw_rate_b=v[:, 1, 2].reshape(shape),
        duration=log.last.reshape(shape),
        in_contact=in_contact.reshape(shape),
        first=first,
    )


#: Normal closing speed below which a contact is sustained, not an impact: restitution 0 [m/s].
RESTING_SPEED = 0.1


@dataclass(frozen=True, slots=True, eq=False)
class _Bodies:
    """Per-pair constants of the sequence (arrays over pairs; (n, 2) for a and b)."""

    mass: np.ndarray
    inertia: np.ndarray
    inv_m: np.ndarray
    hl: np.ndarray
    hw: np.ndarray
    rnd: np.ndarray
    rho: np.ndarray
    reach: np.ndarray

    def shape_of(self, idx: np.ndarray) -> tuple[np.ndarray, ...]:
        """(hl, hw, rnd, rho) of the pairs ``idx``, the arguments of ``_contact``."""
        return self.hl[idx], self.hw[idx], self.rnd[idx], self.rho[idx]


class _PulseLog:
    """Impulses of every pair, summed and grouped into pulses (mutable accumulator)."""

    def __init__(self, n: int, k_max: int, gap: float) -> None:
        self.gap = gap
        self.total = np.zeros((n, 2))
        self.pulses = np.zeros((n, k_max, 2))
        self.points = np.zeros((n, k_max, 2))
        self.times = np.full((n, k_max), np.nan)
        self.energy_before = np.full((n, k_max), np.nan)
        self.energy_after = np.full((n, k_max), np.nan)
        self.n_pulses = np.zeros(n, dtype=int)
        self.n_impulses = np.zeros(n, dtype=int)
        self.last = np.full(n, -np.inf)

    def add(self, rows, t, impulse, point, energy_before, energy_after) -> None:  # noqa: ANN001
        """Add an impulse on b of pairs ``rows`` at times ``t`` [s] (energies [J] or None)."""
        new = (t - self.last[rows] >= self.gap - 1e-12) | (self.n_pulses[rows] == 0)
        k_max = self.pulses.shape[1]
        self.n_pulses[rows] += new
        k = np.minimum(self.n_pulses[rows], k_max) - 1
        first_rows = rows[new & (self.n_pulses[rows] <= k_max)]
        first_k = k[new & (self.n_pulses[rows] <= k_max)]
        self.times[first_rows, first_k] = t[new & (self.n_pulses[rows] <= k_max)]
        self.points[first_rows, first_k] = point[new & (self.n_pulses[rows] <= k_max)]
        self.energy_before[first_rows, first_k] = energy_before[new & (self.n_pulses[rows] <= k_max)]
        np.add.at(self.pulses, (rows, k), impulse)
        if energy_after is not None:
            self.energy_after[rows, k] = energy_after
        self.total[rows] += impulse
        self.n_impulses[rows] += 1
        self.last[rows] = t


def _follow(q, v, idx, bodies, law, friction, skid, step, separation_time, max_duration, log):
    """Move the pairs ``idx`` on from their first impulse, with an impulse at every new contact.

    Updates ``q`` and ``v`` in place to the state where each pair's sequence ended and
    logs every impulse in ``log``. Returns (n,) bool: ended at ``max_duration`` still touching.
    """
    in_contact = np.zeros(q.shape[0], dtype=bool)
    since = np.zeros(idx.size)  # since the last impulse [s]
    qi, vi, ti = q[idx], v[idx], np.zeros(idx.size)
    base = np.zeros(idx.size)  # overlap that is not a new contact [m]
    delay = skid.delay if skid is not None else math.inf

    def restitution(closing):  # noqa: ANN001, ANN202
        return np.where(closing < RESTING_SPEED, 0.0, law(closing))

    # Every iteration advances a pair by at least step / 2^_BISECTIONS; a train of
    # impulses that advances much slower than a step (a Zeno sequence) is cut off here.
    iterations, limit = 0, 8 * int(math.ceil(max_duration / step))
    while idx.size:
        iterations += 1
        if iterations > limit:
            q[idx], v[idx] = qi, vi
            in_contact[idx] = True
            break
        shape = bodies.shape_of(idx)
        brake = since >= delay - 1e-12
        q1, v1 = _advance(qi, vi, step, brake, skid)
        depth = _contact(q1, *shape)[0]
        touch = depth > base + _TOUCH_DEPTH
        base = np.minimum(base, np.maximum(depth, 0.0))
        since = since + step
        ti = ti + step
        touched_again = np.zeros(idx.size, dtype=bool)
        if touch.any():
            rows = np.flatnonzero(touch)
            qt, vt, bt = qi[rows], vi[rows], brake[rows]
            sub = tuple(x[rows] for x in shape)
            level = base[rows] + _TOUCH_DEPTH
            lo, hi = np.zeros(rows.size), np.ones(rows.size)
            # A contact pressed again within a step of its last impulse is sustained: it
            # is resolved at the end of the step (time stepping); a new one is bisected.
            fresh = since[rows] > 1.5 * step
            if fresh.any():
                lo_f, hi_f = lo[fresh], hi[fresh]
                qf, vf, bf = qt[fresh], vt[fresh], bt[fresh]
                sub_f = tuple(x[fresh] for x in sub)
                for _ in range(_BISECTIONS):
                    mid = 0.5 * (lo_f + hi_f)
                    inside = _contact(_advance(qf, vf, mid * step, bf, skid)[0], *sub_f)[0] > level[fresh]
                    hi_f, lo_f = np.where(inside, mid, hi_f), np.where(inside, lo_f, mid)
                hi[fresh] = hi_f
            q_hi, v_hi = _advance(qt, vt, hi * step, bt, skid)
            depth_hi, where, normal, half = _contact(q_hi, *sub)
            pair = idx[rows]
            mass, inertia = bodies.mass[pair], bodies.inertia[pair]
            kick, approaching = _rotating_impulse(
                q_hi, v_hi, where, normal, bodies.inv_m[pair], inertia, restitution, friction
            )
            v_new = _apply(v_hi, kick, where, q_hi, mass, inertia)
            flat_contact = half > _POINT
            if flat_contact.any():
                f = flat_contact
                tangent = np.stack([-normal[f, 1], normal[f, 0]], -1)
                ends = [where[f] - half[f, None] * tangent, where[f] + half[f, None] * tangent]
                parts = _two_point_impulse(
                    q_hi[f],
                    v_hi[f],
                    ends,
                    normal[f],
                    bodies.inv_m[pair][f],
                    inertia[f],
                    restitution,
                    friction,
                )
                kick[f] = parts[0] + parts[1]
                size = [np.hypot(x[:, 0], x[:, 1]) for x in parts]
                weight = np.where(size[0] + size[1] > 0, size[1] / np.maximum(size[0] + size[1], 1e-300), 0.5)
                where[f] = ends[0] + weight[:, None] * (ends[1] - ends[0])
                approaching[f] = (size[0] + size[1]) > 0
                after = _apply(v_hi[f], parts[0], ends[0], q_hi[f], mass[f], inertia[f])
                v_new[f] = _apply(after, parts[1], ends[1], q_hi[f], mass[f], inertia[f])
            before = _energy(v_hi, mass, inertia)
            t_hit = ti[rows] - (1.0 - hi) * step
            go = approaching
            log.add(
                pair[go],
                t_hit[go],
                kick[go],
                where[go],
                before[go],
                _energy(v_new[go], mass[go], inertia[go]),
            )
            # Continue from the touch with the new velocities; a sustained contact stays
            # pressed at this depth, so only a deeper overlap is a new contact.
            q1[rows], v1[rows], ti[rows] = q_hi, v_new, t_hit
            base[rows] = np.maximum(depth_hi, 0.0)
            since[rows] = np.where(go, 0.0, since[rows])
            touched_again[rows] = True
        rx, ry = q1[:, 1, 0] - q1[:, 0, 0], q1[:, 1, 1] - q1[:, 0, 1]
        wx, wy = v1[:, 1, 0] - v1[:, 0, 0], v1[:, 1, 1] - v1[:, 0, 1]
        apart = (rx * rx + ry * ry > bodies.reach[idx] ** 2) & (rx * wx + ry * wy > 0.0)
        timeout = ti >= max_duration - 1e-12
        end = (apart & ~touched_again) | (since >= separation_time - 1e-12) | timeout
        if end.any():
            rows = idx[end]
            q[rows], v[rows] = q1[end], v1[end]
            in_contact[rows] = timeout[end] & (since[end] < separation_time)
        keep = ~end
        idx, qi, vi, ti, since, base = idx[keep], q1[keep], v1[keep], ti[keep], since[keep], base[keep]
    return in_contact


__all__ = [
    "ContactGeometry",
    "DeltaVModel",
    "RESTING_SPEED",
    "ImpactSequence",
    "PlanarImpulse",
    "RestitutionLaw",
    "SkidModel",
    "contact_geometry",
    "planar_impulse",
    "planar_impulse_sequence",
    "yaw_inertia",
]
