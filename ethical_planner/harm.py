"""Harm: injury probability of a collision from delta-v and impact area (paper Eqs. 1, 2).

Every model variant of SPEC section 3 is one row of ``data/harm_parameters.toml``;
each functional form has exactly one vectorised function (``_FORMS``), and each
impact-area scheme is a bin width plus a table from bin code to area key
(``_AREA_BINS``). All functions take and return numpy arrays that broadcast against
each other, so the planner can evaluate arrays of shape (n_traj, n_obs, n_t) in one call.

Angles are counter-clockwise positive in a body's own frame and wrapped into
(-pi, pi]: 0 = front, +pi/2 = left (driver side), -pi/2 = right, pi = rear.
Bin edges follow the reference implementation: a value exactly on an edge goes to
the bin further from the front (45 deg is side, 135 deg is rear, 15 deg is clock 11).
"""

from __future__ import annotations

import functools
import math
import tomllib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from enum import IntEnum, StrEnum
from importlib import resources
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import expit

from ethical_planner.geometry import wrap_angle, wrap_angle_in_place
from ethical_planner.impulse import DeltaVModel, RestitutionLaw, planar_impulse
from ethical_planner.jit import kernel
from ethical_planner.records import from_mapping
from ethical_planner.validation import (
    check_finite,
    finite_array,
    non_negative_array,
    parse_enum,
    positive_array,
    vector_array,
)


class HarmModel(StrEnum):
    """Harm model variant; the value is the row name in ``harm_parameters.toml``."""

    IGNORE_ANGLE = "ignore_angle"  # LR1
    REDUCED = "reduced"  # LR4, asymmetric four areas
    REDUCED_SYM = "reduced_sym"  # LR4S, the default
    COMPLETE = "complete"  # LR12, twelve clock areas
    COMPLETE_SYM = "complete_sym"  # LR12S
    PEDESTRIAN_MAIS3 = "pedestrian_mais3"
    PEDESTRIAN_MAIS2 = "pedestrian_mais2"
    GIDAS = "gidas"  # MAIS2+, no areas
    REF_SPEED_IGNORE_ANGLE = "ref_speed_ignore_angle"
    REF_SPEED_REDUCED_SYM = "ref_speed_reduced_sym"

    @classmethod
    def parse(cls, value: str | HarmModel) -> HarmModel:
        """Return the model named by ``value`` or raise a ValueError listing the allowed names."""
        return parse_enum(cls, value, "harm model")


class FunctionalForm(StrEnum):
    """Functional form of a harm model (one vectorised function each)."""

    PROTECTED_LOGISTIC = "protected_logistic"
    UNPROTECTED_LOGISTIC = "unprotected_logistic"
    REFERENCE_SPEED = "reference_speed"


class AreaScheme(StrEnum):
    """How the impact angle is binned into areas with their own coefficient."""

    NONE = "none"
    REDUCED_ASYM = "reduced_asym"
    REDUCED_SYM = "reduced_sym"
    CLOCK = "clock"
    CLOCK_SYM = "clock_sym"


class ReducedArea(IntEnum):
    """Four impact areas; the driver side is the left (positive angles)."""

    FRONT = 0
    DRIVER_SIDE = 1
    RIGHT_SIDE = 2
    REAR = 3


DEFAULT_MODEL = HarmModel.REDUCED_SYM
DEFAULT_PEDESTRIAN_MODEL = HarmModel.PEDESTRIAN_MAIS3

# Impact areas are found from a bin code: with a wrapped angle a and a bin width w,
# code = 2 * floor(|a| / w + 1/2) + (a > 0), i.e. the number of bin edges behind |a|
# (a value on an edge goes to the bin further from the front) and the side.
_REDUCED_WIDTH = math.radians(90.0)
_CLOCK_WIDTH = math.radians(30.0)
#: ReducedArea by bin code (width 90 deg).
_REDUCED_BY_CODE = np.array(
    [
        ReducedArea.FRONT, ReducedArea.FRONT,
        ReducedArea.RIGHT_SIDE, ReducedArea.DRIVER_SIDE,
        ReducedArea.REAR, ReducedArea.REAR,
    ],
    dtype=np.intp,
)  # fmt: skip
#: Clock position by bin code (width 30 deg): right side k o'clock, left side 12 - k.
_CLOCK_BY_CODE = np.array([12, 12, 1, 11, 2, 10, 3, 9, 4, 8, 5, 7, 6, 6], dtype=np.intp)
_TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------- geometry


def _own(value: ArrayLike, *others: ArrayLike) -> np.ndarray | None:
    """``value`` as the output buffer of an elementwise op with ``others``, if it fits.

    Hot-path helper: reusing buffers of arrays this module just created avoids fresh
    allocations (page faults dominate numpy time on shared machines). Never pass an
    array that came from a caller.
    """
    if isinstance(value, np.ndarray) and value.shape == np.broadcast_shapes(
        value.shape, *(np.shape(o) for o in others)
    ):
        return value
    return None


