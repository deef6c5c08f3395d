"""Maximum-likelihood refit of the logistic harm models from crash records.

Records are a CSV with columns ``dv`` (delta-v [m/s], >= 0), ``mais3`` (0 or 1),
``area`` (impact area, required by area models) and optionally ``weight`` (case
weight >= 0, e.g. a survey's expansion factor). Area names follow the model's
scheme: reduced models take front, side (or driver_side / right_side), rear; clock
models take clock positions 1..12.

Protected form: P = 1 / (1 + exp(-(c0 + c1 dv + c_area))), with the area of the
shipped table's zero coefficient as reference (front, clock 12). Unprotected form:
P = 1 / (1 + exp(c0 - c1 dv)). Newton iterations (``scipy.optimize.minimize``,
trust-exact, analytic gradient and Hessian of the weighted log-likelihood);
standard errors from the inverse observed Fisher information X' W diag(p (1 - p)) X.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit, log_expit

from ethical_planner.harm import AreaScheme, FunctionalForm, HarmModel, coefficients

REQUIRED = ("dv", "mais3")


@dataclass(frozen=True, slots=True)
class CrashRecords:
    """Validated crash records.

    Attributes:
        dv: delta-v [m/s], shape (n,). mais3: labels 0/1, shape (n,).
        area: area key of the model's scheme per record (empty for no-area models).
        weight: case weights, shape (n,).
    """

    dv: np.ndarray
    mais3: np.ndarray
    area: tuple[str, ...]
    weight: np.ndarray


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


def parse_records(
    rows: Sequence[dict[str, str]], model: HarmModel | str, source: str = "records"
) -> CrashRecords:
    """Validate raw CSV rows (dicts of strings) for ``model``.

    Raises:
        ValueError: a missing column, or a row with a negative or non-numeric delta-v,
            a label other than 0/1, an unknown area or a negative weight; the message
            names the row (1-based data row, header excluded) and the column.
    """
    c = coefficients(model)
    if c.form is FunctionalForm.REFERENCE_SPEED:
        raise ValueError(f"harm model {c.model.value!r} is not logistic; refit supports logistic models")
    needs_area = c.areas is not AreaScheme.NONE
    header = set(rows[0]) if rows else set()
    missing = [k for k in (*REQUIRED, *(("area",) if needs_area else ())) if k not in header]
    if missing:
        raise ValueError(f"{source}: missing columns {missing} (have {sorted(header)})")
    allowed = set(c.area)
    dv, y, w, areas = [], [], [], []
    for i, row in enumerate(rows, start=1):
        where = f"{source} row {i}"
        try:
            v = float(row["dv"])
        except (TypeError, ValueError):
            raise ValueError(f"{where}: dv must be a number [m/s], got {row['dv']!r}") from None
        if not math.isfinite(v) or v < 0:
            raise ValueError(f"{where}: dv must be finite and >= 0 [m/s], got {row['dv']!r}")
        label = (row["mais3"] or "").strip()
        if label not in ("0", "1", "0.0", "1.0"):
            raise ValueError(f"{where}: mais3 must be 0 or 1, got {row['mais3']!r}")
        weight = 1.0
        if row.get("weight") not in (None, ""):
            try:
                weight = float(row["weight"])
            except ValueError:
                raise ValueError(f"{where}: weight must be a number, got {row['weight']!r}") from None
            if not math.isfinite(weight) or weight < 0:
                raise ValueError(f"{where}: weight must be finite and >= 0, got {row['weight']!r}")
        key = ""
        if needs_area:
            key = _area_key(c.areas, row["area"] or "") or ""
            if key not in allowed:
                raise ValueError(
                    f"{where}: area {row['area']!r} is not an area of model {c.model.value!r}; "
                    f"allowed: {sorted(allowed)}"
                )
        dv.append(v)
        y.append(float(label))
        w.append(weight)
        areas.append(key)
    if not dv:
        raise ValueError(f"{source}: no records")
    return CrashRecords(np.array(dv), np.array(y), tuple(areas), np.array(w))


def read_records(path: Path, model: HarmModel | str) -> CrashRecords:
    """Read and validate a crash-record CSV (see ``parse_records``)."""
    with Path(path).open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        raise ValueError(f"{path}: no records (need a header with {REQUIRED} and at least one row)")
    return parse_records(rows, model, source=str(path))


@dataclass(frozen=True, slots=True)
class RefitResult:
    """Maximum-likelihood estimates of a logistic harm model.

    Attributes:
        model: model refitted. names: parameter names (c0, c1, area_<key>...).
        estimate: estimates in the model's own convention, shape (k,).
        std_error: standard errors (inverse Fisher information), shape (k,).
        shipped: the coefficients shipped with the planner, shape (k,).
        log_likelihood: at the estimate. n_records: records used.
        weight_sum: sum of case weights. converged: the optimiser reported success.
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

    def to_dict(self) -> dict:
        """JSON-able dict."""
        return {
            "model": self.model,
            "n_records": self.n_records,
            "weight_sum": self.weight_sum,
            "log_likelihood": self.log_likelihood,
            "converged": self.converged,
            "parameters": {
                n: {"estimate": float(e), "std_error": float(s), "shipped": float(p)}
                for n, e, s, p in zip(self.names, self.estimate, self.std_error, self.shipped, strict=True)
            },
        }

    def table(self) -> str:
        """Plain-text table of estimate, standard error and shipped value."""
        lines = [f"model {self.model}: n = {self.n_records}, log-likelihood = {self.log_likelihood:.3f}"]
        lines.append(f"{'parameter':<14}{'estimate':>11}{'std.err':>10}{'shipped':>10}{'z':>8}")
        for n, e, s, p in zip(self.names, self.estimate, self.std_error, self.shipped, strict=True):
            lines.append(f"{n:<14}{e:>11.4f}{s:>10.4f}{p:>10.4f}{(e - p) / s:>8.2f}")
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


