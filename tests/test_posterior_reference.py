"""The posterior sampler of wallcal.analysis.posterior (AR(1) likelihood, the emcee sampler and the burn-in /
thinning that `posterior()` uses) on a linear-Gaussian model with AR(1) errors, whose posterior is known in
closed form.

Model: y = A theta + e, e a stationary AR(1) process (lag-1 correlation phi, marginal sd sigma), optionally plus
a constant sensor bias b ~ N(0, tau^2) integrated out. With a flat prior on a box far wider than the posterior
(> 10 sd on each side, so the truncation is negligible), the posterior is Gaussian:
cov = (A' S^-1 A)^-1, mean = cov A' S^-1 y, where S = sigma^2 phi^|i-j| + tau^2 (formed and inverted densely
here, independently of the likelihood's banded quadratic form).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallcal.analysis.posterior import AR1Likelihood, _stats, burn_and_thin, chain_diagnostics, ensemble_sampler

pytest.importorskip("emcee")

T = 160
SIGMA, PHI = 0.5, 0.8
LOWER = np.array([-2.0, -6.0])
UPPER = np.array([4.0, 6.0])


class LinearModel:
    """The part of the calibration Evaluator the likelihood uses: ``mask``, ``space.from_unit`` and ``errors``."""

    def __init__(self, A, y):
        self.A, self.y = A, y
        self.mask = np.ones((1, len(y)), dtype=bool)
        self.space = self

    def from_unit(self, U):
        return LOWER + np.asarray(U) * (UPPER - LOWER)

    def errors(self, X):
        return (np.atleast_2d(X) @ self.A.T - self.y)[:, None, :]


def _data(seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(T)
    A = np.column_stack([np.sin(2 * np.pi * t / 40.0), t / T - 0.5])
    e = np.empty(T)
    e[0] = SIGMA * rng.standard_normal()
    for k in range(1, T):
        e[k] = PHI * e[k - 1] + SIGMA * math.sqrt(1 - PHI**2) * rng.standard_normal()
    return A, A @ np.array([1.0, 0.5]) + e


def closed_form(A, y, tau):
    i = np.arange(T)
    S = SIGMA**2 * PHI ** np.abs(i[:, None] - i[None, :]) + tau**2
    P = np.linalg.inv(S)
    cov = np.linalg.inv(A.T @ P @ A)
    return cov @ A.T @ P @ y, np.sqrt(np.diag(cov))


@pytest.mark.parametrize("tau", [0.0, 0.3])
def test_posterior_of_a_linear_gaussian_ar1_model(tau):
    A, y = _data()
    mean, sd = closed_form(A, y, tau)
    assert np.all(mean - 10 * sd > LOWER) and np.all(mean + 10 * sd < UPPER)  # the box does not truncate
    model = LinearModel(A, y)
    like = AR1Likelihood(model, [SIGMA], [PHI], [tau])
    walkers, steps = 16, 2500
    sampler = ensemble_sampler(like, walkers, 2, seed=4)
    rng = np.random.default_rng(1)
    p0 = (mean - LOWER) / (UPPER - LOWER) + 0.01 * rng.standard_normal((walkers, 2))
    sampler.run_mcmc(p0, steps)
    chain = sampler.get_chain()
    acc = float(np.mean(sampler.acceptance_fraction))
    tau_ac, burn, thin, warnings = burn_and_thin(chain_diagnostics(chain, sampler.get_log_prob()), acc)
    assert not warnings, warnings  # adequate: long enough, its autocorrelation time settled
    X = model.from_unit(chain[burn::thin].reshape(-1, 2))
    # Monte-Carlo error: n_eff = walkers x (steps - burn) / tau_ac independent draws; the posterior mean's standard
    # error is sd / sqrt(n_eff), the sd's about sd / sqrt(2 n_eff). Tolerance 4 standard errors.
    n_eff = walkers * (steps - burn) / tau_ac
    assert np.all(n_eff > 1000), n_eff
    for j in range(2):
        st = _stats(X[:, j], X[:, j])
        se_mean = sd[j] / math.sqrt(n_eff[j])
        se_sd = sd[j] / math.sqrt(2 * n_eff[j])
        assert abs(st["mean"] - mean[j]) < 4 * se_mean, (j, st["mean"], mean[j], se_mean)
        assert abs(st["sd"] - sd[j]) < 4 * se_sd, (j, st["sd"], sd[j], se_sd)
        # the 95 % interval of the samples brackets the closed-form one (mean +- 1.96 sd) to within 0.1 sd
        assert abs(st["q2.5"] - (mean[j] - 1.96 * sd[j])) < 0.1 * sd[j] + 4 * se_mean
        assert abs(st["q97.5"] - (mean[j] + 1.96 * sd[j])) < 0.1 * sd[j] + 4 * se_mean


def test_ar1_errors_widen_the_posterior_as_the_closed_form_says():
    """Treating AR(1) errors as independent would shrink the sd by about sqrt((1 - phi) / (1 + phi)) = 1/3: the
    closed form with phi = 0.8 is far wider than with phi = 0 (the reason the likelihood models phi)."""
    A, y = _data()
    _, sd_ar1 = closed_form(A, y, 0.0)
    P = np.eye(T) / SIGMA**2
    sd_iid = np.sqrt(np.diag(np.linalg.inv(A.T @ P @ A)))
    assert np.all(sd_ar1 / sd_iid > 2.0)
