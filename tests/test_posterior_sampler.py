"""How wallcal.analysis.posterior samples: the linearisation at the optimum (its information against the closed
form), the walkers drawn from the Laplace approximation, and the log coordinates that keep the prior uniform on
the bounds.

Each is checked where the answer is known in closed form: a linear model y = A theta + e with AR(1) errors and a
constant sensor bias, whose information about theta is A' (S + tau^2 1 1')^-1 A (S the AR(1) covariance), and a
flat likelihood, whose posterior is the uniform prior.
"""

from __future__ import annotations

import numpy as np
import pytest

from wallcal.analysis.posterior import LogCoordinates, ensemble_sampler, initial_walkers, linearise
from wallcal.calibration.space import Parameter, ParameterSpace

pytest.importorskip("emcee")

T = 200
SIGMA, PHI, TAU = 0.5, 0.7, 0.4


def _space(bounds):
    params = tuple(
        Parameter(f"p{j}", "conductivity", (j,), None, base=0.5 * (lo + hi), lower=lo, upper=hi)
        for j, (lo, hi) in enumerate(bounds)
    )
    return ParameterSpace(parameters=params, targets=("T",))


class LinearModel:
    """The part of the Evaluator that linearise() uses: ``mask`` and ``errors`` (simulated minus measured)."""

    def __init__(self, A, y):
        self.A, self.y = A, y
        self.mask = np.ones((1, len(y)), dtype=bool)

    def errors(self, X):
        return (np.atleast_2d(X) @ self.A.T - self.y)[:, None, :]


def test_linearise_gives_the_closed_form_information():
    """With the bias integrated out, the information is the generalised least-squares precision of the model with
    S + tau^2 1 1' (formed densely here) - in unit coordinates, so scaled by the bounds' spans."""
    rng = np.random.default_rng(0)
    t = np.arange(T)
    A = np.column_stack([np.sin(2 * np.pi * t / 50.0), t / T - 0.5, np.cos(2 * np.pi * t / 80.0)])
    space = _space([(-2.0, 4.0), (-6.0, 6.0), (-1.0, 1.0)])
    model = LinearModel(A, A @ np.array([1.0, 0.5, 0.0]) + 0.1 * rng.standard_normal(T))
    lin = linearise(model, space, np.array([0.8, 0.3, 0.1]), {"T": SIGMA}, {"T": PHI}, {"T": TAU})
    i = np.arange(T)
    S = SIGMA**2 * PHI ** np.abs(i[:, None] - i[None, :]) + TAU**2
    Au = A * (space.upper - space.lower)[None]
    expected = Au.T @ np.linalg.solve(S, Au)
    assert np.allclose(lin.information, expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())
    # without the bias the constant direction carries full information: the bias lowers it
    plain = linearise(model, space, np.array([0.8, 0.3, 0.1]), {"T": SIGMA}, {"T": PHI})
    assert plain.information[1, 1] > lin.information[1, 1]


def test_initial_walkers_draw_the_laplace_approximation():
    """In unit coordinates (bounds not all positive) the walkers follow N(u0, (w H + 12 I)^-1): the information
    weighted by the tempering plus a Gaussian with the uniform prior's variance 1/12; all inside the box."""
    space = _space([(-1.0, 1.0), (-1.0, 1.0)])
    H = np.array([[4.0e4, 3.0e4], [3.0e4, 4.0e4]])  # correlated, well inside the box
    x0 = np.array([0.2, -0.1])
    for w in (1.0, 0.25):
        U = initial_walkers(space, x0, 20000, np.random.default_rng(1), H, weight=w)
        cov = np.linalg.inv(w * H + 12.0 * np.eye(2))
        assert np.allclose(U.mean(axis=0), space.to_unit(x0), atol=4 * np.sqrt(np.diag(cov) / 20000))
        assert np.allclose(np.cov(U.T), cov, rtol=0.05, atol=0.05 * np.sqrt(cov[0, 0] * cov[1, 1]))
    # a flat direction (rank-1 information): the spread along it comes from the prior alone and the box holds it
    flat = np.array([[1.0e4, -1.0e4], [-1.0e4, 1.0e4]])
    U = initial_walkers(space, x0, 4000, np.random.default_rng(2), flat)
    assert np.all((U > 0.0) & (U < 1.0))
    along = (U - space.to_unit(x0)) @ np.array([1.0, 1.0]) / np.sqrt(2.0)
    assert 0.15 < along.std() < 0.35  # the prior's sd 0.29, cut by the box


