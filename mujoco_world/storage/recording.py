"""Rerun recordings of closed-loop runs (the only module of the project that imports rerun).

``RerunRecorder`` is a ``RunObserver``: attach it to ``run_scenario`` and it writes
``<out_dir>/recording.rrd`` headless through an explicit ``rr.RecordingStream`` (no
global recording, no viewer). While the run goes on the file is
``<out_dir>/recording.partial.rrd``; it is renamed to ``recording.rrd`` when the
recorder closes (the run ended, also as failed or interrupted), so a file of that name
is always complete. The stream is flushed every ``RecorderConfig.flush_interval`` of
simulated time and at every impact, so a process that dies (a segfault, ``kill -9``)
leaves a readable ``recording.partial.rrd`` that lacks at most that interval.

Entities (all in the world frame, z up, road plane z = 0):

* ``world/road/{surface,boundary,lanes,walls}`` (static): drivable area, its outline,
  lane markings (``RoadGeometry.lane_markings``: solid outer lane edges and centre line
  between the directions, dashed lines between lanes of one direction), wall or kerb
  boxes; ``world/road/no_overtaking``: each no-overtaking zone's double centre line
  (amber).
* ``world/ego`` and ``world/road_users/{boxes,round}`` every logged frame: boxes
  (Boxes3D with yaw quaternions) and pedestrians as cylinders, coloured by type,
  labelled ``type #id``; ``world/ego_path``: the executed ego path.
* ``world/plan/{chosen,candidates}`` and ``world/prediction/{means,sigma1,sigma2}``
  each planning cycle; ``decision`` holds the decision record as a TextLog.
* ``series/{risk,collision_probability,harm}/user_<id>``, ``series/ego/{risk,
  max_acceptable_risk}``, ``series/cost/<term>``, ``series/planning_ms`` (the cycle's
  CPU time, ``Decision.timings_ms["total"]``) and
  ``series/level``, on the ``sim_time`` and ``cycle`` timelines, sent in columns.
* Why this plan, per planning cycle (``sim_time`` and ``cycle``):

  - ``series/candidates/{total,valid,unassessed}`` and ``series/rejected/<level>``
    with <level> one of ``physically_invalid``, ``collision``, ``leaves_road``,
    ``above_max_risk``, ``breaks_traffic_rule``: candidates per validity level (they
    add up to ``total``); ``unassessed``: candidates whose risk the planner did not
    evaluate because their Eq. 5 cost at zero risk is already above the chosen
    plan's (valid, above R_max or rule-breaking, unknown which; drawn in a pale blue-grey, never
    counted as either level);
    ``series/rejected/limit/<limit>``: candidates breaking each physical limit
    (``speed``, ``acceleration``, ``curvature``, ``lateral_acceleration``,
    ``friction``; one candidate may break several); ``series/rejected/
    max_risk_refused``: candidates above R_max that Eq. 5 would have preferred
    to the chosen one (R_max decided the cycle if > 0).
  - ``series/best_cost/<level>`` (``valid`` and the four above): the cost of the
    cheapest candidate of each level (Eq. 5 on ``valid``, Eq. 6 below; nan if the
    level is empty or was not costed: the planner assesses risk only for the best
    level possible without integrals, ``Decision.best_by_level``) and
    ``world/plan/best``: their paths, one strip per costed level (highest level
    first), coloured by level and labelled with the level, family, parameters and
    cost.
  - ``series/chosen/{horizon,end_speed,end_offset,deceleration,family}``: the
    chosen candidate's parameters [s, m/s, m, m/s^2; family: ``CandidateKind``
    value, 0 grid, 1 brake, 2 continuation, 3 emergency].
  - ``series/plan_switch``: 1 when the chosen plan is not the continuation of the
    previous cycle's plan (0 in the first cycle).
* The moment, at the frame rate (``sim_time``): ``series/motion/{speed,
  acceleration}`` of the ego along its heading [m/s, m/s^2]; per road user
  ``series/ttc/user_<id>`` (constant-velocity time to collision from the true
  state [s]; nan if none within ``RecorderConfig.ttc_horizon``),
  ``series/distance/user_<id>`` (geom distance to the ego [m]; nan beyond 50 m)
  and ``series/visible/user_<id>`` (1 if the ego perceives it, 0 if it is out of
  sensor range or occluded; nan while it is not in the world), and in the scene
  ``world/hidden``: a white ring around every road user the ego does not perceive. A
  road user with no value in a flush interval is not written for that interval.
* ``world/impacts/<n>/{point,force}`` and ``impacts/<n>/<body>/{dv_measured,
  dv_predicted,harm_measured,harm_predicted}``, plus an ``impacts`` TextLog.
* ``world/stop_lines/<name>``: each stop line across the road, red while its light
  is red and green otherwise (the colour changes at the red windows' edges); a stop
  sign's line is white.
* ``sight`` (TextLog): a road user's name and type the moment the planner first
  perceives it (``World.first_seen``; sensor range, field of view, occlusion).

The default blueprint shows a top-down view that follows the ego
(``EyeControls3D.tracking_entity = world/ego`` at ``RecorderConfig.follow_height``;
an ``overview`` tab shows the whole road), the decision log below it and three
tabbed groups of plots on the right: risks and costs; rejected candidates, best
cost per level, chosen candidate, plan switch; time to collision, distance,
visibility, ego speed and acceleration.

Rerun is imported when the first ``RerunRecorder`` is built, not with this module,
so the layering check (``mujoco_world`` pulls in no rerun on import) holds.

Timelines: ``sim_time`` (duration [s]) on everything, ``cycle`` (sequence) on the
planning data.
"""

