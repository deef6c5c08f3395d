"""Controlled two-body impact sweeps in the MuJoCo world.

Body a is the default ego (BMW 320i, 1475 kg); body b is a partner of each type.
Every ``ImpactCase`` is launched with ``mujoco_world.impact.ImpactRig`` (one compiled
rig per partner, restitution setting and contact mode and process), compared with the
planner's models (Eq. 1 and the planar impulse model, the latter with the restitution
the world used) by ``mujoco_world.compare.compare_impact`` and flattened into a row.

A *geometry cell* is a partner, an angle and an offset; its impacts differ only in
closing speed. Held-back evaluations split by cell (``harm_calibration.calibration``).

The full grid runs on a spawn-safe process pool and is resumable: cases whose id is
already in ``impacts.csv`` are skipped and new rows are appended as they finish.
"""

from __future__ import annotations

import functools
import itertools
import math
import multiprocessing
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from ethical_planner.impulse import RestitutionLaw
from ethical_planner.road_users import DEFAULT_SHAPES, EGO_MASS_KG, EGO_SHAPE, KinematicState, RoadUserType
from harm_calibration.geometry import Footprint, classify, launch_geometry, speeds_for_closing
from harm_calibration.rows import COLUMNS, Row, read_rows, row_from_impact, write_rows
from mujoco_world.evaluation.compare import compare_impact
from mujoco_world.physics.impact import ImpactMeasurement, ImpactRig
from mujoco_world.physics.scene import BodyProxy
from mujoco_world.scenario.spec import ContactMode, ContactSpec

#: Partner types of the sweep (car-cyclist is the bicycle type).
PARTNERS = ("car", "truck", "bus", "motorcycle", "bicycle", "pedestrian")
#: Largest partner speed [m/s]; vehicles drive at half the closing speed.
PARTNER_SPEED_CAP = {"pedestrian": 2.0, "bicycle": 6.0, "motorcycle": 20.0}
#: Restitution settings: name -> constant coefficient (None: the world's default law,
#: which is also the planner's default).
RESTITUTION_SETS: dict[str, float | None] = {"default": None, "e0.1": 0.1, "e0.2": 0.2, "e0.4": 0.4}


class Grid(StrEnum):
    """Named sweep grids."""

    SMALL = "small"
    FULL = "full"
    SPEED = "speed"


@dataclass(frozen=True, slots=True)
class GridSpec:
    """Axes of a sweep grid (the cartesian product is swept).

    Attributes:
        closing_speeds: relative speeds [m/s]. angles_deg: angles between the velocity
        directions [deg]. offsets: lateral offsets as a fraction of the edge offset.
        partners: partner types. restitution_sets: keys of ``RESTITUTION_SETS``.
        mode: contact mode of the world (``rigid`` for validation).
    """

    closing_speeds: tuple[float, ...]
    angles_deg: tuple[float, ...]
    offsets: tuple[float, ...]
    partners: tuple[str, ...]
    restitution_sets: tuple[str, ...]
    mode: ContactMode = ContactMode.RIGID

    def __post_init__(self) -> None:
        for name in ("closing_speeds", "angles_deg", "offsets", "partners", "restitution_sets"):
            if not getattr(self, name):
                raise ValueError(f"GridSpec.{name} must not be empty")
        if min(self.closing_speeds) <= 0:
            raise ValueError(f"GridSpec.closing_speeds must be > 0 [m/s], got {self.closing_speeds}")
        if not all(0.0 <= a <= 180.0 for a in self.angles_deg):
            raise ValueError(f"GridSpec.angles_deg must lie in [0, 180], got {self.angles_deg}")
        if not all(0.0 <= o < 1.0 for o in self.offsets):
            raise ValueError(f"GridSpec.offsets must lie in [0, 1), got {self.offsets}")
        bad = [p for p in self.partners if p not in PARTNERS]
        if bad:
            raise ValueError(f"GridSpec.partners: unknown {bad}; allowed: {PARTNERS}")
        bad = [r for r in self.restitution_sets if r not in RESTITUTION_SETS]
        if bad:
            raise ValueError(f"GridSpec.restitution_sets: unknown {bad}; allowed: {tuple(RESTITUTION_SETS)}")
        try:
            object.__setattr__(self, "mode", ContactMode(self.mode))
        except ValueError:
            allowed = ", ".join(m.value for m in ContactMode)
            raise ValueError(f"GridSpec.mode: unknown {self.mode!r}; allowed: {allowed}") from None

    def cases(self) -> list[ImpactCase]:
        """Every case of the grid, in a fixed order."""
        return [
            ImpactCase(p, c, a, o, r, self.mode)
            for r, p, c, a, o in itertools.product(
                self.restitution_sets, self.partners, self.closing_speeds, self.angles_deg, self.offsets
            )
        ]


