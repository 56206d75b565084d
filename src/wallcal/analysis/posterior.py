"""Bayesian posterior of the calibration parameters (emcee), with an AR(1) error model.

Model: for each target k the errors e_t = s_t(theta) - y_t follow a stationary AR(1)
process e_t = phi_k e_{t-1} + eta_t with marginal standard deviation sigma_k. The 5-minute
residuals of a wall model are strongly autocorrelated (phi ~ 0.9-0.99): treating them as
independent would count every sample as new information and give intervals 5-20 times
too narrow. The exact AR(1) log-likelihood (gaps restart the process) is

    log L = sum_k [ -1/2 sum_pairs (e_t - phi e_{t-1})^2 / (sigma^2 (1 - phi^2)) - 1/2 sum_starts e_t^2 / sigma^2 ]

(constants dropped). phi_k and sigma_k are fixed before sampling: phi_k is the lag-1
autocorrelation of the residuals at the starting point (the calibrated optimum);
sigma_k is either the RMSE of those residuals (``sigma="estimated"``, default: it
includes model error) or the sensor's stated accuracy (``sigma="accuracy"``).

When the residuals carry more than the AR(1) model expects (a model error: smooth, correlated across
targets and over a day), the likelihood is tempered, L^w with 0 < w <= 1, by the sandwich rule
(:func:`sandwich_weight`): w is the inverse of the mean variance inflation of the score that a
heteroskedasticity-and-autocorrelation-consistent (Newey-West, one-day window) estimate finds over the
identifiable directions. Under a correct error model w = 1 (within its sampling error, capped at 1).

The posterior checks itself (:func:`residual_checks`, :func:`structure_verdict`): posterior predictive
residuals against the sensors' stated accuracy, posterior mass piled up at the edges of the prior box, and
(when given) the extensions that ``wallcal diagnose`` found the data support but the sampled structure lacks.
When any of them fires, the report says plainly that the intervals are conditional on a structure the data
reject.

Priors are uniform on the calibration bounds. The ensemble samples the log of each positive parameter
(:class:`LogCoordinates`; the prior's Jacobian added), where the structural flat directions are straight, and
one coordinate, ln(rho c), for a layer's density and specific heat (the model sees only their product; the split
is drawn from the prior's conditional afterwards),
and starts from the Laplace approximation of the posterior at the optimum (:func:`initial_walkers`), so that
it spans the posterior's flat valleys from the first step. emcee runs with ``vectorize=True``: each half-step
of the ensemble is one engine batch (proposals outside the prior box cost no simulation). By default the chain
runs until it is adequate (:func:`chain_diagnostics`): enough effective samples, and an autocorrelation time that
no longer grows with the chain (a chain shorter than its autocorrelation time gives an estimate capped by its
length, and effective samples that count its length, not its mixing). The chain is checkpointed atomically
(``.npz``) every few seconds and on Ctrl-C, so an interruption loses nothing and ``resume=True`` continues.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .identifiability import verdict

nan = float("nan")

#: effective samples the default chain runs for: the Monte-Carlo sd of a 2.5 % tail probability estimated from
#: n independent draws is sqrt(0.025 x 0.975 / n), 0.7 % at 500
DEFAULT_EFFECTIVE_SAMPLES = 500
#: the default chain stops here even when it is not yet adequate (it says so)
DEFAULT_MAX_STEPS = 5000
#: the default chain is first checked at this many steps, then whenever it has grown by ADAPTIVE_GROWTH (at least
#: ADAPTIVE_EVERY steps): a check costs ~1 s per 2000 steps on two cores, so the checks stay a few % of the run
ADAPTIVE_FIRST_CHECK = 100
ADAPTIVE_EVERY = 25
ADAPTIVE_GROWTH = 0.2
#: an adequate chain is at least this many autocorrelation times long after its burn-in
MIN_TAU_MULTIPLE = 10
#: ... and its autocorrelation time no longer grows with the chain: the estimate over the whole chain after burn-in
#: at most this factor times the one over its first STABLE_SHARE (an estimate that is capped by the chain's length
#: grows in proportion to it: by 1 / STABLE_SHARE = 2)
STABLE_RATIO = 1.2
STABLE_SHARE = 0.5
#: the ensemble's median log-probability, averaged over windows of this many steps, tells the start's transient
BURN_WINDOW = 10


# ============================================================================ likelihood
class AR1Likelihood:
    """Vectorised AR(1) Gaussian log-likelihood over the unit box.

    Parameters
    ----------
    ev : Evaluator
    sigma, phi : ndarray, shape (n_targets,)
        Marginal error sd [target unit] and lag-1 autocorrelation [-].
    bias_sd : ndarray, shape (n_targets,), optional
        Sd of a constant sensor bias integrated out [target unit].
    weight : float
        Power w of the tempered likelihood L^w [-] (1: untempered).
    """

    def __init__(self, ev, sigma, phi, bias_sd=None, weight: float = 1.0):
        self.ev = ev
        self.weight = float(weight)
        self.sigma = np.asarray(sigma, dtype=float)
        self.phi = np.asarray(phi, dtype=float)
        self.tau = np.zeros_like(self.sigma) if bias_sd is None else np.asarray(bias_sd, dtype=float)
        m = ev.mask
        self.pairs = m[:, 1:] & m[:, :-1]
        self.starts = m & ~np.concatenate([np.zeros((m.shape[0], 1), bool), m[:, :-1]], axis=1)
        self.q11 = self.quad(np.ones((1,) + m.shape), np.ones((1,) + m.shape))[0]
        self.calls = 0

    def quad(self, A, B):
        """AR(1) quadratic form a' Sigma^-1 b per candidate and target (gaps restart the process)."""
        phi = self.phi[None, :, None]
        ia = A[:, :, 1:] - phi * A[:, :, :-1]
        ib = B[:, :, 1:] - phi * B[:, :, :-1]
        a = np.einsum("ctk,tk->ct", ia * ib, self.pairs.astype(float)) / (1 - self.phi**2)[None]
        b = np.einsum("ctk,tk->ct", A * B, self.starts.astype(float))
        return (a + b) / (self.sigma**2)[None]

    def loglike_errors(self, E):
        """Log-likelihood per candidate; a constant sensor bias N(0, tau^2) per target is integrated out
        analytically (Sherman-Morrison on Sigma + tau^2 1 1')."""
        qee = self.quad(E, E)
        if np.any(self.tau > 0):
            q1e = self.quad(np.ones_like(E[:1]), E)
            t2 = (self.tau**2)[None]
            qee = qee - t2 * q1e**2 / (1.0 + t2 * self.q11[None])
        return -0.5 * qee.sum(axis=1)

    def __call__(self, U):
        U = np.atleast_2d(U)
        out = np.full(len(U), -np.inf)
        inside = np.all((U >= 0) & (U <= 1), axis=1)
        if inside.any():
            E = self.ev.errors(self.ev.space.from_unit(U[inside]))
            ll = self.weight * self.loglike_errors(E)
            out[inside] = np.where(np.isfinite(ll), ll, -np.inf)
        self.calls += 1
        return out