from __future__ import annotations

import math
import os
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import shapely

from ethical_planner.planner import Decision
from ethical_planner.road_users import RoadUserType
from ethical_planner.sampling import CandidateKind
from ethical_planner.validation import check
from ethical_planner.validity import LIMITS, UNASSESSED, Validity
from mujoco_world.agents.ego_planner import Plan
from mujoco_world.evaluation.compare import ImpactRecord
from mujoco_world.loop.metrics import DISTANCE_CAP, ego_time_to_collision, footprint_extents
from mujoco_world.loop.observers import RunObserver
from mujoco_world.loop.summary import RunSummary
from mujoco_world.loop.world import World
from mujoco_world.scenario.spec import Scenario

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb


def _load_rerun() -> None:
    """Import rerun on first use, so importing ``mujoco_world`` never pulls it in (layering)."""
    global rr, rrb
    import rerun as rr
    import rerun.blueprint as rrb


#: File name of a run's recording inside its output folder.
RECORDING_FILE = "recording.rrd"
#: Name of a recording while its run goes on (left behind by a process that died).
PARTIAL_RECORDING_FILE = "recording.partial.rrd"
#: RGB colour per road-user type.
TYPE_COLORS: dict[RoadUserType, tuple[int, int, int]] = {
    RoadUserType.CAR: (70, 130, 220),
    RoadUserType.TAXI: (240, 200, 40),
    RoadUserType.PARKED_VEHICLE: (120, 120, 140),
    RoadUserType.PRIORITY_VEHICLE: (230, 60, 60),
    RoadUserType.TRUCK: (150, 90, 40),
    RoadUserType.BUS: (230, 130, 30),
    RoadUserType.MOTORCYCLE: (170, 60, 200),
    RoadUserType.BICYCLE: (40, 190, 120),
    RoadUserType.PEDESTRIAN: (250, 100, 160),
    RoadUserType.TRAIN: (90, 90, 90),
}
EGO_COLOR = (20, 220, 220)
#: RGBA colour of candidates per validity level (0, 1, 2, 3, 4, 10).
LEVEL_COLORS: dict[int, tuple[int, int, int, int]] = {
    0: (120, 120, 120, 60),
    1: (220, 40, 40, 90),
    2: (240, 140, 30, 90),
    3: (230, 210, 40, 90),
    4: (170, 80, 220, 90),
    10: (60, 200, 80, 110),
}
#: RGBA colour of candidates whose risk the planner did not evaluate (``UNASSESSED``).
UNASSESSED_COLOR = (150, 160, 190, 50)
_ELLIPSE_POINTS = 25
_Z_LINE = 0.05  # lines slightly above the road surface [m]
#: Stop-line colours: a light red, a light not red, a stop sign.
_RED, _GREEN, _STOP_SIGN = (230, 40, 40), (60, 200, 90), (245, 245, 245)
_Z_GONE = -50.0  # height of bodies out of the world: out of sight below the road [m]


@dataclass(frozen=True, slots=True)
class RecorderConfig:
    """What a ``RerunRecorder`` logs and how often.

    Attributes:
        frame_rate: body poses per simulated second [Hz] (rounded to whole physics steps).
        candidates: candidates logged per cycle; None logs all of them.
        prediction_stride: every how many prediction steps an ellipse is drawn (>= 1).
        flush_interval: simulated time between flushes of the file [s].
        application_id: Rerun application id.
        ttc_horizon: look-ahead of the logged time to collision [s] (longer: not logged).
        follow_height: height of the eye of the view that follows the ego [m] (about
            1.2 times the stretch of road it shows).
    """

    frame_rate: float = 20.0
    candidates: int | None = None
    prediction_stride: int = 5
    flush_interval: float = 1.0
    application_id: str = "ethical_trajectory_planning"
    ttc_horizon: float = 10.0
    follow_height: float = 45.0

    def __post_init__(self) -> None:
        check(
            isinstance(self.frame_rate, int | float)
            and math.isfinite(self.frame_rate)
            and self.frame_rate > 0,
            f"recorder.frame_rate must be a finite number > 0 Hz, got {self.frame_rate!r}",
        )
        check(
            self.candidates is None or (isinstance(self.candidates, int) and self.candidates >= 0),
            f"recorder.candidates must be None (all) or an integer >= 0, got {self.candidates!r}",
        )
        check(
            isinstance(self.prediction_stride, int) and self.prediction_stride >= 1,
            f"recorder.prediction_stride must be an integer >= 1, got {self.prediction_stride!r}",
        )
        check(
            isinstance(self.flush_interval, int | float) and self.flush_interval > 0,
            f"recorder.flush_interval must be > 0 s, got {self.flush_interval!r}",
        )
        check(bool(self.application_id), "recorder.application_id must be a non-empty string")
        check(
            isinstance(self.ttc_horizon, int | float)
            and math.isfinite(self.ttc_horizon)
            and self.ttc_horizon > 0,
            f"recorder.ttc_horizon must be a finite number > 0 s, got {self.ttc_horizon!r}",
        )
        check(
            isinstance(self.follow_height, int | float)
            and math.isfinite(self.follow_height)
            and self.follow_height > 0,
            f"recorder.follow_height must be a finite number > 0 m, got {self.follow_height!r}",
        )