def _area_code(wrapped: np.ndarray, width: float) -> np.ndarray:
    """Bin code 2 * (bins behind |a|) + (a > 0) of wrapped angles [rad], integer array."""
    code = np.abs(wrapped, out=np.empty_like(wrapped))
    code *= 1.0 / width
    code += 0.5
    np.floor(code, out=code)
    code *= 2.0
    code += wrapped > 0.0
    return code.astype(np.intp)


def reduced_area(angle: ArrayLike) -> np.ndarray:
    """Reduced impact area of angles in a body's frame.

    Front |a| < 45 deg, side 45 <= |a| < 135 deg (driver side for a > 0), rear beyond.

    Args:
        angle: impact angle [rad], any shape; wrapped first.

    Returns:
        ``ReducedArea`` values as an integer array, same shape.

    """
    wrapped = wrap_angle(finite_array("angle", angle, "finite angles [rad]"))
    return _REDUCED_BY_CODE[_area_code(wrapped, _REDUCED_WIDTH)]


def clock_area(angle: ArrayLike) -> np.ndarray:
    """Clock position 1..12 of angles: (12 - round(deg / 30)) mod 12, with 0 written as 12.

    12 = front, 3 = right, 6 = rear, 9 = left. Halves round away from zero
    (15 deg is 11, -15 deg is 1), as the reference implementation bins them.

    Args:
        angle: impact angle [rad], any shape; wrapped first.

    Returns:
        Integer array of clock positions, same shape.

    """
    wrapped = wrap_angle(finite_array("angle", angle, "finite angles [rad]"))
    return _CLOCK_BY_CODE[_area_code(wrapped, _CLOCK_WIDTH)]


def impact_angles(
    x_ego: ArrayLike,
    y_ego: ArrayLike,
    yaw_ego: ArrayLike,
    x_obs: ArrayLike,
    y_obs: ArrayLike,
    yaw_obs: ArrayLike,
) -> tuple[np.ndarray, np.ndarray]:
    """Direction of the other body as seen from each body's heading (SPEC impact area).

    rel = atan2(y_obs - y_ego, x_obs - x_ego); ego_angle = wrap(rel - yaw_ego);
    obs_angle = wrap(pi + rel - yaw_obs). Coinciding centres give rel = 0.

    Args:
        x_ego: ego centre x [m], broadcastable.
        y_ego: ego centre y [m], broadcastable.
        yaw_ego: ego heading [rad], broadcastable.
        x_obs: other road user's centre x [m], broadcastable.
        y_obs: other road user's centre y [m], broadcastable.
        yaw_obs: other road user's heading [rad], broadcastable.

    Returns:
        (ego_angle, obs_angle) [rad] in (-pi, pi]: the broadcast shape of the positions
        with ``yaw_ego`` and with ``yaw_obs`` respectively.

    """
    names = ("x_ego", "y_ego", "yaw_ego", "x_obs", "y_obs", "yaw_obs")
    values = (x_ego, y_ego, yaw_ego, x_obs, y_obs, yaw_obs)
    xe, ye, he, xo, yo, ho = (finite_array(n, v) for n, v in zip(names, values, strict=True))
    dy = yo - ye
    dx = xo - xe
    rel = np.arctan2(dy, dx, out=_own(dy, dx))
    obs_angle = np.subtract(rel, ho, out=_own(dx, rel, ho))
    obs_angle += np.pi
    ego_angle = np.subtract(rel, he, out=_own(rel, he))
    return wrap_angle_in_place(ego_angle), wrap_angle_in_place(obs_angle)