def test_initial_walkers_are_gaussian_in_log_coordinates():
    """Positive bounds: the approximation is Gaussian in ln x, whose information is H (du/dz)^2, du/dz = x/span."""
    space = _space([(0.5, 3.0)])
    x0 = np.array([1.2])
    h_u = 2.0e3
    U = initial_walkers(space, x0, 20000, np.random.default_rng(3), np.array([[h_u]]))
    z = np.log(space.from_unit(U)[:, 0])
    dudz = x0[0] / 2.5
    prior_sd = np.log(3.0 / 0.5) / np.sqrt(12.0)
    sd = 1.0 / np.sqrt(h_u * dudz**2 + prior_sd**-2)
    assert abs(z.mean() - np.log(1.2)) < 4 * sd / np.sqrt(20000)
    assert abs(z.std() / sd - 1.0) < 0.03


def test_log_coordinates_keep_the_prior_uniform():
    """A flat likelihood sampled in log coordinates must give the uniform prior on the bounds back (without the
    Jacobian term the posterior would be log-uniform: mean 1.395 instead of 1.75 on [0.5, 3])."""
    space = _space([(0.5, 3.0), (100.0, 1000.0), (-1.0, 1.0)])

    def flat(U):
        U = np.atleast_2d(U)
        return np.where(np.all((U >= 0) & (U <= 1), axis=1), 0.0, -np.inf)

    coords = LogCoordinates(flat, space)
    rng = np.random.default_rng(4)
    U0 = rng.random((24, 3))
    assert np.allclose(coords.to_unit(coords.from_unit(U0)), U0)
    sampler = ensemble_sampler(coords, 24, 3, seed=5)
    sampler.run_mcmc(coords.from_unit(U0), 3000)
    Z = sampler.get_chain(discard=500).reshape(-1, 3)
    U = coords.to_unit(Z)
    assert np.all((U >= 0) & (U <= 1))
    n_eff = len(U) / 40.0  # autocorrelation time well under 40 steps here
    for j in range(3):
        se = np.sqrt(1 / 12 / n_eff)
        assert abs(U[:, j].mean() - 0.5) < 5 * se, (j, U[:, j].mean())
        assert abs(np.mean(U[:, j] < 0.25) - 0.25) < 5 * np.sqrt(0.25 * 0.75 / n_eff), j


def _pair_space():
    """A conductivity, then the density and the specific heat of one layer (relative bounds, all positive)."""
    params = (
        Parameter("conductivity[1]", "conductivity", (0,), None, base=0.04, lower=0.032, upper=0.048),
        Parameter("density[1]", "density", (0,), None, base=100.0, lower=50.0, upper=300.0),
        Parameter("specific_heat[1]", "specific_heat", (0,), None, base=1000.0, lower=800.0, upper=1200.0),
    )
    return ParameterSpace(parameters=params, targets=("T",))