def yaw_quaternions(yaw: np.ndarray) -> np.ndarray:
    """Quaternions (x, y, z, w) of rotations about +z by ``yaw`` [rad], shape (n,) -> (n, 4)."""
    half = 0.5 * np.asarray(yaw, dtype=float)
    zeros = np.zeros_like(half)
    return np.column_stack([zeros, zeros, np.sin(half), np.cos(half)])


def ellipse_strips(mean: np.ndarray, cov: np.ndarray, scale: float, n: int = _ELLIPSE_POINTS) -> np.ndarray:
    """Outlines of the ``scale``-sigma ellipses of 2D Gaussians.

    Args:
        mean: centres [m], shape (m, 2).
        cov: covariances [m^2], shape (m, 2, 2).
        scale: number of standard deviations.
        n: points per closed outline.

    Returns:
        Points [m], shape (m, n, 2); the first and last point coincide.
    """
    values, vectors = np.linalg.eigh(cov)  # (m, 2), (m, 2, 2)
    axes = vectors * (scale * np.sqrt(np.clip(values, 0.0, None)))[:, None, :]
    phi = np.linspace(0.0, 2.0 * math.pi, n)
    unit = np.stack([np.cos(phi), np.sin(phi)])  # (2, n)
    return mean[:, None, :] + np.einsum("mij,jn->mni", axes, unit)


def _to3(points: np.ndarray, z: float = _Z_LINE) -> np.ndarray:
    """Append a constant z to (..., 2) points."""
    return np.concatenate([points, np.full(points.shape[:-1] + (1,), z)], axis=-1)


def _rgb(t: RoadUserType) -> tuple[int, int, int]:
    return TYPE_COLORS.get(t, (200, 200, 200))


#: Validity levels whose candidates were not chosen for a reason, logged under ``series/rejected``.
REJECTED_LEVELS = (
    Validity.PHYSICALLY_INVALID,
    Validity.COLLISION,
    Validity.LEAVES_ROAD,
    Validity.ABOVE_MAX_RISK,
    Validity.BREAKS_TRAFFIC_RULE,
)


def _level_name(level: int) -> str:
    return Validity(level).name.lower()


def _finite(value: float) -> float:
    return float(value) if math.isfinite(value) else math.nan


class _SeriesBuffer:
    """Scalars kept per entity until they are sent as columns."""

    def __init__(self) -> None:
        self.time: dict[str, list[float]] = defaultdict(list)
        self.cycle: dict[str, list[int]] = defaultdict(list)
        self.value: dict[str, list[float]] = defaultdict(list)
        self.rows: dict[str, tuple[list[float], list[np.ndarray]]] = {}

    def add(self, path: str, t: float, cycle: int | None, value: float) -> None:
        self.time[path].append(t)
        self.cycle[path].append(-1 if cycle is None else cycle)
        self.value[path].append(float(value))

    def add_row(self, prefix: str, t: float, values: np.ndarray) -> None:
        """One value per road user at ``t``: entity ``<prefix>/user_<i>`` gets ``values[i - 1]``."""
        times, rows = self.rows.setdefault(prefix, ([], []))
        times.append(t)
        rows.append(np.asarray(values, dtype=float))

    def send(self, rec: rr.RecordingStream) -> None:
        for prefix, (times, rows) in self.rows.items():
            table = np.vstack(rows)  # (frames, road users)
            index = [rr.TimeColumn("sim_time", duration=np.asarray(times))]
            # Road users without a single value in this window (absent, out of range) are left out.
            for j in np.flatnonzero(np.isfinite(table).any(axis=0)):
                rec.send_columns(
                    f"{prefix}/user_{j + 1}", indexes=index, columns=rr.Scalars.columns(scalars=table[:, j])
                )
        self.rows.clear()
        for path, times in self.time.items():
            if not times:
                continue
            indexes = [rr.TimeColumn("sim_time", duration=np.asarray(times))]
            cycles = self.cycle[path]
            if cycles[0] >= 0:
                indexes.append(rr.TimeColumn("cycle", sequence=np.asarray(cycles, dtype=np.int64)))
            rec.send_columns(
                path, indexes=indexes, columns=rr.Scalars.columns(scalars=np.asarray(self.value[path]))
            )
        self.time.clear()
        self.cycle.clear()
        self.value.clear()


