"""The exact fast path for walls with constant properties: the theta scheme, diagonalised.

For a wall whose conductances do not depend on temperature, whose unknown nodes
all store heat and whose links all share one theta, the scheme

    (Cap/dt + theta K) T^{n+1} = (Cap/dt - (1 - theta) K) T^n + p (theta u^{n+1} + (1 - theta) u^n)

(``K`` the conductance matrix of the unknown nodes, boundary coefficients
included; ``p`` the input coupling, one column per boundary input) is
diagonalised once by the symmetric generalized eigenproblem
``K v = lambda Cap v`` with ``V^T Cap V = I``. Each mode then follows the real
first-order recursion

    z_k^{n+1} = mu_k z_k^n + r_k . s^n,   mu_k = (1/dt - (1 - theta) lambda_k) / (1/dt + theta lambda_k),
    r_k = (V^T p)_k / (1/dt + theta lambda_k),  s^n = theta u^{n+1} + (1 - theta) u^n,

which is the same linear algebra as the tridiagonal solve (results agree to
round-off), at about three flops per mode and step. Outputs are formed only at
the requested times, from ``T = V z`` and the boundary inputs. The eigen
decomposition is done per candidate inside the parallel batch loop, so it is
batched too.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True)
def _modal_one(kd, ko, cap_u, p, theta, dt, s, ue, ui, out_step, out_w, H, Dp, Dd, out, t0):
    """One candidate.

    kd, ko : diagonal and off-diagonal of K over the m unknowns
    cap_u : capacities of the unknowns
    p : (m, 2) input coupling of K
    s : (n_steps, 2) theta-weighted inputs per step
    H : (n_q, m) output rows over unknown node temperatures
    Dp : (n_q, 2) direct coefficients of u^n in the outputs
    Dd : (n_q, 2) coefficients of the central difference (u^{n+1} - u^{n-1}) / (2 dt)
    t0 : (m,) initial unknown temperatures, or shape (0,) for the steady state of the first inputs
    """
    m = kd.shape[0]
    n_q = H.shape[0]
    S = np.zeros((m, m))
    dinv = np.empty(m)
    for i in range(m):
        dinv[i] = 1.0 / np.sqrt(cap_u[i])
    for i in range(m):
        S[i, i] = kd[i] * dinv[i] * dinv[i]
        if i < m - 1:
            v = ko[i] * dinv[i] * dinv[i + 1]
            S[i, i + 1] = v
            S[i + 1, i] = v
    lam, W = np.linalg.eigh(S)
    V = np.empty((m, m))
    for i in range(m):
        for k in range(m):
            V[i, k] = W[i, k] * dinv[i]
    mu = np.empty(m)
    r0 = np.zeros(m)
    r1 = np.zeros(m)
    z = np.zeros(m)
    given = t0.shape[0] == m
    for k in range(m):
        den = 1.0 / dt + theta * lam[k]
        mu[k] = (1.0 / dt - (1.0 - theta) * lam[k]) / den
        a0 = 0.0
        a1 = 0.0
        zz = 0.0
        for i in range(m):
            a0 += V[i, k] * p[i, 0]
            a1 += V[i, k] * p[i, 1]
            if given:
                zz += V[i, k] * cap_u[i] * t0[i]
        r0[k] = a0 / den
        r1[k] = a1 / den
        # steady start: K T = p u^0 gives z = Lambda^-1 V^T p u^0 (V^T K V = Lambda)
        z[k] = zz if given else (a0 * ue[0] + a1 * ui[0]) / lam[k]
    # output rows in modal coordinates
    G = np.zeros((n_q, m))
    for q in range(n_q):
        for k in range(m):
            acc = 0.0
            for i in range(m):
                acc += H[q, i] * V[i, k]
            G[q, k] = acc
    _recur(mu, r0, r1, z, s, ue, ui, dt, out_step, out_w, G, Dp, Dd, out)
    # final unknown temperatures
    tend = np.zeros(m)
    for i in range(m):
        acc = 0.0
        for k in range(m):
            acc += V[i, k] * z[k]
        tend[i] = acc
    return tend


@njit(cache=True)
def _direct_at(n, Dp, Dd, ue, ui, dt, y):
    """Output terms that depend on the boundary inputs only, at grid time n."""
    n_last = ue.shape[0] - 1
    lo = max(n - 1, 0)
    hi = min(n + 1, n_last)
    inv = 1.0 / ((hi - lo) * dt)
    de = (ue[hi] - ue[lo]) * inv
    di = (ui[hi] - ui[lo]) * inv
    for q in range(Dp.shape[0]):
        y[q] = Dp[q, 0] * ue[n] + Dp[q, 1] * ui[n] + Dd[q, 0] * de + Dd[q, 1] * di


@njit(cache=True, fastmath=True)
def _recur(mu, r0, r1, z, s, ue, ui, dt, out_step, out_w, G, Dp, Dd, out):
    """The modal recursion over all steps; outputs formed only at the requested times.

    The modal state is interpolated to each output time and stored (memory: outputs x
    modes, independent of the number of steps); the outputs are then one matrix
    product. fastmath lets the mode loop use SIMD (the modes are independent).
    """
    m = z.shape[0]
    n_q = G.shape[0]
    n_steps = s.shape[0]
    n_out = out_step.shape[0]
    Z = np.zeros((n_out, m))
    zprev = np.zeros(m)
    k_out = 0
    for n in range(n_steps):
        hit = k_out < n_out and out_step[k_out] == n
        if hit:
            for k in range(m):
                zprev[k] = z[k]
        s0 = s[n, 0]
        s1 = s[n, 1]
        for k in range(m):
            z[k] = mu[k] * z[k] + r0[k] * s0 + r1[k] * s1
        if hit:
            while k_out < n_out and out_step[k_out] == n:
                w = out_w[k_out]
                for k in range(m):
                    Z[k_out, k] = (1.0 - w) * zprev[k] + w * z[k]
                k_out += 1
    Y = Z @ G.T
    d0 = np.zeros(n_q)
    d1 = np.zeros(n_q)
    for j in range(n_out):
        n = out_step[j]
        w = out_w[j]
        _direct_at(n, Dp, Dd, ue, ui, dt, d0)
        _direct_at(n + 1, Dp, Dd, ue, ui, dt, d1)
        for q in range(n_q):
            out[q, j] = Y[j, q] + (1.0 - w) * d0[q] + w * d1[q]


@njit(parallel=True, cache=True)
def modal_batch(kd, ko, cap_u, p, theta, dt, s, ue, ui, out_step, out_w, H, Dp, Dd, t0):
    """Run every candidate through its modal recursion (see module docstring).

    Shapes: kd, cap_u, t0 (c, m); ko (c, m); p (c, m, 2); H (c, q, m); Dp, Dd (c, q, 2);
    s (n_steps, 2). Returns out (c, q, k) and the final unknown temperatures (c, m).
    """
    nc = kd.shape[0]
    out = np.full((nc, H.shape[1], out_step.shape[0]), np.nan)
    tend = np.zeros(kd.shape)
    for c in prange(nc):
        tend[c] = _modal_one(kd[c], ko[c], cap_u[c], p[c], theta, dt, s, ue, ui, out_step, out_w, H[c], Dp[c],
                             Dd[c], out[c], t0[c])
    return out, tend
