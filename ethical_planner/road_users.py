"""Road-user records: types, shapes, kinematic states and masses.

Everything here is a frozen record validated at construction, so a NaN or a
negative size is rejected where it enters the planner, not deep in a cost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import StrEnum

import numpy as np

from ethical_planner.validation import check_finite, check_positive, parse_enum


class RoadUserType(StrEnum):
    """Type of a road user, spelled as in CommonRoad's obstacle types."""

    CAR = "car"
    TAXI = "taxi"
    PARKED_VEHICLE = "parked_vehicle"
    PRIORITY_VEHICLE = "priority_vehicle"
    TRUCK = "truck"
    BUS = "bus"
    MOTORCYCLE = "motorcycle"
    BICYCLE = "bicycle"
    PEDESTRIAN = "pedestrian"
    TRAIN = "train"

    @classmethod
    def parse(cls, value: str | RoadUserType) -> RoadUserType:
        """Return the type named by ``value`` or raise a ValueError listing the allowed names."""
        return parse_enum(cls, value, "road-user type")


#: Road users without a crash structure around them (paper: unprotected).
UNPROTECTED_TYPES = frozenset({RoadUserType.PEDESTRIAN, RoadUserType.BICYCLE, RoadUserType.MOTORCYCLE})
#: Vulnerable road users, the third group of the paper's Figs. 5 and 6.
VULNERABLE_TYPES = UNPROTECTED_TYPES
#: Road users with an engine; they carry a base responsibility growing with mass.
MOTORISED_TYPES = frozenset(set(RoadUserType) - {RoadUserType.PEDESTRIAN, RoadUserType.BICYCLE})

_CAR_LIKE = frozenset(
    {
        RoadUserType.CAR,
        RoadUserType.TAXI,
        RoadUserType.PARKED_VEHICLE,
        RoadUserType.PRIORITY_VEHICLE,
    }
)
_FIXED_MASS_KG = {
    RoadUserType.TRUCK: 25000.0,
    RoadUserType.BUS: 13000.0,
    RoadUserType.MOTORCYCLE: 250.0,
    RoadUserType.BICYCLE: 90.0,
    RoadUserType.PEDESTRIAN: 75.0,
    RoadUserType.TRAIN: 118800.0,
}
#: Floor of the car mass regression [kg]; the regression is negative below 3.19 m^2.
MIN_CAR_MASS_KG = 500.0


def mass_of(kind: RoadUserType, length: float, width: float) -> float:
    """Mass of a road user [kg] from its type and footprint (reference regression).

    Cars: m = -1333.5 + 526.9 (l w)^0.8, floored at ``MIN_CAR_MASS_KG``.

    Args:
        kind: road-user type.
        length: footprint length [m].
        width: footprint width [m].
    """
    if kind in _CAR_LIKE:
        return max(MIN_CAR_MASS_KG, -1333.5 + 526.9 * (length * width) ** 0.8)
    return _FIXED_MASS_KG[kind]


@dataclass(frozen=True, slots=True)
class Shape:
    """Rectangular footprint [m]; pedestrians are approximated by a small square."""

    length: float
    width: float

    def __post_init__(self) -> None:
        check_positive("Shape", length=self.length, width=self.width)


#: Default shapes [m] used when a scenario gives only a type.
DEFAULT_SHAPES = {
    RoadUserType.CAR: Shape(4.5, 1.8),
    RoadUserType.TAXI: Shape(4.5, 1.8),
    RoadUserType.PARKED_VEHICLE: Shape(4.5, 1.8),
    RoadUserType.PRIORITY_VEHICLE: Shape(5.0, 2.0),
    RoadUserType.TRUCK: Shape(10.0, 2.5),
    RoadUserType.BUS: Shape(12.0, 2.5),
    RoadUserType.MOTORCYCLE: Shape(2.2, 0.8),
    RoadUserType.BICYCLE: Shape(1.8, 0.6),
    RoadUserType.PEDESTRIAN: Shape(0.5, 0.5),
    RoadUserType.TRAIN: Shape(40.0, 3.0),
}

#: Default ego: BMW 320i.
EGO_SHAPE = Shape(4.508, 1.610)
EGO_MASS_KG = 1475.0


