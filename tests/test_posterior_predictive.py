"""The posterior predictive band rule (wallcal.analysis.posterior_predictive): each draw's prediction widened by its
own fitted-period errors, level included (band), taken out of sample (out_of_fold: each block of the fitted period
refitted without); the AR(1) persistence of those errors does not widen it."""

from __future__ import annotations

import numpy as np
import pandas as pd

from wallcal.analysis.posterior_predictive import MAX_FOLDS, band, fold_blocks, out_of_fold


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


class _Space:
    """A two-parameter box (a, b) for :class:`_LinearModel`."""

    lower = np.array([-10.0, -10.0])
    upper = np.array([10.0, 10.0])

    def to_unit(self, x):
        return (np.asarray(x) - self.lower) / (self.upper - self.lower)

    def from_unit(self, u):
        return self.lower + np.asarray(u) * (self.upper - self.lower)


class _LinearModel:
    """An evaluator of the model ``a + b x(t)`` against measured ``y(t)`` (one target)."""

    def __init__(self, times, x, y, mask):
        self.space = _Space()
        self.prepared = type("P", (), {"times": times})()
        self.x, self.y, self.mask = x, y, mask[None]
        self.n_valid = self.mask.sum(axis=1)

    def errors(self, X):
        X = np.atleast_2d(X)
        sim = X[:, :1] + X[:, 1:2] * self.x[None]
        return np.where(self.mask[None], (sim - self.y[None])[:, None, :], 0.0)


def _campaign(curvature, seed=5):
    """Ten days at 10 min of a driver that drifts from one level to another (as the temperature difference across a
    wall does over a record), measured as ``1 + 2 x + curvature x^2`` plus white noise of sd 0.1, a gap included."""
    rng = np.random.default_rng(seed)
    times = pd.date_range("2021-01-01", periods=1440, freq="10min")
    x = np.linspace(0.0, 3.0, times.size) + 0.3 * np.sin(np.arange(times.size) * 2 * np.pi / 144)
    y = 1.0 + 2.0 * x + curvature * x**2 + 0.1 * rng.standard_normal(times.size)
    mask = np.ones(times.size, bool)
    mask[300:340] = False
    return times, x, y, mask


def test_fold_blocks_cut_the_fitted_period_into_pieces_of_the_window_s_length():
    times, _, _, mask = _campaign(0.0)
    blocks = fold_blocks(times, mask, pd.Timedelta("2D"))
    assert len(blocks) == 5
    assert np.array_equal(np.sum(blocks, axis=0), mask.astype(int))  # disjoint, together every valid sample
    for b in blocks:  # contiguous: one run of valid samples between its first and last
        idx = np.flatnonzero(b)
        assert np.array_equal(b[idx[0] : idx[-1] + 1], mask[idx[0] : idx[-1] + 1])
    assert len(fold_blocks(times, mask, pd.Timedelta("30D"))) == 2
    assert len(fold_blocks(times, mask, pd.Timedelta("1h"))) == MAX_FOLDS


def test_out_of_fold_errors_are_those_of_fits_without_each_block():
    """A straight line fitted to a curved truth: inside each block, the model's errors once the block is left out
    of the fit (exact least squares as the reference) minus its errors fitted on everything; with a straight
    truth (white noise only) the widening is negligible."""
    times, x, y, mask = _campaign(0.3)
    ev = _LinearModel(times, x, y, mask)
    delta = out_of_fold(ev, np.array([0.5, 1.5]), pd.Timedelta("2D"))
    A = np.column_stack([np.ones_like(x), x])

    def fit(keep):
        coef = np.linalg.lstsq(A[keep], y[keep], rcond=None)[0]
        return A @ coef - y

    full = fit(mask)
    expected = np.zeros_like(y)
    for block in fold_blocks(times, mask, pd.Timedelta("2D")):
        expected[block] = (fit(mask & ~block) - full)[block]
    assert np.abs(delta[0] - expected).max() < 2e-3 * np.abs(expected).max()
    assert np.all(delta[0][~mask] == 0.0)
    rms = lambda e: np.sqrt(np.mean(e[mask] ** 2))  # noqa: E731
    assert rms(full + delta[0]) > 1.5 * rms(full)  # the out-of-fold errors are larger than the fitted ones
    times, x, y, mask = _campaign(0.0)
    delta = out_of_fold(_LinearModel(times, x, y, mask), np.array([0.5, 1.5]), pd.Timedelta("2D"))
    assert rms(delta[0]) < 0.02  # against the noise's 0.1
