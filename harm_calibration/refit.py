"""Maximum-likelihood refit of the logistic harm models.

Two kinds of input file are read (``read_records`` tells them apart by their header):

* **Crash records**: a CSV with columns ``dv`` (delta-v [m/s], >= 0), ``mais3`` (0 or
  1), ``area`` (impact area, required by area models) and optionally ``weight`` (case
  weight >= 0, e.g. a survey's expansion factor). Area names follow the model's
  scheme: reduced models take front, side (or driver_side / right_side), rear; clock
  models take clock positions 1..12.
* **An impact table** (``impacts.csv`` of ``etp impacts``): every body assessed with
  the model becomes one record whose outcome is the injury probability the model
  gives at the *measured* delta-v and area (``harm_measured``), and whose inputs are
  the planner's *predicted* delta-v (Eq. 1) and geometric area (``inputs="predicted"``,
  the default) or the measured ones (``inputs="measured"``, which gives back the
  shipped coefficients: a check). The refit then answers: which coefficients make the
  planner's harm estimate, fed with what the planner can know, match the harm implied
  by the physics?

Protected form: P = 1 / (1 + exp(-(c0 + c1 dv + c_area))), with the area of the
shipped table's zero coefficient as reference (front, clock 12). Unprotected form:
P = 1 / (1 + exp(c0 - c1 dv)).

The fit is Newton's method on the weighted log-likelihood (for fractional outcomes,
the Bernoulli quasi-likelihood of Papke and Wooldridge 1996) with step halving.
Before fitting, records that cannot identify the parameters are refused with a
``ValueError`` that says why: a parameter no record informs, parameters that the
records cannot tell apart (a rank-deficient design, e.g. a single delta-v), and
separable outcomes (all 0, all 1, or a combination of inputs that splits them
perfectly), for which no maximum-likelihood estimate exists. ``converged`` is true
when the Newton decrement of the *summed* log-likelihood, the increase still to be
gained, is below ``tolerance`` (1e-10), whatever the number of records. Standard
errors: inverse observed Fisher information X' W diag(p (1 - p)) X for 0/1 outcomes;
the sandwich (robust) estimate for fractional outcomes, since their variance is not
Bernoulli.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import linprog
from scipy.special import expit, log_expit

from ethical_planner.harm import AreaScheme, FunctionalForm, HarmCoefficients, HarmModel, coefficients

REQUIRED = ("dv", "mais3")
#: What the inputs of an impact-table record are (see the module docstring).
INPUTS = ("predicted", "measured")
#: Newton decrement of the summed log-likelihood below which the fit has converged.
TOLERANCE = 1e-10
#: Newton iterations before giving up (``converged`` is then false).
MAX_ITERATIONS = 100


@dataclass(frozen=True, slots=True)
class CrashRecords:
    """Validated records.

    Attributes:
        dv: delta-v [m/s], shape (n,).
        mais3: outcome in [0, 1], shape (n,): 0/1 labels of crash records, or
            injury probabilities of an impact table.
        area: area key of the model's scheme per record (empty for no-area models).
        weight: case weights, shape (n,).
        source: file or description the records came from (for messages).
    """

    dv: np.ndarray
    mais3: np.ndarray
    area: tuple[str, ...]
    weight: np.ndarray
    source: str = "records"

    @property
    def fractional(self) -> bool:
        """True if any outcome lies strictly between 0 and 1."""
        return bool(np.any((self.mais3 > 0) & (self.mais3 < 1)))


def _area_key(scheme: AreaScheme, raw: str) -> str | None:
    text = raw.strip().lower().replace(" ", "_").replace("-", "_")
    if scheme in (AreaScheme.REDUCED_SYM, AreaScheme.REDUCED_ASYM):
        if scheme is AreaScheme.REDUCED_SYM and text in ("driver_side", "right_side", "left", "right"):
            return "side"
        if scheme is AreaScheme.REDUCED_ASYM and text in ("left", "right"):
            return {"left": "driver_side", "right": "right_side"}[text]
        return text
    try:
        clock = int(float(text))
    except ValueError:
        return text
    if not 1 <= clock <= 12:
        return text
    if scheme is AreaScheme.CLOCK:
        return str(clock)
    return str(clock) if clock in (6, 12) else f"{min(clock, 12 - clock)}_{max(clock, 12 - clock)}"


def _logistic(model: HarmModel | str):
    c = coefficients(model)
    if c.form is FunctionalForm.REFERENCE_SPEED:
        logistic = [m.value for m in HarmModel if coefficients(m).form is not FunctionalForm.REFERENCE_SPEED]
        raise ValueError(
            f"harm model {c.model.value!r} is not logistic; refit supports: {', '.join(logistic)}"
        )
    return c


def parse_records(
    rows: Sequence[dict[str, str]], model: HarmModel | str, source: str = "records"
) -> CrashRecords:
    """Validate raw crash-record rows (dicts of strings) for ``model``.

    Raises:
        ValueError: a missing column, or a row with a negative or non-numeric delta-v,
            a label other than 0/1, an unknown area or a negative weight; the message
            names the row (1-based data row, header excluded) and the column.
    """
    c = _logistic(model)
    needs_area = c.areas is not AreaScheme.NONE
    header = set(rows[0]) if rows else set()
    missing = [k for k in (*REQUIRED, *(("area",) if needs_area else ())) if k not in header]
    if missing:
        raise ValueError(f"{source}: missing columns {missing} (have {sorted(header)})")
    dv, y, w, areas = [], [], [], []
    for i, row in enumerate(rows, start=1):
        where = f"{source} row {i}"
        if None in row or any(row.get(k) is None for k in header):
            raise ValueError(f"{where}: has {'more' if None in row else 'fewer'} fields than the header")
        dv.append(_row_dv(row, where))
        y.append(_row_label(row, where))
        w.append(_row_weight(row, where))
        areas.append(_row_area(row, where, c) if needs_area else "")
    if not dv:
        raise ValueError(f"{source}: no records")
    return CrashRecords(np.array(dv), np.array(y), tuple(areas), np.array(w), source)


def _row_dv(row: dict[str, str], where: str) -> float:
    try:
        v = float(row["dv"])
    except (TypeError, ValueError):
        raise ValueError(f"{where}: dv must be a number [m/s], got {row['dv']!r}") from None
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"{where}: dv must be finite and >= 0 [m/s], got {row['dv']!r}")
    return v


def _row_label(row: dict[str, str], where: str) -> float:
    label = (row["mais3"] or "").strip()
    if label not in ("0", "1", "0.0", "1.0"):
        raise ValueError(f"{where}: mais3 must be 0 or 1, got {row['mais3']!r}")
    return float(label)


def _row_weight(row: dict[str, str], where: str) -> float:
    if row.get("weight") in (None, ""):
        return 1.0
    try:
        weight = float(row["weight"])
    except ValueError:
        raise ValueError(f"{where}: weight must be a number, got {row['weight']!r}") from None
    if not math.isfinite(weight) or weight < 0:
        raise ValueError(f"{where}: weight must be finite and >= 0, got {row['weight']!r}")
    return weight


def _row_area(row: dict[str, str], where: str, c: HarmCoefficients) -> str:
    key = _area_key(c.areas, row["area"] or "") or ""
    if key not in c.area:
        raise ValueError(
            f"{where}: area {row['area']!r} is not an area of model {c.model.value!r}; "
            f"allowed: {sorted(set(c.area))}"
        )
    return key


def records_from_impacts(
    rows: Sequence[dict[str, str]],
    model: HarmModel | str,
    inputs: str = "predicted",
    source: str = "impacts.csv",
) -> CrashRecords:
    """Records from the rows of an impact table (``impacts.csv``, strings as read).

    Every body (a and b of each row) assessed with ``model`` is one record: outcome
    ``harm_measured``, inputs ``dv_<inputs>`` and ``area_<inputs>`` (``clock_<inputs>``
    for clock models), weight 1. Rows without a measurement (status other than ok or
    incomplete) and bodies with a non-finite value are left out.

    Raises:
        ValueError: an unknown ``inputs``, a missing column, a malformed number, or
            no body assessed with ``model`` (the message lists the models present).
    """
    c = _logistic(model)
    if inputs not in INPUTS:
        raise ValueError(f"inputs must be one of {', '.join(INPUTS)}, got {inputs!r}")
    area_column = "clock" if c.areas in (AreaScheme.CLOCK, AreaScheme.CLOCK_SYM) else "area"
    needed = ["status"] + [
        f"{name}_{side}"
        for side in ("a", "b")
        for name in ("model", "harm_measured", f"dv_{inputs}", f"{area_column}_{inputs}")
    ]
    header = set(rows[0]) if rows else set()
    missing = [k for k in needed if k not in header]
    if missing:
        raise ValueError(f"{source}: missing columns {missing}")
    dv, y, areas, present = [], [], [], set()
    for i, row in enumerate(rows, start=2):
        if row.get("status") not in ("ok", "incomplete"):
            continue
        for side in ("a", "b"):
            name = row[f"model_{side}"] or ""
            present.add(name or "none (wall)")
            if name != c.model.value:
                continue
            record = _impact_record(row, side, c, inputs, area_column, f"{source} line {i}")
            if record is not None:
                dv.append(record[0])
                y.append(record[1])
                areas.append(record[2])
    if not dv:
        raise ValueError(
            f"{source}: no measured body was assessed with model {c.model.value!r}; "
            f"models present: {', '.join(sorted(present)) or 'none'}"
        )
    return CrashRecords(np.array(dv), np.array(y), tuple(areas), np.ones(len(dv)), source)


def _impact_record(
    row: dict[str, str], side: str, c: HarmCoefficients, inputs: str, area_column: str, where: str
) -> tuple[float, float, str] | None:
    """(delta-v, measured harm, area key) of one body of an impact row; None if not finite."""
    try:
        v = float(row[f"dv_{inputs}_{side}"])
        h = float(row[f"harm_measured_{side}"])
    except (TypeError, ValueError):
        raise ValueError(f"{where}: dv_{inputs}_{side} and harm_measured_{side} must be numbers") from None
    if not (math.isfinite(v) and math.isfinite(h)):
        return None
    if v < 0 or not 0.0 <= h <= 1.0:
        raise ValueError(
            f"{where}: dv_{inputs}_{side} must be >= 0 and harm_measured_{side} in [0, 1], got {v} and {h}"
        )
    if c.areas is AreaScheme.NONE:
        return v, h, ""
    raw = row[f"{area_column}_{inputs}_{side}"] or ""
    key = _area_key(c.areas, raw) or ""
    if key not in c.area:
        raise ValueError(
            f"{where}: {area_column}_{inputs}_{side} {raw!r} is not an area of model {c.model.value!r}"
        )
    return v, h, key


def _read_csv(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    """Header and rows of a CSV file; every failure becomes a ValueError naming the file."""
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            rows = list(reader)
            header = list(reader.fieldnames or [])
    except IsADirectoryError:
        raise ValueError(f"{path}: is a folder, not a CSV file") from None
    except OSError as error:
        raise ValueError(f"{path}: cannot read: {error.strerror}") from None
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not UTF-8 text (byte {error.start}); save the CSV as UTF-8") from None
    except csv.Error as error:
        raise ValueError(f"{path}: not a readable CSV file: {error}") from None
    return header, rows


def read_records(path: Path, model: HarmModel | str, inputs: str = "predicted") -> CrashRecords:
    """Read and validate a crash-record CSV or an ``impacts.csv`` (see the module docstring).

    Raises:
        ValueError: the file is missing, unreadable, not UTF-8, of neither format, or
            holds a bad row; the message names the file (and the row).
    """
    header, rows = _read_csv(path)
    if not header:
        raise ValueError(f"{path}: empty file (need a header with {REQUIRED} and at least one row)")
    if "harm_measured_a" in header and "dv" not in header:
        return records_from_impacts(rows, model, inputs, source=str(path))
    if not rows:
        raise ValueError(f"{path}: no records (need a header with {REQUIRED} and at least one row)")
    if not set(REQUIRED) <= set(header):
        raise ValueError(
            f"{path}: neither crash records (columns dv, mais3, area[, weight]) nor an impact "
            f"table of etp impacts (columns dv_measured_a, harm_measured_a, ...); header: {header}"
        )
    return parse_records(rows, model, source=str(path))


@dataclass(frozen=True, slots=True)
class RefitResult:
    """Maximum-likelihood estimates of a logistic harm model.

    Attributes:
        model: model refitted. names: parameter names (c0, c1, area_<key>...).
        estimate: estimates in the model's own convention, shape (k,).
        std_error: standard errors, shape (k,) (``std_error_kind``).
        shipped: the coefficients shipped with the planner, shape (k,).
        log_likelihood: at the estimate (summed, weighted). n_records: records used.
        weight_sum: sum of case weights.
        converged: the Newton decrement fell below ``TOLERANCE``.
        newton_decrement: the log-likelihood still to be gained at the estimate.
        iterations: Newton iterations taken.
        std_error_kind: "fisher" (0/1 outcomes) or "sandwich" (fractional outcomes).
        source: where the records came from.
    """

    model: str
    names: tuple[str, ...]
    estimate: np.ndarray
    std_error: np.ndarray
    shipped: np.ndarray
    log_likelihood: float
    n_records: int
    weight_sum: float
    converged: bool
    newton_decrement: float = 0.0
    iterations: int = 0
    std_error_kind: str = "fisher"
    source: str = "records"

    def to_dict(self) -> dict:
        """JSON-able dict."""
        return {
            "model": self.model,
            "source": self.source,
            "n_records": self.n_records,
            "weight_sum": self.weight_sum,
            "log_likelihood": self.log_likelihood,
            "converged": self.converged,
            "newton_decrement": self.newton_decrement,
            "iterations": self.iterations,
            "std_error_kind": self.std_error_kind,
            "parameters": {
                n: {"estimate": float(e), "std_error": float(s), "shipped": float(p)}
                for n, e, s, p in zip(self.names, self.estimate, self.std_error, self.shipped, strict=True)
            },
        }

    def table(self) -> str:
        """Plain-text table of estimate, standard error, shipped value and z; widths fit the values."""
        head = ("parameter", "estimate", "std.err", "shipped", "z")
        body = [
            (n, f"{e:.4f}", f"{s:.4f}", f"{p:.4f}", f"{(e - p) / s:.2f}" if s > 0 else "-")
            for n, e, s, p in zip(self.names, self.estimate, self.std_error, self.shipped, strict=True)
        ]
        widths = [max(len(row[i]) for row in (head, *body)) for i in range(len(head))]

        def line(row: Sequence[str]) -> str:
            return "  ".join(
                cell.ljust(w) if i == 0 else cell.rjust(w)
                for i, (cell, w) in enumerate(zip(row, widths, strict=True))
            )

        state = "converged" if self.converged else "NOT converged"
        lines = [
            f"model {self.model}: n = {self.n_records}, log-likelihood = {self.log_likelihood:.3f}, "
            f"{state} after {self.iterations} Newton steps; std.err: {self.std_error_kind}",
            line(head),
        ]
        lines += [line(row) for row in body]
        return "\n".join(lines)


def _design(
    records: CrashRecords, model: HarmModel | str
) -> tuple[np.ndarray, tuple[str, ...], np.ndarray, float]:
    """Design matrix (n, k), parameter names, shipped values, sign of c0 in the logit."""
    c = coefficients(model)
    sign = -1.0 if c.form is FunctionalForm.UNPROTECTED_LOGISTIC else 1.0
    columns = [np.ones_like(records.dv), records.dv]
    names = ["c0", "c1"]
    shipped = [c.c0, c.c1]
    if c.areas is not AreaScheme.NONE:
        reference = next(k for k, v in c.area.items() if v == 0.0)
        area = np.array(records.area, dtype=object)
        for key, value in c.area.items():
            if key == reference:
                continue
            columns.append((area == key).astype(float))
            names.append(f"area_{key}")
            shipped.append(value)
    return np.column_stack(columns), tuple(names), np.array(shipped), sign


def _check_identifiable(x: np.ndarray, y: np.ndarray, names: Sequence[str], source: str) -> None:
    """Refuse records whose likelihood has no unique finite maximum (rank, separation).

    Args:
        x: design of the records with positive weight, shape (n, k).
        y: their outcomes in [0, 1], shape (n,).
        names: parameter names, length k.
        source: for messages.

    Raises:
        ValueError: the design is rank-deficient or the outcomes are separable.
    """
    norms = np.linalg.norm(x, axis=0)
    empty = [n for n, norm in zip(names, norms, strict=True) if norm == 0]
    if empty:
        raise ValueError(f"{source}: no weighted records inform parameter(s) {empty}")
    scaled = x / norms
    _, sv, vt = np.linalg.svd(scaled, full_matrices=False)
    if sv[-1] < 1e-9 * sv[0]:
        involved = [n for n, v in zip(names, vt[-1], strict=True) if abs(v) > 1e-6]
        hint = ""
        if np.ptp(x[:, 1]) == 0:
            hint = f" (every record has dv = {x[0, 1]:g} m/s: c1 needs more than one delta-v)"
        raise ValueError(
            f"{source}: the records cannot tell parameters {involved} apart (rank-deficient "
            f"design){hint}; add records that vary them independently"
        )
    if np.all(y == y[0]) and y[0] in (0.0, 1.0):
        raise ValueError(
            f"{source}: every record has mais3 = {int(y[0])}; a logistic model needs both outcomes "
            "(no maximum-likelihood estimate exists)"
        )
    # Separation (Albert and Anderson 1984): a direction b with x_i.b >= 0 wherever an
    # outcome can be 1 and x_i.b <= 0 wherever it can be 0, strict somewhere, raises the
    # likelihood without bound. Found by a linear program on the unit box (Konis 2007).
    upper = y > 0  # x_i.b >= 0 allowed
    lower = y < 1  # x_i.b <= 0 allowed
    a_ub = np.vstack([-scaled[upper], scaled[lower]])
    objective = -(scaled[y == 1].sum(axis=0) - scaled[y == 0].sum(axis=0))
    result = linprog(
        objective, A_ub=a_ub, b_ub=np.zeros(len(a_ub)), bounds=[(-1.0, 1.0)] * x.shape[1], method="highs"
    )
    if result.status == 0 and -result.fun > 1e-7 * max(len(y), 1):
        direction = [n for n, v in zip(names, result.x, strict=True) if abs(v) > 1e-6]
        raise ValueError(
            f"{source}: the outcomes are separable: a combination of {direction} separates "
            "MAIS3+ records from the others (perfectly, or up to ties on the boundary), so no "
            "maximum-likelihood estimate exists (the estimates grow without bound); add "
            "overlapping records or fit a model with fewer areas"
        )


def fit_logistic(records: CrashRecords, model: HarmModel | str = HarmModel.REDUCED_SYM) -> RefitResult:
    """Maximum-likelihood estimate of a logistic harm model with standard errors.

    Args:
        records: validated records (``read_records`` / ``parse_records`` /
            ``records_from_impacts``).
        model: logistic harm model whose parameters are estimated.

    Returns:
        Estimates in the model's convention (the unprotected c0 enters with a minus sign).

    Raises:
        ValueError: a parameter no record informs, a rank-deficient design or separable
            outcomes (see the module docstring).
    """
    c = _logistic(model)
    x, names, shipped, sign = _design(records, model)
    keep = records.weight > 0
    x, y, w = x[keep], records.mais3[keep], records.weight[keep]
    if not len(y):
        raise ValueError(f"{records.source}: every record has weight 0")
    _check_identifiable(x, y, names, records.source)

    def log_likelihood(beta: np.ndarray) -> float:
        z = x @ beta
        return float(np.sum(w * (y * log_expit(z) + (1 - y) * log_expit(-z))))

    beta = shipped.astype(float).copy()
    beta[0] *= sign
    current = log_likelihood(beta)
    decrement = math.inf
    iterations = 0
    for iterations in range(1, MAX_ITERATIONS + 1):  # noqa: B007 - the count is reported
        p = expit(x @ beta)
        gradient = x.T @ (w * (y - p))
        information = (x * (w * p * (1 - p))[:, None]).T @ x
        try:
            step = np.linalg.solve(information, gradient)
        except np.linalg.LinAlgError:
            break
        decrement = float(gradient @ step)  # twice the gain a Newton step would make
        if decrement / 2 < TOLERANCE:
            break
        t = 1.0
        while t > 1e-8:
            candidate = log_likelihood(beta + t * step)
            if candidate >= current:
                break
            t *= 0.5
        beta, current = beta + t * step, log_likelihood(beta + t * step)
    p = expit(x @ beta)
    information = (x * (w * p * (1 - p))[:, None]).T @ x
    cov = np.linalg.pinv(information)
    kind = "fisher"
    if records.fractional:
        scores = x * (w * (y - p))[:, None]
        cov = cov @ (scores.T @ scores) @ cov
        kind = "sandwich"
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    estimate = beta.copy()
    estimate[0] *= sign
    return RefitResult(
        model=c.model.value,
        names=names,
        estimate=estimate,
        std_error=se,
        shipped=shipped,
        log_likelihood=current,
        n_records=int(y.size),
        weight_sum=float(w.sum()),
        converged=bool(decrement / 2 < TOLERANCE),
        newton_decrement=decrement / 2,
        iterations=iterations,
        std_error_kind=kind,
        source=records.source,
    )


def simulate_records(
    model: HarmModel | str, n: int, rng: np.random.Generator, dv_max: float = 30.0
) -> list[dict[str, str]]:
    """Synthetic records drawn from the shipped coefficients of ``model`` (CSV-like rows).

    delta-v uniform on [0, ``dv_max``] [m/s], areas uniform over the scheme's keys.
    """
    c = coefficients(model)
    keys = list(c.area)
    dv = rng.uniform(0.0, dv_max, n)
    area = [keys[i] for i in rng.integers(0, len(keys), n)]
    offset = np.array([c.area[k] for k in area]) if c.areas is not AreaScheme.NONE else 0.0
    if c.form is FunctionalForm.UNPROTECTED_LOGISTIC:
        p = expit(-c.c0 + c.c1 * dv)
    else:
        p = expit(c.c0 + c.c1 * dv + offset)
    y = rng.random(n) < p
    return [
        {"dv": repr(float(v)), "mais3": str(int(label)), "area": a}
        for v, label, a in zip(dv, y, area, strict=True)
    ]
