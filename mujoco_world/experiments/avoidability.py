"""Avoidability search: could the ego have avoided its collision in the same world?

For a run with an ego-involved collision, the search re-simulates the run with its
own planner, world and seed, and copies the whole closed loop at every planning cycle
in the window before the collision (``ClosedLoop.fork``: MuJoCo data, behaviours,
controllers, contact episodes, metrics, the noise generator). From each copy, a
family of open-loop manoeuvres (``AvoidabilityFamily``) replaces the planner and is
simulated to the end of the window through the ego-planner protocol
(``agents.scripted.ScriptedPlanner``). The collision was **avoidable** if some
manoeuvre avoids every ego contact until the window's end; the search stops at the
first such manoeuvre.

Faithfulness: the copies are exact (the run continued from a copy with its own
planner gives the same summary bit for bit; tested), and the re-simulated run must
reproduce the stored record's ego collisions (time and partner), otherwise the
search refuses (the code or the planner changed since the run).

Branch times ("states the ego actually passed through"): the planning cycles from
``max(crash - lookback, first cycle at which the ego perceived its collision
partner)`` up to the last cycle before the collision. A manoeuvre started before the
ego could see what it hit would be hindsight, not avoidance.

Order (coarse to fine, early exit):

1. coarse: every ``coarse_step`` seconds from the earliest branch time, the coarse
   family (``AvoidabilityFamily.coarse``) at each;
2. fine: the whole family at the coarse branch time whose best manoeuvre had the
   least harm, then the ``refine`` best manoeuvres at every cycle within
   ``coarse_step`` of it.

The verdict "not avoidable" means no manoeuvre of the family at the searched branch
times avoided the collision; the best (least ego-involved harm) is reported.
"""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ethical_planner.config import VehicleConfig
from ethical_planner.road_users import Shape
from ethical_planner.validation import check, check_positive
from mujoco_world.agents.ego_planner import EGO_PLANNERS, EgoSetup, PlannerSpec
from mujoco_world.agents.scripted import ScriptedPlanner
from mujoco_world.evaluation.avoidability import Avoidability, BranchResult, ManoeuvreSpec
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.rules import Stop
from mujoco_world.loop.runner import ClosedLoop, closed_loop
from mujoco_world.loop.state import RunState
from mujoco_world.loop.summary import RunSummary
from mujoco_world.scenario.sources import resolve_scenario
from mujoco_world.scenario.spec import Scenario
from mujoco_world.storage.run_folder import store_avoidability
from mujoco_world.storage.run_record import RunRecord, read_record

#: Peak lateral acceleration of the quintic lateral move per metre over duration^2
#: (max |d''| of 10u^3 - 15u^4 + 6u^5 is 10 / sqrt(3)).
_QUINTIC_PEAK = 10.0 / math.sqrt(3.0)


