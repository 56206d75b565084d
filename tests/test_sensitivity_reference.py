"""Sobol' and Morris estimators of wallcal.analysis.sensitivity (the functions `sensitivity()` calls) on functions
whose indices are known in closed form.

Tolerances follow the estimators' Monte-Carlo error: SALib reports a bootstrap 95 % half-width ``conf`` (about
1.96 standard errors) with each index; an estimate must lie within 2 conf (about 4 standard errors, a chance of
1e-4 per index for a correct estimator, and the seed is fixed) of the analytic value, and conf itself must be
small, so that the check has teeth.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallcal.analysis.sensitivity import morris_indices, morris_sample, sobol_indices, sobol_sample

pytest.importorskip("SALib")


# ---------------------------------------------------------------------------- Ishigami
def ishigami_indices(a=7.0, b=0.1):
    """Analytic S1 and ST of f = sin x1 + a sin^2 x2 + b x3^4 sin x1 on [-pi, pi]^3 (Ishigami & Homma 1990)."""
    v1 = 0.5 * (1 + b * math.pi**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = b**2 * math.pi**8 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    return np.array([v1, v2, 0.0]) / v, np.array([v1 + v13, v2, v13]) / v


def test_ishigami_analytic_values():
    s1, st = ishigami_indices()
    np.testing.assert_allclose(s1, [0.3139, 0.4424, 0.0], atol=1e-4)  # the values quoted in the literature
    np.testing.assert_allclose(st, [0.5576, 0.4424, 0.2437], atol=1e-4)


def test_sobol_on_ishigami():
    problem = {"num_vars": 3, "names": ["x1", "x2", "x3"], "bounds": [[-math.pi, math.pi]] * 3}
    X = sobol_sample(problem, 4096, seed=3)
    assert X.shape == (4096 * 5, 3)
    Y = np.sin(X[:, 0]) + 7.0 * np.sin(X[:, 1]) ** 2 + 0.1 * X[:, 2] ** 4 * np.sin(X[:, 0])
    r = sobol_indices(problem, Y, seed=3)
    s1, st = ishigami_indices()
    for k in ("S1", "ST"):
        assert (r[f"{k}_conf"] < 0.06).all(), r
    np.testing.assert_array_less(np.abs(r["S1"].to_numpy() - s1), 2 * r["S1_conf"].to_numpy())
    np.testing.assert_array_less(np.abs(r["ST"].to_numpy() - st), 2 * r["ST_conf"].to_numpy())


# ---------------------------------------------------------------------------- Sobol' G
def g_indices(a):
    """Analytic S1 and ST of G = prod (|4 x_i - 2| + a_i) / (1 + a_i) on [0, 1]^n: V_i = 1 / (3 (1 + a_i)^2)."""
    vi = 1.0 / (3.0 * (1.0 + np.asarray(a)) ** 2)
    v = np.prod(1 + vi) - 1
    st = np.array([vi[i] * np.prod(np.delete(1 + vi, i)) for i in range(len(vi))]) / v
    return vi / v, st


def test_sobol_on_the_g_function():
    a = np.array([0.0, 1.0, 4.5, 9.0, 99.0])
    problem = {"num_vars": 5, "names": [f"x{i}" for i in range(5)], "bounds": [[0.0, 1.0]] * 5}
    X = sobol_sample(problem, 4096, seed=5)
    Y = np.prod((np.abs(4 * X - 2) + a) / (1 + a), axis=1)
    r = sobol_indices(problem, Y, seed=5)
    s1, st = g_indices(a)
    # by hand: V_i = 1/3, 1/12, 1/90.75, 1/300, 1/30000; V = (4/3)(13/12)(1.011019)(1.003333)(1.0000333) - 1
    # = 0.465278; S1_1 = (1/3) / V = 0.7164; ST_1 = (1/3)(1.098958) / V = 0.7873
    assert s1[0] == pytest.approx(0.7164, abs=1e-4) and st[0] == pytest.approx(0.7873, abs=1e-4)
    for k in ("S1", "ST"):
        assert (r[f"{k}_conf"] < 0.06).all(), r
    np.testing.assert_array_less(np.abs(r["S1"].to_numpy() - s1), 2 * r["S1_conf"].to_numpy() + 1e-12)
    np.testing.assert_array_less(np.abs(r["ST"].to_numpy() - st), 2 * r["ST_conf"].to_numpy() + 1e-12)


# ---------------------------------------------------------------------------- Morris
def test_morris_elementary_effects_by_hand():
    """f = 3 x1 - 2 x2 + x3^2 + 0 x4, x1 in [-1, 1], the others in [0, 1]; 4 levels, step Delta = 2/3 of the range.

    Elementary effects are per unit of the normalised range: x1: 3 x 2 = 6 on every trajectory (mu* = mu = 6,
    sigma = 0); x2: -2 (mu* = 2, mu = -2, sigma = 0); x4: 0. x3: the step joins levels 0 <-> 2/3 (EE = 2/3) or
    1/3 <-> 1 (EE = 4/3), equally likely, so mu* = mu = 1 and sigma = 1/3 in expectation; their Monte-Carlo
    standard error is sigma / sqrt(r)."""
    problem = {"num_vars": 4, "names": ["x1", "x2", "x3", "x4"], "bounds": [[-1.0, 1.0], [0, 1], [0, 1], [0, 1]]}
    r = 400
    X = morris_sample(problem, r, levels=4, seed=2)
    assert X.shape == (r * 5, 4)
    Y = 3 * X[:, 0] - 2 * X[:, 1] + X[:, 2] ** 2
    m = morris_indices(problem, X, Y, levels=4, seed=2)
    np.testing.assert_allclose(m.loc["x1", ["mu_star", "mu", "sigma"]].to_numpy(float), [6, 6, 0], atol=1e-12)
    np.testing.assert_allclose(m.loc["x2", ["mu_star", "mu", "sigma"]].to_numpy(float), [2, -2, 0], atol=1e-12)
    np.testing.assert_allclose(m.loc["x4", ["mu_star", "mu", "sigma"]].to_numpy(float), [0, 0, 0], atol=1e-12)
    se = (1 / 3) / math.sqrt(r)  # 0.0167
    assert abs(m.loc["x3", "mu_star"] - 1.0) < 4 * se
    assert abs(m.loc["x3", "mu"] - 1.0) < 4 * se
    # the sd of a two-point variable (+-1/3 about 1) is 1/3; its estimate's error is about sigma / sqrt(2 r)
    assert abs(m.loc["x3", "sigma"] - 1 / 3) < 4 * (1 / 3) / math.sqrt(2 * r)
    # every EE of x3 is 2/3 or 4/3: mu* sits between them whatever the sample
    assert 2 / 3 <= m.loc["x3", "mu_star"] <= 4 / 3
