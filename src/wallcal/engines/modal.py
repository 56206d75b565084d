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
def _modal_one(kd, ko, cap_u, p, theta, dt, s, ue, ui, out_step, out_w, H, Dp, Dd, smooth, out, t0):
    """One candidate.

    kd, ko : diagonal and off-diagonal of K over the m unknowns
    cap_u : capacities of the unknowns
    p : (m, 2) input coupling of K
    s : (n_steps, 2) theta-weighted inputs per step
    H : (n_q, m) output rows over unknown node temperatures
    Dp : (n_q, 2) direct coefficients of u^n in the outputs
    Dd : (n_q, 2) coefficients of the central difference (u^{n+1} - u^{n-1}) / (2 dt)
    smooth : (n_q,) bool, rows that are face fluxes averaged over the two steps around each time
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
    _recur(mu, r0, r1, z, s, ue, ui, dt, theta, out_step, out_w, G, Dp, Dd, smooth, out)
    # final unknown temperatures
    tend = np.zeros(m)
    for i in range(m):
        acc = 0.0
        for k in range(m):
            acc += V[i, k] * z[k]
        tend[i] = acc
    return tend


@njit(cache=True, inline="always")
def _smooth_index(j, n_steps, theta):
    """Weights (w_prev, w_here, w_next) of the energy-consistent face flux at grid time j.

    q^j = (F^{j-1/2} + F^{j+1/2}) / 2 with F^{n+1/2} = theta L^{n+1} + (1 - theta) L^n (one-sided
    at the ends), so q^j = w_prev L^{j-1} + w_here L^j + w_next L^{j+1} for any quantity L linear in
    the state.
    """
    if j == 0:
        return 0.0, 1.0 - theta, theta
    if j >= n_steps:
        return 1.0 - theta, theta, 0.0
    return 0.5 * (1.0 - theta), 0.5, 0.5 * theta


@njit(cache=True, fastmath=True, inline="always")
def _finalize(k, nk, w, ring, n_steps, theta, ue, ui, dt, G, Dp, Dd, smooth, zp, zf, out):
    """Output k (between grid nk and nk + 1) from the ring of modal states.

    Probe rows use the state interpolated in time; face-flux rows use the energy-consistent
    two-step average of the state (and of the inputs).
    """
    m = ring.shape[1]
    n_q = Dp.shape[0]
    r0 = nk % 4
    r1 = (nk + 1) % 4
    for k2 in range(m):
        zp[k2] = (1.0 - w) * ring[r0, k2] + w * ring[r1, k2]
        zf[k2] = 0.0
    for q in range(n_q):
        out[q, k] = 0.0
    for jj in range(2):
        j = nk + jj
        wt = (1.0 - w) if jj == 0 else w
        if wt == 0.0:
            continue
        a, b, c = _smooth_index(j, n_steps, theta)
        jm = max(j - 1, 0)
        jp = min(j + 1, n_steps)
        ra = jm % 4
        rb = j % 4
        rc = jp % 4
        wa = wt * a
        wb = wt * b
        wc = wt * c
        for k2 in range(m):
            zf[k2] += wa * ring[ra, k2] + wb * ring[rb, k2] + wc * ring[rc, k2]
        ue_s = a * ue[jm] + b * ue[j] + c * ue[jp]
        ui_s = a * ui[jm] + b * ui[j] + c * ui[jp]
        inv = 1.0 / ((jp - jm) * dt)
        de = (ue[jp] - ue[jm]) * inv
        di = (ui[jp] - ui[jm]) * inv
        for q in range(n_q):
            if smooth[q]:
                out[q, k] += wt * (Dp[q, 0] * ue_s + Dp[q, 1] * ui_s + Dd[q, 0] * de + Dd[q, 1] * di)
            else:
                out[q, k] += wt * (Dp[q, 0] * ue[j] + Dp[q, 1] * ui[j])
    for q in range(n_q):
        acc = 0.0
        if smooth[q]:
            for k2 in range(m):
                acc += G[q, k2] * zf[k2]
        else:
            for k2 in range(m):
                acc += G[q, k2] * zp[k2]
        out[q, k] += acc


@njit(cache=True, fastmath=True)
def _recur(mu, r0, r1, z, s, ue, ui, dt, theta, out_step, out_w, G, Dp, Dd, smooth, out):
    """The modal recursion over all steps; outputs formed only at the requested times.

    The state is advanced in a plain 1-D array (it vectorises: the modes are independent);
    near output times it is copied into a ring of the last four states, from which each
    output is formed at once. Memory does not depend on the number of steps.
    """
    m = z.shape[0]
    n_steps = s.shape[0]
    n_out = out_step.shape[0]
    ring = np.zeros((4, m))
    zp = np.zeros(m)
    zf = np.zeros(m)
    for k in range(m):
        ring[0, k] = z[k]
    k_out = 0
    zc = z.copy()
    for n in range(n_steps):
        s0 = s[n, 0]
        s1 = s[n, 1]
        for k in range(m):
            zc[k] = mu[k] * zc[k] + r0[k] * s0 + r1[k] * s1
        if k_out < n_out and n + 2 >= out_step[k_out]:
            b = (n + 1) % 4
            for k in range(m):
                ring[b, k] = zc[k]
            # an output between grid nk and nk + 1 is complete once the state at nk + 2 is known
            while k_out < n_out and out_step[k_out] <= n - 1:
                _finalize(k_out, out_step[k_out], out_w[k_out], ring, n_steps, theta, ue, ui, dt, G, Dp, Dd,
                          smooth, zp, zf, out)
                k_out += 1
    while k_out < n_out:
        _finalize(k_out, out_step[k_out], out_w[k_out], ring, n_steps, theta, ue, ui, dt, G, Dp, Dd, smooth,
                  zp, zf, out)
        k_out += 1
    for k in range(m):
        z[k] = zc[k]


@njit(parallel=True, cache=True)
def modal_batch(kd, ko, cap_u, p, theta, dt, s, ue, ui, out_step, out_w, H, Dp, Dd, smooth, t0):
    """Run every candidate through its modal recursion (see module docstring).

    Shapes: kd, cap_u, t0 (c, m); ko (c, m); p (c, m, 2); H (c, q, m); Dp, Dd (c, q, 2);
    s (n_steps, 2). Returns out (c, q, k) and the final unknown temperatures (c, m).
    """
    nc = kd.shape[0]
    out = np.full((nc, H.shape[1], out_step.shape[0]), np.nan)
    tend = np.zeros(kd.shape)
    for c in prange(nc):
        tend[c] = _modal_one(kd[c], ko[c], cap_u[c], p[c], theta, dt, s, ue, ui, out_step, out_w, H[c], Dp[c],
                             Dd[c], smooth, out[c], t0[c])
    return out, tend