#: Closing speeds [m/s], angles [deg] and offsets of the full and speed grids: every
#: angle x offset bin of ``calibration.ANGLE_EDGES_DEG`` x ``OFFSET_EDGES`` holds one value.
_FULL_SPEEDS = (5.0, 7.5, 10.0, 15.0, 20.0, 25.0, 30.0)
_FULL_ANGLES = tuple(float(a) for a in range(0, 181, 15))
_FULL_OFFSETS = (0.0, 0.25, 0.5, 0.75, 0.9)

GRIDS = {
    Grid.SMALL: GridSpec(
        closing_speeds=(5.0, 10.0, 20.0, 30.0),
        angles_deg=(0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0),
        offsets=(0.0, 0.5),
        partners=PARTNERS,
        restitution_sets=("default",),
    ),
    Grid.FULL: GridSpec(
        closing_speeds=_FULL_SPEEDS,
        angles_deg=_FULL_ANGLES,
        offsets=_FULL_OFFSETS,
        partners=PARTNERS,
        restitution_sets=("default",),
    ),
    # Speed independence of the measurement: the small grid's vehicle cells at a constant
    # restitution, so that the restitution law's speed dependence cannot move a ratio.
    Grid.SPEED: GridSpec(
        closing_speeds=(5.0, 10.0, 20.0, 30.0),
        angles_deg=(0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0),
        offsets=(0.0, 0.5),
        partners=("car", "truck", "bus"),
        restitution_sets=("e0.1",),
    ),
}


@dataclass(frozen=True, slots=True)
class ImpactCase:
    """One controlled impact.

    Attributes:
        partner: type of body b. closing_speed: |v_a - v_b| [m/s].
        angle_deg: angle between the velocity directions [deg], 0 rear-end, 180 head-on.
        offset: lateral offset, fraction of the edge offset. restitution_set: key of
        ``RESTITUTION_SETS``. mode: contact mode.
    """

    partner: str
    closing_speed: float
    angle_deg: float
    offset: float
    restitution_set: str
    mode: ContactMode = ContactMode.RIGID

    @property
    def id(self) -> str:
        """Stable identifier (the resume key in ``impacts.csv``)."""
        return (
            f"{self.partner}|v{self.closing_speed:g}|a{self.angle_deg:g}|o{self.offset:g}"
            f"|{self.restitution_set}|{ContactMode(self.mode).value}"
        )

    @property
    def cell(self) -> str:
        """Geometry cell: partner, angle and offset (all closing speeds share it)."""
        return f"{self.partner}|a{self.angle_deg:g}|o{self.offset:g}"

    def design(self) -> dict[str, object]:
        """Design columns of the row."""
        return {
            "id": self.id,
            "partner": self.partner,
            "closing_speed": float(self.closing_speed),
            "angle_deg": float(self.angle_deg),
            "offset": float(self.offset),
            "restitution_set": self.restitution_set,
            "class": classify(self.angle_deg, self.offset),
            "cell": self.cell,
            "mode": ContactMode(self.mode).value,
        }


def ego_proxy() -> BodyProxy:
    """The default ego as a rig body (BMW 320i)."""
    return BodyProxy("ego", RoadUserType.CAR, EGO_SHAPE.length, EGO_SHAPE.width, EGO_MASS_KG)


def restitution_for(restitution_set: str) -> RestitutionLaw:
    """Restitution law of a setting (the default law, or a constant)."""
    e = RESTITUTION_SETS[restitution_set]
    return ContactSpec().restitution_law if e is None else RestitutionLaw.constant(e)


def contact_for(restitution_set: str, mode: ContactMode | str = ContactMode.RIGID) -> ContactSpec:
    """Contact model of a restitution setting in a contact mode."""
    return ContactSpec(mode=ContactMode(mode), restitution_law=restitution_for(restitution_set))


@functools.lru_cache(maxsize=32)
def _rig(partner: str, restitution_set: str, mode: str) -> ImpactRig:
    """Rig of this process for a partner, restitution setting and mode (compiled once)."""
    return ImpactRig(
        ego_proxy(), BodyProxy.of_type("partner", partner), contact=contact_for(restitution_set, mode)
    )