def test_a_density_and_specific_heat_pair_is_sampled_as_its_product():
    """rho and c of one layer: one sampled coordinate, ln(rho c); the split does not change the product, and the
    round trip through the sampled coordinates keeps every other parameter and the product."""
    space = _pair_space()
    coords = LogCoordinates(None, space)
    assert coords.dim == 2 and coords.names == ["conductivity[1]", "ln(density[1]*specific_heat[1])"]
    U = np.random.default_rng(6).random((50, 3))
    Z = coords.from_unit(U)
    X = space.from_unit(U)
    assert np.allclose(Z[:, 1], np.log(X[:, 1] * X[:, 2]), rtol=0, atol=1e-12)
    for v in (0.0, 0.3, 1.0):
        Xv = space.from_unit(coords.to_unit(Z, v))
        assert np.all((Xv >= space.lower) & (Xv <= space.upper))
        assert np.allclose(Xv[:, 1] * Xv[:, 2], X[:, 1] * X[:, 2], rtol=1e-12)
        assert np.allclose(Xv[:, 0], X[:, 0], rtol=1e-12)
    assert np.allclose(coords.from_unit(coords.to_unit(Z)), Z, atol=1e-12)
    # a product outside the range the box allows has no prior mass
    assert coords.log_prior(np.array([[0.5, np.log(50.0 * 800.0) - 1e-6]]))[0] == -np.inf
    assert np.isfinite(coords.log_prior(np.array([[0.5, np.log(50.0 * 800.0) + 1e-6]]))[0])
    # the autocorrelation times of the sampled coordinates, per parameter: the pair's two get the product's
    assert list(coords.full_tau(np.array([3.0, 7.0]))) == [3.0, 7.0, 7.0]


def test_a_pair_sampled_as_its_product_keeps_the_prior_uniform():
    """A flat likelihood: the product's induced prior p(s) ~ P ln(hi/lo) and the split drawn log-uniform on its
    range must give back rho and c uniform on their bounds and independent. (With the split drawn uniform in rho,
    or without the ln(hi/lo) factor, the marginals are not uniform: the mean of u_rho moves by 0.03-0.09.)"""
    space = _pair_space()

    def flat(U):
        U = np.atleast_2d(U)
        return np.where(np.all((U >= 0) & (U <= 1), axis=1), 0.0, -np.inf)

    coords = LogCoordinates(flat, space)
    rng = np.random.default_rng(7)
    sampler = ensemble_sampler(coords, 16, coords.dim, seed=8)
    sampler.run_mcmc(coords.from_unit(rng.random((16, 3))), 6000)
    Z = sampler.get_chain(discard=500).reshape(-1, coords.dim)
    U = coords.draw_unit(Z, rng)
    assert np.all((U >= 0) & (U <= 1))
    n_eff = len(U) / 30.0  # autocorrelation time well under 30 steps here
    for j in range(3):
        assert abs(U[:, j].mean() - 0.5) < 5 * np.sqrt(1 / 12 / n_eff), (j, U[:, j].mean())
        for q in (0.1, 0.25, 0.75, 0.9):
            assert abs(np.mean(U[:, j] < q) - q) < 5 * np.sqrt(q * (1 - q) / n_eff), (j, q)
    assert abs(np.corrcoef(U[:, 1], U[:, 2])[0, 1]) < 5 / np.sqrt(n_eff)


def test_the_likelihood_sees_only_the_product_of_a_pair(example_study):
    """The engine's outputs depend on rho and c through rho*c alone: two splits of the same products give the
    same errors to round-off on the bundled example (what makes sampling the product alone exact)."""
    from wallcal.analysis.identifiability import capacity_pairs
    from wallcal.calibration.objective import Evaluator
    from wallcal.calibration.space import parse_space
    from wallcal.simulation import prepare

    space = parse_space(example_study)
    assert len(capacity_pairs(space)) == 6
    coords = LogCoordinates(None, space)
    Z = coords.from_unit(np.random.default_rng(9).uniform(0.1, 0.9, (4, space.n)))
    ev = Evaluator(prepare(example_study), space)
    a = ev.errors(space.from_unit(coords.to_unit(Z, 0.1)))
    b = ev.errors(space.from_unit(coords.to_unit(Z, 0.9)))
    assert not np.allclose(coords.to_unit(Z, 0.1), coords.to_unit(Z, 0.9))
    assert np.nanmax(np.abs(a - b)) < 1e-9
