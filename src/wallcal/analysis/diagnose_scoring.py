"""The scoring of ``wallcal diagnose`` (:mod:`wallcal.analysis.diagnose`): the criterion (BIC on the AR(1)
likelihood of the residuals, the sensor biases integrated out), the residuals with the biases profiled out,
and the warm-started recalibration of a structure.
"""

from __future__ import annotations

import math

import numpy as np

#: Jacobians allowed in each warm-started recalibration
MAX_JACOBIANS = 8
#: the criterion is the likelihood of the residuals' means over blocks of this length [s] (hourly means): at the
#: 5-10 min sampling of the data the AR(1) coefficient of the residuals is 0.99 and more, the likelihood then
#: scores almost only the increments and barely sees a level error (docs/identifiability.md, "The error model")
SCORE_RESOLUTION = 3600.0
#: relative change of the least-squares cost that ends a recalibration (a BIC change of 1 is about 2 / N)
FTOL = 1e-5


# ============================================================================ the criterion
def ar1_loglike(e: np.ndarray, mask: np.ndarray, bias_sd: float = 0.0) -> tuple[float, int, float]:
    """Maximised conditional AR(1) Gaussian log-likelihood of one residual series, a constant sensor bias with
    a Gaussian prior integrated out.

    The residuals follow e_t = b + u_t, u_t = phi u_{t-1} + eta_t, eta ~ N(0, s^2), with a constant bias
    b ~ N(0, bias_sd^2) (the posterior's error model: a sensor's bias within its stated accuracy is part of
    the error, not of the structure). Conditioning on the first value of every gap-free run, the m consecutive
    valid pairs give innovations r_t - c b with r_t = e_t - phi e_{t-1} and c = 1 - phi; integrating b out
    exactly,

        log L = -m/2 ln(2 pi s^2) - sum (r_t - c b*)^2 / (2 s^2) - b*^2 / (2 bias_sd^2)
                - 1/2 ln(1 + m c^2 bias_sd^2 / s^2),

    b* = c sum r_t / (m c^2 + s^2 / bias_sd^2) the bias's posterior mean, maximised over phi and s^2 by
    alternating their closed-form updates with b* (this maximises the joint density of phi, s and b; the last
    term's dependence on phi and s is left out of the maximisation, which costs a few thousandths). With
    ``bias_sd`` 0 (no bias: it shows as misfit) this is -m/2 (ln(2 pi s^2) + 1) with
    phi = sum e_t e_{t-1} / sum e_{t-1}^2 and s^2 the mean squared innovation.

    Parameters
    ----------
    e : ndarray, shape (n,)
        Residuals [unit of the signal].
    mask : ndarray of bool, shape (n,)
        Valid samples.
    bias_sd : float
        Prior sd of the sensor's constant bias [unit of the signal]; 0: no bias.

    Returns
    -------
    (log L, m, phi)
    """
    return _ar1_fit(e, mask, bias_sd)[:3]


def _ar1_fit(e, mask, bias_sd=0.0) -> tuple[float, int, float, float, float]:
    """:func:`ar1_loglike` and its innovation sd s and bias b*."""
    e = np.where(mask, e, 0.0)
    pair = mask[1:] & mask[:-1]
    m = int(pair.sum())
    if m < 2:
        return 0.0, 0, 0.0, 1.0, 0.0
    a, p = e[1:][pair], e[:-1][pair]

    def ar(b):
        den = float(np.sum((p - b) ** 2))
        phi = float(np.clip(np.sum((a - b) * (p - b)) / den, -0.999, 0.999)) if den > 0 else 0.0
        s2 = max(float(np.mean(((a - b) - phi * (p - b)) ** 2)), 1e-300)
        return phi, s2

    b = 0.0
    phi, s2 = ar(b)
    if not bias_sd > 0:
        return -0.5 * m * (math.log(2 * math.pi * s2) + 1.0), m, phi, math.sqrt(s2), 0.0
    t2 = float(bias_sd) ** 2
    for _ in range(50):
        c = 1.0 - phi
        b_new = c * float(np.sum(a - phi * p)) / (m * c * c + s2 / t2)
        phi, s2 = ar(b_new)
        done = abs(b_new - b) <= 1e-9 * (abs(b_new) + math.sqrt(s2))
        b = b_new
        if done:
            break
    c = 1.0 - phi
    b = c * float(np.sum(a - phi * p)) / (m * c * c + s2 / t2)
    q = float(np.sum((a - phi * p - c * b) ** 2))
    s2 = max(q / m, 1e-300)
    ll = -0.5 * m * (math.log(2 * math.pi * s2) + 1.0) - 0.5 * b * b / t2 - 0.5 * math.log1p(m * c * c * t2 / s2)
    return ll, m, phi, math.sqrt(s2), b


