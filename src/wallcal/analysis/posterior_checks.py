"""The posterior's self-checks (:mod:`wallcal.analysis.posterior`): posterior predictive residuals against the
sensors' accuracy, posterior mass piled up at the edges of the prior box, the extensions ``wallcal diagnose``
found, and the verdict on the structure.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .posterior_likelihood import lag1

nan = float("nan")


# ============================================================================ self-checks
#: the posterior mass within the outer PILE_BAND of the prior (each end) above which it "piles up" there
PILE_BAND = 0.02
PILE_FRACTION = 0.25
PILES_SHOWN = 5  # the report names the most piled-up ones


def residual_checks(study, space, ev, E: np.ndarray) -> pd.DataFrame:
    """Posterior predictive residuals against the sensors' stated accuracy.

    Parameters
    ----------
    E : ndarray, shape (draws, targets, times)
        Simulated minus measured for posterior draws (0 at missing samples).

    Returns
    -------
    DataFrame, one row per target
        ``RMSE`` (median over the draws), ``bias`` (mean error), ``RMSE without bias``, ``white noise`` (the
        high-frequency part, sqrt(mean((e_t - e_(t-1))^2) / 2): sensor noise is white, a model error is smooth at
        the sampling interval), ``model error`` (the rest, sqrt(max(0, var - white^2))), ``lag-1`` of the
        residuals without bias, ``accuracy`` (stated), ``RMSE / accuracy`` and ``verdict``: "beyond the stated
        accuracy" when the RMSE exceeds it (the sensor cannot explain the misfit), "model error above the noise"
        when the smooth part exceeds half the accuracy (the sd of a sensor whose accuracy is a 95 % bound),
        else "consistent with the sensor".
    """
    from .identifiability import sensor_sigma

    rows = []
    for k, t in enumerate(space.targets):
        m = ev.mask[k]
        e = E[:, k][:, m]
        if e.shape[1] < 3:
            continue
        bias = e.mean(axis=1)
        d = e - bias[:, None]
        rmse = np.sqrt(np.mean(e**2, axis=1))
        sd = np.sqrt(np.mean(d**2, axis=1))
        white = np.sqrt(np.mean(np.diff(e, axis=1) ** 2, axis=1) / 2.0)
        model = np.sqrt(np.maximum(0.0, sd**2 - white**2))
        acc = sensor_sigma(study, t, ev.y[k][m])
        row = {
            "target": t,
            "RMSE": float(np.median(rmse)),
            "bias": float(np.median(bias)),
            "RMSE without bias": float(np.median(sd)),
            "white noise": float(np.median(white)),
            "model error": float(np.median(model)),
            "lag-1": lag1(np.where(m, E[0, k] - bias[0], 0.0), m),
            "accuracy": acc,
        }
        row["RMSE / accuracy"] = row["RMSE"] / acc if acc > 0 else nan
        if row["RMSE"] > acc:
            row["verdict"] = "beyond the stated accuracy"
        elif row["model error"] > 0.5 * acc:
            row["verdict"] = "model error above the noise"
        else:
            row["verdict"] = "consistent with the sensor"
        rows.append(row)
    return pd.DataFrame(rows).set_index("target")


def piled_up(samples: np.ndarray, prior: np.ndarray, band: float = PILE_BAND) -> tuple[float, float]:
    """Fractions of the posterior ``samples`` below the prior's ``band`` quantile and above its 1 - ``band``
    quantile [-]. A flat posterior puts ``band`` at each end; a posterior pushed against the edge of the box
    (the data want a value the bounds forbid) puts most of its mass there."""
    lo, hi = np.quantile(prior, [band, 1.0 - band])
    return float(np.mean(samples < lo)), float(np.mean(samples > hi))


def structure_verdict(checks: pd.DataFrame, summary: pd.DataFrame, combinations: pd.DataFrame, missing=()) -> dict:
    """Whether the data reject the sampled structure, with the reasons in words.

    Returns
    -------
    dict
        ``rejected`` (bool), ``reasons`` (list of str), ``statement`` (one paragraph for the report).
    """
    reasons = []
    for t, r in checks.iterrows():
        if r["verdict"] == "beyond the stated accuracy":
            reasons.append(
                f"{t}: residual RMSE {r['RMSE']:.3g} is {r['RMSE / accuracy']:.1f} x the stated accuracy "
                f"{r['accuracy']:.3g}"
            )
        elif r["verdict"] == "model error above the noise":
            reasons.append(
                f"{t}: a smooth model error of {r['model error']:.3g} (lag-1 {r['lag-1']:.2f}) exceeds the sensor's "
                f"noise ({0.5 * r['accuracy']:.3g}, half its stated accuracy)"
            )
    piles = []
    for table in (combinations, summary):
        for name, r in table.iterrows():
            frac = max(r["at lower edge"], r["at upper edge"])
            if frac >= PILE_FRACTION:
                side = "lower" if r["at lower edge"] >= r["at upper edge"] else "upper"
                piles.append((frac, f"{name} ({frac:.0%} at its {side} edge)"))
    if piles:
        piles.sort(key=lambda p: -p[0])
        shown = ", ".join(text for _, text in piles[:PILES_SHOWN])
        more = f" and {len(piles) - PILES_SHOWN} more" if len(piles) > PILES_SHOWN else ""
        reasons.append(
            f"{len(piles)} parameter(s) or combination(s) pile up at the edge of their prior (at least "
            f"{PILE_FRACTION:.0%} of the posterior within the outer {PILE_BAND:.0%} of the prior): {shown}{more}"
        )
    if missing:
        reasons.append(
            "wallcal diagnose found that the data support " + ", ".join(missing) + ", which this structure lacks"
        )
    if reasons:
        statement = (
            "The data reject this model structure: " + "; ".join(reasons) + ". The intervals are conditional on "
            "this structure and do not hold the truth as often as they claim: its parameters compensate for what "
            "the structure lacks. Run `wallcal diagnose` and sample the study it writes."
        )
    else:
        statement = (
            "No self-check fired: the residuals are within the sensors' stated accuracy and no parameter or "
            "combination piles up at the edge of its prior. The intervals are still conditional on the model "
            "structure."
        )
    return {"rejected": bool(reasons), "reasons": reasons, "statement": statement}


def missing_from_diagnosis(study, folder) -> list[str]:
    """The extensions a ``wallcal diagnose`` output (``folder``) adopted that ``study`` lacks.

    ``folder/candidates.csv`` lists each candidate or combination (names joined by " + ") with its ``extension``
    and ``adopted`` (the row of the adopted set); ``folder/study.toml``
    is the study with the adopted extensions. When ``study`` is that file, nothing is missing.
    """
    from ..errors import WallcalError

    folder = Path(folder)
    path = folder / "candidates.csv"
    if not path.exists():
        raise WallcalError(f"{path}: not found (--diagnosis expects the output folder of `wallcal diagnose`)")
    table = pd.read_csv(path)
    absent = [c for c in ("extension", "adopted") if c not in table.columns]
    if absent:
        raise WallcalError(f"{path}: no column {', '.join(absent)} (not a `wallcal diagnose` output)")
    if study.path is not None and Path(study.path).resolve() == (folder / "study.toml").resolve():
        return []
    adopted = table["adopted"].astype(str).str.strip().str.lower().isin(("true", "1", "yes"))
    names = [name.strip() for e in table.loc[adopted, "extension"] for name in str(e).split(" + ")]
    return list(dict.fromkeys(n for n in names if n))