def delta_v(
    mass_a: ArrayLike, mass_b: ArrayLike, vel_a: ArrayLike, vel_b: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Delta-v of both bodies in a perfectly plastic collision (paper Eq. 1).

    dv_a = m_b / (m_a + m_b) |v_a - v_b|, dv_b = m_a / (m_a + m_b) |v_a - v_b|,
    so m_a dv_a = m_b dv_b.

    Args:
        mass_a: mass of body a [kg], > 0, broadcastable against ``vel_a[..., 0]``.
        mass_b: mass of body b [kg], > 0.
        vel_a: velocity of body a [m/s], shape (..., 2).
        vel_b: velocity of body b [m/s], shape (..., 2), broadcastable against ``vel_a``.

    Returns:
        (dv_a, dv_b) [m/s], of the broadcast shape without the last axis.

    """
    m_a = positive_array("mass_a", mass_a, "[kg]")
    m_b = positive_array("mass_b", mass_b, "[kg]")
    va = vector_array("vel_a", vel_a, "[m/s]")
    vb = vector_array("vel_b", vel_b, "[m/s]")
    closing = np.subtract(va[..., 0], vb[..., 0])
    closing = np.multiply(closing, closing, out=_own(closing))
    dy = np.subtract(va[..., 1], vb[..., 1])
    closing = np.add(closing, np.multiply(dy, dy, out=_own(dy)), out=_own(closing))
    closing = np.sqrt(closing, out=_own(closing))
    total = m_a + m_b
    dv_a = closing * (m_b / total)
    return dv_a, np.multiply(closing, m_a / total, out=_own(closing, total))


def delta_v_polar(
    mass_a: ArrayLike,
    mass_b: ArrayLike,
    speed_a: ArrayLike,
    speed_b: ArrayLike,
    yaw_a: ArrayLike,
    yaw_b: ArrayLike,
) -> tuple[np.ndarray, np.ndarray]:
    """Delta-v from speeds and headings, the paper's cosine form of Eq. 1.

    dv_a = m_b / (m_a + m_b) sqrt(v_a^2 + v_b^2 - 2 v_a v_b cos(yaw_b - yaw_a)).

    Args:
        mass_a: mass of body a [kg], > 0.
        mass_b: mass of body b [kg], > 0.
        speed_a: speed of a along its heading [m/s] (may be negative).
        speed_b: speed of b along its heading [m/s] (may be negative).
        yaw_a: heading of a [rad].
        yaw_b: heading of b [rad].

    Returns:
        (dv_a, dv_b) [m/s], of the broadcast shape of the arguments.

    """
    m_a = positive_array("mass_a", mass_a, "[kg]")
    m_b = positive_array("mass_b", mass_b, "[kg]")
    v_a = finite_array("speed_a", speed_a, "finite speeds [m/s]")
    v_b = finite_array("speed_b", speed_b, "finite speeds [m/s]")
    alpha = finite_array("yaw_b", yaw_b) - finite_array("yaw_a", yaw_a)
    squared = v_a * v_a + v_b * v_b - 2.0 * v_a * v_b * np.cos(alpha)
    closing = np.sqrt(np.maximum(squared, 0.0))
    total = m_a + m_b
    return m_b / total * closing, m_a / total * closing


# --------------------------------------------------------------------------- coefficients


def _sym_clock_key(clock: int) -> str:
    return str(clock) if clock in (6, 12) else f"{min(clock, 12 - clock)}_{max(clock, 12 - clock)}"


@dataclass(frozen=True, slots=True)
class _AreaBins:
    """Bin width [rad] of a scheme and the area key of each bin code."""

    width: float
    keys: tuple[str, ...]


#: Impact-area schemes; None: no areas, the row's single key is "all".
_AREA_BINS: dict[AreaScheme, _AreaBins | None] = {
    AreaScheme.NONE: None,
    AreaScheme.REDUCED_ASYM: _AreaBins(
        _REDUCED_WIDTH, tuple(ReducedArea(a).name.lower() for a in _REDUCED_BY_CODE)
    ),
    AreaScheme.REDUCED_SYM: _AreaBins(
        _REDUCED_WIDTH,
        tuple("side" if 0 < a < 3 else ReducedArea(a).name.lower() for a in _REDUCED_BY_CODE),
    ),
    AreaScheme.CLOCK: _AreaBins(_CLOCK_WIDTH, tuple(str(c) for c in _CLOCK_BY_CODE)),
    AreaScheme.CLOCK_SYM: _AreaBins(_CLOCK_WIDTH, tuple(_sym_clock_key(c) for c in _CLOCK_BY_CODE)),
}


def _area_keys(scheme: AreaScheme) -> tuple[str, ...]:
    bins = _AREA_BINS[scheme]
    return ("all",) if bins is None else bins.keys


_INJURY_LEVELS = ("MAIS2+", "MAIS3+")


@dataclass(frozen=True, slots=True)
class HarmCoefficients:
    """One row of ``harm_parameters.toml``.

    Attributes:
        model: the model variant.
        label: short name as in the literature (``"LR4S"``).
        injury: injury level whose probability the model gives (``"MAIS3+"``, ``"MAIS2+"``).
        form: functional form.
        areas: impact-area scheme.
        c0: constant (logistic forms); 0 for the reference-speed form.
        c1: speed coefficient [s/m] (logistic forms) or exponent (reference speed).
        area: area coefficients as in the file (reference speeds [m/s] for that form).
        lookup: ``area`` expanded to one value per bin code of the scheme.

    """

    model: HarmModel
    label: str
    injury: str
    form: FunctionalForm
    areas: AreaScheme
    c0: float
    c1: float
    area: Mapping[str, float] | None = field(default=None, hash=False)
    lookup: np.ndarray = field(init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        model = parse_enum(HarmModel, self.model, "harm model")
        where = model.value
        object.__setattr__(self, "model", model)
        object.__setattr__(
            self, "form", parse_enum(FunctionalForm, self.form, "functional form", f"{where}.form")
        )
        object.__setattr__(self, "areas", parse_enum(AreaScheme, self.areas, "area scheme", f"{where}.areas"))
        check_finite(where, c0=self.c0, c1=self.c1)
        object.__setattr__(self, "c0", float(self.c0))
        object.__setattr__(self, "c1", float(self.c1))
        if self.injury not in _INJURY_LEVELS:
            raise ValueError(
                f"{where}.injury: unknown injury level {self.injury!r}; allowed: {', '.join(_INJURY_LEVELS)}"
            )
        area = self.area
        if area is None:
            if self.form is FunctionalForm.REFERENCE_SPEED or self.areas is not AreaScheme.NONE:
                raise ValueError(f"{where}.area is missing (scheme {self.areas.value!r} has areas)")
            area = {"all": 0.0}
        if not isinstance(area, Mapping):
            raise ValueError(f"{where}.area must be a table, got {area!r}")
        keys = _area_keys(self.areas)
        expected = set(keys)
        if set(area) != expected:
            raise ValueError(
                f"{where}.area keys for scheme {self.areas.value!r} must be "
                f"{sorted(expected)}, got {sorted(area)}"
            )
        check_finite(f"{where}.area", **area)
        if self.form is FunctionalForm.UNPROTECTED_LOGISTIC and self.areas is not AreaScheme.NONE:
            raise ValueError(f"{where}: the unprotected_logistic form takes areas = 'none'")
        if self.form is FunctionalForm.REFERENCE_SPEED:
            if self.c0 != 0.0 or self.c1 <= 0.0 or min(area.values()) <= 0.0:
                raise ValueError(
                    f"{where}: reference_speed needs c0 = 0, exponent c1 > 0 and "
                    "reference speeds (area) > 0 m/s"
                )
        lookup = np.array([float(area[key]) for key in keys])
        lookup.flags.writeable = False
        object.__setattr__(self, "area", MappingProxyType(dict(area)))
        object.__setattr__(self, "lookup", lookup)


def parse_harm_parameters(text: str) -> Mapping[HarmModel, HarmCoefficients]:
    """Parse a harm parameter table in the format of ``data/harm_parameters.toml``.

    Args:
        text: TOML text with one ``[models.<name>]`` table per ``HarmModel``; each
            table holds the fields of ``HarmCoefficients`` except ``model``.

    Returns:
        Read-only mapping from every ``HarmModel`` to its coefficients.

    Raises:
        ValueError: a model is missing or unknown, a key is unknown or missing, or a
            value is out of range; the message names it by its dotted key
            (``models.reduced_sym.area``).

    """
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"harm parameters are not valid TOML: {error}") from None
    if set(raw) != {"models"}:
        raise ValueError(f"harm parameters need exactly one top-level table 'models', got {sorted(raw)}")
    rows = raw["models"]
    missing = sorted(m.value for m in HarmModel if m.value not in rows)
    if missing:
        raise ValueError(f"harm parameters: missing models {missing}")
    table: dict[HarmModel, HarmCoefficients] = {}
    for name, row in rows.items():
        model = parse_enum(HarmModel, name, "harm model", "models")
        if isinstance(row, Mapping) and "model" in row:
            raise ValueError(f"unknown key 'models.{name}.model': a model is named by its table")
        data = {**row, "model": model} if isinstance(row, Mapping) else row
        table[model] = from_mapping(HarmCoefficients, data, f"models.{name}")
    return MappingProxyType(table)


@functools.cache
def harm_coefficients() -> Mapping[HarmModel, HarmCoefficients]:
    """Coefficients of every harm model, read once from the package's ``harm_parameters.toml``."""
    source = resources.files("ethical_planner").joinpath("data", "harm_parameters.toml")
    return parse_harm_parameters(source.read_text(encoding="utf-8"))


def coefficients(model: HarmModel | str) -> HarmCoefficients:
    """Coefficients of one harm model (``model`` may be its name)."""
    return harm_coefficients()[HarmModel.parse(model)]


# --------------------------------------------------------------------------- harm


def _protected_logistic(c: HarmCoefficients, dv: np.ndarray, area: np.ndarray) -> np.ndarray:
    logit = np.multiply(dv, c.c1)
    logit = np.add(logit, c.c0, out=_own(logit))
    logit = np.add(logit, area, out=_own(logit, area))
    return expit(logit, out=_own(logit))


def _unprotected_logistic(c: HarmCoefficients, dv: np.ndarray, area: np.ndarray) -> np.ndarray:
    logit = np.multiply(dv, c.c1)
    logit = np.subtract(logit, c.c0, out=_own(logit))
    return expit(logit, out=_own(logit))


def _reference_speed(c: HarmCoefficients, dv: np.ndarray, area: np.ndarray) -> np.ndarray:
    return np.minimum(1.0, np.power(dv / area, c.c1))


#: One vectorised function per functional form: (coefficients, dv [m/s], area value) -> H.
_FORMS: dict[FunctionalForm, Callable[[HarmCoefficients, np.ndarray, np.ndarray], np.ndarray]] = {
    FunctionalForm.PROTECTED_LOGISTIC: _protected_logistic,
    FunctionalForm.UNPROTECTED_LOGISTIC: _unprotected_logistic,
    FunctionalForm.REFERENCE_SPEED: _reference_speed,
}


def uses_angle(model: HarmModel | str) -> bool:
    """Return True if ``model`` distinguishes impact areas (``harm`` then needs an angle)."""
    return coefficients(model).areas is not AreaScheme.NONE


def _harm_unchecked(c: HarmCoefficients, dv: np.ndarray, wrapped: np.ndarray) -> np.ndarray:
    bins = _AREA_BINS[c.areas]
    area = c.lookup[0] if bins is None else np.take(c.lookup, _area_code(wrapped, bins.width))
    return _FORMS[c.form](c, dv, area)


def harm(model: HarmModel | str, dv: ArrayLike, angle: ArrayLike | None = None) -> np.ndarray:
    """Injury probability (paper Eq. 2) of a road user with delta-v ``dv``.

    The probability is of the model's injury level: MAIS3+ for all models but
    ``pedestrian_mais2`` and ``gidas`` (MAIS2+), see ``HarmCoefficients.injury``.

    Args:
        model: harm model variant (or its name).
        dv: delta-v of the road user [m/s], >= 0, any shape.
        angle: impact angle in the road user's own frame [rad], broadcastable against
            ``dv``; required by models with impact areas, ignored by the others.

    Returns:
        Probability in [0, 1]: the broadcast shape of ``dv`` and ``angle`` for area
        models, the shape of ``dv`` otherwise.

    Raises:
        ValueError: unknown model, dv negative or not finite, angle missing or not finite.

    """
    c = coefficients(model)
    dv_array = non_negative_array("dv", dv, "[m/s]")
    if c.areas is AreaScheme.NONE:
        return _harm_unchecked(c, dv_array, dv_array)
    if angle is None:
        raise ValueError(
            f"harm model {c.model.value!r} distinguishes impact areas ({c.areas.value}); pass angle [rad]"
        )
    wrapped = wrap_angle(finite_array("angle", angle, "finite angles [rad]"))
    return _harm_unchecked(c, dv_array, wrapped)


def boundary_harm(ego_speed: ArrayLike) -> np.ndarray:
    """Ego harm when leaving the road: a rigid wall, dv = |ego speed|, ignore-angle model.

    Args:
        ego_speed: ego speed [m/s], any shape; the sign (reversing) is ignored.

    Returns:
        MAIS3+ probability, same shape.

    """
    speed = np.abs(finite_array("ego_speed", ego_speed, "finite speeds [m/s]"))
    return _harm_unchecked(coefficients(HarmModel.IGNORE_ANGLE), speed, speed)


@dataclass(frozen=True, slots=True, eq=False)
class CollisionHarm:
    """Harm of both partners of a collision of the ego with another road user.

    All arrays have the broadcast shape of ``collision_harm``'s arguments.
    ``harm_ego, harm_obs = collision_harm(...)`` unpacks the two harms.

    Attributes:
        harm_ego: ego injury probability.
        harm_obs: other road user's injury probability.
        dv_ego: ego delta-v [m/s].
        dv_obs: other road user's delta-v [m/s].
        ego_angle: impact angle in the ego frame [rad], (-pi, pi].
        obs_angle: impact angle in the other road user's frame [rad], (-pi, pi].

    """

    harm_ego: np.ndarray
    harm_obs: np.ndarray
    dv_ego: np.ndarray
    dv_obs: np.ndarray
    ego_angle: np.ndarray
    obs_angle: np.ndarray

    def __iter__(self) -> Iterator[np.ndarray]:
        """Yield ``harm_ego`` then ``harm_obs``."""
        yield self.harm_ego
        yield self.harm_obs


@dataclass(frozen=True, slots=True, eq=False)
class _Body:
    """Inputs of a delta-v model for one body (broadcastable arrays)."""

    mass: ArrayLike
    pos: np.ndarray
    yaw: ArrayLike
    vel: ArrayLike
    shape: tuple[ArrayLike, ArrayLike] | None
    round: ArrayLike


def _dv_eq1(ego: _Body, obs: _Body, restitution: RestitutionLaw | None, ratio: float):  # noqa: ANN202
    return delta_v(ego.mass, obs.mass, ego.vel, obs.vel)


def _dv_planar(ego: _Body, obs: _Body, restitution: RestitutionLaw | None, ratio: float):  # noqa: ANN202
    result = planar_impulse(
        positive_array("ego_mass", ego.mass, "[kg]"), ego.pos, finite_array("ego_yaw", ego.yaw), ego.shape[0],
        ego.shape[1], vector_array("ego_vel", ego.vel, "[m/s]"), positive_array("obs_mass", obs.mass, "[kg]"),
        obs.pos, finite_array("obs_yaw", obs.yaw), obs.shape[0], obs.shape[1],
        vector_array("obs_vel", obs.vel, "[m/s]"), restitution, ratio, round_b=obs.round,
    )  # fmt: skip
    return result.dv_a, result.dv_b


#: One function per delta-v model: (ego, other, restitution law, impulse ratio) -> (dv_ego, dv_obs).
_DELTA_V: dict[DeltaVModel, Callable[..., tuple[np.ndarray, np.ndarray]]] = {
    DeltaVModel.EQ1: _dv_eq1,
    DeltaVModel.PLANAR_IMPULSE: _dv_planar,
}


def _select(condition: np.ndarray, if_true: np.ndarray, if_false: np.ndarray) -> np.ndarray:
    """``np.where(condition, if_true, if_false)``, written into ``if_false`` when it fits."""
    out = _own(if_false, condition, if_true)
    if out is None:
        return np.where(condition, if_true, if_false)
    np.copyto(out, if_true, where=condition)
    return out


def collision_harm(
    ego_mass: ArrayLike,
    ego_vel: ArrayLike,
    ego_pos: ArrayLike,
    ego_yaw: ArrayLike,
    obs_mass: ArrayLike,
    obs_vel: ArrayLike,
    obs_pos: ArrayLike,
    obs_yaw: ArrayLike,
    obs_unprotected: ArrayLike,
    model: HarmModel | str = DEFAULT_MODEL,
    pedestrian_model: HarmModel | str = DEFAULT_PEDESTRIAN_MODEL,
    *,
    delta_v_model: DeltaVModel | str = DeltaVModel.EQ1,
    restitution: RestitutionLaw | None = None,
    impulse_ratio: float = 0.3,
    obs_round: ArrayLike = False,
    ego_shape: tuple[ArrayLike, ArrayLike] | None = None,
    obs_shape: tuple[ArrayLike, ArrayLike] | None = None,
) -> CollisionHarm:
    """Harm of the ego and of another road user if they collide in the given states.

    Delta-v by ``delta_v_model`` (Eq. 1, or the planar impulse model of
    ``ethical_planner.impulse`` with ``restitution`` and ``impulse_ratio``, which needs
    both shapes) and impact angles as in ``impact_angles``. A protected partner:
    both harms by ``model``, each with its own impact angle. An unprotected partner
    (pedestrian, cyclist, motorcyclist): its harm by ``pedestrian_model``, the ego's
    harm by the ignore-angle model (SPEC section 3).

    Typical planner shapes: ego arrays (n_traj, 1, n_t), other (1, n_obs, n_t),
    vectors with a trailing axis of 2, ``obs_unprotected`` (1, n_obs, 1).

    Args:
        ego_mass: [kg], > 0, broadcastable.
        ego_vel: ego velocity vector [m/s], shape (..., 2).
        ego_pos: ego centre [m], shape (..., 2).
        ego_yaw: ego heading [rad].
        obs_mass: other road user's mass [kg], > 0.
        obs_vel: its velocity vector [m/s], shape (..., 2).
        obs_pos: its centre [m], shape (..., 2).
        obs_yaw: its heading [rad].
        obs_unprotected: bool array, True where the other road user is unprotected.
        model: harm model of protected road users.
        pedestrian_model: harm model of unprotected road users.
        delta_v_model: ``eq1`` or ``planar_impulse``.
        restitution: restitution law of the planar model (default ``RestitutionLaw()``).
        impulse_ratio: largest tangential / normal impulse of the planar model (inf: stick).
        obs_round: bool, broadcastable: the other road user is a disc (pedestrians) in the
            planar model.
        ego_shape: (length, width) of the ego [m], broadcastable; required by the planar
            model, unused by Eq. 1.
        obs_shape: (length, width) of the other road user [m], each broadcastable
            (e.g. shape (1, n_obs, 1)); required by the planar model.

    Returns:
        ``CollisionHarm`` with arrays of the broadcast shape (vectors without their last axis).

    Raises:
        ValueError: non-positive or non-finite mass, non-finite state, vectors without a
            last axis of 2, ``obs_unprotected`` not boolean, unknown model, a shape
            missing (or not > 0) with the planar model.

    """
    protected_c = coefficients(model)
    unprotected_c = coefficients(pedestrian_model)
    unprotected = np.asarray(obs_unprotected)
    if unprotected.dtype != np.bool_:
        raise ValueError(
            f"obs_unprotected must be boolean (True for pedestrians, cyclists, motorcyclists), "
            f"got dtype {unprotected.dtype}"
        )
    ep = vector_array("ego_pos", ego_pos, "[m]")
    op = vector_array("obs_pos", obs_pos, "[m]")
    dv_model = parse_enum(DeltaVModel, delta_v_model, "delta-v model")
    if dv_model is DeltaVModel.PLANAR_IMPULSE and (ego_shape is None or obs_shape is None):
        raise ValueError(
            "collision_harm: the planar impulse model needs ego_shape=(length, width) and "
            "obs_shape=(length, width) [m]"
        )
    ego = _Body(ego_mass, ep, ego_yaw, ego_vel, ego_shape, False)
    obs = _Body(obs_mass, op, obs_yaw, obs_vel, obs_shape, obs_round)
    dv_ego, dv_obs = _DELTA_V[dv_model](ego, obs, restitution, impulse_ratio)
    ego_angle, obs_angle = impact_angles(ep[..., 0], ep[..., 1], ego_yaw, op[..., 0], op[..., 1], obs_yaw)
    shape = np.broadcast_shapes(dv_ego.shape, ego_angle.shape, obs_angle.shape, unprotected.shape)

    any_unprotected = bool(unprotected.any())
    all_unprotected = any_unprotected and bool(unprotected.all())
    harm_ego = harm_obs = None
    if not all_unprotected:
        harm_ego = _harm_unchecked(protected_c, dv_ego, ego_angle)
        harm_obs = _harm_unchecked(protected_c, dv_obs, obs_angle)
    if any_unprotected:
        ego_u = _harm_unchecked(coefficients(HarmModel.IGNORE_ANGLE), dv_ego, ego_angle)
        obs_u = _harm_unchecked(unprotected_c, dv_obs, obs_angle)
        if all_unprotected:
            harm_ego, harm_obs = ego_u, obs_u
        else:
            harm_ego = _select(unprotected, ego_u, harm_ego)
            harm_obs = _select(unprotected, obs_u, harm_obs)

    def full(array: np.ndarray) -> np.ndarray:
        return array if array.shape == shape else np.broadcast_to(array, shape).copy()

    return CollisionHarm(
        harm_ego=full(harm_ego),
        harm_obs=full(harm_obs),
        dv_ego=full(dv_ego),
        dv_obs=full(dv_obs),
        ego_angle=full(ego_angle),
        obs_angle=full(obs_angle),
    )


# --------------------------------------------------------------------------- compiled harm

#: Functional forms as the compiled harm reads them (column 0 of a model row).
_FORM_CODE: dict[FunctionalForm, int] = {
    FunctionalForm.PROTECTED_LOGISTIC: 0,
    FunctionalForm.UNPROTECTED_LOGISTIC: 1,
    FunctionalForm.REFERENCE_SPEED: 2,
}
#: A model row: form code, c0, c1, bin width [rad] (0: no areas), then the area value of
#: each bin code (``HarmCoefficients.lookup``, padded with zeros).
_ROW_LOOKUP = 4
_ROW_SIZE = _ROW_LOOKUP + _CLOCK_BY_CODE.size


def _model_row(model: HarmModel | str) -> np.ndarray:
    """One harm model as a row of numbers for ``_compiled_harm`` (see _ROW_SIZE)."""
    c = coefficients(model)
    bins = _AREA_BINS[c.areas]
    row = np.zeros(_ROW_SIZE)
    row[:_ROW_LOOKUP] = (_FORM_CODE[c.form], c.c0, c.c1, 0.0 if bins is None else bins.width)
    row[_ROW_LOOKUP : _ROW_LOOKUP + c.lookup.size] = c.lookup
    return row


@kernel
def _wrapped(angle: float) -> float:
    """``wrap_angle_in_place`` of one angle [rad], the same operations in the same order."""
    turns = np.rint(angle * (1.0 / _TWO_PI)) * _TWO_PI
    angle -= turns
    if angle <= -math.pi:
        angle += _TWO_PI
    if angle > math.pi:
        angle -= _TWO_PI
    return angle


@kernel
def _compiled_harm(row: np.ndarray, dv: float, wrapped: float) -> float:
    """``_harm_unchecked`` of one collision: the model ``row``, delta-v [m/s], wrapped angle [rad]."""
    width = row[3]
    area = row[_ROW_LOOKUP]
    if width > 0.0:
        code = math.floor(abs(wrapped) * (1.0 / width) + 0.5) * 2.0
        if wrapped > 0.0:
            code += 1.0
        area = row[_ROW_LOOKUP + int(code)]
    form = row[0]
    if form == 0.0:
        logit = dv * row[2] + row[1] + area
        return 1.0 / (1.0 + math.exp(-logit))
    if form == 1.0:
        logit = dv * row[2] - row[1]
        return 1.0 / (1.0 + math.exp(-logit))
    return min(1.0, (dv / area) ** row[2])


@kernel
def _collision_harm_eq1(
    ego: np.ndarray,
    ego_mass: float,
    obs: np.ndarray,
    obs_mass: np.ndarray,
    obs_unprotected: np.ndarray,
    flat: np.ndarray,
    n_obs: int,
    n_t: int,
    rows: np.ndarray,
    harm_ego: np.ndarray,
    harm_obs: np.ndarray,
) -> None:
    """``collision_harm`` with Eq. 1 at triples (i, obs, step) of a (m, n_obs, n_t) grid.

    Args:
        ego: ego states per (i, step), column i * n_t + step, shape (5, m * n_t): x, y,
            yaw, vx, vy [m, m, rad, m/s, m/s].
        ego_mass: [kg].
        obs: road-user states per (obs, step), column obs * n_t + step, shape (5, n_obs * n_t).
        obs_mass: [kg], shape (n_obs,).
        obs_unprotected: bool, shape (n_obs,).
        flat: the triples' flat indices (i * n_obs + obs) * n_t + step, shape (q,).
        n_obs, n_t: the grid's sizes.
        rows: model rows (``_model_row``): protected, the ego's with an unprotected
            partner (ignore angle), the unprotected partner's, shape (3, _ROW_SIZE).
        harm_ego, harm_obs: outputs, shape (q,).
    """
    for j in range(flat.size):
        pair = flat[j] // n_t
        step = flat[j] - pair * n_t
        i = pair // n_obs
        road_user = pair - i * n_obs
        e, o = i * n_t + step, road_user * n_t + step
        mass = obs_mass[road_user]
        closing = ego[3, e] - obs[3, o]
        closing = closing * closing
        dy = ego[4, e] - obs[4, o]
        closing = math.sqrt(closing + dy * dy)
        total = ego_mass + mass
        dv_ego = closing * (mass / total)
        dv_obs = closing * (ego_mass / total)
        rel = math.atan2(obs[1, o] - ego[1, e], obs[0, o] - ego[0, e])
        ego_angle = _wrapped(rel - ego[2, e])
        obs_angle = _wrapped(rel - obs[2, o] + math.pi)
        if obs_unprotected[road_user]:
            harm_ego[j] = _compiled_harm(rows[1], dv_ego, ego_angle)
            harm_obs[j] = _compiled_harm(rows[2], dv_obs, obs_angle)
        else:
            harm_ego[j] = _compiled_harm(rows[0], dv_ego, ego_angle)
            harm_obs[j] = _compiled_harm(rows[0], dv_obs, obs_angle)


def collision_harm_at(
    ego: np.ndarray,
    ego_mass: float,
    obs: np.ndarray,
    obs_mass: np.ndarray,
    obs_unprotected: np.ndarray,
    flat: np.ndarray,
    model: HarmModel | str = DEFAULT_MODEL,
    pedestrian_model: HarmModel | str = DEFAULT_PEDESTRIAN_MODEL,
) -> tuple[np.ndarray, np.ndarray]:
    """``collision_harm`` with Eq. 1 delta-v at triples of a (candidate, road user, step) grid, compiled.

    The planner's hot path: the collision at triple (i, obs, step) is between ego state
    (i, step) and road-user state (obs, step); nothing is gathered per triple. The
    arithmetic is ``collision_harm``'s in the same order (the same numbers to the bit
    where the platform's libm is numpy's, as on Linux; tests compare the two).

    Args:
        ego: ego states, shape (5, m, n_t): x, y, yaw [m, m, rad] and velocity vx, vy [m/s].
        ego_mass: [kg], > 0.
        obs: road-user states, shape (5, n_obs, n_t), as ``ego``.
        obs_mass: [kg], > 0, shape (n_obs,).
        obs_unprotected: True where the road user is unprotected, shape (n_obs,), bool.
        flat: flat indices (i * n_obs + obs) * n_t + step of the triples, shape (q,).
        model: harm model of protected road users.
        pedestrian_model: harm model of unprotected road users.

    Returns:
        (harm_ego, harm_obs), shape (q,) each.

    Raises:
        ValueError: on shapes that do not match, a triple outside the grid, a mass not > 0.
    """
    ego = np.ascontiguousarray(ego, dtype=float)
    obs = np.ascontiguousarray(obs, dtype=float)
    if (
        ego.ndim != 3
        or ego.shape[0] != 5
        or obs.ndim != 3
        or obs.shape[0] != 5
        or obs.shape[2] != ego.shape[2]
    ):
        raise ValueError(
            f"ego and obs must have shapes (5, m, n_t) and (5, n_obs, n_t), got {ego.shape}, {obs.shape}"
        )
    m, n_obs, n_t = ego.shape[1], obs.shape[1], ego.shape[2]
    flat = np.ascontiguousarray(flat, dtype=np.int64)
    obs_mass = np.ascontiguousarray(obs_mass, dtype=float)
    obs_unprotected = np.ascontiguousarray(obs_unprotected, dtype=np.bool_)
    if flat.ndim != 1 or (flat.size and (flat.min() < 0 or flat.max() >= m * n_obs * n_t)):
        raise ValueError(f"flat must hold indices of the ({m}, {n_obs}, {n_t}) grid, shape (q,)")
    if obs_mass.shape != (n_obs,) or obs_unprotected.shape != (n_obs,):
        raise ValueError(f"obs_mass and obs_unprotected must have shape ({n_obs},)")
    if not (math.isfinite(ego_mass) and ego_mass > 0.0) or np.any(~(obs_mass > 0.0)):
        raise ValueError("ego_mass and obs_mass must be finite masses > 0 [kg]")
    rows = np.stack([_model_row(model), _model_row(HarmModel.IGNORE_ANGLE), _model_row(pedestrian_model)])
    harm_ego = np.empty(flat.size)
    harm_obs = np.empty(flat.size)
    _collision_harm_eq1(
        ego.reshape(5, m * n_t),
        float(ego_mass),
        obs.reshape(5, n_obs * n_t),
        obs_mass,
        obs_unprotected,
        flat,
        n_obs,
        n_t,
        rows,
        harm_ego,
        harm_obs,
    )
    return harm_ego, harm_obs