class LogCoordinates:
    """The log-posterior over the sampling coordinates z: the log of each positive parameter, the unit coordinate
    of the others (:func:`wallcal.analysis.identifiability.to_z`), and one coordinate per layer for a density and
    a specific heat that are both free.

    In z the structural flat directions (rho against c of a layer; without a heat flux, the common scale of every
    conductivity and heat capacity) are straight lines, and a conductivity or capacity enters the model through
    products and ratios, so the posterior is closer to Gaussian than in the unit box: the ensemble's moves, which
    propose along straight differences between walkers, mix better. The prior stays uniform on the bounds: in z
    its density is prod x_j over the log coordinates (the Jacobian dx/dz), added here.

    Density and specific heat of a layer group act on the model only through their product P = rho c
    (:func:`wallcal.analysis.identifiability.capacity_pairs`), so their joint posterior is that of
    ``s = ln P`` times the prior's conditional of the split. The ensemble samples ``s`` alone (one coordinate
    instead of two, in the density's column; the specific heat's is dropped), with the prior that the uniform
    box induces on it,

        p(s) ~ P ln(hi / lo),   lo = max(rho_lo, P / c_hi),   hi = min(rho_hi, P / c_lo)

    (``rho`` ranges over [lo, hi] given P, the measure of that range in ln rho). Given ``s``, the prior's
    conditional of ``rho`` is log-uniform on [lo, hi] (the uniform density over the box, times the Jacobian
    1/rho of c = P/rho); :meth:`to_unit` splits P at a fraction ``v`` of [ln lo, ln hi] (the likelihood is the
    same for every split; 1/2 by default) and :meth:`draw_unit` draws the split from that conditional, which gives
    exact draws of the joint posterior. The flat direction the ensemble would otherwise have to cross (its
    extent set by the box alone) is gone: on the 22-parameter space of ``bench/posterior_coverage.py --speed
    --speed-space linear`` (six such pairs) the autocorrelation time fell from ~200 to ~100 steps.

    Parameters
    ----------
    like : callable
        Log-likelihood over unit coordinates, shape (c, n) -> (c,) (-inf outside the box).
    space : ParameterSpace
    """

    def __init__(self, like, space):
        from .identifiability import capacity_pairs, log_coordinates

        self.like = like
        self.space = space
        self.log = log_coordinates(space)
        self.pairs = np.array(capacity_pairs(space), dtype=np.int64).reshape(-1, 2)
        #: the parameters that have a sampling coordinate (a pair's density column carries s = ln(rho c))
        self.keep = np.setdiff1d(np.arange(space.n), self.pairs[:, 1])
        self.dim = len(self.keep)
        rho, c = self.pairs[:, 0], self.pairs[:, 1]
        self._rho_lo, self._rho_hi = space.lower[rho], space.upper[rho]
        self._c_lo, self._c_hi = space.lower[c], space.upper[c]
        # a pair's column in z
        self._col = np.searchsorted(self.keep, rho)
        # the sampled coordinates whose prior term is their own value (log coordinates outside the pairs)
        single = self.log.copy()
        single[self.pairs.reshape(-1)] = False
        self._single = single[self.keep]

    @property
    def names(self) -> list[str]:
        """The sampled coordinates, named (``ln(rho*c)`` of a pair)."""
        names = list(self.space.names)
        for j_rho, j_c in self.pairs:
            names[j_rho] = f"ln({names[j_rho]}*{names[j_c]})"
        return [names[j] for j in self.keep]

    def _split(self, s):
        """ln lo, ln hi of the density's range given s = ln(rho c), shape (c, pairs)."""
        log_lo = np.maximum(np.log(self._rho_lo), s - np.log(self._c_hi))
        log_hi = np.minimum(np.log(self._rho_hi), s - np.log(self._c_lo))
        return log_lo, log_hi

    def to_z_full(self, Z, v=0.5):
        """Analysis coordinates of every parameter (ln rho and ln c split at the fraction ``v`` of their range)."""
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        full = np.empty((len(Z), self.space.n))
        full[:, self.keep] = Z
        if len(self.pairs):
            s = Z[:, self._col]
            log_lo, log_hi = self._split(s)
            log_rho = log_lo + v * (log_hi - log_lo)
            # (a P outside the box gives lo > hi: the density's own bound then, which the likelihood rejects)
            log_rho = np.where(log_hi >= log_lo, log_rho, np.log(self._rho_lo)[None])
            full[:, self.pairs[:, 0]] = log_rho
            full[:, self.pairs[:, 1]] = s - log_rho
        return full

    def to_unit(self, Z, v=0.5):
        from .identifiability import from_z

        U = self.space.to_unit(from_z(self.space, self.to_z_full(Z, v)))
        if len(self.pairs):  # inside the box in exact arithmetic: keep exp(ln x) from stepping out by rounding
            cols = self.pairs.reshape(-1)
            Up = U[:, cols]
            U[:, cols] = np.where((Up > -1e-9) & (Up < 1 + 1e-9), np.clip(Up, 0.0, 1.0), Up)
        return U

    def draw_unit(self, Z, rng):
        """Unit coordinates of every parameter with each pair's split drawn from the prior's conditional given
        its product: exact draws of the joint posterior from draws of the sampled coordinates."""
        Z = np.atleast_2d(Z)
        return self.to_unit(Z, rng.random((len(Z), len(self.pairs))))

    def from_unit(self, U):
        from .identifiability import to_z

        z = to_z(self.space, self.space.from_unit(np.asarray(U, dtype=float)))
        z = np.atleast_2d(z)
        if len(self.pairs):
            z[:, self.pairs[:, 0]] += z[:, self.pairs[:, 1]]
        return z[:, self.keep]

    def full_tau(self, tau):
        """Per-parameter autocorrelation times from those of the sampled coordinates: a pair's two parameters get
        their product's (the split is drawn independently for every sample)."""
        tau = np.asarray(tau, dtype=float)
        out = np.empty(self.space.n)
        out[self.keep] = tau
        out[self.pairs[:, 1]] = tau[self._col]
        return out

    def log_prior(self, Z):
        """Log prior density of the sampled coordinates, up to a constant (-inf where a product is outside the
        box's range)."""
        Z = np.atleast_2d(Z)
        lp = np.sum(np.where(self._single[None], Z, 0.0), axis=1)
        if len(self.pairs):
            s = Z[:, self._col]
            log_lo, log_hi = self._split(s)
            width = log_hi - log_lo
            with np.errstate(divide="ignore", invalid="ignore"):
                lp = lp + np.sum(np.where(width > 0, s + np.log(np.where(width > 0, width, 1.0)), -np.inf), axis=1)
        return lp

    def __call__(self, Z):
        Z = np.atleast_2d(Z)
        lp = self.log_prior(Z)
        out = np.full(len(Z), -np.inf)
        ok = np.isfinite(lp)
        if ok.any():
            out[ok] = self.like(self.to_unit(Z[ok])) + lp[ok]
        return out


def lag1(e: np.ndarray, mask: np.ndarray) -> float:
    """Lag-1 autocorrelation of an error series about zero (valid consecutive pairs only)."""
    p = mask[1:] & mask[:-1]
    den = float(np.sum(np.where(mask, e, 0.0) ** 2))
    return float(np.clip(np.sum(np.where(p, e[1:] * e[:-1], 0.0)) / den, 0.0, 0.995)) if den > 0 else 0.0


# ============================================================================ tempering
def whiten(x: np.ndarray, mask: np.ndarray, phi: float, sigma: float) -> np.ndarray:
    """AR(1) innovations of series ``x`` (last axis time), scaled to unit variance: (x_t - phi x_(t-1)) /
    (sigma sqrt(1 - phi^2)) within a run of valid samples, x_t / sigma at the start of each run, 0 at missing
    samples. The sum of their squares is the AR(1) quadratic form of :class:`AR1Likelihood`."""
    x = np.asarray(x, dtype=float)
    pairs = mask[1:] & mask[:-1]
    starts = mask & ~np.concatenate([[False], mask[:-1]])
    out = np.zeros_like(x)
    out[..., 1:] = np.where(pairs, (x[..., 1:] - phi * x[..., :-1]) / (sigma * np.sqrt(1.0 - phi**2)), 0.0)
    out = np.where(starts, x / sigma, out)
    return out


def hac(S: np.ndarray, bandwidth: int) -> np.ndarray:
    """Newey-West (Bartlett kernel) long-run covariance sum_l (1 - l/(L+1)) (G_l + G_l') of the score
    contributions ``S``, shape (n, times) [their unit squared]; G_l = sum_t s_t s_(t-l)'."""
    J = S @ S.T
    for lag in range(1, int(bandwidth) + 1):
        G = S[:, lag:] @ S[:, :-lag].T
        J += (1.0 - lag / (bandwidth + 1.0)) * (G + G.T)
    return J


