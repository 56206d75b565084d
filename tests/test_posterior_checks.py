"""The posterior's self-checks and its tempered likelihood (wallcal.analysis.posterior).

The tempering is checked where the right answer is known in closed form: a linear-Gaussian model y = A theta + e
whose least-squares estimate has a Gaussian sampling distribution. With an AR(1) error model that is right, the
sandwich rule must leave the likelihood alone (w near 1) and the 95 % intervals hold the truth 95 % of the time;
with a slow model error added to the noise (the AR(1) model fitted to the residuals is then wrong), the
untempered intervals are far too narrow and the tempered ones must restore most of the coverage.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from wallcal.analysis.posterior import (
    AR1Likelihood,
    hac,
    lag1,
    missing_from_diagnosis,
    piled_up,
    posterior,
    residual_checks,
    sandwich_inflation,
    structure_verdict,
    whiten,
)
from wallcal.errors import WallcalError

T, DAY = 2304, 288  # 8 days of 5-minute samples
t = np.arange(T)
A = np.column_stack(
    [np.sin(2 * np.pi * t / DAY), np.cos(2 * np.pi * t / DAY), np.sin(4 * np.pi * t / DAY), t / T - 0.5]
)
THETA = np.array([1.0, 0.5, -0.3, 0.2])


def _ar1(rng, phi, sd):
    e = np.empty(T)
    e[0] = sd * rng.standard_normal()
    z = sd * np.sqrt(1 - phi**2) * rng.standard_normal(T)
    for k in range(1, T):
        e[k] = phi * e[k - 1] + z[k]
    return e


def _coverage(slow_sd, reps=80, seed=0):
    """95 % coverage of the 4 coefficients, untempered and tempered, and the median w, over ``reps`` records.

    Each record: white noise 0.1 + AR(1) noise (phi 0.3, sd 0.05) + optionally a slow model error (AR(1),
    phi 0.995, sd ``slow_sd``). As in posterior(): phi is the lag-1 correlation and sigma the RMSE of the residuals
    (without their mean) at the least-squares fit; the posterior with a flat prior is Gaussian about the AR(1)
    (generalised least-squares) estimate with covariance H^-1, tempered (w H)^-1.
    """
    rng = np.random.default_rng(seed)
    m = np.ones(T, bool)
    inside = {"none": 0.0, "sandwich": 0.0}
    ws = []
    for _ in range(reps):
        e = 0.1 * rng.standard_normal(T) + _ar1(rng, 0.3, 0.05) + (_ar1(rng, 0.995, slow_sd) if slow_sd else 0.0)
        y = A @ THETA + e
        r0 = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
        r0 = r0 - r0.mean()
        phi, sig = lag1(r0, m), float(np.sqrt(np.mean(r0**2)))
        Aw = np.array([whiten(a, m, phi, sig) for a in A.T])
        yw = whiten(y, m, phi, sig)
        H = Aw @ Aw.T
        theta = np.linalg.solve(H, Aw @ yw)
        inflation, k = sandwich_inflation(Aw[:, None, :], (yw - theta @ Aw)[None], DAY)
        assert k == 4
        w = min(1.0, 1.0 / inflation)
        ws.append(w)
        sd = np.sqrt(np.diag(np.linalg.inv(H)))
        inside["none"] += np.mean(np.abs(theta - THETA) < 1.96 * sd) / reps
        inside["sandwich"] += np.mean(np.abs(theta - THETA) < 1.96 * sd / np.sqrt(w)) / reps
    return inside, float(np.median(ws))


def test_whiten_gives_the_likelihood_quadratic_form():
    class Ev:
        mask = np.array([[True, True, False, True, True, True]])

    e = np.array([0.3, 0.2, 0.0, -0.1, 0.05, 0.4])
    like = AR1Likelihood(Ev(), [0.2], [0.6])
    r = whiten(e, Ev.mask[0], 0.6, 0.2)
    assert np.isclose(-0.5 * np.sum(r**2), like.loglike_errors(e[None, None])[0])
    assert r[2] == 0.0  # missing sample
    # a tempered likelihood is the power L^w
    half = AR1Likelihood(Ev(), [0.2], [0.6], weight=0.5)
    half.ev = SimpleNamespace(errors=lambda X: e[None, None], space=SimpleNamespace(from_unit=lambda u: u))
    like.ev = half.ev
    assert np.isclose(half(np.array([[0.5]]))[0], 0.5 * like(np.array([[0.5]]))[0])


def test_hac_by_hand():
    S = np.array([[1.0, -2.0, 0.5, 3.0], [0.0, 1.0, 1.0, -1.0]])
    L = 2
    J = np.zeros((2, 2))
    for i in range(4):
        for j in range(4):
            lag = abs(i - j)
            if lag <= L:
                J += (1 - lag / (L + 1)) * np.outer(S[:, i], S[:, j])
    assert np.allclose(hac(S, L), J)


def test_sandwich_leaves_a_correct_error_model_alone():
    inside, w = _coverage(0.0)
    assert w > 0.9, w
    assert inside["none"] > 0.92 and inside["sandwich"] > 0.92, inside


@pytest.mark.slow
def test_sandwich_restores_coverage_under_a_slow_model_error():
    inside, w = _coverage(0.1)
    assert inside["none"] < 0.7, inside  # the AR(1) model fitted to the residuals is far too confident
    assert w < 0.3, w
    assert inside["sandwich"] > 0.85, inside  # measured 0.88 (a scalar w averages over directions)


# ============================================================================ self-checks
def _study(accuracy=0.5):
    return SimpleNamespace(sensor=lambda name: SimpleNamespace(accuracy=accuracy, accuracy_relative=None))


def _ev(n):
    return SimpleNamespace(mask=np.ones((1, n), bool), y=np.zeros((1, n)))


def test_residual_checks_tell_noise_from_model_error():
    rng = np.random.default_rng(3)
    n = 2000
    space = SimpleNamespace(targets=("T3A",))
    noise = 0.1 * rng.standard_normal((5, 1, n)) + 0.2  # white noise and a sensor bias
    c = residual_checks(_study(), space, _ev(n), noise)
    assert c.loc["T3A", "verdict"] == "consistent with the sensor"
    assert abs(c.loc["T3A", "white noise"] - 0.1) < 0.01
    assert abs(c.loc["T3A", "bias"] - 0.2) < 0.01
    smooth = noise + 0.45 * np.sin(2 * np.pi * np.arange(n) / 288)[None, None]  # model error sd 0.32 > 0.25
    c = residual_checks(_study(), space, _ev(n), smooth)
    assert c.loc["T3A", "verdict"] == "model error above the noise"
    assert abs(c.loc["T3A", "model error"] - 0.45 / np.sqrt(2)) < 0.02
    big = noise + 0.8 * np.sin(2 * np.pi * np.arange(n) / 288)[None, None]
    assert residual_checks(_study(), space, _ev(n), big).loc["T3A", "verdict"] == "beyond the stated accuracy"


def test_pile_up_and_the_structure_verdict():
    rng = np.random.default_rng(0)
    prior = rng.random(20000)
    assert max(piled_up(rng.random(4000), prior)) < 0.04  # a flat posterior: 2 % at each end
    lo, hi = piled_up(1.0 - 0.03 * rng.random(4000), prior)  # pushed against the upper bound
    assert lo == 0.0 and hi > 0.6
    checks = pd.DataFrame(
        [{"target": "T3A", "verdict": "consistent with the sensor", "RMSE": 0.1, "accuracy": 0.5}]
    ).set_index("target")
    ok = pd.DataFrame({"at lower edge": [0.02], "at upper edge": [0.02]}, index=["R[3]"])
    v = structure_verdict(checks, ok, ok)
    assert not v["rejected"] and "No self-check fired" in v["statement"]
    pile = pd.DataFrame({"at lower edge": [0.0], "at upper edge": [0.7]}, index=["(rho c)[5,8]"])
    v = structure_verdict(checks, ok, pile)
    assert v["rejected"] and "pile up at the edge of their prior" in v["statement"]
    assert "(rho c)[5,8] (70% at its upper edge)" in v["statement"]
    many = pd.DataFrame({"at lower edge": np.linspace(0.3, 0.9, 8), "at upper edge": 0.0}, index=list("abcdefgh"))
    v = structure_verdict(checks, ok, many)
    assert "8 parameter(s) or combination(s)" in v["statement"] and "and 3 more" in v["statement"]
    assert v["statement"].index("h (90%") < v["statement"].index("g (81%")  # the most piled-up first
    v = structure_verdict(checks, ok, ok, missing=["depth[T3A]"])
    assert v["rejected"] and "depth[T3A]" in v["statement"] and "wallcal diagnose" in v["statement"]


def test_missing_extensions_from_a_diagnose_output(example_study, tmp_path):
    with pytest.raises(WallcalError, match="candidates.csv: not found"):
        missing_from_diagnosis(example_study, tmp_path)
    (tmp_path / "candidates.csv").write_text(
        "extension,adopted\ndepth[T3A],False\ncontact_resistance[3],False\ndepth[T3A] + offset[T1A],True\n"
    )
    assert missing_from_diagnosis(example_study, tmp_path) == ["depth[T3A]", "offset[T1A]"]
    (tmp_path / "candidates.csv").write_text("extension\ndepth[T3A]\n")
    with pytest.raises(WallcalError, match="no column adopted"):
        missing_from_diagnosis(example_study, tmp_path)


def test_a_wrong_probe_depth_makes_the_check_fire(example_study):
    """The bundled campaign with T3A declared 25 mm off its true depth: the residuals of T3A are far beyond the
    thermocouple's accuracy and the report says the data reject the structure. The true structure, started at
    the true wall, passes the residual check."""
    from wallcal.analysis import reference_values
    from wallcal.calibration import parse_space

    space = parse_space(example_study)
    truth = reference_values(example_study, space)
    good = posterior(example_study, x_start=truth, walkers=40, steps=6, progress=False, nonunique_candidates=16)
    assert (good.checks["verdict"] == "consistent with the sensor").all(), good.checks
    wrong = example_study.replace(wall=example_study.wall.replace_probe("T3A", depth=0.075))
    bad = posterior(wrong, x_start=truth, walkers=40, steps=6, progress=False, nonunique_candidates=16)
    assert bad.checks.loc["T3A", "verdict"] == "beyond the stated accuracy", bad.checks
    assert bad.structure["rejected"]
    assert "STRUCTURE REJECTED" in bad.report() and "T3A: residual RMSE" in bad.report()
    assert bad.tempering["kind"] == "sandwich" and 0 < bad.tempering["weight"] <= 1
