"""The ensemble slice sampler (wallcal.analysis.ensemble_slice), on targets whose answer is known in closed form:
a correlated Gaussian, and a flat density on a box sampled in log coordinates (the posterior's prior)."""

from __future__ import annotations

import numpy as np
import pytest

from wallcal.analysis.ensemble_slice import EnsembleSliceSampler
from wallcal.analysis.posterior import LogCoordinates, chain_diagnostics, ensemble_sampler
from wallcal.calibration.space import Parameter, ParameterSpace


def _gaussian(n, seed=0):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    C = A @ A.T + 0.1 * np.eye(n)  # condition number ~100: strongly correlated
    P = np.linalg.inv(C)

    def log_prob(X):
        X = np.atleast_2d(X)
        return -0.5 * np.einsum("ij,jk,ik->i", X, P, X)

    return C, log_prob


def test_slice_sampler_draws_a_correlated_gaussian():
    """Mean and covariance of a 5-D correlated Gaussian within their Monte-Carlo errors, the chain adequate by the
    posterior's own rule, and every walker moved at every step (a slice step never rejects)."""
    n, walkers, steps = 5, 20, 2000
    C, log_prob = _gaussian(n)
    s = EnsembleSliceSampler(log_prob, walkers, n, seed=3)
    rng = np.random.default_rng(1)
    for _ in s.sample(0.1 * rng.standard_normal((walkers, n)), steps):
        pass
    chain = s.get_chain()
    assert chain.shape == (steps, walkers, n) and s.get_log_prob().shape == (steps, walkers)
    assert np.all(np.diff(chain, axis=0) != 0.0)
    d = chain_diagnostics(chain, s.get_log_prob(), target=1000)
    assert d.adequate, d.reasons
    X = chain[d.burn :].reshape(-1, n)
    n_eff = d.effective_samples
    sd = np.sqrt(np.diag(C))
    # standard errors: the mean's sd / sqrt(n_eff), a covariance entry's about sqrt((C_ii C_jj + C_ij^2) / n_eff)
    assert np.all(np.abs(X.mean(axis=0)) < 4 * sd / np.sqrt(n_eff))
    se_cov = np.sqrt((np.outer(sd**2, sd**2) + C**2) / n_eff)
    assert np.all(np.abs(np.cov(X.T) - C) < 4 * se_cov)
    assert 0.4 < s.expansion_share < 0.6  # mu tuned: expansions and contractions balance
    assert 2.0 < s.evaluations / (walkers * steps) < 8.0


def test_slice_sampler_keeps_the_prior_uniform_in_log_coordinates():
    """A flat likelihood sampled in log coordinates gives the uniform prior on the bounds back, and no walker
    ever leaves the box (outside, the density is zero: it only shrinks the slice)."""
    params = tuple(
        Parameter(f"p{j}", "conductivity", (j,), None, base=0.5 * (lo + hi), lower=lo, upper=hi)
        for j, (lo, hi) in enumerate([(0.5, 3.0), (100.0, 1000.0), (-1.0, 1.0)])
    )
    space = ParameterSpace(parameters=params, targets=("T",))

    def flat(U):
        U = np.atleast_2d(U)
        return np.where(np.all((U >= 0) & (U <= 1), axis=1), 0.0, -np.inf)

    coords = LogCoordinates(flat, space)
    s = ensemble_sampler(coords, 24, 3, seed=5, kind="slice")
    assert isinstance(s, EnsembleSliceSampler)
    U0 = np.random.default_rng(4).random((24, 3))
    for _ in s.sample(coords.from_unit(U0), 1500):
        pass
    U = coords.to_unit(s.get_chain()[200:].reshape(-1, 3))
    assert np.all((U >= 0) & (U <= 1))
    n_eff = len(U) / 20.0  # autocorrelation time well under 20 steps here
    for j in range(3):
        assert abs(U[:, j].mean() - 0.5) < 5 * np.sqrt(1 / 12 / n_eff), j
        assert abs(np.mean(U[:, j] < 0.25) - 0.25) < 5 * np.sqrt(0.25 * 0.75 / n_eff), j


def test_slice_sampler_is_seeded_and_leaves_the_global_generators_alone():
    """The same seed gives the same chain; numpy's global generator is not drawn from (zeus's is)."""
    _, log_prob = _gaussian(3)
    start = np.random.default_rng(2).standard_normal((8, 3))
    state = np.random.get_state()[1].copy()  # noqa: NPY002 - the legacy global generator is the point
    chains = []
    for _ in range(2):
        s = EnsembleSliceSampler(log_prob, 8, 3, seed=7)
        for _ in s.sample(start, 30):
            pass
        chains.append(s.get_chain())
    assert np.array_equal(chains[0], chains[1])
    assert np.array_equal(np.random.get_state()[1], state)  # noqa: NPY002


def test_slice_sampler_refuses_a_start_of_zero_density():
    s = EnsembleSliceSampler(lambda X: np.full(len(X), -np.inf), 4, 2, seed=1)
    with pytest.raises(ValueError, match="finite log-probability"):
        next(s.sample(np.zeros((4, 2)), 1))


def test_posterior_with_the_slice_sampler_resumes_with_its_tuned_scale(example_study, tmp_path):
    """posterior(sampler="slice") runs the same walker chain (same diagnostics, no acceptance fraction: a slice
    step always moves); its checkpoint keeps the sampler and the tuned scale, --resume continues with them and
    refuses a checkpoint of the other sampler."""
    from wallcal.analysis.posterior import _save, checkpoint_path, posterior
    from wallcal.errors import WallcalError

    out = tmp_path / "post"
    kw = {"walkers": 40, "progress": False, "out_dir": out, "nonunique_candidates": 8, "sampler": "slice"}
    r = posterior(example_study, steps=4, **kw)
    assert r.chain.shape == (4, 40, 18) and np.isnan(r.acceptance)
    assert not any("acceptance" in w for w in r.warnings)
    assert r.simulations > 40 * 4  # several evaluations per walker and step
    ck = checkpoint_path(out)
    meta = {
        "names": r.space.names,
        "targets": list(r.space.targets),
        "sigma": r.sigma,
        "phi": r.phi,
        "walkers": 40,
        "study_sha256": example_study.sha256,
        "sampler": "slice",
        "mu": 0.37,
    }
    _save(ck, r.chain, r.log_prob, meta)
    with pytest.raises(WallcalError, match="another sampler"):
        posterior(example_study, steps=5, resume=True, **{**kw, "sampler": "emcee"})
    r2 = posterior(example_study, steps=5, resume=True, **kw)
    assert np.array_equal(r2.chain[:4], r.chain) and r2.chain.shape[0] == 5
    assert r2.sampler["kind"] == "slice" and r2.sampler["mu"] == 0.37  # tuned before: not tuned again
    assert "ensemble slice sampling" in r2.report()