def fit_logistic(records: CrashRecords, model: HarmModel | str = HarmModel.REDUCED_SYM) -> RefitResult:
    """Maximum-likelihood estimate of a logistic harm model with standard errors.

    Args:
        records: validated records (``read_records`` / ``parse_records``).
        model: logistic harm model whose parameters are estimated.

    Returns:
        Estimates in the model's convention (the unprotected c0 enters with a minus sign).

    Raises:
        ValueError: an area column is constant zero (no records of that area) or the
            data are separable (the Fisher information is singular).
    """
    x, names, shipped, sign = _design(records, model)
    y, w = records.mais3, records.weight
    empty = [n for n, col in zip(names, x.T, strict=True) if not np.any(col * w)]
    if empty:
        raise ValueError(f"no weighted records inform parameter(s) {empty}")

    scale = 1.0 / float(w.sum())  # the optimiser sees the mean, well scaled for its tolerance

    def nll(beta: np.ndarray) -> float:
        z = x @ beta
        return -float(np.sum(w * (y * log_expit(z) + (1 - y) * log_expit(-z))))

    def grad(beta: np.ndarray) -> np.ndarray:
        return -x.T @ (w * (y - expit(x @ beta)))

    def hess(beta: np.ndarray) -> np.ndarray:
        p = expit(x @ beta)
        return (x * (w * p * (1 - p))[:, None]).T @ x

    start = shipped.copy()
    start[0] *= sign
    result = minimize(
        lambda b: scale * nll(b),
        start,
        jac=lambda b: scale * grad(b),
        hess=lambda b: scale * hess(b),
        method="trust-exact",
        options={"gtol": 1e-9},
    )
    beta = result.x
    info = hess(beta)
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        raise ValueError("the Fisher information is singular (separable data?)") from None
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    estimate = beta.copy()
    estimate[0] *= sign
    c = coefficients(model)
    return RefitResult(
        model=c.model.value,
        names=names,
        estimate=estimate,
        std_error=se,
        shipped=shipped,
        log_likelihood=-nll(beta),
        n_records=int(y.size),
        weight_sum=float(w.sum()),
        converged=bool(result.success),
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