@dataclass(frozen=True, slots=True)
class AvoidabilityFamily:
    """The manoeuvres tried at each branch time, and the search's windows.

    Every combination of a deceleration and a lateral move (none, a swerve of each
    ``swerves`` offset to either side, or a lane change to each neighbouring lane
    centre) over each duration, kept if its peak accelerations fit the friction
    circle: sqrt(decel^2 + (10/sqrt(3) |offset| / duration^2)^2) <= friction.

    Attributes:
        decelerations: braking levels [m/s^2] (0 keeps the speed; the vehicle's
            emergency deceleration is the hardest).
        swerves: lateral swerve sizes [m] (each to the left and to the right).
        durations: times of the lateral move [s].
        coarse_decelerations, coarse_durations: the subset of the coarse pass.
        lookback: how long before the collision branches start at the earliest [s].
        coarse_step: spacing of the coarse branch times [s].
        refine: manoeuvres refined at every cycle around the best coarse branch time.
        after: the window ends this long after the run's collision [s].
        after_contact: a branch ends this long after its own first ego contact [s].
        friction: friction-circle radius [m/s^2].
    """

    decelerations: tuple[float, ...] = (0.0, 3.0, 6.0, VehicleConfig().emergency_deceleration)
    swerves: tuple[float, ...] = (1.0, 2.0)
    durations: tuple[float, ...] = (1.0, 1.5, 2.5)
    coarse_decelerations: tuple[float, ...] = (0.0, 4.0, VehicleConfig().emergency_deceleration)
    coarse_durations: tuple[float, ...] = (1.5,)
    lookback: float = 5.0
    coarse_step: float = 0.5
    refine: int = 3
    after: float = 2.0
    after_contact: float = 0.5
    friction: float = VehicleConfig().friction_acceleration

    def __post_init__(self) -> None:
        check_positive(
            "avoidability",
            lookback=self.lookback,
            coarse_step=self.coarse_step,
            after=self.after,
            after_contact=self.after_contact,
            friction=self.friction,
        )
        check(self.refine >= 0, f"avoidability.refine must be >= 0, got {self.refine}")

    def manoeuvres(
        self, start: float, lane_moves: Sequence[float], coarse: bool = False
    ) -> list[ManoeuvreSpec]:
        """The family at one branch time, cheapest-to-judge first (braking, then lateral moves).

        Args:
            start: branch time [s].
            lane_moves: lateral offsets [m] from the ego's position to each other lane's
                centre (left positive).
            coarse: the coarse subset.
        """
        decels = self.coarse_decelerations if coarse else self.decelerations
        durations = self.coarse_durations if coarse else self.durations
        swerves = [sign * size for size in self.swerves for sign in (1.0, -1.0)]
        moves = [(0.0, 0.0, False)]
        moves += [(d, T, False) for d in swerves for T in durations]
        moves += [(d, T, True) for d in lane_moves for T in durations]
        out = []
        for offset, duration, lane in moves:
            lateral = _QUINTIC_PEAK * abs(offset) / duration**2 if duration > 0 else 0.0
            for decel in decels:
                if math.hypot(decel, lateral) <= self.friction + 1e-9:
                    out.append(ManoeuvreSpec(start, decel, offset, duration, lane))
        return out

    def describe(self) -> str:
        """The family in one line (kept in the verdict)."""
        return (
            f"decelerations {list(self.decelerations)} m/s^2 x (none, swerves +-{list(self.swerves)} m, "
            f"lane changes to neighbouring lane centres) over {list(self.durations)} s within the friction "
            f"circle {self.friction} m/s^2; branch times every cycle from max(crash - {self.lookback} s, "
            f"partner first seen), coarse every {self.coarse_step} s; window to crash + {self.after} s"
        )


class _Window:
    """Stop rule of a branch: the window's end, or ``after_contact`` after the ego's first contact."""

    def __init__(self, end: float, after_contact: float) -> None:
        self.end, self.after_contact = end, after_contact
        self.interval = 10

    def start(self, run: RunState) -> None:
        """Nothing to reset."""

    def check(self, run: RunState) -> Stop | None:
        """``crash``/``timeout`` at the window's end or shortly after a contact."""
        if run.crash_time is not None and run.time >= run.crash_time + self.after_contact:
            return Stop("crash", "avoidability window: after the ego's contact")
        if run.time >= self.end - 1e-9:
            return Stop("crash" if run.crash_time is not None else "timeout", "avoidability window ended")
        return None


def _first_ego_contact(summary: RunSummary) -> tuple[float, int]:
    """Time [s] and partner entity of the run's first ego collision (-1: a wall)."""
    first = min(summary.ego_collisions, key=lambda c: c.measurement.time)
    m = first.measurement
    return float(m.time), int(m.b.entity)


def _lane_moves(loop: ClosedLoop) -> list[float]:
    """Lateral offsets [m] from the ego to each other lane centre of its road."""
    world = loop.world
    env = world.environment()
    _, d = world.ego_path.to_frenet(world.scene.qpos[0, 0], world.scene.qpos[0, 1])
    offsets = np.asarray(env.lane_offsets, dtype=float)
    own = offsets[int(np.argmin(np.abs(offsets - float(d))))]
    return [float(o - float(d)) for o in offsets if abs(o - own) > 1e-9]


