"""Error metrics between measured and simulated series (one place for all of them).

Definitions (y measured, s simulated, n samples, e = s - y):

- ``rmse`` = sqrt(mean(e^2)) -- the study's eq. (1).
- ``rn_rmse`` = rmse / (max(y) - min(y)) -- range-normalised, eq. (2); a fraction.
- ``cv_rmse_eff`` = rmse / y_eff with y_eff = sqrt(mean(y^2)) -- eq. (3), the
  study's CV(RMSE) over the effective value; a fraction.
- ``mbe`` = sum(y - s) / n and ``nmbe`` = sum(y - s) / ((n - p) mean(y)) with
  p = 1 -- ASHRAE Guideline 14-2014 (measured minus simulated: positive when the
  model under-predicts); nmbe a fraction.
- ``cv_rmse_g14`` = sqrt(sum((y - s)^2) / (n - p)) / mean(y), p = 1 -- ASHRAE
  Guideline 14-2014 CV(RMSE), a fraction. Both Guideline-14 figures normalise by
  the mean, which for temperatures depends on the temperature scale (degC here)
  and for heat fluxes near zero mean is meaningless: read rn_rmse / cv_rmse_eff.
- ``mae`` = mean(|e|), ``max_abs_error`` = max(|e|).
- ``accuracy``: the sensor's stated accuracy [unit of the signal]; for a relative
  accuracy a, a * y_eff. ``within_accuracy`` = rmse <= accuracy.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

METRIC_COLUMNS = (
    "signal",
    "n",
    "rmse",
    "rn_rmse",
    "cv_rmse_eff",
    "mbe",
    "nmbe",
    "cv_rmse_g14",
    "mae",
    "max_abs_error",
    "accuracy",
    "within_accuracy",
)
G14_PARAMETERS = 1
_COLUMN_INDEX = pd.Index(METRIC_COLUMNS)


def compute(measured, simulated, accuracy: float | None = None, accuracy_relative: float | None = None) -> dict:
    """All metrics for one signal; NaN pairs are skipped.

    Parameters
    ----------
    measured, simulated : array-like
        Same length. Units of the signal (degC or W/m2).
    accuracy : float, optional
        Absolute sensor accuracy [unit of the signal].
    accuracy_relative : float, optional
        Relative accuracy [-], applied to the effective value.

    Returns
    -------
    dict
        Keys of :data:`METRIC_COLUMNS` except ``signal``.
    """
    y = np.asarray(measured, dtype=float)
    s = np.asarray(simulated, dtype=float)
    ok = np.isfinite(y) & np.isfinite(s)
    y, s = y[ok], s[ok]
    n = len(y)
    nan = float("nan")
    if n == 0:
        return dict(
            n=0,
            rmse=nan,
            rn_rmse=nan,
            cv_rmse_eff=nan,
            mbe=nan,
            nmbe=nan,
            cv_rmse_g14=nan,
            mae=nan,
            max_abs_error=nan,
            accuracy=accuracy if accuracy is not None else nan,
            within_accuracy=False,
        )
    e = s - y
    rmse = float(np.sqrt(np.mean(e**2)))
    rng = float(y.max() - y.min())
    y_eff = float(np.sqrt(np.mean(y**2)))
    ybar = float(np.mean(y))
    dof = n - G14_PARAMETERS
    mbe = float(np.sum(y - s) / n)
    with np.errstate(divide="ignore", invalid="ignore"):
        nmbe = float(np.sum(y - s) / (dof * ybar)) if dof > 0 and ybar != 0 else nan
        cv_g14 = float(np.sqrt(np.sum(e**2) / dof) / ybar) if dof > 0 and ybar != 0 else nan
    acc = accuracy if accuracy is not None else (accuracy_relative * y_eff if accuracy_relative else None)
    return dict(
        n=n,
        rmse=rmse,
        rn_rmse=rmse / rng if rng > 0 else nan,
        cv_rmse_eff=rmse / y_eff if y_eff > 0 else nan,
        mbe=mbe,
        nmbe=nmbe,
        cv_rmse_g14=cv_g14,
        mae=float(np.mean(np.abs(e))),
        max_abs_error=float(np.max(np.abs(e))),
        accuracy=float(acc) if acc is not None else nan,
        within_accuracy=bool(acc is not None and rmse <= acc),
    )


def table(measured: pd.DataFrame, simulated: pd.DataFrame, accuracies: dict[str, tuple]) -> pd.DataFrame:
    """Metrics of every column, one row per signal (columns :data:`METRIC_COLUMNS`).

    ``accuracies`` maps a signal to ``(accuracy, accuracy_relative)``.
    """
    names = list(measured.columns)
    acc = [accuracies.get(name, (None, None)) for name in names]
    return table_arrays(names, measured.to_numpy(dtype=float).T, simulated[names].to_numpy(dtype=float).T, acc)


def _nan_where(bad: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` with NaN where ``bad`` (a copy only when needed)."""
    if bad.any():
        values = np.where(bad, np.nan, values)
    return values


