"""Posterior predictive bands (:mod:`wallcal.analysis.posterior`): any period of the study's data predicted from
the posterior's draws plus the errors they make where the fit did not see the data; by default the study's
held-out validation window.

For each of ``draws`` posterior samples the window is simulated (one engine batch, simulated from the warm-up start
through the window's end), and the measured value at each of its timestamps is predicted as

    measured = simulated - offsets - e

with ``offsets`` the draw's calibrated sensor offsets and ``e`` one of this same draw's errors (simulated -
measured) over the fitted period, picked at random (:func:`band`), **as they would be out of sample**: each
fitted timestamp's error plus how much worse the model predicts it when the fit does not see it
(:func:`out_of_fold`: the fitted period cut into blocks as long as the window, each refitted without in turn).
The band is thus the draws' spread (the parameters' uncertainty) widened by the empirical distribution of each
draw's out-of-sample errors, level included: model error, sensor bias and sensor noise, as the fitted period
shows them, with no assumption of their shape. A draw whose simulated level is off carries its own level error
into its prediction, so the parameters' spread in level is not counted twice. The AR(1) error model of the
likelihood does not enter: it describes how an error follows the previous one, which matters to the likelihood,
not the marginal distribution of an error at a timestamp, which is what a band is (docs/identifiability.md,
"Posterior predictive bands").

The band at each timestamp is the 2.5 and 97.5 % quantiles of these predictions (``median`` of predictive.csv
their median: the model's, shifted by the median error); ``coverage_95`` the share of measured points inside
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
#: most blocks of the fitted period refitted without them (:func:`out_of_fold`)
MAX_FOLDS = 6


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


def fold_blocks(times: pd.DatetimeIndex, valid: np.ndarray, length: pd.Timedelta) -> list[np.ndarray]:
    """The fitted period cut into contiguous blocks of about ``length`` each (at least 2, at most
    :data:`MAX_FOLDS`, of equal duration from its first to its last valid timestamp): one boolean array over
    ``times`` per block."""
    idx = np.flatnonzero(valid)
    if len(idx) < 2:
        return []
    first, last = times[idx[0]], times[idx[-1]]
    span = last - first
    k = int(np.clip(round(span / length) if length > pd.Timedelta(0) else 2, 2, MAX_FOLDS))
    edges = [first + span * i / k for i in range(k + 1)]
    blocks = []
    for i in range(k):
        inside = (times >= edges[i]) & ((times < edges[i + 1]) if i < k - 1 else (times <= last))
        blocks.append(np.asarray(inside) & valid)
    return [b for b in blocks if b.any()]


def out_of_fold(ev, x_ref: np.ndarray, length: pd.Timedelta) -> np.ndarray:
    """How much worse the fitted period is predicted where the fit did not see it: per block of about
    ``length`` (:func:`fold_blocks`), the change of the model's errors when that block is left out of the fit.

    The structure is refitted by least squares (the errors of each target over its RMS at ``x_ref``,
    :func:`~wallcal.analysis.diagnose_scoring.refine` from ``x_ref``) on the whole fitted period, then on the
    period without each block in turn; inside the block the difference of the two fits' errors is returned.

    Parameters
    ----------
    ev : Evaluator
        Of the fitted period.
    x_ref : ndarray, shape (n,)
        A point of the posterior [SI] (where the refits start).
    length : Timedelta
        The predicted window's length.

    Returns
    -------
    ndarray, shape (n_targets, n_times)
        Out-of-fold minus in-sample error [target unit]; 0 at invalid samples.
    """
    from .diagnose_scoring import refine

    space = ev.space
    mask = ev.mask
    delta = np.zeros(mask.shape)
    blocks = fold_blocks(ev.prepared.times, mask.any(axis=0), length)
    if not blocks:
        return delta
    e_ref = ev.errors(np.asarray(x_ref, dtype=float)[None])[0]
    scale = np.sqrt(np.einsum("kt,kt->k", e_ref, e_ref) / np.maximum(ev.n_valid, 1))
    scale = np.where(scale > 0, scale, 1.0)

    def fit(keep):
        def residuals(U):
            e = ev.errors(space.from_unit(U))
            return (np.where(keep[None], e, 0.0) / scale[None, :, None]).reshape(len(U), -1)

        u, _ = refine(residuals, space.to_unit(np.asarray(x_ref, dtype=float)))
        return ev.errors(space.from_unit(u[None]))[0]

    e_full = fit(mask)
    for block in blocks:
        e_out = fit(mask & ~block[None])
        delta[:, block] = (e_out - e_full)[:, block]
    return np.where(mask, delta, 0.0)


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
    out_of_sample: bool = True,
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
    out_of_sample : bool
        Widen each draw's fitted-period errors by :func:`out_of_fold` (the default), or take them as they are.

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
    errors = ev.errors(X)
    if out_of_sample:  # each draw's fitted errors as they would be where the fit did not see them
        length = pd.Timestamp(window[1]) - pd.Timestamp(window[0])
        errors = errors + out_of_fold(ev, np.median(X, axis=0), length)[None]
    lo, med, hi = band(predicted, errors, ev.mask, rng)
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