class _Search:
    """One search: the re-simulated run's copies and the branches tried from them."""

    def __init__(self, scenario: Scenario, family: AvoidabilityFamily, window_end: float) -> None:
        self.scenario, self.family, self.window_end = scenario, family, window_end
        self.snapshots: dict[float, ClosedLoop] = {}
        self.tried: dict[ManoeuvreSpec, BranchResult] = {}
        self.found: BranchResult | None = None

    def branch(self, spec: ManoeuvreSpec) -> BranchResult:
        """Simulate one manoeuvre from its branch time (memoised)."""
        if spec in self.tried:
            return self.tried[spec]
        snapshot = self.snapshots[spec.start]
        ego = self.scenario.ego
        world = snapshot.world
        setup = EgoSetup(world.environment(), Shape(ego.length, ego.width), ego.mass, world.goal_s)
        planner = ScriptedPlanner(spec.manoeuvre(), setup)
        fork = snapshot.fork(planner, rules=[_Window(self.window_end, self.family.after_contact)])
        s = fork.resume()
        ego_hits = s.ego_collisions
        result = BranchResult(
            manoeuvre=spec,
            outcome=s.outcome,
            ego_collided=bool(ego_hits) or fork.run.crash_time is not None,
            collision_time=float(fork.run.crash_time) if fork.run.crash_time is not None else math.nan,
            min_distance=float(s.min_distance),
            min_distance_vulnerable=float(s.min_distance_vulnerable),
            harm_ego_involved=dict(s.harm_ego_involved),
        )
        self.tried[spec] = result
        if not result.ego_collided and self.found is None:
            self.found = result
        return result

    def first_free(self, specs: Iterable[ManoeuvreSpec]) -> BranchResult | None:
        """Simulate ``specs`` in order until one avoids every ego contact."""
        for spec in specs:
            if not self.branch(spec).ego_collided:
                return self.tried[spec]
        return None


def _rank(result: BranchResult) -> tuple[float, float, float]:
    """Least ego-involved harm first, then the later collision, then the larger clearance."""
    later = -result.collision_time if math.isfinite(result.collision_time) else -math.inf
    return (result.total_harm, later, -result.min_distance)


def _replay(
    scenario: Scenario,
    planner: PlannerSpec,
    seed: int,
    config: RunConfig,
    crash_time: float,
    partner: int,
    lookback: float,
) -> tuple[dict[float, ClosedLoop], float, RunSummary]:
    """Re-simulate the run, copying it at every cycle in the lookback window.

    Returns:
        (copies by branch time from the first cycle at which the partner was seen,
        that earliest branch time, the re-simulated run's summary).
    """
    loop = closed_loop(scenario, planner, seed, config)
    loop.start()
    cycle = loop.steps_per_cycle * loop.world.scene.dt
    n_crash = int(math.floor(crash_time / cycle - 1e-9))
    first = max(0, int(math.ceil((crash_time - lookback) / cycle - 1e-9)))
    snapshots: dict[float, ClosedLoop] = {}
    seen_at: float | None = None if partner >= 1 else 0.0
    for k in range(n_crash + 1):
        t = round(k * cycle, 9)
        stop = loop.advance(t)
        if stop is not None:
            break
        if seen_at is None and bool(loop.world.visible()[partner]):
            seen_at = t
        if k >= first and seen_at is not None and loop.run.crash_time is None:
            snapshots[t] = loop.fork(None)
    summary = loop.resume()
    earliest = max(first * cycle, seen_at if seen_at is not None else math.inf)
    return {t: s for t, s in snapshots.items() if t >= earliest - 1e-9}, earliest, summary