def measured_stats(measured: np.ndarray, valid: np.ndarray | None = None) -> dict:
    """What the metrics need of the measured series alone (computed once for many simulated series).

    Parameters
    ----------
    measured : ndarray, shape (n_signals, n_times)
    valid : ndarray of bool, same shape, optional
        Samples to use; default the finite measured ones.
    """
    y = np.asarray(measured, dtype=float)
    ok = np.isfinite(y) if valid is None else valid
    n = ok.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        yz = np.where(ok, y, 0.0)
        return {
            "ok": ok,
            "n": n,
            "range": np.where(ok, y, -np.inf).max(axis=1, initial=-np.inf)
            - np.where(ok, y, np.inf).min(axis=1, initial=np.inf),
            "y_eff": np.sqrt(np.einsum("kt,kt->k", yz, yz) / n),
            "mean": yz.sum(axis=1) / n,
        }


def table_arrays(names, measured: np.ndarray, simulated: np.ndarray, accuracies, stats: dict | None = None):
    """:func:`table` for arrays, every signal in one numpy pass (the definitions of :func:`compute`).

    Parameters
    ----------
    names : sequence of str or pandas string array
        Signal names, one per row of the arrays.
    measured, simulated : ndarray, shape (n_signals, n_times)
    accuracies : sequence of (accuracy, accuracy_relative)
    stats : dict, optional
        :func:`measured_stats` of ``measured`` (used when ``simulated`` is finite everywhere).

    Returns
    -------
    DataFrame
        Columns :data:`METRIC_COLUMNS`, one row per signal.
    """
    y = np.asarray(measured, dtype=float)
    s = np.asarray(simulated, dtype=float)
    if stats is None or not np.isfinite(s).all():
        stats = measured_stats(y, np.isfinite(y) & np.isfinite(s))
    ok, n, rng, y_eff, ybar = stats["ok"], stats["n"], stats["range"], stats["y_eff"], stats["mean"]
    nan = float("nan")
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.where(ok, s - y, 0.0)
        se2 = np.einsum("kt,kt->k", e, e)
        se = e.sum(axis=1)
        ae = np.abs(e)
        rmse = np.sqrt(se2 / n)
        dof = n - G14_PARAMETERS
        acc = [a if a is not None else (ar * y_eff[k] if ar else nan) for k, (a, ar) in enumerate(accuracies)]
        acc = np.array(acc, dtype=float)
        has = n > 0
        no_g14 = ~has | (dof <= 0) | (ybar == 0)
        cols = {
            "signal": names
            if isinstance(names, pd.api.extensions.ExtensionArray)
            else pd.array(list(names), dtype="str"),
            "n": n.astype(np.int64),
            "rmse": rmse,
            "rn_rmse": _nan_where(~has | (rng <= 0), rmse / rng),
            "cv_rmse_eff": _nan_where(~has | (y_eff <= 0), rmse / y_eff),
            "mbe": -se / n,
            "nmbe": _nan_where(no_g14, -se / (dof * ybar)),
            "cv_rmse_g14": _nan_where(no_g14, np.sqrt(se2 / dof) / ybar),
            "mae": ae.sum(axis=1) / n,
            "max_abs_error": ae.max(axis=1, initial=0.0),
            "accuracy": acc,
            "within_accuracy": has & (rmse <= acc),
        }
        if not has.all():  # a signal without a valid sample: NaN metrics, its stated accuracy kept
            for c in ("rmse", "mbe", "mae", "max_abs_error"):
                cols[c] = _nan_where(~has, cols[c])
            cols["accuracy"] = _nan_where(~has & np.array([a is None for a, _ in accuracies]), acc)
    # built with integer column labels, then named: pandas infers nothing from string labels that way
    frame = pd.DataFrame(dict(enumerate(cols.values())))
    frame.columns = _COLUMN_INDEX
    return frame


def rmse(measured, simulated, axis=-1):
    """RMSE over ``axis`` skipping NaN in ``measured`` (batch-friendly)."""
    y = np.asarray(measured, dtype=float)
    s = np.asarray(simulated, dtype=float)
    e = s - y
    ok = np.isfinite(e)
    return np.sqrt(np.where(ok, e, 0.0).__pow__(2).sum(axis=axis) / np.maximum(ok.sum(axis=axis), 1))


#: Columns of ``validation.csv``: the held-out window's error of each sensor (rmse, mbe as in :func:`compute`)
VALIDATION_COLUMNS = ("sensor", "rmse", "mbe", "n")


def validation_table(names, measured: np.ndarray, simulated: np.ndarray) -> pd.DataFrame:
    """RMSE, MBE (measured - simulated) and samples of each signal over a held-out window.

    Parameters
    ----------
    names : sequence of str
    measured, simulated : ndarray, shape (n_signals, n_times)
        NaN pairs are skipped.

    Returns
    -------
    DataFrame
        Columns :data:`VALIDATION_COLUMNS`, one row per signal.
    """
    rows = []
    for k, name in enumerate(names):
        m = compute(measured[k], simulated[k])
        rows.append({"sensor": str(name), "rmse": m["rmse"], "mbe": m["mbe"], "n": int(m["n"])})
    return pd.DataFrame(rows, columns=list(VALIDATION_COLUMNS))


#: the held-out window's table in an output directory (:func:`wallcal.validation.score_wall`)
VALIDATION_CSV = "validation.csv"


def write_validation(table: pd.DataFrame | None, directory) -> list[str]:
    """Write ``validation.csv`` (:data:`VALIDATION_COLUMNS`) into ``directory`` (nothing without a table); the
    names written."""
    from pathlib import Path

    if table is None:
        return []
    table.to_csv(Path(directory) / VALIDATION_CSV, index=False, float_format="%.6g")
    return [VALIDATION_CSV]