class RerunRecorder(RunObserver):
    """Writes a Rerun recording of one run (see the module docstring for its content).

    Args:
        out_dir: folder of the run; the recording is ``out_dir / "recording.rrd"``
            (``recording.partial.rrd`` until the recorder closes).
        config: what to log.
        recording_id: Rerun recording id (default: the folder's name).

    Attributes:
        path: the recording file, once the recorder is closed.
        partial_path: the file while the run goes on.
        cycle: planning cycles seen so far.
    """

    def __init__(
        self, out_dir: str | Path, config: RecorderConfig | None = None, recording_id: str | None = None
    ) -> None:
        _load_rerun()
        self.config = config or RecorderConfig()
        self.out_dir = Path(out_dir)
        self.path = self.out_dir / RECORDING_FILE
        self.partial_path = self.out_dir / PARTIAL_RECORDING_FILE
        self.recording_id = recording_id or self.out_dir.resolve().name
        self.rec: rr.RecordingStream | None = None
        self.cycle = 0
        self.step_interval = 50
        self._series = _SeriesBuffer()
        self._path_xy: list[np.ndarray] = []
        self._next_flush = 0.0
        self._impacts = 0
        self._decisions = 0
        self._hidden_shown = False
        self._rng = np.random.default_rng(0)  # candidate subsampling only, fixed for reproducibility
        self._closed = False
        self._seen = np.zeros(0, dtype=bool)  # road users logged as first seen

    # ------------------------------------------------------------------ hooks

    def on_start(self, world: World, scenario: Scenario, planner: str, seed: int) -> None:
        """Open the stream, write the blueprint and the static scene."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.step_interval = max(int(round(1.0 / (self.config.frame_rate * world.scene.dt))), 1)
        rec = rr.RecordingStream(self.config.application_id, recording_id=self.recording_id)
        self.path.unlink(missing_ok=True)  # an older run's complete file is not this run's
        rec.save(self.partial_path, default_blueprint=self._blueprint(world))
        self.rec = rec
        self._world_static(world, scenario, planner, seed)
        self._bodies = _BodyLayout(world)
        self._extent = footprint_extents(world)
        self._seen = np.zeros(world.n, dtype=bool)
        self._log_body_shapes()
        rec.set_time("sim_time", duration=world.time)
        self._log_bodies(world)
        self._log_state_series(world, world.time)
        self._next_flush = world.time + self.config.flush_interval
        rec.flush()

    def on_step(self, world: World, time: float) -> None:
        """Log every body's pose (called at the recorder's frame rate)."""
        if self.rec is None:
            return
        self.rec.set_time("sim_time", duration=time)
        self._log_bodies(world)
        self._log_state_series(world, time)
        self._log_first_seen(world)
        if time >= self._next_flush:
            self._flush()
            self._next_flush = time + self.config.flush_interval

    def on_cycle(self, plan: Plan, time: float) -> None:
        """Log the plan and, if it carries a decision, the candidates, prediction, record and series."""
        rec = self.rec
        if rec is None:
            return
        rec.set_time("sim_time", duration=time)
        rec.set_time("cycle", sequence=self.cycle)
        traj = plan.trajectory
        rec.log(
            "world/plan/chosen",
            rr.LineStrips3D(
                [_to3(np.column_stack([traj.x, traj.y]), 2 * _Z_LINE)], colors=[EGO_COLOR], radii=0.12
            ),
        )
        if plan.decision is not None:
            self._log_decision(plan.decision, time)
        self.cycle += 1
        rec.disable_timeline("cycle")  # body poses between cycles carry sim_time only

    def _log_decision(self, decision: Decision, time: float) -> None:
        rec = self._stream()
        self._log_candidates(decision)
        self._log_prediction(decision)
        rec.log("decision", rr.TextLog(decision.summary(), level="INFO" if decision.level == 10 else "WARN"))
        s, c = self._series, self.cycle
        for u in decision.road_users:
            s.add(f"series/risk/user_{u.id}", time, c, u.risk)
            s.add(f"series/collision_probability/user_{u.id}", time, c, u.collision_probability)
            s.add(f"series/harm/user_{u.id}", time, c, u.harm)
        s.add("series/ego/risk", time, c, decision.ego_combined_risk)
        s.add("series/ego/max_acceptable_risk", time, c, decision.max_acceptable_risk)
        for name, value in decision.costs.items():
            if math.isfinite(value):
                s.add(f"series/cost/{name}", time, c, value)
        s.add("series/planning_ms", time, c, float(decision.timings_ms["total"]))
        s.add("series/level", time, c, float(decision.level))
        self._log_rejections(decision, time)
        self._log_best(decision, time)
        chosen = decision.candidate
        for name, value in (
            ("horizon", chosen.horizon),
            ("end_speed", chosen.end_speed),
            ("end_offset", chosen.end_offset),
            ("deceleration", chosen.deceleration),
            ("family", float(chosen.kind)),
        ):
            s.add(f"series/chosen/{name}", time, c, value)
        # A plan switch: a plan existed and the chosen one is not its continuation.
        s.add("series/plan_switch", time, c, float(self._decisions > 0 and not decision.continued))
        self._decisions += 1

    def _log_rejections(self, decision: Decision, time: float) -> None:
        """Candidates per validity level (they sum to ``total``) and per broken physical limit."""
        s, c = self._series, self.cycle
        counts = decision.level_counts
        s.add("series/candidates/total", time, c, float(len(decision.candidate_levels)))
        s.add("series/candidates/valid", time, c, float(counts.get(int(Validity.VALID), 0)))
        s.add("series/candidates/unassessed", time, c, float(counts.get(UNASSESSED, 0)))
        for level in REJECTED_LEVELS:
            s.add(f"series/rejected/{_level_name(level)}", time, c, float(counts.get(int(level), 0)))
        s.add("series/rejected/max_risk_refused", time, c, float(decision.max_risk_refused))
        s.add("series/rejected/terminal_unsafe", time, c, float(decision.terminal_unsafe))
        for limit in LIMITS:
            s.add(f"series/rejected/limit/{limit}", time, c, float(decision.invalid_counts.get(limit, 0)))

    def _log_best(self, decision: Decision, time: float) -> None:
        """The cheapest candidate of every level: its cost as a series, its path in the scene."""
        s, c = self._series, self.cycle
        strips, colors, labels = [], [], []
        for level in sorted(Validity, reverse=True):
            name = _level_name(level)
            best = decision.best_by_level.get(int(level))
            s.add(f"series/best_cost/{name}", time, c, math.nan if best is None else best.cost)
            if best is None:
                continue
            xy = np.column_stack([decision.candidate_x[best.index], decision.candidate_y[best.index]])
            strips.append(_to3(xy, 1.5 * _Z_LINE))
            colors.append(LEVEL_COLORS[int(level)][:3])
            labels.append(f"{name}: {best.candidate.describe()}, cost {best.cost:.4g}")
        # One entity, one strip per level present (the levels absent this cycle vanish).
        self._stream().log(
            "world/plan/best",
            rr.LineStrips3D(strips, colors=colors, radii=0.06, labels=labels, show_labels=False),
        )

    def on_impact(self, record: ImpactRecord) -> None:
        """Log the contact point, the force arrow, delta-v and harm (measured and predicted)."""
        rec = self.rec
        if rec is None:
            return
        m = record.measurement
        k = self._impacts
        self._impacts += 1
        rec.set_time("sim_time", duration=m.time)
        points, vectors, labels = [], [], []
        lines = [f"impact {k} at t = {m.time:.3f} s: {m.a.name} ({m.a.type}) - {m.b.name} ({m.b.type})"]
        for body, comp in ((m.a, record.a), (m.b, record.b)):
            if body.is_static:
                continue
            c, s_ = math.cos(body.yaw), math.sin(body.yaw)
            px = body.position[0] + c * body.contact_point[0] - s_ * body.contact_point[1]
            py = body.position[1] + s_ * body.contact_point[0] + c * body.contact_point[1]
            impulse = np.asarray(body.impulse, dtype=float)
            norm = float(np.hypot(*impulse))
            direction = impulse / norm if norm > 0 else np.zeros(2)
            points.append((px, py, 0.5))
            vectors.append((*(direction * max(comp.dv_measured, 0.5)), 0.0))
            label = (
                f"{body.name}: dv {comp.dv_measured:.2f} m/s (pred {comp.dv_predicted:.2f}), "
                f"area {comp.area_measured} (pred {comp.area_predicted}), "
                f"harm {comp.harm_measured:.3f} (pred {comp.harm_predicted:.3f})"
            )
            labels.append(label)
            lines.append("  " + label)
            base = f"impacts/{k}/{body.name}"
            for name, value in (
                ("dv_measured", comp.dv_measured),
                ("dv_predicted", comp.dv_predicted),
                ("harm_measured", comp.harm_measured),
                ("harm_predicted", comp.harm_predicted),
            ):
                rec.log(f"{base}/{name}", rr.Scalars(_finite(value)))
        if points:
            rec.log(
                f"world/impacts/{k}/point",
                rr.Points3D(points, radii=0.3, colors=[(255, 0, 0)], labels=labels),
            )
            rec.log(
                f"world/impacts/{k}/force",
                rr.Arrows3D(origins=points, vectors=vectors, colors=[(255, 60, 0)], radii=0.08),
            )
        rec.log("impacts", rr.TextLog("\n".join(lines), level="ERROR"))
        rec.flush()

    def on_end(self, summary: RunSummary) -> None:
        """Log the final path and the outcome, then close the file."""
        rec = self.rec
        if rec is None or self._closed:
            return
        rec.set_time("sim_time", duration=summary.duration)
        rec.log(
            "decision",
            rr.TextLog(f"run ended: {summary.outcome} ({summary.reason})", level="INFO"),
        )
        self.close()

    # ------------------------------------------------------------------ lifecycle

    def close(self) -> None:
        """Send what is buffered, close the file and give it its final name (idempotent)."""
        if self.rec is None or self._closed:
            return
        self._flush()
        self.rec.disconnect()
        self._closed = True
        os.replace(self.partial_path, self.path)

    def _stream(self) -> rr.RecordingStream:
        if self.rec is None:
            raise RuntimeError("RerunRecorder: on_start has not been called")
        return self.rec

    def _flush(self) -> None:
        rec = self.rec
        if rec is None:
            return
        if self._path_xy:
            rec.log(
                "world/ego_path",
                rr.LineStrips3D([_to3(np.asarray(self._path_xy))], colors=[EGO_COLOR], radii=0.06),
            )
        self._series.send(rec)
        rec.flush()

    # ------------------------------------------------------------------ content

    def _world_static(self, world: World, scenario: Scenario, planner: str, seed: int) -> None:
        rec = self._stream()
        road = world.road
        area = road.drivable_area
        try:
            triangles = shapely.constrained_delaunay_triangles(area)
            tri = np.asarray([np.asarray(t.exterior.coords)[:3] for t in triangles.geoms])
            vertices = _to3(tri.reshape(-1, 2), 0.0)
            rec.log(
                "world/road/surface",
                rr.Mesh3D(
                    vertex_positions=vertices,
                    triangle_indices=np.arange(len(vertices)).reshape(-1, 3),
                    albedo_factor=(60, 60, 66, 255),
                ),
                static=True,
            )
        except (AttributeError, ValueError):  # older shapely or a degenerate area: outline only
            pass
        # A mapped road's drivable area may fall apart into several polygons.
        polygons = getattr(area, "geoms", [area])
        rings = [np.asarray(r.coords) for p in polygons for r in (p.exterior, *p.interiors)]
        rec.log(
            "world/road/boundary",
            rr.LineStrips3D([_to3(r) for r in rings], colors=[(240, 240, 240)], radii=0.08),
            static=True,
        )
        markings = road.lane_markings()
        lines = [*markings.solid, *markings.dashed]
        if lines:
            rec.log(
                "world/road/lanes",
                rr.LineStrips3D([_to3(line) for line in lines], colors=[(250, 250, 200)], radii=0.06),
                static=True,
            )
        if markings.no_overtaking:
            rec.log(
                "world/road/no_overtaking",
                rr.LineStrips3D(
                    [_to3(line) for line in markings.no_overtaking], colors=[(255, 190, 40)], radii=0.07
                ),
                static=True,
            )
        boxes = road.static_boxes()
        if boxes:
            rec.log(
                "world/road/walls",
                rr.Boxes3D(
                    centers=[(b.center[0], b.center[1], b.half_height) for b in boxes],
                    half_sizes=[(b.half_length, b.half_width, b.half_height) for b in boxes],
                    quaternions=yaw_quaternions(np.array([b.yaw for b in boxes])),
                    colors=[(160, 160, 160)],
                    fill_mode="solid",
                ),
                static=True,
            )
        self._log_stop_lines(world, scenario)
        rec.log(
            "run",
            rr.TextDocument(
                f"# {scenario.name}\n\n{scenario.description}\n\nplanner: {planner}, seed: {seed}, "
                f"road users: {world.n - 1}",
                media_type="text/markdown",
            ),
            static=True,
        )
        series_style = [
            ("series/ego/risk", (20, 220, 220)),
            ("series/ego/max_acceptable_risk", (255, 60, 60)),
        ]
        for path, color in series_style:
            rec.log(path, rr.SeriesLines(colors=[color], names=[path.rsplit("/", 1)[-1]]), static=True)
        for i in range(1, world.n):
            name = f"{world.types[i].value} #{i}"
            color = _rgb(world.types[i])
            for kind in ("risk", "collision_probability", "harm", "ttc", "distance", "visible"):
                rec.log(f"series/{kind}/user_{i}", rr.SeriesLines(colors=[color], names=[name]), static=True)
        for level in Validity:
            color = LEVEL_COLORS[int(level)][:3]
            name = _level_name(level)
            rec.log(f"series/best_cost/{name}", rr.SeriesLines(colors=[color], names=[name]), static=True)
            if level in REJECTED_LEVELS:
                rec.log(f"series/rejected/{name}", rr.SeriesLines(colors=[color], names=[name]), static=True)
        rec.log(
            "series/candidates/valid",
            rr.SeriesLines(colors=[LEVEL_COLORS[10][:3]], names=["valid"]),
            static=True,
        )
        rec.log(
            "series/candidates/total", rr.SeriesLines(colors=[(230, 230, 230)], names=["total"]), static=True
        )
        rec.log(
            "series/candidates/unassessed",
            rr.SeriesLines(colors=[UNASSESSED_COLOR[:3]], names=["not risk-assessed"]),
            static=True,
        )
        for limit in LIMITS:
            rec.log(f"series/rejected/limit/{limit}", rr.SeriesLines(names=[f"limit: {limit}"]), static=True)
        families = ", ".join(f"{k.value} {k.name.lower()}" for k in CandidateKind)
        rec.log(
            "series/chosen/family",
            rr.SeriesPoints(names=[f"family ({families})"], marker_sizes=[3.0]),
            static=True,
        )

    def _log_stop_lines(self, world: World, scenario: Scenario) -> None:
        """``world/stop_lines/<name>``: each line across the road, red while its light is red.

        The red windows are known at the start, so each colour change is logged at its
        own time; a stop sign is drawn white all run.
        """
        if not scenario.stop_lines:
            return
        rec = self._stream()
        environment = world.environment()
        offsets = np.asarray(environment.lane_offsets, dtype=float)
        half = 0.5 * environment.lane_width
        across = np.array([offsets.min() - half, offsets.max() + half])
        for line in scenario.stop_lines:  # a few lines, a few windows
            x, y = environment.reference_path.to_cartesian(np.full(2, line.s), across)
            strip = _to3(np.column_stack([x, y]))
            path = f"world/stop_lines/{line.name}"
            label = f"{line.name} ({'stop sign' if line.stop else 'traffic light'})"
            edges = sorted({0.0, *(max(t, 0.0) for window in line.red for t in window)})
            for t in edges:
                red = any(start <= t < end for start, end in line.red)
                color = _STOP_SIGN if line.stop else _RED if red else _GREEN
                rec.set_time("sim_time", duration=t)
                rec.log(path, rr.LineStrips3D([strip], colors=[color], radii=0.2, labels=[label]))
        rec.set_time("sim_time", duration=world.time)

    def _log_body_shapes(self) -> None:
        """Sizes, colours and labels once, as static data; frames then carry poses only."""
        rec = self._stream()
        layout = self._bodies
        rec.log(
            "world/ego",
            rr.Boxes3D.from_fields(
                half_sizes=layout.half_sizes[:1],
                colors=[EGO_COLOR],
                labels=[layout.labels[0]],
                fill_mode="solid",
            ),
            static=True,
        )
        boxes, round_ = layout.boxes, layout.round
        if len(boxes):
            rec.log(
                "world/road_users/boxes",
                rr.Boxes3D.from_fields(
                    half_sizes=layout.half_sizes[boxes],
                    colors=layout.colors[boxes],
                    labels=[layout.labels[i] for i in boxes],
                    fill_mode="solid",
                ),
                static=True,
            )
        if len(round_):
            rec.log(
                "world/road_users/round",
                rr.Cylinders3D.from_fields(
                    lengths=2.0 * layout.z[round_],
                    radii=layout.radius[round_],
                    colors=layout.colors[round_],
                    labels=[layout.labels[i] for i in round_],
                    fill_mode="solid",
                ),
                static=True,
            )

    def _log_first_seen(self, world: World) -> None:
        """A ``sight`` entry, at its time, for each road user first perceived since the last frame."""
        seen = ~np.isnan(world.first_seen)
        seen[0] = False
        new = np.flatnonzero(seen & ~self._seen)
        if new.size == 0:
            return
        self._seen[new] = True
        rec = self._stream()
        for i in new:
            t = float(world.first_seen[i])
            rec.set_time("sim_time", duration=t)
            who = f"{world.scene.names[i]} ({world.types[i].value})"
            rec.log("sight", rr.TextLog(f"first seen at {t:.2f} s: {who}"))
        rec.set_time("sim_time", duration=world.time)

    def _log_bodies(self, world: World) -> None:
        rec = self._stream()
        layout = self._bodies
        qpos = world.scene.qpos
        gone = ~world.present
        if gone.any():
            # A body out of the world sinks below the road where it left (one that has not
            # entered yet, below the ego), not drawn where it is parked far away.
            hidden = np.where(np.isnan(world.exit_pose), qpos[0], world.exit_pose)
            qpos = np.where(gone[:, None], hidden, qpos)
        centers = np.column_stack([qpos[:, :2], np.where(gone, _Z_GONE, layout.z)])
        quaternions = yaw_quaternions(qpos[:, 2])
        self._path_xy.append(qpos[0, :2].copy())
        rec.log("world/ego", rr.Boxes3D.from_fields(centers=centers[:1], quaternions=quaternions[:1]))
        boxes, round_ = layout.boxes, layout.round
        if len(boxes):
            rec.log(
                "world/road_users/boxes",
                rr.Boxes3D.from_fields(centers=centers[boxes], quaternions=quaternions[boxes]),
            )
        if len(round_):
            rec.log("world/road_users/round", rr.Cylinders3D.from_fields(centers=centers[round_]))

    def _log_state_series(self, world: World, time: float) -> None:
        """Ego speed and acceleration; TTC, distance and visibility of every road user."""
        s = self._series
        s.add("series/motion/speed", time, None, float(world.speeds_along_heading()[0]))
        s.add("series/motion/acceleration", time, None, float(world.accelerations_along_heading()[0]))
        if world.n < 2:
            return
        present = world.present[1:]
        ttc = ego_time_to_collision(world, self._extent, self.config.ttc_horizon)
        s.add_row("series/ttc", time, np.where(present & np.isfinite(ttc), ttc, math.nan))
        distance = world.ego_distances(DISTANCE_CAP)
        s.add_row("series/distance", time, np.where(present & (distance < DISTANCE_CAP), distance, math.nan))
        visible = world.visible()[1:]
        s.add_row("series/visible", time, np.where(present, visible, math.nan))
        # In the scene: a white ring around every road user the ego does not perceive now,
        # above the tallest body so that the vehicle hiding it does not hide the ring too.
        hidden = np.flatnonzero(present & ~visible) + 1
        if hidden.size or self._hidden_shown:
            centres = np.asarray(world.positions[hidden], dtype=float)
            radius = 0.5 * np.hypot(world.lengths[hidden], world.widths[hidden]) + 0.5
            circles = radius[:, None, None] ** 2 * np.eye(2)
            self._stream().log(
                "world/hidden",
                rr.LineStrips3D(
                    _to3(ellipse_strips(centres, circles, 1.0), self._bodies.z.max() * 2.0 + 0.2),
                    colors=[(255, 255, 255)],
                    radii=0.08,
                    labels=["not perceived"] * hidden.size,
                ),
            )
            self._hidden_shown = bool(hidden.size)

    def _log_candidates(self, decision: Decision) -> None:
        rec = self._stream()
        cx, cy = decision.candidate_x, decision.candidate_y
        levels = np.asarray(decision.candidate_levels)
        n = len(cx)
        limit = self.config.candidates
        if n == 0 or limit == 0:
            return
        index = np.arange(n)
        if limit is not None and n > limit:
            index = np.sort(self._rng.choice(n, size=limit, replace=False))
        strips = _to3(np.stack([cx[index], cy[index]], axis=-1))
        # Row v + 1 of the palette colours level v; row 0 the unassessed (v = -1).
        palette = np.array(
            [UNASSESSED_COLOR, *(LEVEL_COLORS.get(v, (200, 200, 200, 80)) for v in range(11))], dtype=np.uint8
        )
        colors = palette[np.clip(levels[index].astype(int) - UNASSESSED, 0, 11)]
        rec.log("world/plan/candidates", rr.LineStrips3D(strips, colors=colors, radii=0.02))

    def _log_prediction(self, decision: Decision) -> None:
        rec = self._stream()
        pred = decision.prediction
        mean = np.asarray(pred.mean)
        if mean.size == 0:
            rec.log("world/prediction", rr.Clear(recursive=True))
            return
        k, n_t = mean.shape[:2]
        colors = [_rgb(t) for t in pred.types]
        rec.log(
            "world/prediction/means",
            rr.LineStrips3D(
                _to3(mean),
                colors=colors,
                radii=0.05,
                labels=[f"#{int(i)}" for i in pred.ids],
                show_labels=False,
            ),
        )
        steps = np.arange(self.config.prediction_stride, n_t, self.config.prediction_stride)
        if steps.size == 0:
            steps = np.array([n_t - 1])
        m = mean[:, steps].reshape(-1, 2)
        cov = np.asarray(pred.cov)[:, steps].reshape(-1, 2, 2)
        ellipse_colors = np.repeat(np.asarray(colors, dtype=np.uint8), len(steps), axis=0)
        for scale, name in ((1.0, "sigma1"), (2.0, "sigma2")):
            rec.log(
                f"world/prediction/{name}",
                rr.LineStrips3D(
                    _to3(ellipse_strips(m, cov, scale)),
                    colors=ellipse_colors,
                    radii=0.03 if scale == 1.0 else 0.015,
                ),
            )

    def _blueprint(self, world: World) -> rrb.Blueprint:
        lo = np.asarray(world.road.drivable_area.bounds[:2])
        hi = np.asarray(world.road.drivable_area.bounds[2:])
        centre = 0.5 * (lo + hi)
        height = float(max(hi - lo)) * 0.9 + 10.0
        overview = rrb.Spatial3DView(
            origin="world",
            name="overview",
            eye_controls=rrb.EyeControls3D(
                position=[float(centre[0]), float(centre[1]) - 1.0, height],
                look_target=[float(centre[0]), float(centre[1]), 0.0],
                eye_up=[0.0, 0.0, 1.0],
            ),
        )
        # The ego view keeps the eye at its offset from the ego while the ego moves.
        ego = np.asarray(world.positions[0], dtype=float)
        follow = rrb.Spatial3DView(
            origin="world",
            name="top-down (follows the ego)",
            eye_controls=rrb.EyeControls3D(
                position=[float(ego[0]), float(ego[1]) - 1.0, self.config.follow_height],
                look_target=[float(ego[0]), float(ego[1]), 0.0],
                eye_up=[0.0, 0.0, 1.0],
                tracking_entity="world/ego",
            ),
        )
        return rrb.Blueprint(
            rrb.Horizontal(
                rrb.Vertical(
                    rrb.Tabs(follow, overview, name="scene"),
                    rrb.TextLogView(origin="/", contents=["decision", "impacts", "sight"], name="decisions"),
                    row_shares=[3, 1],
                ),
                rrb.Vertical(
                    rrb.Tabs(
                        rrb.TimeSeriesView(origin="series/risk", name="risk per road user"),
                        rrb.TimeSeriesView(
                            origin="series/collision_probability", name="collision probability"
                        ),
                        rrb.TimeSeriesView(origin="series/ego", name="ego risk vs R_max"),
                        rrb.TimeSeriesView(origin="series/cost", name="principle costs"),
                        rrb.TimeSeriesView(origin="series/planning_ms", name="planning CPU time [ms]"),
                    ),
                    rrb.Tabs(
                        rrb.TimeSeriesView(
                            origin="series",
                            contents=["$origin/rejected/**", "$origin/candidates/**"],
                            name="rejected candidates",
                        ),
                        rrb.TimeSeriesView(origin="series/best_cost", name="best cost per level"),
                        rrb.TimeSeriesView(origin="series/chosen", name="chosen candidate"),
                        rrb.TimeSeriesView(origin="series/plan_switch", name="plan switch"),
                    ),
                    rrb.Tabs(
                        rrb.TimeSeriesView(origin="series/ttc", name="time to collision [s]"),
                        rrb.TimeSeriesView(origin="series/distance", name="distance [m]"),
                        rrb.TimeSeriesView(origin="series/visible", name="visible"),
                        rrb.TimeSeriesView(origin="series/motion", name="ego speed and acceleration"),
                    ),
                ),
                column_shares=[3, 2],
            ),
            collapse_panels=True,
        )


class _BodyLayout:
    """Per-body constants for logging, computed once: sizes, colours, labels."""

    def __init__(self, world: World) -> None:
        bodies = world.scene.bodies
        self.round = np.array([i for i in range(1, world.n) if bodies[i].is_round], dtype=int)
        self.boxes = np.array([i for i in range(1, world.n) if not bodies[i].is_round], dtype=int)
        self.z = np.array([0.5 * b.height for b in bodies])
        self.half_sizes = np.column_stack([0.5 * world.lengths, 0.5 * world.widths, self.z])
        self.radius = np.array([b.radius if b.is_round else 0.0 for b in bodies])
        self.colors = np.array([EGO_COLOR] + [_rgb(t) for t in world.types[1:]], dtype=np.uint8)
        self.labels = ["ego #0"] + [
            f"{world.types[i].value} #{i} {bodies[i].name}" for i in range(1, world.n)
        ]