def _check_reproduced(original: RunSummary, again: RunSummary) -> None:
    """Raise ``ValueError`` unless the re-simulation has the record's first ego collision."""
    if not again.ego_collisions:
        raise ValueError(
            f"run {original.scenario}/{original.planner}/s{original.seed} does not reproduce: the "
            f"re-simulated ego did not collide ({again.outcome}: {again.reason}); the code or the "
            f"planner changed since the run was recorded"
        )
    t0, p0 = _first_ego_contact(original)
    t1, p1 = _first_ego_contact(again)
    if p0 != p1 or abs(t0 - t1) > 1e-6:
        raise ValueError(
            f"run {original.scenario}/{original.planner}/s{original.seed} does not reproduce: the first "
            f"ego collision was with entity {p0} at {t0:.3f} s, re-simulated with {p1} at {t1:.3f} s"
        )


def search(
    scenario: Scenario,
    planner: PlannerSpec,
    seed: int,
    original: RunSummary,
    config: RunConfig | None = None,
    family: AvoidabilityFamily | None = None,
) -> Avoidability:
    """Search whether the run's ego collision was avoidable (see the module docstring).

    Args:
        scenario: the run's scenario.
        planner: the run's planner (name, configuration or factory).
        seed: the run's seed.
        original: the run's summary (it must hold an ego collision).
        config: the run's loop settings.
        family: the manoeuvres and windows.

    Raises:
        ValueError: the run has no ego collision, or the re-simulation does not
            reproduce it.
    """
    clock = time.perf_counter()
    config = config or RunConfig()
    family = family or AvoidabilityFamily()
    check(bool(original.ego_collisions), "avoidability: the run has no ego-involved collision")
    crash_time, partner = _first_ego_contact(original)
    snapshots, earliest, again = _replay(
        scenario, planner, seed, config, crash_time, partner, family.lookback
    )
    _check_reproduced(original, again)
    window_end = min(crash_time + family.after, scenario.duration)
    run = _Search(scenario, family, window_end)
    run.snapshots = snapshots
    best = _explore(run, family)
    names = {b.id: b.name for b in original.bodies}
    return Avoidability(
        avoidable=best is not None and not best.ego_collided,
        crash_time=crash_time,
        partner=names.get(partner, "") if partner >= 0 else "",
        earliest_branch=earliest if math.isfinite(earliest) else crash_time,
        window_end=window_end,
        best=best,
        branches=len(run.tried),
        original_harm=dict(original.harm_ego_involved),
        wall_time=time.perf_counter() - clock,
        family=family.describe(),
    )


def _explore(run: _Search, family: AvoidabilityFamily) -> BranchResult | None:
    """Coarse to fine with early exit; the first collision-free branch, else the least harmful."""
    times = sorted(run.snapshots)
    if not times:
        return None
    moves = {t: _lane_moves(run.snapshots[t]) for t in times}
    stride = max(1, int(round(family.coarse_step / max(times[1] - times[0], 1e-9)))) if len(times) > 1 else 1
    coarse = times[::stride]
    for t in coarse:
        found = run.first_free(family.manoeuvres(t, moves[t], coarse=True))
        if found is not None:
            return found
    best_time = min(coarse, key=lambda t: min(_rank(r) for r in run.tried.values() if r.manoeuvre.start == t))
    found = run.first_free(family.manoeuvres(best_time, moves[best_time]))
    if found is not None:
        return found
    at_best = sorted((r for r in run.tried.values() if r.manoeuvre.start == best_time), key=_rank)
    near = [t for t in times if abs(t - best_time) <= family.coarse_step + 1e-9 and t != best_time]
    for result in at_best[: family.refine]:
        m = result.manoeuvre
        specs = [ManoeuvreSpec(t, m.deceleration, m.offset, m.duration, m.lane_change) for t in near]
        if m.lane_change:  # the lane centre is as far as the ego is from it at each time
            specs = [
                s
                for t in near
                for s in family.manoeuvres(t, moves[t])
                if s.lane_change
                and s.deceleration == m.deceleration
                and s.duration == m.duration
                and np.sign(s.offset) == np.sign(m.offset)
            ]
        found = run.first_free(specs)
        if found is not None:
            return found
    return min(run.tried.values(), key=_rank)