def sandwich_inflation(G: np.ndarray, r: np.ndarray, bandwidth: int, rtol: float = 1e-8) -> tuple[float, int]:
    """Mean variance inflation of a least-squares score under correlated errors.

    Parameters
    ----------
    G : ndarray, shape (n, targets, times)
        Whitened sensitivities of the residuals to the parameters (each series through :func:`whiten`).
    r : ndarray, shape (targets, times)
        Whitened residuals at the optimum.
    bandwidth : int
        Newey-West window L [samples], at most a quarter of the record.
    rtol : float
        Directions whose information is below ``rtol`` x the largest are structural null directions, left out.

    Returns
    -------
    inflation : float
        tr(H^-1 J) / k over the k identifiable directions, H = sum G G' (the information the AR(1) likelihood
        assumes) and J the Newey-West covariance of the score contributions s_t = sum_targets G_t r_t (the
        variance the residuals actually show), divided by 1 - b + b^2/3 (b = L / T): the expectation of a
        Bartlett estimate from the residuals of a fitted model over a window that is a fixed fraction b of the
        record (Kiefer and Vogelsang 2005). About 1 when the whitened residuals are white noise of unit variance.
    k : int
    """
    H = np.einsum("iks,jks->ij", G, G)
    S = np.einsum("iks,ks->is", G, r)
    lam, V = np.linalg.eigh(H)
    keep = lam > rtol * max(float(lam.max()), 1e-300)
    if not keep.any():
        return 1.0, 0
    W = V[:, keep] / np.sqrt(lam[keep])[None]
    Sw = W.T @ S  # score contributions along the identifiable directions, unit information each
    bandwidth = max(0, min(int(bandwidth), S.shape[1] // 4))
    b = bandwidth / S.shape[1]
    M = hac(Sw, bandwidth) / (1.0 - b + b**2 / 3.0)
    return float(np.trace(M) / keep.sum()), int(keep.sum())


@dataclass
class Linearisation:
    """The model linearised at a point: whitened residuals and their sensitivities (see :func:`linearise`).

    Attributes
    ----------
    u0 : ndarray, shape (n,)
        The point in unit coordinates.
    G : ndarray, shape (n, targets, times)
        Whitened sensitivities of the residuals (without their constant part) to the unit coordinates.
    r : ndarray, shape (targets, times)
        Whitened residuals (without their constant part) at ``u0``.
    information : ndarray, shape (n, n)
        Fisher information of the likelihood (AR(1) errors plus the constant sensor bias integrated out) about
        the unit coordinates [-].
    """

    u0: np.ndarray
    G: np.ndarray
    r: np.ndarray
    information: np.ndarray


def error_model(study, space, ev, x, sigma: str = "estimated", bias: bool = True) -> tuple[dict, dict, dict]:
    """The error model of :func:`posterior` per target of ``space``, from the residuals at ``x`` [SI] (``ev``: its
    :class:`~wallcal.calibration.objective.Evaluator`): the noise sd sigma (the RMSE of the residuals without
    their constant part, ``sigma="estimated"``, or the sensor's stated accuracy, ``"accuracy"``) [target unit],
    the lag-1 correlation phi of those residuals, and the prior sd of the constant sensor bias (half the stated
    accuracy; 0 without ``bias``) [target unit]; three dicts keyed by target."""
    from .identifiability import sensor_sigma

    e0 = ev.errors(np.asarray(x, dtype=float)[None])[0]
    sig, ph, tau = {}, {}, {}
    for k, t in enumerate(space.targets):
        m = ev.mask[k]
        ek = np.where(m, e0[k] - e0[k][m].mean(), 0.0)  # the constant part is the sensor bias, modelled apart
        ph[t] = lag1(ek, m)
        sig[t] = float(np.sqrt(np.mean(ek[m] ** 2))) if sigma == "estimated" else sensor_sigma(study, t, ev.y[k][m])
        tau[t] = (0.5 * sensor_sigma(study, t, ev.y[k][m])) if bias else 0.0
    return sig, ph, tau


def linearise(ev, space, x_start, sigma, phi, bias_sd=None, *, h: float = 1e-3) -> Linearisation:
    """Central-difference sensitivities of the residuals at ``x_start`` (one batch of 2n + 1 runs), whitened by
    the AR(1) model of each target (:func:`whiten`; the constant part of each series, the sensor bias, removed),
    and the likelihood's information.

    The information of :class:`AR1Likelihood` about the parameters is, per target, D' (S + tau^2 1 1')^-1 D with
    D the sensitivities, S the AR(1) covariance and tau the sd of the sensor bias integrated out:
    Gw Gw' - tau^2 a a' / (1 + tau^2 q11) with Gw the whitened sensitivities, a = Gw 1w and q11 = 1w' 1w
    (Sherman-Morrison, as in the likelihood).

    Parameters
    ----------
    ev : Evaluator
    space : ParameterSpace
    x_start : ndarray
        [SI]
    sigma, phi : dict
        Per target, as used by the likelihood.
    bias_sd : dict, optional
        Sd of the constant sensor bias per target (0 or missing: none).
    h : float
        Step in unit coordinates (one-sided at a bound).
    """
    bias_sd = bias_sd or {}
    n = space.n
    u0 = space.to_unit(np.asarray(x_start, dtype=float))
    up = np.clip(u0[None] + h * np.eye(n), 0.0, 1.0)
    um = np.clip(u0[None] - h * np.eye(n), 0.0, 1.0)
    E = ev.errors(space.from_unit(np.vstack([u0[None], up, um])))
    step = (up - um)[np.arange(n), np.arange(n)]
    D = (E[1 : n + 1] - E[n + 1 :]) / step[:, None, None]
    G = np.zeros_like(D)
    r = np.zeros(E.shape[1:])
    info = np.zeros((n, n))
    for k, t in enumerate(space.targets):
        m = ev.mask[k]
        e = np.where(m, E[0, k] - E[0, k][m].mean(), 0.0)  # the constant part is the sensor bias
        d = np.where(m[None], D[:, k] - D[:, k][:, m].mean(axis=1, keepdims=True), 0.0)
        r[k] = whiten(e, m, phi[t], sigma[t])
        G[:, k] = whiten(d, m, phi[t], sigma[t])
        gw = whiten(np.where(m[None], D[:, k], 0.0), m, phi[t], sigma[t])
        ow = whiten(m.astype(float), m, phi[t], sigma[t])
        a, t2 = gw @ ow, float(bias_sd.get(t, 0.0)) ** 2
        info += gw @ gw.T - t2 * np.outer(a, a) / (1.0 + t2 * float(ow @ ow))
    return Linearisation(u0=u0, G=G, r=r, information=info)


def sandwich_weight(
    ev, space, x_start, sigma, phi, *, h: float = 1e-3, bandwidth: int | None = None, lin: Linearisation | None = None
) -> dict:
    """Power w of the tempered likelihood, from the residuals at ``x_start`` (the optimum).

    The AR(1) likelihood assumes that its whitened residuals are independent with unit variance; its curvature
    H is then the variance of its score. A model error makes the whitened residuals correlated (over a day, and
    across targets at the same time), so the score varies more: J > H, and the posterior (curvature H) is too
    narrow by the factor of the sandwich covariance H^-1 J H^-1 against H^-1. A power posterior L^w with
    w = k / tr(H^-1 J) matches the sandwich on average over the k identifiable directions (w <= 1 is kept: the
    data never sharpen the posterior beyond the AR(1) model).

    Parameters
    ----------
    ev : Evaluator
    space : ParameterSpace
    x_start : ndarray
        [SI]
    sigma, phi : dict
        Per target, as used by the likelihood.
    h : float
        Central-difference step in unit coordinates (one-sided at a bound); one batch of 2n + 1 runs.
    bandwidth : int, optional
        Newey-West window [samples]; default one day (the period of the forcing: a model error repeats from one
        day to the next), at most a quarter of the record.
    lin : Linearisation, optional
        :func:`linearise` at ``x_start`` with these ``sigma`` and ``phi``, when already made.

    Returns
    -------
    dict
        ``weight`` w, ``inflation`` tr(H^-1 J)/k, ``directions`` k, ``bandwidth`` [samples], ``window_s`` [s].
    """
    lin = lin or linearise(ev, space, x_start, sigma, phi, h=h)
    dt = _sample_interval(ev)
    if bandwidth is None:
        bandwidth = int(round(86400.0 / dt)) if np.isfinite(dt) and dt > 0 else ev.mask.shape[1] // 8
    bandwidth = max(1, min(int(bandwidth), ev.mask.shape[1] // 4))
    inflation, k = sandwich_inflation(lin.G, lin.r, bandwidth)
    return {
        "weight": float(min(1.0, 1.0 / inflation)) if inflation > 0 else 1.0,
        "inflation": inflation,
        "directions": k,
        "bandwidth": bandwidth,
        "window_s": bandwidth * dt,
    }


def _sample_interval(ev) -> float:
    """Median interval between the measured samples [s] (nan when unknown)."""
    idx = getattr(ev.prepared, "measured", None)
    try:
        t = pd.DatetimeIndex(idx.index)
        return float(np.median((t[1:] - t[:-1]).total_seconds()))
    except (AttributeError, TypeError, ValueError):
        return float("nan")


# ============================================================================ self-checks
#: the posterior mass within the outer PILE_BAND of the prior (each end) above which it "piles up" there
PILE_BAND = 0.02
PILE_FRACTION = 0.25
PILES_SHOWN = 5  # the report names the most piled-up ones


def residual_checks(study, space, ev, E: np.ndarray) -> pd.DataFrame:
    """Posterior predictive residuals against the sensors' stated accuracy.

    Parameters
    ----------
    E : ndarray, shape (draws, targets, times)
        Simulated minus measured for posterior draws (0 at missing samples).

    Returns
    -------
    DataFrame, one row per target
        ``RMSE`` (median over the draws), ``bias`` (mean error), ``RMSE without bias``, ``white noise`` (the
        high-frequency part, sqrt(mean((e_t - e_(t-1))^2) / 2): sensor noise is white, a model error is smooth at
        the sampling interval), ``model error`` (the rest, sqrt(max(0, var - white^2))), ``lag-1`` of the
        residuals without bias, ``accuracy`` (stated), ``RMSE / accuracy`` and ``verdict``: "beyond the stated
        accuracy" when the RMSE exceeds it (the sensor cannot explain the misfit), "model error above the noise"
        when the smooth part exceeds half the accuracy (the sd of a sensor whose accuracy is a 95 % bound),
        else "consistent with the sensor".
    """
    from .identifiability import sensor_sigma

    rows = []
    for k, t in enumerate(space.targets):
        m = ev.mask[k]
        e = E[:, k][:, m]
        if e.shape[1] < 3:
            continue
        bias = e.mean(axis=1)
        d = e - bias[:, None]
        rmse = np.sqrt(np.mean(e**2, axis=1))
        sd = np.sqrt(np.mean(d**2, axis=1))
        white = np.sqrt(np.mean(np.diff(e, axis=1) ** 2, axis=1) / 2.0)
        model = np.sqrt(np.maximum(0.0, sd**2 - white**2))
        acc = sensor_sigma(study, t, ev.y[k][m])
        row = {
            "target": t,
            "RMSE": float(np.median(rmse)),
            "bias": float(np.median(bias)),
            "RMSE without bias": float(np.median(sd)),
            "white noise": float(np.median(white)),
            "model error": float(np.median(model)),
            "lag-1": lag1(np.where(m, E[0, k] - bias[0], 0.0), m),
            "accuracy": acc,
        }
        row["RMSE / accuracy"] = row["RMSE"] / acc if acc > 0 else nan
        if row["RMSE"] > acc:
            row["verdict"] = "beyond the stated accuracy"
        elif row["model error"] > 0.5 * acc:
            row["verdict"] = "model error above the noise"
        else:
            row["verdict"] = "consistent with the sensor"
        rows.append(row)
    return pd.DataFrame(rows).set_index("target")


def piled_up(samples: np.ndarray, prior: np.ndarray, band: float = PILE_BAND) -> tuple[float, float]:
    """Fractions of the posterior ``samples`` below the prior's ``band`` quantile and above its 1 - ``band``
    quantile [-]. A flat posterior puts ``band`` at each end; a posterior pushed against the edge of the box
    (the data want a value the bounds forbid) puts most of its mass there."""
    lo, hi = np.quantile(prior, [band, 1.0 - band])
    return float(np.mean(samples < lo)), float(np.mean(samples > hi))


def structure_verdict(checks: pd.DataFrame, summary: pd.DataFrame, combinations: pd.DataFrame, missing=()) -> dict:
    """Whether the data reject the sampled structure, with the reasons in words.

    Returns
    -------
    dict
        ``rejected`` (bool), ``reasons`` (list of str), ``statement`` (one paragraph for the report).
    """
    reasons = []
    for t, r in checks.iterrows():
        if r["verdict"] == "beyond the stated accuracy":
            reasons.append(
                f"{t}: residual RMSE {r['RMSE']:.3g} is {r['RMSE / accuracy']:.1f} x the stated accuracy "
                f"{r['accuracy']:.3g}"
            )
        elif r["verdict"] == "model error above the noise":
            reasons.append(
                f"{t}: a smooth model error of {r['model error']:.3g} (lag-1 {r['lag-1']:.2f}) exceeds the sensor's "
                f"noise ({0.5 * r['accuracy']:.3g}, half its stated accuracy)"
            )
    piles = []
    for table in (combinations, summary):
        for name, r in table.iterrows():
            frac = max(r["at lower edge"], r["at upper edge"])
            if frac >= PILE_FRACTION:
                side = "lower" if r["at lower edge"] >= r["at upper edge"] else "upper"
                piles.append((frac, f"{name} ({frac:.0%} at its {side} edge)"))
    if piles:
        piles.sort(key=lambda p: -p[0])
        shown = ", ".join(text for _, text in piles[:PILES_SHOWN])
        more = f" and {len(piles) - PILES_SHOWN} more" if len(piles) > PILES_SHOWN else ""
        reasons.append(
            f"{len(piles)} parameter(s) or combination(s) pile up at the edge of their prior (at least "
            f"{PILE_FRACTION:.0%} of the posterior within the outer {PILE_BAND:.0%} of the prior): {shown}{more}"
        )
    if missing:
        reasons.append(
            "wallcal diagnose found that the data support " + ", ".join(missing) + ", which this structure lacks"
        )
    if reasons:
        statement = (
            "The data reject this model structure: " + "; ".join(reasons) + ". The intervals are conditional on "
            "this structure and do not hold the truth as often as they claim: its parameters compensate for what "
            "the structure lacks. Run `wallcal diagnose` and sample the study it writes."
        )
    else:
        statement = (
            "No self-check fired: the residuals are within the sensors' stated accuracy and no parameter or "
            "combination piles up at the edge of its prior. The intervals are still conditional on the model "
            "structure."
        )
    return {"rejected": bool(reasons), "reasons": reasons, "statement": statement}


def missing_from_diagnosis(study, folder) -> list[str]:
    """The extensions a ``wallcal diagnose`` output (``folder``) adopted that ``study`` lacks.

    ``folder/candidates.csv`` lists each candidate or combination (names joined by " + ") with its ``extension``
    and ``adopted`` (the row of the adopted set); ``folder/study.toml``
    is the study with the adopted extensions. When ``study`` is that file, nothing is missing.
    """
    from ..errors import WallcalError

    folder = Path(folder)
    path = folder / "candidates.csv"
    if not path.exists():
        raise WallcalError(f"{path}: not found (--diagnosis expects the output folder of `wallcal diagnose`)")
    table = pd.read_csv(path)
    absent = [c for c in ("extension", "adopted") if c not in table.columns]
    if absent:
        raise WallcalError(f"{path}: no column {', '.join(absent)} (not a `wallcal diagnose` output)")
    if study.path is not None and Path(study.path).resolve() == (folder / "study.toml").resolve():
        return []
    adopted = table["adopted"].astype(str).str.strip().str.lower().isin(("true", "1", "yes"))
    names = [name.strip() for e in table.loc[adopted, "extension"] for name in str(e).split(" + ")]
    return list(dict.fromkeys(n for n in names if n))


# ============================================================================ result
@dataclass
class PosteriorResult:
    """Outcome of :func:`posterior`.

    Attributes
    ----------
    chain : ndarray, shape (steps, walkers, n)
        Unit coordinates (the split of each rho*c pair drawn from its conditional, see :class:`LogCoordinates`).
    log_prob : ndarray, shape (steps, walkers)
        Log posterior density of each chain entry, up to a constant, in the sampling coordinates
        (:class:`LogCoordinates`).
    samples : ndarray, shape (m, n)
        Post-burn-in, thinned samples [SI].
    summary : DataFrame
        Per parameter: mean, sd, q2.5, q97.5 [SI], bounds, sd ratio to the prior, verdict, truth, inside.
    correlation : DataFrame
    combinations : DataFrame
        Derived quantities (R = d/lambda, rho*c, diffusivity, ratios, R_total) with the same columns.
    nonunique : DataFrame
        Distinct posterior parameter sets whose RMSEs all sit within the sensor accuracy.
    tempering : dict
        ``kind`` ("sandwich" or "none"), ``weight`` w of the tempered likelihood L^w and, for "sandwich", the
        measured ``inflation``, ``directions``, ``bandwidth`` (see :func:`sandwich_weight`).
    checks : DataFrame
        Posterior predictive residuals per target (:func:`residual_checks`).
    structure : dict
        The self-checks' verdict (:func:`structure_verdict`): ``rejected``, ``reasons``, ``statement``.
    tau : ndarray
        Integrated autocorrelation time per parameter over the chain after burn-in [steps].
    acceptance : float
    effective_samples : float
        Walkers x steps after burn-in / the largest autocorrelation time.
    adequate : bool
        Whether the chain is adequate (:func:`chain_diagnostics`): ``target_effective_samples`` effective samples,
        long enough for its autocorrelation time and that time no longer growing with the chain.
    """

    study: object
    space: object
    chain: np.ndarray
    log_prob: np.ndarray
    samples: np.ndarray
    summary: pd.DataFrame
    correlation: pd.DataFrame
    combinations: pd.DataFrame
    nonunique: pd.DataFrame
    tau: np.ndarray
    acceptance: float
    burn: int
    thin: int
    sigma: dict
    phi: dict
    sigma_kind: str
    evaluations: int  # walkers x steps: the chain's proposals
    seconds: float
    status: str = "complete"
    warnings: list = field(default_factory=list)
    truth: np.ndarray | None = None
    tempering: dict = field(default_factory=lambda: {"kind": "none", "weight": 1.0})
    checks: pd.DataFrame = field(default_factory=pd.DataFrame)
    structure: dict = field(default_factory=lambda: {"rejected": False, "reasons": [], "statement": ""})
    effective_samples: float = nan
    adequate: bool = False
    target_effective_samples: float = DEFAULT_EFFECTIVE_SAMPLES
    simulations: int | None = None

    def coverage(self) -> tuple[int, int]:
        """(identified parameters whose 95 % interval holds the truth, identified parameters with a truth)."""
        s = self.summary
        sel = s["verdict"].str.startswith("identified") & s["truth"].notna()
        return int(s.loc[sel, "inside 95%"].sum()), int(sel.sum())

    def combination_coverage(self) -> dict:
        """Coverage of the identifiable combinations (verdict identified or weakly identified) with a truth:
        ``n`` and the numbers inside the 50 % and 95 % intervals (``inside 50%``, ``inside 95%``)."""
        c = self.combinations
        if "truth" not in c:
            return {"n": 0, "inside 50%": 0, "inside 95%": 0}
        sel = ~c["verdict"].str.startswith("not") & c["truth"].notna()
        return {
            "n": int(sel.sum()),
            "inside 50%": int(c.loc[sel, "inside 50%"].sum()),
            "inside 95%": int(c.loc[sel, "inside 95%"].sum()),
        }

    def _pairs_line(self) -> str:
        from .identifiability import capacity_pairs

        k = len(capacity_pairs(self.space))
        if not k:
            return ""
        return (
            f"; {self.space.n - k} sampled coordinates: the density and specific heat of {k} layer "
            f"group{'s' if k > 1 else ''} as their product rho*c (the split drawn from the prior)"
        )

    def report(self) -> str:
        lines = [
            f"posterior ({self.status}): {self.chain.shape[1]} walkers x {self.chain.shape[0]} steps = "
            f"{self.evaluations} proposals{self._simulated()} in {self.seconds:.1f} s; burn-in {self.burn}, "
            f"thin {self.thin}, "
            f"{len(self.samples)} samples{self._pairs_line()}",
            f"error model AR(1) per target + constant sensor bias integrated out, sigma {self.sigma_kind}: "
            + ", ".join(
                f"{k} sigma {self.sigma[k]:.3g} phi {self.phi[k]:.3f} (n_eff factor "
                f"{(1 - self.phi[k]) / (1 + self.phi[k]):.3f})"
                for k in self.sigma
            ),
            f"acceptance fraction {self.acceptance:.2f}; integrated autocorrelation time "
            + (
                f"{np.nanmin(self.tau):.0f}..{np.nanmax(self.tau):.0f} steps"
                if np.isfinite(self.tau).any()
                else "not estimated (chain too short)"
            )
            + f"; {self.effective_samples:.0f} effective samples (target {self.target_effective_samples:.0f}): chain "
            + ("adequate" if self.adequate else "NOT adequate"),
            self.tempering_line(),
        ]
        lines += [f"warning: {w}" for w in self.warnings]
        if len(self.checks):
            lines.append(
                "posterior predictive residuals: "
                + "; ".join(
                    f"{t} RMSE {r['RMSE']:.3g} ({r['RMSE / accuracy']:.2f} x accuracy), model error "
                    f"{r['model error']:.3g}, white noise {r['white noise']:.3g}: {r['verdict']}"
                    for t, r in self.checks.iterrows()
                )
            )
        if self.structure.get("statement"):
            lines.append(("STRUCTURE REJECTED. " if self.structure["rejected"] else "") + self.structure["statement"])
        if self.truth is not None:
            k, n = self.coverage()
            lines.append(f"truth (reference wall) inside the 95 % interval for {k} of {n} identified parameters")
            c = self.combination_coverage()
            lines.append(
                f"truth inside the 95 % interval for {c['inside 95%']} of {c['n']} identifiable combinations, "
                f"inside the 50 % interval for {c['inside 50%']}"
            )
        return "\n".join(lines)

    def _simulated(self) -> str:
        if self.simulations is None:
            return ""
        return f" ({self.simulations} simulated; the others fell outside the prior box and cost no simulation)"

    def tempering_line(self) -> str:
        t = self.tempering
        if t.get("kind") != "sandwich":
            return "likelihood not tempered (w = 1)"
        return (
            f"likelihood tempered by the sandwich rule: the score of the residuals varies {t['inflation']:.2f} x what "
            f"the AR(1) model expects (Newey-West over {t['window_s'] / 3600:.0f} h, {t['directions']} identifiable "
            f"directions), w = {t['weight']:.3f}: intervals {1 / np.sqrt(t['weight']):.2f} x as wide as untempered"
        )

    def to_json(self) -> dict:
        return {
            "status": self.status,
            "evaluations": self.evaluations,
            "simulations": self.simulations,
            "seconds": self.seconds,
            "walkers": self.chain.shape[1],
            "steps": self.chain.shape[0],
            "burn": self.burn,
            "thin": self.thin,
            "acceptance_fraction": self.acceptance,
            "tau": dict(zip(self.space.names, self.tau.tolist(), strict=True)),
            "effective_samples": self.effective_samples,
            "target_effective_samples": self.target_effective_samples,
            "adequate": self.adequate,
            "sigma": self.sigma,
            "phi": self.phi,
            "sigma_kind": self.sigma_kind,
            "warnings": self.warnings,
            "coverage": list(self.coverage()) if self.truth is not None else None,
            "combination_coverage": self.combination_coverage() if self.truth is not None else None,
            "tempering": self.tempering,
            "structure": self.structure,
            "checks": self.checks.reset_index().to_dict(orient="records"),
            "summary": self.summary.reset_index().to_dict(orient="records"),
        }

    def write_into(self, d: Path) -> None:
        d = Path(d)
        self.summary.to_csv(d / "posterior_summary.csv", float_format="%.6g")
        self.correlation.to_csv(d / "posterior_correlation.csv", float_format="%.4f")
        self.combinations.to_csv(d / "posterior_combinations.csv", float_format="%.6g")
        self.nonunique.to_csv(d / "non_uniqueness.csv", float_format="%.6g")
        self.checks.to_csv(d / "posterior_checks.csv", float_format="%.6g")
        np.savez_compressed(
            d / "chain.npz",
            chain=self.chain,
            log_prob=self.log_prob,
            names=np.array(self.space.names),
            lower=self.space.lower,
            upper=self.space.upper,
        )
        (d / "posterior.json").write_text(json.dumps(self.to_json(), indent=2, default=float))
        from .plots import plot_corner, plot_trace

        comb = self.combination_samples()
        keys = [k for k in comb if k.startswith(("R[", "(rho c)["))]
        truth = self.combination_truth()
        plot_corner(
            np.column_stack([comb[k] for k in keys]),
            keys,
            d / "corner.png",
            truth=None if truth is None else np.array([truth[k] for k in keys]),
        )
        plot_corner(self.samples, self.space.names, d / "corner_parameters.png", truth=self.truth)
        plot_trace(self.chain, self.space.names, d / "trace.png")

    # derived quantities
    def combination_samples(self, X=None) -> dict:
        return derived(self.space, self.study.wall, self.samples if X is None else X)

    def combination_truth(self):
        return (
            None
            if self.truth is None
            else {k: float(v[0]) for k, v in self.combination_samples(self.truth[None]).items()}
        )


def derived(space, wall, X) -> dict:
    """Physically meaningful combinations of parameter samples ``X`` [SI]: R = d/lambda [m2K/W], rho*c [J/(m3K)],
    diffusivity lambda/(rho c) [m2/s], conductivity ratios to the first group [-], R_total [m2K/W]."""
    X = np.atleast_2d(X)
    props, _ = space.properties(wall, X)
    lam, C = props.conductivity, props.volumetric_heat_capacity
    groups: dict[tuple, set] = {}
    for p in space.parameters:
        if p.layers:
            groups.setdefault(p.layers, set()).add(p.property)
    out = {}
    first = None
    for layers, ps in groups.items():
        lab = ",".join(wall.layers[i].id for i in layers)
        li = list(layers)
        d = np.array([wall.layers[i].thickness for i in li])
        if "conductivity" in ps:
            out[f"R[{lab}]"] = (d[None] / lam[:, li]).sum(axis=1)
        if ps & {"density", "specific_heat"}:
            out[f"(rho c)[{lab}]"] = C[:, li[0]]
        if "conductivity" in ps and ps & {"density", "specific_heat"}:
            out[f"alpha[{lab}]"] = lam[:, li[0]] / C[:, li[0]]
        if "conductivity" in ps:
            if first is None:
                first = (lab, li[0])
            else:
                out[f"lambda[{lab}]/lambda[{first[0]}]"] = lam[:, li[0]] / lam[:, first[1]]
    thick = np.array([layer.thickness for layer in wall.layers])
    massive = np.array([not layer.is_massless for layer in wall.layers])
    with np.errstate(divide="ignore"):
        out["R_total"] = (np.where(massive[None], thick[None] / lam, 0.0)).sum(axis=1)
    return out


def _stats(samples: np.ndarray, prior: np.ndarray, truth=None) -> dict:
    lo, q25, q75, hi = np.percentile(samples, [2.5, 25.0, 75.0, 97.5])
    sd = float(np.std(samples))
    psd = float(np.std(prior))
    at_lo, at_hi = piled_up(samples, prior)
    row = {
        "mean": float(np.mean(samples)),
        "sd": sd,
        "q2.5": lo,
        "q25": q25,
        "q75": q75,
        "q97.5": hi,
        "sd/prior sd": sd / psd,
        "verdict": verdict(sd / psd),
        "at lower edge": at_lo,
        "at upper edge": at_hi,
    }
    if truth is not None:
        row["truth"] = truth
        row["inside 50%"] = bool(q25 <= truth <= q75) if np.isfinite(truth) else False
        row["inside 95%"] = bool(lo <= truth <= hi) if np.isfinite(truth) else False
    return row


# ============================================================================ the output folder, read back
#: The command whose output :meth:`PosteriorResult.write_into` writes (its format version: :mod:`wallcal.outputs`).
COMMAND = "posterior"


@dataclass
class Samples:
    """Posterior draws applied to a base wall: ``walls`` (one per draw), ``values`` (draw x parameter, SI),
    ``names`` (parameter names as the posterior wrote them), ``point`` (the posterior-median wall)."""

    walls: list
    values: np.ndarray
    names: list[str]
    point: object
    source: str


def apply_named(wall, names: list[str], x: np.ndarray):
    """Apply parameter values named like the calibration space's ('conductivity[5,8]'); probe depths skip."""
    for name, v in zip(names, x, strict=True):
        prop, _, ids = name.partition("[")
        if prop == "depth":
            continue
        for lid in ids.rstrip("]").split(","):
            wall = wall.replace_layer(lid, **{prop: float(v)})
    return wall


def load_samples(from_dir: Path, wall, n_max: int) -> Samples:
    """Posterior samples from a ``wallcal posterior`` output (``chain.npz``, ``posterior.json``) of the format
    this wallcal writes: the chain after its burn-in, thinned as the posterior did, at most ``n_max`` draws
    evenly spread, applied to ``wall``.

    Raises
    ------
    OutputFormatError
        A folder of another format version, or without one (:func:`wallcal.outputs.check_format`).
    DataError
        Unreadable files, a chain of the wrong shape, no draw after the burn-in.
    StudyError
        A parameter naming a layer ``wall`` does not have.
    """
    from ..errors import DataError, StudyError
    from ..outputs import check_format

    from_dir = Path(from_dir)
    check_format(from_dir, COMMAND)
    chain_f, info_f = from_dir / "chain.npz", from_dir / "posterior.json"
    try:
        with np.load(chain_f, allow_pickle=False) as z:
            chain, names, lower, upper = z["chain"], [str(s) for s in z["names"]], z["lower"], z["upper"]
        info = json.loads(info_f.read_text())
        burn, thin = int(info.get("burn", 0)), max(1, int(info.get("thin", 1)))
    except (OSError, KeyError, ValueError) as exc:
        raise DataError(f"{from_dir}: not a readable posterior output (chain.npz, posterior.json): {exc}") from exc
    if chain.ndim != 3 or chain.shape[2] != len(names):
        raise DataError(f"{chain_f}: chain has shape {chain.shape}, expected (steps, walkers, {len(names)})")
    flat = chain[burn::thin].reshape(-1, chain.shape[2])
    if len(flat) == 0:
        raise DataError(f"{from_dir}: no posterior draw after the burn-in")
    X = lower + flat * (upper - lower)
    ids = {layer.id for layer in wall.layers}
    for name in names:
        prop, _, lids = name.partition("[")
        if prop != "depth":
            bad = [i for i in lids.rstrip("]").split(",") if i not in ids]
            if bad:
                raise StudyError(
                    [f"{chain_f}: parameter {name!r} names layer(s) {', '.join(bad)} that the wall does not have"]
                )
    pick = np.unique(np.linspace(0, len(X) - 1, min(n_max, len(X))).round().astype(int))
    Xs = X[pick]
    walls = [apply_named(wall, names, x) for x in Xs]
    point = apply_named(wall, names, np.median(X, axis=0))
    return Samples(walls=walls, values=Xs, names=names, point=point, source=str(from_dir))


# ============================================================================ the run
def initial_walkers(space, x_start, nw, rng, information, weight: float = 1.0, tries: int = 100):
    """Walkers drawn from the Laplace approximation of the posterior at ``x_start`` (unit coordinates).

    The approximation is Gaussian in the analysis coordinates z (log of each positive parameter, else the unit
    coordinate): mean z(``x_start``), precision ``weight`` x the likelihood's information plus the precision of
    a Gaussian with the uniform prior's variance (which bounds the structural and the nearly flat directions).
    Draws outside the prior box are drawn again (at most ``tries`` times, then clipped into it).

    The ensemble then starts with the posterior's spread and orientation, along its flat valleys too: the
    ensemble moves propose along differences between walkers, so walkers started in a small ball only creep
    along a valley that spans the prior box (on the ``offset`` campaign of ``bench/posterior_coverage.py`` the
    autocorrelation time grew from ~130 to ~500 steps as a chain so started spread over it).

    Parameters
    ----------
    space : ParameterSpace
    x_start : ndarray
        [SI] (the calibrated optimum).
    nw : int
        Walkers.
    rng : numpy Generator
    information : ndarray, shape (n, n)
        Fisher information about the unit coordinates at ``x_start`` (:attr:`Linearisation.information`).
    weight : float
        Power w of the tempered likelihood.

    Returns
    -------
    ndarray, shape (nw, n)
        Unit coordinates inside the box.
    """
    from .identifiability import from_z, log_coordinates, prior_sd_z, to_z

    x_start = np.asarray(x_start, dtype=float)
    lg = log_coordinates(space)
    # du/dz: a log coordinate z = ln x moves u = (x - lo) / (hi - lo) by x / (hi - lo)
    dudz = np.where(lg, x_start / (space.upper - space.lower), 1.0)
    precision = weight * np.asarray(information) * np.outer(dudz, dudz) + np.diag(prior_sd_z(space) ** -2.0)
    L = np.linalg.cholesky(precision)
    z0 = to_z(space, x_start[None])[0]
    U = np.full((nw, space.n), np.nan)
    todo = np.arange(nw)
    for _ in range(tries):
        Z = z0[None] + np.linalg.solve(L.T, rng.standard_normal((space.n, len(todo)))).T
        Ui = space.to_unit(from_z(space, Z))
        ok = np.all((Ui > 0.0) & (Ui < 1.0), axis=1)
        U[todo[ok]] = Ui[ok]
        todo = todo[~ok]
        if not len(todo):
            break
    if len(todo):
        U[todo] = np.clip(Ui[~ok], 1e-3, 1 - 1e-3)
    return U


def checkpoint_path(out_dir) -> Path | None:
    if out_dir is None:
        return None
    out_dir = Path(out_dir).resolve()
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    return out_dir.parent / f".{out_dir.name}.posterior-checkpoint.npz"


def _save(path, chain, logp, meta):
    if path is None:
        return
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, chain=chain, log_prob=logp, meta=json.dumps(meta))
    os.replace(tmp, path)


def posterior(
    study,
    *,
    x_start=None,
    targets=None,
    sigma: str = "estimated",
    walkers: int | None = None,
    steps: int | None = None,
    seed: int = 1,
    out_dir=None,
    resume: bool = False,
    progress: bool = True,
    prepared=None,
    max_evaluations: int | None = None,
    nonunique_candidates: int = 256,
    bias: bool = True,
    tempering: str = "sandwich",
    missing_extensions=(),
    effective_samples: float | None = None,
    max_steps: int | None = None,
) -> PosteriorResult:
    """Sample the posterior of the calibration parameters.

    Parameters
    ----------
    study : Study
    x_start : ndarray, optional
        Starting point [SI] (the calibrated optimum); default the base case.
    targets : list of str, optional
        Default the study's ``calibration.targets``.
    sigma : {"estimated", "accuracy"}
        Error sd per target: the residual RMSE at ``x_start``, or the sensor's stated accuracy.
    walkers : int, optional
        Default 4 per sampled coordinate (:class:`LogCoordinates`; even), at least 16.
    steps : int, optional
        Ensemble steps (simulations = walkers x steps). Default: run until the chain is adequate
        (:func:`chain_diagnostics`: ``effective_samples`` effective samples, at least ``MIN_TAU_MULTIPLE``
        autocorrelation times after burn-in, the autocorrelation time no longer growing), checked whenever the
        chain has grown by 20 % (at least 25 steps), at most ``max_steps``.
    seed : int
    out_dir : path, optional
        The checkpoint ``.<name>.posterior-checkpoint.npz`` is kept next to it.
    resume : bool
        Continue from that checkpoint.
    max_evaluations : int, optional
        Cap on simulations (steps are reduced to fit).
    bias : bool
        Integrate out a constant bias per sensor with sd = half the stated accuracy (accuracy read as a 95 %
        bound); without it a thermocouple's offset is fitted by the wall properties and the intervals miss
        the truth.
    nonunique_candidates : int
        Posterior samples re-simulated to show distinct sets with RMSEs within the sensor accuracy (and for the
        posterior predictive residual checks).
    tempering : {"sandwich", "none"}
        Temper the likelihood by the sandwich rule (:func:`sandwich_weight`; one extra batch of 2n + 1 runs), or
        not.
    missing_extensions : sequence of str
        Structure extensions that ``wallcal diagnose`` adopted for this study but the sampled structure lacks;
        any makes the self-check say that the data reject the structure.

    effective_samples : float, optional
        Effective samples an adequate chain holds (default :data:`DEFAULT_EFFECTIVE_SAMPLES`).
    max_steps : int, optional
        Longest default chain (when ``steps`` is not given) [steps] (default :data:`DEFAULT_MAX_STEPS`).

    Returns
    -------
    PosteriorResult
    """
    from ..calibration.algorithms import Progress
    from ..calibration.objective import Evaluator
    from ..calibration.space import parse_space
    from ..errors import WallcalError, require
    from ..simulation import BATCH_NEEDS, prepare
    from . import reference_values, space_with_targets

    require("emcee", "analysis")  # a clear error when the analysis extra is missing
    space = space_with_targets(study, parse_space(study), targets)
    x_start = space.base if x_start is None else np.asarray(x_start, dtype=float)
    prepared = prepared or prepare(study, needs=BATCH_NEEDS, purpose="the posterior sampling")
    ev = Evaluator(prepared, space)
    n = space.n
    coords = LogCoordinates(None, space)  # the sampled coordinates (the likelihood is set below)
    dim = coords.dim
    nw = int(walkers or max(4 * dim, 16))
    nw += nw % 2
    adaptive = steps is None
    check_positive({"steps": steps, "max_steps": max_steps, "effective_samples": effective_samples})
    effective_samples = DEFAULT_EFFECTIVE_SAMPLES if effective_samples is None else effective_samples
    max_steps = DEFAULT_MAX_STEPS if max_steps is None else max_steps
    steps = int(max_steps if adaptive else steps)
    if max_evaluations:
        steps = min(steps, max(1, int(max_evaluations) // nw))
    sig, ph, tau = error_model(study, space, ev, x_start, sigma, bias)
    if tempering not in ("sandwich", "none"):
        raise WallcalError(f"tempering: {tempering!r} is not one of 'sandwich', 'none'")
    temp = {"kind": "none", "weight": 1.0}
    lin = None if resume else linearise(ev, space, x_start, sig, ph, tau)
    if tempering == "sandwich" and not resume:
        temp = {"kind": "sandwich", **sandwich_weight(ev, space, x_start, sig, ph, lin=lin)}
    like = AR1Likelihood(
        ev,
        [sig[t] for t in space.targets],
        [ph[t] for t in space.targets],
        [tau[t] for t in space.targets],
        weight=temp["weight"],
    )
    ckpt = checkpoint_path(out_dir)
    meta = {
        "names": space.names,
        "targets": list(space.targets),
        "sigma": sig,
        "phi": ph,
        "walkers": nw,
        "sampled_coordinates": coords.names,
        "study_sha256": study.sha256,
        "tempering": temp,
    }
    rng = np.random.default_rng(seed)
    prev_chain = np.zeros((0, nw, dim))  # the chain of the sampled coordinates
    prev_lp = np.zeros((0, nw))
    if resume:
        if ckpt is None or not ckpt.exists():
            raise WallcalError(f"nothing to resume: no checkpoint {ckpt} (run without --resume)")
        data = np.load(ckpt)
        old = json.loads(str(data["meta"]))
        for key in ("names", "targets", "walkers", "sampled_coordinates", "study_sha256"):
            if old.get(key) != meta[key]:
                raise WallcalError(f"{ckpt}: made with another {key.replace('_', ' ')}; run without --resume")
        prev_chain, prev_lp = data["chain"], data["log_prob"]
        sig, ph = old["sigma"], old["phi"]
        temp = old.get("tempering", {"kind": "none", "weight": 1.0})
        like = AR1Likelihood(
            ev,
            [sig[t] for t in space.targets],
            [ph[t] for t in space.targets],
            [tau[t] for t in space.targets],
            weight=temp["weight"],
        )
        meta.update(sigma=sig, phi=ph, tempering=temp)
        p0 = prev_chain[-1]
        steps = max(0, steps - len(prev_chain))
    else:
        p0 = coords.from_unit(initial_walkers(space, x_start, nw, rng, lin.information, temp["weight"]))
    coords.like = like
    sampler = ensemble_sampler(coords, nw, dim, seed)

    prog = Progress("posterior (emcee)", enabled=progress)
    runs0 = ev.evaluations
    t0 = time.perf_counter()
    status = "complete"
    last = time.perf_counter()
    done = 0
    next_check = max(ADAPTIVE_FIRST_CHECK, len(prev_chain))
    ess = ""
    final = None  # the diagnostics of the chain as it ends, when the adequacy check computed them
    if adaptive and len(prev_chain) >= ADAPTIVE_FIRST_CHECK:
        d = chain_diagnostics(prev_chain, prev_lp, effective_samples)
        if d.adequate:
            steps = 0  # the resumed chain is adequate already
            final = d
    try:
        if steps > 0:
            for _ in sampler.sample(p0, iterations=steps):
                done += 1
                if adaptive and len(prev_chain) + done >= next_check:
                    d = chain_diagnostics(
                        np.concatenate([prev_chain, sampler.get_chain()]),
                        np.concatenate([prev_lp, sampler.get_log_prob()]),
                        effective_samples,
                    )
                    if d.adequate:
                        final = d
                        break
                    length = len(prev_chain) + done
                    next_check = length + max(ADAPTIVE_EVERY, int(ADAPTIVE_GROWTH * length))
                    ess = f", {d.effective_samples:.0f} effective samples" + (
                        "" if d.stable else " (tau still growing)"
                    )
                if time.perf_counter() - last > 10.0:
                    _save(
                        ckpt,
                        np.concatenate([prev_chain, sampler.get_chain()]),
                        np.concatenate([prev_lp, sampler.get_log_prob()]),
                        meta,
                    )
                    last = time.perf_counter()
                prog.update(
                    f"step {len(prev_chain) + done}/{'at most ' if adaptive else ''}{len(prev_chain) + steps}, "
                    f"{ev.evaluations} simulations, acceptance {np.mean(sampler.acceptance_fraction):.2f}{ess}"
                )
    except KeyboardInterrupt:
        status = "interrupted"
    chain = np.concatenate([prev_chain, sampler.get_chain()]) if done else prev_chain
    logp = np.concatenate([prev_lp, sampler.get_log_prob()]) if done else prev_lp
    _save(ckpt, chain, logp, meta)
    seconds = time.perf_counter() - t0
    simulated = ev.evaluations - runs0
    prog.close(f"{len(chain)} steps, {ev.evaluations} simulations, {seconds:.1f} s ({status})")
    if len(chain) < 4:
        raise WallcalError("the chain is too short to summarise (interrupted at once); continue with --resume")
    # the diagnostics belong to the Markov chain (the sampled coordinates); the summary reads the chain of every
    # parameter, each rho*c split drawn from its conditional
    final = final or chain_diagnostics(chain, logp, effective_samples)
    final = dataclasses.replace(final, tau=coords.full_tau(final.tau))
    split_rng = np.random.default_rng([seed, 1])
    unit = coords.draw_unit(chain.reshape(-1, dim), split_rng).reshape(chain.shape[:2] + (n,))
    res = summarise(
        study,
        space,
        unit,
        logp,
        ev,
        sig,
        ph,
        sigma,
        seconds,
        status,
        acceptance=float(np.mean(sampler.acceptance_fraction)) if done else float("nan"),
        truth=reference_values(study, space),
        nonunique_candidates=nonunique_candidates,
        seed=seed,
        tempering=temp,
        missing_extensions=missing_extensions,
        effective_samples=effective_samples,
        diagnostics=final,
    )
    res.simulations = simulated if not resume else None  # a resumed chain's earlier part is not counted
    if prepared.note:
        res.warnings.insert(0, prepared.note)
    if status == "complete" and ckpt is not None and ckpt.exists():
        ckpt.unlink()
    return res


def ensemble_sampler(like, walkers: int, n: int, seed: int):
    """The emcee ensemble sampler of :func:`posterior`: vectorised log-probability ``like`` (over the sampling
    coordinates), differential-evolution moves (80 % DE, 20 % DE snooker), seeded."""
    import emcee

    sampler = emcee.EnsembleSampler(
        walkers, n, like, vectorize=True, moves=[(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    )
    sampler.random_state = np.random.RandomState(seed).get_state()
    return sampler


def check_positive(settings: dict) -> None:
    """Raise :class:`WallcalError` naming the first of ``settings`` (name -> value; None: not given) that is not
    positive (the chain's length settings; the command line checks its flags with it before calibrating)."""
    from ..errors import WallcalError

    for name, value in settings.items():
        if value is not None and not value > 0:
            raise WallcalError(f"{name}: must be positive, got {value!r}")


@dataclass
class ChainDiagnostics:
    """What a chain (steps, walkers, n) says about itself (:func:`chain_diagnostics`).

    Attributes
    ----------
    tau : ndarray, shape (n,)
        Integrated autocorrelation time per parameter over the chain after burn-in [steps].
    tau_early : float
        The largest autocorrelation time over the first ``STABLE_SHARE`` of the chain after burn-in [steps].
    burn : int
        Burn-in [steps].
    effective_samples : float
        Walkers x steps after burn-in / the largest autocorrelation time.
    stable : bool
        The autocorrelation time no longer grows with the chain (``tau.max() <= STABLE_RATIO x tau_early``).
    adequate : bool
        At least ``target`` effective samples, ``MIN_TAU_MULTIPLE`` autocorrelation times after burn-in, stable.
    reasons : list of str
        Why not adequate (empty when adequate).
    """

    tau: np.ndarray
    tau_early: float
    burn: int
    effective_samples: float
    stable: bool
    adequate: bool
    reasons: list


def integrated_time(chain: np.ndarray, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time per parameter of a chain (steps, walkers, n) [steps]: emcee's estimate
    (``emcee.autocorr.integrated_time``: the autocorrelation function of each walker's series averaged over the
    walkers, summed over Sokal's automatic window with ``c``), with the FFTs of all walkers at once; nan for a
    parameter in which a walker never moved."""
    from scipy import fft

    nsteps = chain.shape[0]
    if nsteps <= 10:
        return np.full(chain.shape[2], nan)
    size = fft.next_fast_len(2 * nsteps - 1, real=True)  # zero-padded: the circular correlation is the linear one
    out = np.empty(chain.shape[2])
    lag = np.arange(nsteps)
    for j in range(chain.shape[2]):
        x = chain[:, :, j] - chain[:, :, j].mean(axis=0, keepdims=True)
        f = fft.rfft(x, n=size, axis=0, workers=-1)
        acf = fft.irfft(f * np.conjugate(f), n=size, axis=0, workers=-1)[:nsteps]
        with np.errstate(invalid="ignore", divide="ignore"):
            rho = (acf / acf[0][None]).mean(axis=1)
        taus = 2.0 * np.cumsum(rho) - 1.0
        short = lag < c * taus
        out[j] = taus[int(np.argmin(short))] if short.any() else taus[-1]
    return out


def transient_end(log_prob: np.ndarray) -> int:
    """The step at which the ensemble's median log-probability (averaged over ``BURN_WINDOW`` steps) first reaches
    its level over the second half of the chain: from a start narrower than the posterior it falls to it, from one
    wider or off the mode it climbs to it."""
    m = np.median(np.asarray(log_prob, dtype=float), axis=1)
    n = len(m) // BURN_WINDOW
    if n < 4:
        return 0
    w = m[: n * BURN_WINDOW].reshape(n, BURN_WINDOW).mean(axis=1)
    level = float(np.median(m[len(m) // 2 :]))
    side = np.sign(w[0] - level)
    crossed = np.flatnonzero(np.sign(w - level) != side)
    return int(crossed[0] * BURN_WINDOW) if len(crossed) else len(m) // 2


def chain_diagnostics(chain: np.ndarray, log_prob=None, target: float = DEFAULT_EFFECTIVE_SAMPLES) -> ChainDiagnostics:
    """Burn-in, autocorrelation time and effective samples of a chain (steps, walkers, n), and whether it is adequate.

    Burn-in: the end of the start's transient in the log-probability (:func:`transient_end`), and at least one
    autocorrelation time, at most half the chain; without ``log_prob``, two autocorrelation times. The
    autocorrelation time is estimated on the chain after burn-in (emcee's windowed estimator, averaged over the
    walkers). A chain too short for it gives an estimate capped by its length, which grows in proportion to the
    chain: so an adequate chain also has an estimate that no longer grows (over the whole chain after burn-in at
    most ``STABLE_RATIO`` x the one over its first ``STABLE_SHARE``), is at least ``MIN_TAU_MULTIPLE``
    autocorrelation times long after burn-in, and holds ``target`` effective samples.
    """
    nsteps, walkers = chain.shape[:2]
    start = max(transient_end(log_prob), 1) if log_prob is not None and len(log_prob) == nsteps else 0
    start = min(start, nsteps // 2)
    tau = integrated_time(chain[start:])
    t = float(np.nanmax(tau)) if np.isfinite(tau).any() else float(nsteps)
    burn = int(min(max(start, int(np.ceil(t))) if start else int(np.ceil(2 * t)), nsteps // 2))
    post = chain[burn:]
    if burn != start:
        tau = integrated_time(post)
    tmax = float(np.nanmax(tau)) if np.isfinite(tau).any() else float(nsteps)
    early = integrated_time(post[: int(STABLE_SHARE * len(post))])
    tau_early = float(np.nanmax(early)) if np.isfinite(early).any() else nan
    ess = walkers * len(post) / tmax if tmax > 0 else 0.0
    stable = bool(np.isfinite(tau_early) and tmax <= STABLE_RATIO * tau_early)
    reasons = []
    if ess < target:
        reasons.append(f"{ess:.0f} effective samples < {target:.0f}")
    if len(post) < MIN_TAU_MULTIPLE * tmax:
        reasons.append(
            f"{len(post)} steps after burn-in < {MIN_TAU_MULTIPLE} x the largest autocorrelation time "
            f"({tmax:.0f} steps)"
        )
    if not stable:
        reasons.append(
            f"the autocorrelation time still grows with the chain ({tau_early:.0f} steps over the first "
            f"{STABLE_SHARE:.0%} after burn-in, {tmax:.0f} over all): it is a lower bound, the effective samples an "
            "upper one"
        )
    return ChainDiagnostics(
        tau=tau,
        tau_early=tau_early,
        burn=burn,
        effective_samples=float(ess),
        stable=stable,
        adequate=not reasons,
        reasons=reasons,
    )


def burn_and_thin(d: ChainDiagnostics, acceptance: float = nan) -> tuple[np.ndarray, int, int, list]:
    """Integrated autocorrelation time per parameter [steps], burn-in and thinning of a chain, from its
    :func:`chain_diagnostics` ``d``, and the warnings on its adequacy and acceptance."""
    warnings = []
    if not d.adequate:
        warnings.append(
            "chain not adequate for reliable intervals: " + "; ".join(d.reasons) + "; run longer (--steps) or --resume"
        )
    if np.isfinite(acceptance) and not 0.1 <= acceptance <= 0.7:
        warnings.append(f"acceptance fraction {acceptance:.2f} is outside 0.1..0.7")
    thin = max(1, int(0.5 * np.nanmin(d.tau))) if np.isfinite(d.tau).any() else 1
    return d.tau, d.burn, thin, warnings


def summarise(
    study,
    space,
    chain,
    logp,
    ev,
    sig,
    ph,
    sigma_kind,
    seconds,
    status,
    acceptance,
    truth=None,
    nonunique_candidates=256,
    seed=1,
    tempering=None,
    missing_extensions=(),
    effective_samples: float = DEFAULT_EFFECTIVE_SAMPLES,
    diagnostics: ChainDiagnostics | None = None,
) -> PosteriorResult:
    """Burn-in, thinning, diagnostics, per-parameter and derived summaries, non-uniqueness demonstration,
    posterior predictive checks and the structure verdict. ``diagnostics``: those of this very chain
    (:func:`chain_diagnostics` with ``effective_samples``), when the caller has them already."""
    diag = diagnostics or chain_diagnostics(chain, logp, effective_samples)
    tau, burn, thin, warnings = burn_and_thin(diag, acceptance)
    flat_u = chain[burn::thin].reshape(-1, chain.shape[2])
    X = space.from_unit(flat_u)
    rng = np.random.default_rng(seed)
    prior_u = rng.random((20000, space.n))
    prior_X = space.from_unit(prior_u)
    rows = []
    for j, p in enumerate(space.parameters):
        r = {
            "parameter": p.name,
            **_stats(X[:, j], prior_X[:, j], None if truth is None else truth[j]),
            "lower": p.lower,
            "upper": p.upper,
        }
        rows.append(r)
    summary = pd.DataFrame(rows).set_index("parameter")
    # structural facts override the marginal widths: a lone rho or c is never identified (only rho*c is; its
    # marginal is narrowed by the bounds of its partner), and without a heat flux the absolute scale of the
    # conductivities comes from the bounds of the other layers, not from the data
    from .identifiability import structural_directions

    with_flux = any(study.sensor(t).quantity == "heat_flux" for t in space.targets)
    for key, _, d in structural_directions(space, study.wall, with_flux=with_flux):
        for j in np.flatnonzero(np.abs(d) > 0.05):
            name = space.names[j]
            if key.startswith("rho_c"):
                summary.loc[name, "verdict"] = "not identified (only rho*c)"
            elif summary.loc[name, "verdict"] != "not identified" and "rho*c" not in summary.loc[name, "verdict"]:
                summary.loc[name, "verdict"] += " (scale from the bounds)"
    corr = pd.DataFrame(np.corrcoef(X.T), index=space.names, columns=space.names)
    dpost = derived(space, study.wall, X)
    dprior = derived(space, study.wall, prior_X)
    dtruth = derived(space, study.wall, truth[None]) if truth is not None else None
    crow = [
        {"combination": k, **_stats(dpost[k], dprior[k], None if dtruth is None else float(dtruth[k][0]))}
        for k in dpost
    ]
    comb = pd.DataFrame(crow).set_index("combination").sort_values("sd/prior sd")
    # non-uniqueness: distinct posterior sets, all RMSEs within the sensor accuracy
    pick = rng.choice(len(X), size=min(nonunique_candidates, len(X)), replace=False)
    Xc = X[pick]
    E = ev.errors(Xc)
    rmse = np.sqrt(np.einsum("ctk,ctk->ct", E, E) / ev.n_valid[None])
    checks = residual_checks(study, space, ev, E)
    structure = structure_verdict(checks, summary, comb, missing_extensions)
    acc = np.array([_accuracy(study, t, ev.y[k][ev.mask[k]]) for k, t in enumerate(space.targets)])
    ok = np.all(rmse <= acc[None], axis=1)
    chosen = []
    if ok.any():
        Uc = space.to_unit(Xc[ok])
        idx = [int(np.argmin(rmse[ok].sum(axis=1)))]
        while len(idx) < min(5, len(Uc)):
            dmin = np.min(np.linalg.norm(Uc[:, None] - Uc[idx][None], axis=2), axis=1)
            idx.append(int(np.argmax(dmin)))
        chosen = np.flatnonzero(ok)[idx]
    nonunique = pd.DataFrame(Xc[chosen], columns=space.names)
    for k, t in enumerate(space.targets):
        nonunique[f"RMSE {t}"] = rmse[chosen, k]
    nonunique.index = pd.Index([f"set {i + 1}" for i in range(len(chosen))], name="set")
    return PosteriorResult(
        study=study,
        space=space,
        chain=chain,
        log_prob=logp,
        samples=X,
        summary=summary,
        correlation=corr,
        combinations=comb,
        nonunique=nonunique,
        tau=tau,
        acceptance=acceptance,
        burn=burn,
        thin=thin,
        sigma=sig,
        phi=ph,
        sigma_kind=sigma_kind,
        evaluations=int(chain.shape[0] * chain.shape[1]),
        seconds=seconds,
        status=status,
        warnings=warnings,
        truth=truth,
        tempering=tempering or {"kind": "none", "weight": 1.0},
        checks=checks,
        structure=structure,
        effective_samples=diag.effective_samples,
        adequate=diag.adequate,
        target_effective_samples=float(effective_samples),
    )


def _accuracy(study, name, y) -> float:
    from .identifiability import sensor_sigma

    return sensor_sigma(study, name, y)