def launch_case(case: ImpactCase, rig: ImpactRig | None = None) -> ImpactMeasurement | None:
    """Launch one impact; the measured sequence, or None for a miss.

    Body a (the ego) drives along +x; the partner drives at half the closing speed (capped
    by ``PARTNER_SPEED_CAP``) along the case's angle, placed by ``geometry.launch_geometry``
    so that the two meet with the case's offset.

    Args:
        case: the impact.
        rig: rig to launch in (default: this process's rig of the case, whose bodies skid
            between impulses as in the world).
    """
    shape = DEFAULT_SHAPES[RoadUserType(case.partner)]
    partner_speed = min(0.5 * case.closing_speed, PARTNER_SPEED_CAP.get(case.partner, math.inf))
    alpha = math.radians(case.angle_deg)
    speed_a, speed_b = speeds_for_closing(case.closing_speed, alpha, partner_speed)
    launch = launch_geometry(
        Footprint(EGO_SHAPE.length, EGO_SHAPE.width),
        Footprint(shape.length, shape.width, case.partner == "pedestrian"),
        speed_a,
        speed_b,
        alpha,
        case.offset,
    )
    rig = rig or _rig(case.partner, case.restitution_set, ContactMode(case.mode).value)
    return rig.launch(
        KinematicState(0.0, 0.0, 0.0, speed_a),
        KinematicState(launch.position_b[0], launch.position_b[1], launch.yaw_b, speed_b),
        max_time=launch.time_to_contact + 4.0,
        velocity_a=launch.velocity_a,
        velocity_b=launch.velocity_b,
    )


def run_case(case: ImpactCase) -> Row:
    """Launch one impact and return its row (status "miss" or "error: ..." on failure)."""
    design = case.design()
    try:
        measurement = launch_case(case)
    except Exception as error:  # noqa: BLE001 - one failed case must not end a sweep
        row = {c: math.nan for c in COLUMNS} | design
        row.update(source="sweep", status=f"error: {type(error).__name__}: {error}")
        return row
    if measurement is None:
        row = {c: math.nan for c in COLUMNS} | design
        row.update(source="sweep", status="miss")
        return row
    record = compare_impact(measurement, restitution=restitution_for(case.restitution_set))
    return row_from_impact(record, source="sweep", design=design)


def run_sweep(
    cases: Sequence[ImpactCase],
    csv_path: Path,
    workers: int = 2,
    progress: bool = True,
    on_row: Callable[[Row], None] | None = None,
) -> list[Row]:
    """Run the cases not yet in ``csv_path``, appending their rows; return all rows.

    Args:
        cases: impacts to run.
        csv_path: ``impacts.csv``; existing rows with a case's id are kept and skipped.
        workers: processes (spawn context); 1 runs in this process.
        progress: show a tqdm progress bar.
        on_row: called with every new row.

    Returns:
        Rows of all requested cases (existing ones read back from the CSV), in case order.
    """
    existing = {r["id"]: r for r in read_rows(csv_path)} if csv_path.exists() else {}
    todo = [c for c in cases if c.id not in existing]
    new: dict[str, Row] = {}
    if todo:
        write_rows(csv_path, [], append=bool(existing))
        bar = _progress(len(todo), progress)
        for row in _map(todo, workers):
            write_rows(csv_path, [row], append=True)
            new[row["id"]] = row
            if on_row is not None:
                on_row(row)
            bar.update(1)
        bar.close()
    merged = existing | new
    return [merged[c.id] for c in cases]


def _map(cases: Sequence[ImpactCase], workers: int) -> Iterable[Row]:
    if workers <= 1 or len(cases) < 8:
        yield from map(run_case, cases)
        return
    # Group by rig so each process compiles few models; chunks keep the bar moving.
    ordered = sorted(cases, key=lambda c: (c.restitution_set, c.mode, c.partner))
    context = multiprocessing.get_context("spawn")
    with context.Pool(workers) as pool:
        yield from pool.imap_unordered(run_case, ordered, chunksize=16)


class _NoBar:
    def update(self, n: int) -> None:
        """Do nothing."""

    def close(self) -> None:
        """Do nothing."""


def _progress(total: int, enabled: bool):  # noqa: ANN202 - tqdm or a stand-in
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, unit="impact", desc="impacts")