def planner_of(record: RunRecord, planner: PlannerSpec | None = None) -> PlannerSpec:
    """The planner a stored run ran with: ``planner`` if given, else its registered name or file.

    Raises:
        ValueError: the run's planner is neither registered nor a file (a configuration
            given on the command line): pass it as ``planner``.
    """
    if planner is not None:
        return planner
    source = record.planner_source or record.summary.planner
    if source in EGO_PLANNERS.names() or source.endswith(".toml"):
        return source
    raise ValueError(
        f"run {record.run_id}: its planner {source!r} is not a registered name or file; pass the "
        f"planner configuration it ran with (etp avoidability --config FILE.toml)"
    )


def search_record(
    record: RunRecord, planner: PlannerSpec | None = None, family: AvoidabilityFamily | None = None
) -> Avoidability:
    """``search`` on a stored run (scenario, planner, seed and loop settings from its record).

    Raises:
        ValueError: no ego collision, an unknown planner (see ``planner_of``), or a run
            that does not reproduce.
    """
    summary = record.summary
    scenario = resolve_scenario(record.scenario_source or summary.scenario)
    return search(scenario, planner_of(record, planner), summary.seed, summary, record.config, family)


def search_run_folder(
    folder: str | Path, planner: PlannerSpec | None = None, family: AvoidabilityFamily | None = None
) -> RunRecord:
    """Search a stored run and store the verdict in its record and index (``store_avoidability``)."""
    record = read_record(folder)
    verdict = search_record(record, planner, family)
    return store_avoidability(Path(folder) if Path(folder).is_dir() else Path(folder).parent, verdict)


def _search_in_worker(
    folder: str, planner: PlannerSpec | None, family: AvoidabilityFamily | None
) -> RunRecord:
    return search_run_folder(folder, planner, family)


def search_crashes(
    folders: Sequence[str | Path],
    planners: dict[str, PlannerSpec] | None = None,
    family: AvoidabilityFamily | None = None,
    workers: int = 2,
    progress: bool = False,
    worker_initializer: Callable[[], object] | None = None,
) -> list[tuple[Path, RunRecord | str]]:
    """Search every run folder whose record holds an ego collision, on ``workers`` processes.

    Args:
        folders: run folders (runs without an ego collision are skipped).
        planners: planner by the runs' planner name, for runs whose planner is not
            registered (``--config``); others are resolved from their record.
        family: the manoeuvres and windows.
        workers: processes (1: in this process).
        progress: show a progress bar.
        worker_initializer: called once in each worker process.

    Returns:
        (folder, the record with its verdict, or the error message) per searched run,
        in the order of ``folders``.
    """
    from tqdm import tqdm

    planners = planners or {}
    todo = []
    for folder in map(Path, folders):
        record = read_record(folder)
        if record.summary.ego_collisions and record.summary.outcome != "failed":
            todo.append((folder, planners.get(record.summary.planner)))
    results: dict[Path, RunRecord | str] = {}
    bar = tqdm(total=len(todo), disable=not progress, unit="crash", desc="avoidability", dynamic_ncols=True)
    if workers == 1 or len(todo) <= 1:
        for folder, planner in todo:
            try:
                results[folder] = search_run_folder(folder, planner, family)
            except ValueError as error:
                results[folder] = str(error)
            bar.update(1)
    else:
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(workers, mp_context=context, initializer=worker_initializer) as pool:
            futures = {pool.submit(_search_in_worker, str(f), p, family): f for f, p in todo}
            for future in as_completed(futures):
                try:
                    results[futures[future]] = future.result()
                except Exception as error:  # noqa: BLE001 - one failing search does not stop the others
                    results[futures[future]] = f"{type(error).__name__}: {error}"
                bar.update(1)
    bar.close()
    return [(f, results[f]) for f, _ in todo]


__all__ = [
    "AvoidabilityFamily",
    "planner_of",
    "search",
    "search_crashes",
    "search_record",
    "search_run_folder",
]