@dataclass(frozen=True, slots=True)
class KinematicState:
    """Planar state of a body's geometric centre.

    Attributes:
        x: position [m].
        y: position [m].
        yaw: heading [rad], counter-clockwise from the x axis.
        v: speed along the heading [m/s].
        a: longitudinal acceleration [m/s^2].
        yaw_rate: [rad/s].
    """

    x: float
    y: float
    yaw: float
    v: float
    a: float = 0.0
    yaw_rate: float = 0.0

    def __post_init__(self) -> None:
        check_finite(
            "KinematicState",
            x=self.x,
            y=self.y,
            yaw=self.yaw,
            v=self.v,
            a=self.a,
            yaw_rate=self.yaw_rate,
        )

    @property
    def velocity(self) -> np.ndarray:
        """Velocity vector [m/s], shape (2,)."""
        return np.array([self.v * math.cos(self.yaw), self.v * math.sin(self.yaw)])


@dataclass(frozen=True, slots=True)
class LegalCorridor:
    """What a road user may legally do within the horizon (its legal reachable set).

    The set is an oriented strip along the road user's current heading: it may move
    between full braking and accelerating to its speed limit, and sideways by at most
    ``lateral_half_width`` [m] (staying in its lane or on its sidewalk). A stop line
    (red light, give-way) ``stop_distance`` [m] ahead of its centre caps the strip.

    Attributes:
        speed_limit: legal speed [m/s].
        lateral_half_width: allowed sideways excursion of its centre [m].
        stop_distance: distance to a stop line it must respect [m], or None.
        max_acceleration: [m/s^2].
        max_deceleration: positive braking capability [m/s^2].
    """

    speed_limit: float
    lateral_half_width: float
    stop_distance: float | None = None
    max_acceleration: float = 2.0
    max_deceleration: float = 8.0

    def __post_init__(self) -> None:
        check_finite(
            "LegalCorridor",
            speed_limit=self.speed_limit,
            lateral_half_width=self.lateral_half_width,
            max_acceleration=self.max_acceleration,
            max_deceleration=self.max_deceleration,
        )
        if self.speed_limit < 0 or self.lateral_half_width < 0:
            raise ValueError("LegalCorridor.speed_limit and lateral_half_width must be >= 0")
        if self.max_acceleration < 0 or self.max_deceleration <= 0:
            raise ValueError("LegalCorridor.max_acceleration must be >= 0 and max_deceleration > 0 m/s^2")
        if self.stop_distance is not None:
            check_finite("LegalCorridor", stop_distance=self.stop_distance)


@dataclass(frozen=True, slots=True, eq=False)
class MotionHistory:
    """Recent observed motion of a road user's centre, sampled at a fixed step.

    Times are seconds relative to the observation the history belongs to: all
    ``<= 0``, strictly increasing by ``step`` (within 1e-6 s); the last sample is at
    most one step old (a world samples on its own grid, between two samples the
    current state is newer). A history of one sample is allowed (just appeared).

    Attributes:
        times: [s], shape (n,), n >= 1.
        positions: centre [m], shape (n, 2).
        headings: [rad], shape (n,).
        speeds: along the heading [m/s], shape (n,).
    """

    times: np.ndarray
    positions: np.ndarray
    headings: np.ndarray
    speeds: np.ndarray

    def __post_init__(self) -> None:
        arrays = {}
        for name in ("times", "positions", "headings", "speeds"):
            try:
                value = np.array(getattr(self, name), dtype=float)
            except (TypeError, ValueError):
                raise ValueError(
                    f"MotionHistory.{name} must be numeric, got {getattr(self, name)!r}"
                ) from None
            value.setflags(write=False)
            object.__setattr__(self, name, value)
            arrays[name] = value
        n = arrays["times"].shape[0] if arrays["times"].ndim == 1 else -1
        expected = {"times": (n,), "positions": (n, 2), "headings": (n,), "speeds": (n,)}
        if n < 1:
            raise ValueError(
                f"MotionHistory.times must have shape (n,) with n >= 1, got {arrays['times'].shape}"
            )
        for name, shape in expected.items():
            if arrays[name].shape != shape:
                raise ValueError(f"MotionHistory.{name} must have shape {shape}, got {arrays[name].shape}")
            if not np.all(np.isfinite(arrays[name])):
                raise ValueError(f"MotionHistory.{name} must be finite (found NaN or inf)")
        times = arrays["times"]
        if times[-1] > 1e-9:
            raise ValueError(f"MotionHistory.times must be <= 0 s (the past), got last {times[-1]:.6g}")
        if n > 1:
            steps = np.diff(times)
            if steps.min() <= 0 or steps.max() - steps.min() > 1e-6:
                raise ValueError(
                    "MotionHistory.times must increase by one fixed step, got steps between "
                    f"{steps.min():.6g} and {steps.max():.6g} s"
                )
            if times[-1] < -steps[0] - 1e-6:
                raise ValueError(
                    f"MotionHistory: the last sample ({times[-1]:.6g} s) is older than one step "
                    f"({steps[0]:.6g} s)"
                )

    @property
    def step(self) -> float | None:
        """Sampling step [s], or None for a single sample."""
        return float(self.times[1] - self.times[0]) if len(self.times) > 1 else None

    @property
    def duration(self) -> float:
        """Time from the oldest sample to now [s]."""
        return float(-self.times[0])

    def __len__(self) -> int:
        return len(self.times)


