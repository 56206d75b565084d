"""When the posterior's chain is adequate (wallcal.analysis.posterior.chain_diagnostics): the burn-in read from the
start's transient in the log-probability, the autocorrelation time against its closed form, and the refusal to call
a chain adequate while its autocorrelation time still grows with its length (an estimate capped by a short chain).

The chains here are independent AR(1) series per walker, x_t = phi x_(t-1) + sqrt(1 - phi^2) e_t, whose integrated
autocorrelation time is (1 + phi) / (1 - phi) steps.
"""

from __future__ import annotations

import numpy as np
import pytest

from wallcal.analysis.posterior import chain_diagnostics, integrated_time, posterior, transient_end
from wallcal.errors import WallcalError

pytest.importorskip("emcee")


def _ar1_chain(steps, walkers, n, phi, seed=0, start=0.0):
    rng = np.random.default_rng(seed)
    x = np.empty((steps, walkers, n))
    x[0] = start + rng.standard_normal((walkers, n))
    s = np.sqrt(1.0 - phi**2)
    for t in range(1, steps):
        x[t] = phi * x[t - 1] + s * rng.standard_normal((walkers, n))
    return x


def test_integrated_time_is_emcees():
    """All walkers' FFTs at once give emcee's estimate (mean of the walkers' autocorrelation functions, Sokal's
    window with c = 5)."""
    import emcee

    for steps, phi in ((300, 0.5), (1001, 0.95)):
        chain = _ar1_chain(steps, 24, 3, phi, seed=steps)
        expected = emcee.autocorr.integrated_time(chain, quiet=True, tol=0)
        assert np.allclose(integrated_time(chain), expected, rtol=1e-10)


def test_a_long_chain_is_adequate_and_its_autocorrelation_time_is_right():
    phi = 0.9  # tau = 19 steps
    chain = _ar1_chain(3000, 32, 2, phi)
    log_prob = -0.5 * np.sum(chain**2, axis=2)
    d = chain_diagnostics(chain, log_prob, target=500)
    assert np.allclose(d.tau, (1 + phi) / (1 - phi), rtol=0.15), d.tau  # the windowed estimate is ~5 % low
    assert d.stable and d.adequate, d.reasons
    assert d.burn < 100  # stationary from the start: the burn-in is about one autocorrelation time
    assert d.effective_samples == pytest.approx(32 * (3000 - d.burn) / np.max(d.tau))


def test_a_chain_shorter_than_its_autocorrelation_time_is_not_adequate():
    """tau = 1999 steps, 600 steps sampled: the windowed estimate is capped by the chain (tens of steps) and would
    claim thousands of effective samples; the estimate grows with the chain, so the chain is not adequate."""
    chain = _ar1_chain(600, 88, 3, 0.999, seed=1)
    d = chain_diagnostics(chain, -0.5 * np.sum(chain**2, axis=2), target=500)
    assert np.max(d.tau) < 200  # the capped estimate
    assert d.effective_samples > 500  # what the capped estimate claims
    assert not d.stable and not d.adequate
    assert any("still grows" in r for r in d.reasons), d.reasons


def test_burn_in_ends_where_the_log_probability_reaches_its_level():
    """Walkers started 6 sd off relax with phi = 0.9 (about 25 steps to within 0.5 sd); the log-probability
    climbs to its stationary level there."""
    chain = _ar1_chain(2000, 32, 2, 0.9, seed=2, start=6.0)
    log_prob = -0.5 * np.sum(chain**2, axis=2)
    end = transient_end(log_prob)
    assert 10 <= end <= 60, end
    d = chain_diagnostics(chain, log_prob)
    assert end <= d.burn <= 100
    assert abs(chain[d.burn :].mean()) < 0.1  # the start's offset is gone after the burn-in


def test_the_default_chain_stops_at_max_steps_and_says_it_is_not_adequate(example_study):
    r = posterior(
        example_study, walkers=40, max_steps=60, effective_samples=1e6, progress=False, nonunique_candidates=8
    )
    assert r.chain.shape[0] == 60
    assert not r.adequate
    assert any("not adequate" in w for w in r.warnings)
    assert r.simulations is not None and 0 < r.simulations <= r.evaluations
    assert r.to_json()["adequate"] is False
    with pytest.raises(WallcalError, match="effective_samples"):
        posterior(example_study, effective_samples=0, progress=False)


def test_the_default_chain_stops_when_adequate_and_is_summarised_with_that_check(example_study, monkeypatch):
    """The chain stops at the first check that finds it adequate (here forced at step ADAPTIVE_FIRST_CHECK), and the
    summary reuses that check's diagnostics of the same chain instead of computing them again."""
    import dataclasses

    from wallcal.analysis import posterior as post

    calls = []

    def adequate(chain, log_prob=None, target=post.DEFAULT_EFFECTIVE_SAMPLES):
        calls.append(len(chain))
        return dataclasses.replace(chain_diagnostics(chain, log_prob, target), adequate=True, reasons=[])

    monkeypatch.setattr(post, "chain_diagnostics", adequate)
    r = posterior(example_study, walkers=40, progress=False, nonunique_candidates=8)
    assert calls == [post.ADAPTIVE_FIRST_CHECK]
    assert r.chain.shape[0] == post.ADAPTIVE_FIRST_CHECK
    assert r.adequate and r.to_json()["adequate"] is True
    assert not any("not adequate" in w for w in r.warnings)


@pytest.mark.parametrize("flag", ["--steps", "--effective-samples", "--max-steps"])
def test_cli_refuses_a_chain_length_that_is_not_positive(flag, capsys):
    from conftest import EXAMPLE
    from wallcal.cli import main

    assert main(["posterior", str(EXAMPLE), flag, "0"]) == 2
    assert f"{flag}: must be positive" in capsys.readouterr().err