def block_means(E: np.ndarray, mask: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Means of ``E`` (targets x times) over consecutive blocks of ``block`` samples, and their validity (a block
    is valid when at least half its samples are; a last, shorter block is dropped)."""
    if block <= 1:
        return E, mask
    nb = E.shape[-1] // block
    shape = E.shape[:-1] + (nb, block)
    m = mask[..., : nb * block].reshape(shape)
    e = np.where(m, E[..., : nb * block].reshape(shape), 0.0)
    cnt = m.sum(axis=-1)
    ok = cnt >= (block + 1) // 2
    return np.where(ok, e.sum(axis=-1) / np.maximum(cnt, 1), 0.0), ok


def ar1_profile(
    E: np.ndarray, mask: np.ndarray, bias_sd=None, block: int = 1
) -> tuple[float, int, np.ndarray, np.ndarray]:
    """The AR(1) fit of every target's residuals ``E`` (targets x times), each with its sensor bias of prior sd
    ``bias_sd[k]`` integrated out (None: no bias): (log L summed over the targets, N pairs, phi per target,
    innovation sd per target). ``block`` > 1: of the residuals' means over blocks of that many samples
    (:func:`block_means`; ``diagnose`` scores hourly means, see :data:`SCORE_RESOLUTION`)."""
    E, mask = block_means(E, mask, block)
    ll, n = 0.0, 0
    phi = np.zeros(E.shape[0])
    sd = np.ones(E.shape[0])
    tau = np.zeros(E.shape[0]) if bias_sd is None else np.asarray(bias_sd, dtype=float)
    for k in range(E.shape[0]):
        lk, mk, phi[k], sk, _ = _ar1_fit(E[k], mask[k], float(tau[k]))
        ll += lk
        n += mk
        if mk:
            sd[k] = sk
    return ll, n, phi, sd


# ============================================================================ recalibration
def debiased_residuals(ev, X, bias_sd, noise) -> np.ndarray:
    """The study's least-squares residuals with every target's constant sensor bias profiled out under its
    prior: the objective sum_k w_k (sum_t (e_kt - b_k)^2 + noise_k^2 b_k^2 / bias_sd_k^2), minimised over b_k
    in closed form, b_k = sum_t e_kt / (n_k + noise_k^2 / bias_sd_k^2) (b_k = 0 where bias_sd_k is 0).

    The criterion integrates the same bias out, so the structure it scores is fitted under its own error
    model: fitted on the raw errors, the wall's properties would absorb a sensor's bias.

    Parameters
    ----------
    ev : Evaluator
    X : ndarray, shape (c, n)
        Parameter values [SI].
    bias_sd, noise : ndarray, shape (n_targets,)
        Prior sd of each target's bias and its noise sd [target unit].

    Returns
    -------
    ndarray, shape (c, n_targets * n_times + n_targets)
    """
    from ..calibration.objective import residual_weights

    e = ev.errors(np.atleast_2d(X))
    w = np.sqrt(residual_weights(ev.space.objective, ev.n_valid, ev.weights, ev.scale))
    tau = np.asarray(bias_sd, dtype=float)
    has = tau > 0
    ratio = np.where(has, np.asarray(noise, dtype=float) ** 2 / np.where(has, tau, 1.0) ** 2, np.inf)
    b = np.einsum("ctk->ct", e) / (ev.n_valid + ratio)[None]  # e is 0 at missing samples
    r = np.where(ev.mask[None], e - b[:, :, None], 0.0) * w[None, :, None]
    prior = np.where(has, b * (np.asarray(noise) / np.where(has, tau, 1.0))[None], 0.0) * w[None]
    return np.concatenate([r.reshape(e.shape[0], -1), prior], axis=1)


def refine(residuals, u0, max_jacobians: int = MAX_JACOBIANS, ftol: float = FTOL, h: float = 1e-6):
    """Warm-started bounded Levenberg-Marquardt in the unit box; every engine call is one batch.

    Each iteration runs one batch of n forward-difference runs (the Jacobian) and one batch of four trial
    steps (damping lambda/10, lambda, 10 lambda, 100 lambda, each clipped to the box; parameters at a bound
    whose gradient points out of the box stay there) and keeps the best trial. The normal equations are
    n x n (no decomposition of the tall Jacobian).

    Parameters
    ----------
    residuals : callable
        ``residuals(U) -> R``, U shape (c, n) in unit coordinates, R shape (c, m).
    u0 : ndarray, shape (n,)
    max_jacobians : int
    ftol : float
        Stop when an accepted step lowers the cost by less than this fraction.

    Returns
    -------
    (u, runs)
        The best point and the number of simulations run.
    """
    u = np.clip(np.asarray(u0, dtype=float), 0.0, 1.0)
    n = len(u)
    r = residuals(u[None])[0]
    cost = float(np.einsum("m,m->", r, r))
    runs = 1
    lam = 1e-3
    for _ in range(max_jacobians):
        step = np.where(u + h > 1.0, -h, h)
        U = np.repeat(u[None], n, axis=0)
        U[np.arange(n), np.arange(n)] += step
        D = (residuals(U) - r[None]) / step[:, None]  # the Jacobian's transpose, (n, m)
        runs += n
        # einsum, not BLAS: on a shared machine a threaded BLAS product of this tall matrix can take 100x longer
        A = np.einsum("im,jm->ij", D, D)
        g = np.einsum("im,m->i", D, r)
        free = ~(((u <= 0.0) & (g > 0)) | ((u >= 1.0) & (g < 0)))
        if not free.any():
            break
        Af, gf = A[np.ix_(free, free)], g[free]
        d = np.diag(Af).copy()
        d[d <= 0] = 1.0
        lams = lam * np.array([0.1, 1.0, 10.0, 100.0])
        trials = []
        for lm in lams:
            try:
                delta = np.linalg.solve(Af + lm * np.diag(d), -gf)
            except np.linalg.LinAlgError:
                delta = -gf / (d * (1 + lm))
            ut = u.copy()
            ut[free] = np.clip(u[free] + delta, 0.0, 1.0)
            trials.append(ut)
        T = np.array(trials)
        R = residuals(T)
        runs += len(T)
        costs = np.einsum("cm,cm->c", R, R)
        costs = np.where(np.isfinite(costs), costs, np.inf)
        k = int(np.argmin(costs))
        if not costs[k] < cost:
            lam *= 1000.0
            if lam > 1e10:
                break
            continue
        gain = (cost - costs[k]) / cost if cost > 0 else 0.0
        u, r, cost, lam = T[k], R[k], float(costs[k]), max(lams[k] / 3.0, 1e-9)
        if gain < ftol:
            break
    return u, runs
