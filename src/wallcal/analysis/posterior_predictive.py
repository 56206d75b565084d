"""Posterior predictive bands (:mod:`wallcal.analysis.posterior`): any period of the study's data predicted from
the posterior's draws plus the errors they leave over the fitted period; by default the study's held-out
validation window.

For each of ``draws`` posterior samples the window is simulated (one engine batch, simulated from the warm-up start
through the window's end), and the measured value at each of its timestamps is predicted as

    measured = simulated - offsets - e

with ``offsets`` the draw's calibrated sensor offsets and ``e`` one of the errors (simulated - measured) that this
same draw leaves over the fitted period, picked at random (:func:`band`). The band is thus the draws' spread (the
parameters' uncertainty) widened by the empirical distribution of each draw's fitted-period errors, level
included: model error, sensor bias and sensor noise, as the fitted period shows them, with no assumption of their
shape. A draw whose simulated level is off carries its own level error into its prediction, so the parameters'
spread in level is not counted twice. The AR(1) error model of the likelihood does not enter: it describes how an
error follows the previous one, which matters to the likelihood, not the marginal distribution of an error at a
timestamp, which is what a band is (docs/identifiability.md, "Posterior predictive bands").

The band at each timestamp is the 2.5 and 97.5 % quantiles of these predictions (``median`` of predictive.csv
their median: the model's, shifted by the median fitted error); ``coverage_95`` the share of measured points inside
it, ``band_width_95`` its mean width; ``rmse`` and ``mbe`` are those of the model, the draws' median simulation.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

#: posterior draws simulated for a predictive band
PREDICTIVE_DRAWS = 200
#: fitted-period errors drawn per posterior draw and timestamp (the band's quantiles read draws x this many values)
ERROR_DRAWS = 5
#: columns of predictive.csv
PREDICTIVE_COLUMNS = ("timestamp", "sensor", "measured", "median", "p2.5", "p97.5")
#: timestamps per block of :func:`band` (bounds its memory on a long period)
_BLOCK = 4096


@dataclasses.dataclass
class Predictive:
    """A posterior predictive band over a window.

    Attributes
    ----------
    window : (Timestamp, Timestamp)
    bands : DataFrame
        :data:`PREDICTIVE_COLUMNS`, one row per timestamp and target (long format).
    table : DataFrame
        Per target: ``sensor, rmse, mbe, n`` of the draws' median simulation (minus offsets) against the measured
        values (as every ``validation.csv``), ``coverage_95`` and ``band_width_95`` [target unit].
    draws : int
    """

    window: tuple
    bands: pd.DataFrame
    table: pd.DataFrame
    draws: int


def band(
    predicted: np.ndarray, fitted_errors: np.ndarray, fitted_mask: np.ndarray, rng, error_draws: int = ERROR_DRAWS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 2.5, 50 and 97.5 % quantiles of the posterior predictive at each timestamp.

    Each draw's prediction minus ``error_draws`` of its own fitted-period errors, picked at random (independently
    per timestamp) among the valid ones; the quantiles are over draws x error draws.

    Parameters
    ----------
    predicted : ndarray, shape (c, k, t)
        The draws' simulated target series minus their sensor offsets [target unit].
    fitted_errors : ndarray, shape (c, k, n)
        The same draws' errors over the fitted period, simulated - measured (offsets applied to the measured)
        [target unit].
    fitted_mask : ndarray of bool, shape (k, n)
        Valid fitted samples; a target with none gets the draws' spread alone.
    rng : numpy Generator
    error_draws : int

    Returns
    -------
    lo, median, hi : ndarray, shape (k, t)
    """
    predicted = np.asarray(predicted, dtype=float)
    c, k, t = predicted.shape
    out = np.empty((3, k, t))
    rows = np.arange(c)[None, :, None]
    for j in range(k):
        valid = np.flatnonzero(fitted_mask[j])
        for a in range(0, t, _BLOCK):
            p = predicted[:, j, a : a + _BLOCK]
            if len(valid):
                pick = valid[rng.integers(0, len(valid), size=(error_draws,) + p.shape)]
                p = (p[None] - fitted_errors[rows, j, pick]).reshape(-1, p.shape[1])
            out[:, j, a : a + _BLOCK] = np.quantile(p, [0.025, 0.5, 0.975], axis=0)
    return out[0], out[1], out[2]


def window_study(study, start, end):
    """The study with ``[start, end]`` as its validation window (warm-up from the study's, or from ``start`` when
    that is earlier)."""
    p = study.period
    start, end = pd.Timestamp(start).to_pydatetime(), pd.Timestamp(end).to_pydatetime()
    warm = p.warmup_start or p.start
    if start < warm:
        warm = start
    return study.replace(period=dataclasses.replace(p, warmup_start=warm, validation_start=start, validation_end=end))


def predictive(
    study,
    space,
    samples: np.ndarray,
    ev,
    window=None,
    draws: int = PREDICTIVE_DRAWS,
    seed: int = 1,
) -> Predictive | None:
    """The posterior predictive band over ``window`` ((start, end); default the study's validation window).

    Parameters
    ----------
    study : Study
    space : ParameterSpace
    samples : ndarray, shape (m, n)
        Posterior samples [SI].
    ev : Evaluator
        Of the fitted period (each draw's errors there widen its prediction: :func:`band`).
    window : (start, end), optional
    draws : int
    seed : int

    Returns
    -------
    Predictive or None
        None without a window.
    """
    from ..metrics import validation_table
    from ..validation import Validator

    if window is None:
        if study.period.validation is None:
            return None
        window = study.period.validation
    wstudy = window_study(study, *window)
    val = Validator(wstudy, space)
    rng = np.random.default_rng([seed, 2])
    X = np.asarray(samples, dtype=float)
    X = X[rng.choice(len(X), size=min(draws, len(X)), replace=False)]
    targets = list(space.targets)
    predicted = val.simulate(X) - space.offsets(X)[:, :, None]  # (c, k, t): the measured signal has no offsets
    lo, med, hi = band(predicted, ev.errors(X), ev.mask, rng)
    y = np.where(val.ev.mask, val.ev.y, np.nan)
    times = val.times
    nt = len(times)
    bands = pd.DataFrame(
        {
            "timestamp": np.tile(times.strftime("%Y-%m-%dT%H:%M:%S"), len(targets)),
            "sensor": np.repeat(targets, nt),
            "measured": y.ravel(),
            "median": med.ravel(),
            "p2.5": lo.ravel(),
            "p97.5": hi.ravel(),
        },
        columns=list(PREDICTIVE_COLUMNS),
    )
    # rmse and mbe are the model's (the draws' median simulation), as in every validation.csv; the band's median
    # is shifted from it by the median fitted error
    table = validation_table(targets, y, np.median(predicted, axis=0))
    ok = np.isfinite(y)
    inside = (y >= lo) & (y <= hi) & ok
    table["coverage_95"] = inside.sum(axis=1) / np.maximum(ok.sum(axis=1), 1)
    table["band_width_95"] = np.where(ok, hi - lo, 0.0).sum(axis=1) / np.maximum(ok.sum(axis=1), 1)
    return Predictive(window=(pd.Timestamp(window[0]), pd.Timestamp(window[1])), bands=bands, table=table, draws=len(X))