@dataclass(frozen=True, slots=True)
class RoadUser:
    """Another road user as the planner observes it.

    Attributes:
        id: unique integer id.
        type: road-user type.
        state: current kinematic state of its centre.
        shape: footprint.
        mass: [kg]; defaults to ``mass_of(type, length, width)``.
        legal: its legal corridor, or None to derive one from the road (see
            ``ethical_planner.responsibility``).
        history: its recent observed motion (for learned predictors), or None.
    """

    id: int
    type: RoadUserType
    state: KinematicState
    shape: Shape
    mass: float = field(default=float("nan"))
    legal: LegalCorridor | None = None
    history: MotionHistory | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "type", RoadUserType.parse(self.type))
        if self.history is not None and not isinstance(self.history, MotionHistory):
            kind = type(self.history).__name__
            raise ValueError(f"RoadUser.history must be a MotionHistory or None, got {kind}")
        if math.isnan(self.mass):
            object.__setattr__(self, "mass", mass_of(self.type, self.shape.length, self.shape.width))
        check_finite("RoadUser", mass=self.mass)
        if self.mass <= 0:
            raise ValueError(f"RoadUser.mass must be > 0 kg, got {self.mass}")

    def advanced(self, dt: float) -> RoadUser:
        """The same road user ``dt`` [s] later at constant speed and turn rate.

        The history moves back by ``dt`` and gains the state it leaves (kept at the
        history's step; a history of one sample gets ``dt`` as its step).
        """
        state = self.state
        yaw = state.yaw + state.yaw_rate * dt
        mid = state.yaw + 0.5 * state.yaw_rate * dt
        moved = replace(
            state,
            x=state.x + state.v * dt * math.cos(mid),
            y=state.y + state.v * dt * math.sin(mid),
            yaw=yaw,
        )
        return replace(self, state=moved, history=self._history_after(dt))

    def _history_after(self, dt: float) -> MotionHistory | None:
        history = self.history
        if history is None:
            return None
        step = history.step or dt
        times = history.times - dt
        # Samples of the history grid that the advance passed, filled at constant velocity.
        new_times = np.arange(times[-1] + step, 1e-9, step)
        if len(new_times) == 0 and times[-1] < -step - 1e-9:
            new_times = np.array([times[-1] + step])
        since = new_times + dt  # seconds after the current state
        state = self.state
        heading = state.yaw + state.yaw_rate * since
        mid = state.yaw + 0.5 * state.yaw_rate * since
        new_pos = np.stack(
            [state.x + state.v * since * np.cos(mid), state.y + state.v * since * np.sin(mid)], axis=-1
        )
        return MotionHistory(
            np.concatenate([times, new_times]),
            np.concatenate([history.positions, new_pos]),
            np.concatenate([history.headings, heading]),
            np.concatenate([history.speeds, np.full(len(new_times), state.v)]),
        )

    @property
    def is_vulnerable(self) -> bool:
        """True for pedestrians, cyclists and motorcyclists."""
        return self.type in VULNERABLE_TYPES
