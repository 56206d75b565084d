"""Posterior predictive bands (:mod:`wallcal.analysis.posterior`): any period of the study's data predicted from
the posterior's draws plus its error model; by default the study's held-out validation window.

For each of ``draws`` posterior samples the window is simulated (one engine batch, simulated from the warm-up start
through the window's end), and a measured series is drawn from the error model the posterior's likelihood uses:

    measured = simulated - offsets - b - u_t

with ``offsets`` the draw's calibrated sensor offsets, ``b`` the target's constant sensor bias drawn from its
posterior given the fitted period's residuals of that draw (prior N(0, tau^2), tau half the stated accuracy; the
same AR(1) quadratic form as the likelihood: mean tau^2 q_1e / (1 + tau^2 q_11), variance tau^2 / (1 + tau^2 q_11))
and ``u`` a stationary AR(1) series of marginal sd sigma and lag-1 correlation phi (the posterior's per-target
values). The band at each timestamp is the 2.5 and 97.5 % quantiles over the draws; ``coverage_95`` the share of
measured points inside it, ``band_width_95`` its mean width.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

#: posterior draws simulated for a predictive band
PREDICTIVE_DRAWS = 200
#: columns of predictive.csv
PREDICTIVE_COLUMNS = ("timestamp", "sensor", "measured", "median", "p2.5", "p97.5")


@dataclasses.dataclass
class Predictive:
    """A posterior predictive band over a window.

    Attributes
    ----------
    window : (Timestamp, Timestamp)
    bands : DataFrame
        :data:`PREDICTIVE_COLUMNS`, one row per timestamp and target (long format).
    table : DataFrame
        Per target: ``sensor, rmse, mbe, n`` of the band's median against the measured values (as
        ``validation.csv``), ``coverage_95`` and ``band_width_95`` [target unit].
    draws : int
    """

    window: tuple
    bands: pd.DataFrame
    table: pd.DataFrame
    draws: int


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
    sigma: dict,
    phi: dict,
    bias_sd: dict,
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
        Of the fitted period (the sensor bias's posterior is formed from its residuals).
    sigma, phi, bias_sd : dict
        Target -> the error model's marginal sd, lag-1 correlation and bias prior sd (:func:`error_model`).
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
    c = len(X)
    targets = list(space.targets)
    sig = np.array([sigma[t] for t in targets])
    ph = np.clip(np.array([phi[t] for t in targets]), -0.999, 0.999)
    tau = np.array([bias_sd.get(t, 0.0) for t in targets])
    # the bias's posterior given each draw's fitted-period residuals (the likelihood's quadratic form)
    from .posterior_likelihood import AR1Likelihood

    like = AR1Likelihood(ev, sig, ph, tau)
    E = ev.errors(X)
    q1e = like.quad(np.ones_like(E[:1]), E)  # (c, k)
    t2 = (tau**2)[None]
    den = 1.0 + t2 * like.q11[None]
    b = t2 * q1e / den + np.sqrt(t2 / den) * rng.standard_normal((c, len(targets)))
    sim = val.simulate(X)  # (c, k, t)
    nt = sim.shape[2]
    u = np.empty_like(sim)
    u[:, :, 0] = sig[None] * rng.standard_normal((c, len(targets)))
    innov = (sig * np.sqrt(1.0 - ph**2))[None]
    for i in range(1, nt):
        u[:, :, i] = ph[None] * u[:, :, i - 1] + innov * rng.standard_normal((c, len(targets)))
    pred = sim - space.offsets(X)[:, :, None] - b[:, :, None] - u
    lo, med, hi = np.quantile(pred, [0.025, 0.5, 0.975], axis=0)
    y = np.where(val.ev.mask, val.ev.y, np.nan)  # the measured values (no offsets: the prediction carries them)
    times = val.times
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
    table = validation_table(targets, y, med)
    ok = np.isfinite(y)
    inside = (y >= lo) & (y <= hi) & ok
    table["coverage_95"] = inside.sum(axis=1) / np.maximum(ok.sum(axis=1), 1)
    table["band_width_95"] = np.where(ok, hi - lo, 0.0).sum(axis=1) / np.maximum(ok.sum(axis=1), 1)
    return Predictive(window=(pd.Timestamp(window[0]), pd.Timestamp(window[1])), bands=bands, table=table, draws=c)
