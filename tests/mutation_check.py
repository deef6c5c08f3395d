"""Apply each mutant of a planner rule to a scratch copy and check that a test goes red.

Run from the repository root (not collected by pytest)::

    python tests/mutation_check.py                               # every mutant
    python tests/mutation_check.py accel_max                     # the named ones
    python tests/mutation_check.py -k planner_never accel_max    # only tests matching -k

Each mutant replaces one exact piece of source (it must occur exactly once; a mutant
whose text is gone after a refactor is reported as ``stale``, so update it here) in a
copy of the repository under a temporary folder, then runs the tests named for it from
inside that copy (the copy wins over the editable install). A mutant is ``killed``
when at least one of those tests fails; the script exits 1 if any mutant survives.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VALIDITY = "ethical_planner/validity.py"
COST = "ethical_planner/cost.py"
TEST_VALIDITY = "tests/ethical_planner/test_validity.py"
TEST_COST = "tests/ethical_planner/test_cost.py"
TEST_PLANNER = "tests/ethical_planner/test_planner.py"
RECORDING = "mujoco_world/storage/recording.py"
TEST_RECORDING = "tests/mujoco_world/storage/test_recording.py"


@dataclass(frozen=True)
class Mutant:
    """One change of one rule: ``old`` becomes ``new`` in ``path``; ``tests`` should catch it."""

    name: str
    path: str
    old: str
    new: str
    tests: tuple[str, ...]


MUTANTS = (
    # --- validity level 0: each limit removed
    Mutant(
        "accel_removed",
        VALIDITY,
        '"acceleration": np.any(',
        '"acceleration": False & np.any(',
        (TEST_VALIDITY,),
    ),
    Mutant("accel_max", VALIDITY, "(a > vehicle.a_max + slack) | ", "", (TEST_VALIDITY,)),
    Mutant("accel_min", VALIDITY, " | (a < -vehicle.emergency_deceleration - slack)", "", (TEST_VALIDITY,)),
    Mutant("speed_max", VALIDITY, "np.any(v > vehicle.v_max, axis=1) | ", "", (TEST_VALIDITY,)),
    Mutant(
        "reversing",
        VALIDITY,
        " | np.any(candidates.s_dot < -_REVERSE_TOLERANCE, axis=1)",
        "",
        (TEST_VALIDITY,),
    ),
    Mutant(
        "curvature_removed",
        VALIDITY,
        '"curvature": np.any(',
        '"curvature": False & np.any(',
        (TEST_VALIDITY,),
    ),
    Mutant(
        "curvature_gate",
        VALIDITY,
        "moving = v > vehicle.curvature_check_speed",
        "moving = v > -1.0",
        (TEST_VALIDITY,),
    ),
    Mutant(
        "curvature_sign",
        VALIDITY,
        "np.abs(kappa) > vehicle.steering_curvature",
        "kappa > vehicle.steering_curvature",
        (TEST_VALIDITY,),
    ),
    Mutant(
        "lateral_removed",
        VALIDITY,
        '"lateral_acceleration": np.any(',
        '"lateral_acceleration": False & np.any(',
        (TEST_VALIDITY,),
    ),
    Mutant(
        "lateral_sign",
        VALIDITY,
        "lateral = np.square(v) * np.abs(kappa)",
        "lateral = np.square(v) * kappa",
        (TEST_VALIDITY,),
    ),
    Mutant(
        "friction_removed",
        VALIDITY,
        '"friction": np.any(',
        '"friction": False & np.any(',
        (TEST_VALIDITY,),
    ),
    # --- each validity level removed, and the order of levels
    Mutant(
        "level_0",
        VALIDITY,
        "level[invalid] = Validity.PHYSICALLY_INVALID",
        "pass",
        (TEST_VALIDITY,),
    ),
    Mutant(
        "level_1",
        VALIDITY,
        "level[np.any(mean_overlap, axis=(1, 2))] = Validity.COLLISION",
        "pass",
        (TEST_VALIDITY,),
    ),
    Mutant(
        "level_2",
        VALIDITY,
        "level[np.any(outside_road, axis=1)] = Validity.LEAVES_ROAD",
        "pass",
        (TEST_VALIDITY,),
    ),
    Mutant("level_3", VALIDITY, "level[too_risky] = Validity.ABOVE_MAX_RISK", "pass", (TEST_VALIDITY,)),
    Mutant(
        "level_3_ego",
        VALIDITY,
        "(ego_combined > max_acceptable_risk) | ",
        "",
        (TEST_VALIDITY,),
    ),
    Mutant(
        "level_3_others",
        VALIDITY,
        " | np.any(risk_obs > max_acceptable_risk, axis=1)",
        "",
        (TEST_VALIDITY,),
    ),
    Mutant(
        "level_3_boundary",
        VALIDITY,
        "(ego_combined > max_acceptable_risk)",
        "(ego_combined >= max_acceptable_risk)",
        (TEST_VALIDITY,),
    ),
    Mutant(
        "level_order",
        VALIDITY,
        "    level[np.any(outside_road, axis=1)] = Validity.LEAVES_ROAD\n"
        "    level[np.any(mean_overlap, axis=(1, 2))] = Validity.COLLISION\n",
        "    level[np.any(mean_overlap, axis=(1, 2))] = Validity.COLLISION\n"
        "    level[np.any(outside_road, axis=1)] = Validity.LEAVES_ROAD\n",
        (TEST_VALIDITY,),
    ),
    # --- each principle's sign in Eq. 7, and Eqs. 5 / 6
    Mutant("sign_bayes", COST, "weights.bayes * j_b\n", "-weights.bayes * j_b\n", (TEST_COST,)),
    Mutant("sign_equality", COST, "+ weights.equality * j_e", "- weights.equality * j_e", (TEST_COST,)),
    Mutant("sign_maximin", COST, "+ weights.maximin * j_m", "- weights.maximin * j_m", (TEST_COST,)),
    Mutant(
        "sign_responsibility",
        COST,
        "- weights.responsibility * weights.bayes * j_r",
        "+ weights.responsibility * weights.bayes * j_r",
        (TEST_COST,),
    ),
    Mutant(
        "sign_ego_risk",
        COST,
        "+ weights.ego_risk * ego_combined",
        "- weights.ego_risk * ego_combined",
        (TEST_COST,),
    ),
    # --- S_R: the road edge is an entry only for candidates that leave the road
    Mutant(
        "road_edge_always_in_s_r",
        COST,
        "np.ones((n, 2 * k), dtype=bool), leaves_road[:, None]",
        "np.ones((n, 2 * k), dtype=bool), np.ones((n, 1), dtype=bool)",
        (TEST_COST, TEST_PLANNER),
    ),
    Mutant(
        "eq6_below_valid",
        COST,
        "np.where(valid, weights.risk * j_risk + comfort + mobility, j_risk)",
        "weights.risk * j_risk + comfort + mobility",
        (TEST_COST,),
    ),
    # --- the best candidate of each level (Decision.best_by_level)
    Mutant(
        "best_is_dearest",
        "ethical_planner/planner.py",
        "costs.comfort[rows] + costs.mobility[rows], costs.total[rows], grid.levels[rows]",
        "costs.comfort[rows] + costs.mobility[rows], -costs.total[rows], grid.levels[rows]",
        (TEST_PLANNER,),
    ),
    # --- what a recording shows of each decision and moment
    *(
        Mutant(name, RECORDING, old, new, (TEST_RECORDING,))
        for name, old, new in (
            (
                "rejected_level_mixed_up",
                "float(counts.get(int(level), 0))",
                "float(counts.get(int(level) ^ 3, 0))",
            ),
            ("refused_dropped", "float(decision.max_risk_refused)", "0.0"),
            ("best_cost_of_chosen", "math.nan if best is None else best.cost", "decision.costs['total']"),
            ("chosen_offset_at_start", '("end_offset", chosen.end_offset)', '("end_offset", 0.0)'),
            ("switch_inverted", "self._decisions > 0 and not decision.continued", "decision.continued"),
            ("switch_on_first", "self._decisions > 0 and not decision.continued", "not decision.continued"),
            ("speed_of_user", "world.speeds_along_heading()[0]", "world.speeds_along_heading()[-1]"),
            (
                "acceleration_sign",
                "world.accelerations_along_heading()[0]",
                "-world.accelerations_along_heading()[0]",
            ),
            ("ttc_not_masked", "present & np.isfinite(ttc), ttc", "present, ttc"),
            ("distance_uncapped", "present & (distance < DISTANCE_CAP)", "present"),
            (
                "visible_is_present",
                "np.where(present, visible, math.nan)",
                "present.astype(float)",
            ),
            (
                "hidden_ring_on_visible",
                "np.flatnonzero(present & ~visible)",
                "np.flatnonzero(present & visible)",
            ),
        )
    ),
    # --- control after contact (issue 15): the [expect] items of a struck ego, the rest
    # rule under continue, the controller cut inside an impact
    Mutant(
        "ego_strikes_flipped",
        "mujoco_world/evaluation/compare.py",
        "return approach_speed(ego, m.contact_position) >= approach_speed(other, m.contact_position)",
        "return approach_speed(ego, m.contact_position) < approach_speed(other, m.contact_position)",
        ("tests/mujoco_world/scenario/test_language.py",),
    ),
    Mutant(
        "max_ego_collisions_counts_all",
        "mujoco_world/loop/expectations.py",
        "lambda s: len(s.ego_collisions), ",
        "lambda s: len(s.collisions), ",
        ("tests/mujoco_world/scenario/test_language.py",),
    ),
    Mutant(
        "crash_at_rest_ignores_continue",
        "mujoco_world/loop/rules.py",
        "if run.crash_time is None or (world.crashed[0] and world.ego_on_plan):",
        "if run.crash_time is None:",
        ("tests/mujoco_world/loop/test_rules_and_metrics.py",),
    ),
    Mutant(
        "controller_on_inside_impacts",
        "mujoco_world/loop/world.py",
        "ctrl[self.recorder.in_impact] = 0.0",
        "pass",
        ("tests/mujoco_world/loop/test_post_crash.py",),
    ),
    Mutant(
        "persistence_one_cycle_late",
        "ethical_planner/planner.py",
        "outvoted >= commitment.switch_after_cycles",
        "outvoted > commitment.switch_after_cycles",
        ("tests/ethical_planner/test_commitment.py",),
    ),
    Mutant(
        "fallback_bound_doubled",
        "ethical_planner/planner.py",
        "bound = lower_bound(rows)",
        "bound = 2.0 * lower_bound(rows)",
        ("tests/ethical_planner/test_branch_and_bound.py",),
    ),
    Mutant(
        "fallback_hard_stops_not_forced",
        "ethical_planner/planner.py",
        "first = np.flatnonzero((kind == CandidateKind.CONTINUATION) | (kind == CandidateKind.BRAKE))",
        "first = np.flatnonzero(kind == CandidateKind.CONTINUATION)",
        ("tests/ethical_planner/test_branch_and_bound.py",),
    ),
)


def _copy_repository(target: Path) -> None:
    files = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    for name in files:
        source = ROOT / name
        if source.is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)


def run(mutants: tuple[Mutant, ...], select: str | None = None) -> int:
    """Apply each mutant in turn to a scratch copy, run its tests; return the survivors' count.

    ``select`` narrows the tests with pytest's ``-k``.
    """
    survivors = 0
    with tempfile.TemporaryDirectory(prefix="etp-mutants-") as scratch:
        copy = Path(scratch)
        _copy_repository(copy)
        for mutant in mutants:
            path = copy / mutant.path
            original = path.read_text(encoding="utf-8")
            if original.count(mutant.old) != 1:
                print(f"{mutant.name:<22} stale (text found {original.count(mutant.old)} times)")
                survivors += 1
                continue
            path.write_text(original.replace(mutant.old, mutant.new), encoding="utf-8")
            start = time.perf_counter()
            result = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "pytest",
                    "-x",
                    "-q",
                    "-p",
                    "no:cacheprovider",
                    *(["-k", select] if select else []),
                    *mutant.tests,
                ],  # fmt: skip
                cwd=copy,
                capture_output=True,
                text=True,
            )
            path.write_text(original, encoding="utf-8")
            failed = [
                line.split(" - ")[0] for line in result.stdout.splitlines() if line.startswith("FAILED")
            ]
            elapsed = time.perf_counter() - start
            if result.returncode == 0:
                survivors += 1
                print(f"{mutant.name:<22} SURVIVED ({elapsed:.0f} s)")
            else:
                culprit = failed[0] if failed else result.stdout[-200:]
                print(f"{mutant.name:<22} killed by {culprit} ({elapsed:.0f} s)")
    return survivors


if __name__ == "__main__":
    names = sys.argv[1:]
    expression = None
    if names[:1] == ["-k"]:
        expression, names = names[1], names[2:]
    chosen = tuple(m for m in MUTANTS if not names or m.name in names)
    sys.exit(1 if run(chosen, expression) else 0)
