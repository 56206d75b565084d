"""The posterior predictive band rule (wallcal.analysis.posterior_predictive.band): each draw's prediction widened
by its own fitted-period errors, level included; the AR(1) persistence of those errors does not widen it."""

from __future__ import annotations

import numpy as np

from wallcal.analysis.posterior_predictive import band


def _ar1(rng, n, phi, sd):
    """A stationary AR(1) series of marginal sd ``sd``."""
    u = np.empty(n)
    u[0] = sd * rng.standard_normal()
    innov = sd * np.sqrt(1.0 - phi**2) * rng.standard_normal(n)
    for i in range(1, n):
        u[i] = phi * u[i - 1] + innov[i]
    return u


def _coverage(lo, hi, y):
    return float(np.mean((y >= lo) & (y <= hi)))


def test_band_covers_95_percent_of_errors_like_the_fitted_ones_level_included():
    """Fitted errors N(-0.5, 0.3^2) (the sensor reads 0.5 above the model): the band is centred on the level and
    covers ~95 % of new measurements from the same distribution; ignoring the level it would cover ~80 %."""
    rng = np.random.default_rng(3)
    c, n, t = 200, 5000, 5000
    predicted = np.zeros((c, 1, t))
    errors = -0.5 + 0.3 * rng.standard_normal((c, 1, n))  # simulated - measured
    lo, med, hi = band(predicted, errors, np.ones((1, n), bool), rng)
    y = 0.5 + 0.3 * rng.standard_normal(t)
    assert 0.94 <= _coverage(lo[0], hi[0], y) <= 0.96
    assert abs(np.mean(med) - 0.5) < 0.02
    assert abs(np.mean(hi - lo) - 2 * 1.96 * 0.3) < 0.03
    assert _coverage(-1.96 * 0.3, 1.96 * 0.3, y) < 0.85  # the level matters


def test_band_is_not_widened_by_persistent_errors():
    """Fitted errors from an AR(1) with phi 0.995 (the real walls' 5-10 min residuals) and marginal sd 0.2: the
    band's width is the errors' own 95 % range, not sigma / sqrt(1 - phi^2) (10 x wider), and invalid samples are
    not drawn."""
    rng = np.random.default_rng(4)
    n, t = 200_000, 500
    e = _ar1(rng, n, 0.995, 0.2)
    mask = np.ones(n, bool)
    mask[::7] = False
    e_with_gaps = np.where(mask, e, 1e6)
    predicted = np.zeros((20, 1, t))
    lo, _, hi = band(predicted, np.broadcast_to(e_with_gaps, (20, 1, n)), mask[None], rng)
    spread = np.subtract(*np.quantile(e[mask], [0.975, 0.025]))
    assert abs(np.mean(hi - lo) / spread - 1.0) < 0.05
    assert np.mean(hi - lo) < 1.2 * 2 * 1.96 * 0.2


def test_band_carries_the_draws_spread_and_each_draws_own_level():
    """Draws whose simulated level differs (the parameters' uncertainty) each carry their own fitted errors: a draw
    0.4 too high left errors 0.4 higher, so the band is not widened by a level the fit already saw; a spread the
    fitted errors do not offset widens it."""
    rng = np.random.default_rng(5)
    c, n, t = 100, 2000, 2000
    level = rng.uniform(-0.4, 0.4, c)
    noise = 0.1 * rng.standard_normal((c, 1, n))
    predicted = np.broadcast_to(level[:, None, None], (c, 1, t))
    mask = np.ones((1, n), bool)
    lo, _, hi = band(predicted, level[:, None, None] + noise, mask, rng)
    assert abs(np.mean(hi - lo) - 2 * 1.96 * 0.1) < 0.03
    lo2, _, hi2 = band(predicted, noise, mask, rng)
    assert np.mean(hi2 - lo2) > 2.0 * np.mean(hi - lo)
