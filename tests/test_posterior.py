"""Posterior: AR(1) likelihood, a short emcee run, checkpoint and resume; the coverage check is slow."""

import numpy as np
import pytest

from wallcal.analysis.posterior import AR1Likelihood, lag1, posterior


def test_ar1_likelihood_matches_direct_formula():
    class Ev:
        mask = np.array([[True, True, False, True, True]])

    e = np.array([[[0.3, 0.2, 0.0, -0.1, 0.05]]])
    like = AR1Likelihood(Ev(), [0.2], [0.6])
    s2, phi = 0.04, 0.6
    # two segments: [0.3, 0.2] and [-0.1, 0.05]
    direct = -0.5 * ((0.3**2 + 0.1**2) / s2 + ((0.2 - phi * 0.3) ** 2 + (0.05 + phi * 0.1) ** 2) / (s2 * (1 - phi**2)))
    assert np.isclose(like.loglike_errors(e)[0], direct)
    assert np.isclose(lag1(np.array([1.0, 1.0, 1.0, 1.0]), np.ones(4, bool)), 0.75)


def test_short_run_checkpoint_and_resume(example_study, tmp_path):
    out = tmp_path / "post"
    r = posterior(example_study, walkers=40, steps=6, progress=False, out_dir=out, nonunique_candidates=16)
    assert r.chain.shape == (6, 40, 18)
    assert r.warnings  # far too short: says so
    assert set(r.summary.columns) >= {"mean", "sd", "q2.5", "q97.5", "verdict", "truth", "inside 95%"}
    assert "R_total" in r.combinations.index
    r.write_into(tmp_path)
    assert (tmp_path / "corner.png").exists() and (tmp_path / "chain.npz").exists()
    # an interrupted run leaves its chain next to --out; --resume continues it
    from wallcal.analysis.posterior import LogCoordinates, _save, checkpoint_path

    ck = checkpoint_path(out)
    coords = LogCoordinates(None, r.space)  # the checkpoint holds the chain of the sampled coordinates
    _save(
        ck,
        coords.from_unit(r.chain.reshape(-1, 18)).reshape(6, 40, coords.dim),
        r.log_prob,
        {
            "names": r.space.names,
            "targets": list(r.space.targets),
            "sigma": r.sigma,
            "phi": r.phi,
            "walkers": 40,
            "sampled_coordinates": coords.names,
            "study_sha256": example_study.sha256,
        },
    )
    r2 = posterior(
        example_study, walkers=40, steps=9, progress=False, out_dir=out, resume=True, nonunique_candidates=16
    )
    assert r2.chain.shape[0] == 9
    assert np.allclose(r2.chain[:6], r.chain, rtol=0, atol=1e-12)  # (the same splits of rho*c: same seed)
    assert not ck.exists()


@pytest.mark.slow
def test_posterior_covers_the_true_wall(example_study):
    from wallcal.calibration import calibrate

    cal = calibrate(example_study, progress=False)
    r = posterior(example_study, x_start=cal.x_opt, steps=600, progress=False)
    k, n = r.coverage()
    assert n >= 1
    assert k == n, r.summary
