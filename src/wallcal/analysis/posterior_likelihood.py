"""The posterior's likelihood (:mod:`wallcal.analysis.posterior`): the AR(1) error model, the sampling
coordinates, and the tempering of the likelihood by the sandwich rule.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

nan = float("nan")


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
