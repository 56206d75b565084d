"""Numba kernels of the finite-volume engine. They see only arrays and scalars.

The theta scheme on the unknown nodes ``T`` (Dirichlet faces are known) reads

    (Cap/dt + K_theta) T^{n+1} = (Cap/dt - K_{1-theta}) T^n + p1 u^{n+1} + p0 u^n

where ``K_theta = sum_l theta_l K_l`` sums the link conductance matrices
weighted by each link's theta (1/2 for Crank-Nicolson, 1 for fully implicit,
and 1 for links that touch a zero-capacity node or are too stiff for the time
step, see :mod:`wallcal.engines.fd`), and ``u = (u_e, u_i)`` are the two
boundary inputs. Every link flux is evaluated identically for the two nodes it
joins, so the scheme conserves energy exactly; :func:`run_batch` reports the
balance.

Boundary codes: 0 surface temperature (Dirichlet), 1 air temperature with a
surface coefficient (Robin), 2 heat flux density (positive towards the interior).
Conductivity codes per link: 0 constant, 1 exponential ``exp(f (T - T_ref))``,
2 table (piecewise linear, normalised to 1 at the reference temperature).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

DIRICHLET = 0
ROBIN = 1
FLUX = 2


@njit(cache=True)
def _link_factor(kind, coef, tref, tab_start, tab_len, tab_T, tab_v, temp):
    if kind == 0:
        return 1.0
    if kind == 1:
        return np.exp(coef * (temp - tref))
    # table, constant beyond its ends
    s = tab_start
    n = tab_len
    if temp <= tab_T[s]:
        return tab_v[s]
    if temp >= tab_T[s + n - 1]:
        return tab_v[s + n - 1]
    for k in range(s, s + n - 1):
        if temp <= tab_T[k + 1]:
            w = (temp - tab_T[k]) / (tab_T[k + 1] - tab_T[k])
            return tab_v[k] * (1.0 - w) + tab_v[k + 1] * w
    return tab_v[s + n - 1]


@njit(cache=True)
def _assemble(cap, g, theta, bc_type, bc_h, bc_theta, dt, j0, m, Ad, Aoff, Bd, Boff, p):
    """Fill the tridiagonal A and B and the input coefficients p[0:4] = (pe1, pe0, pi1, pi0)."""
    n_links = g.shape[0]
    for i in range(m):
        Ad[i] = cap[j0 + i] / dt
        Bd[i] = Ad[i]
        Aoff[i] = 0.0
        Boff[i] = 0.0
    for k in range(4):
        p[k] = 0.0
    for lnk in range(n_links):
        th = theta[lnk]
        gl = g[lnk]
        ia = lnk - j0
        ib = lnk + 1 - j0
        if 0 <= ia < m:
            Ad[ia] += th * gl
            Bd[ia] -= (1.0 - th) * gl
        if 0 <= ib < m:
            Ad[ib] += th * gl
            Bd[ib] -= (1.0 - th) * gl
        if 0 <= ia < m and 0 <= ib < m:
            Aoff[ia] = -th * gl
            Boff[ia] = (1.0 - th) * gl
        if ia < 0 and ib < m:  # link from the known exterior node into unknown 0
            p[0] = th * gl
            p[1] = (1.0 - th) * gl
        if ib >= m and ia >= 0:  # link from the last unknown to the known interior node
            p[2] = th * gl
            p[3] = (1.0 - th) * gl
    # exterior face
    if bc_type[0] == 1:
        th = bc_theta[0]
        Ad[0] += th * bc_h[0]
        Bd[0] -= (1.0 - th) * bc_h[0]
        p[0] = th * bc_h[0]
        p[1] = (1.0 - th) * bc_h[0]
    elif bc_type[0] == 2:
        p[0] = bc_theta[0]
        p[1] = 1.0 - bc_theta[0]
    # interior face
    if bc_type[1] == 1:
        th = bc_theta[1]
        Ad[m - 1] += th * bc_h[1]
        Bd[m - 1] -= (1.0 - th) * bc_h[1]
        p[2] = th * bc_h[1]
        p[3] = (1.0 - th) * bc_h[1]
    elif bc_type[1] == 2:  # q_i positive towards the interior leaves the wall
        p[2] = -bc_theta[1]
        p[3] = -(1.0 - bc_theta[1])


@njit(cache=True)
def _factor(Ad, Aoff, m, cp, inv):
    """LU of the symmetric tridiagonal A (Thomas): stores c' and 1/pivot."""
    inv[0] = 1.0 / Ad[0]
    for i in range(1, m):
        cp[i - 1] = Aoff[i - 1] * inv[i - 1]
        inv[i] = 1.0 / (Ad[i] - Aoff[i - 1] * cp[i - 1])


@njit(cache=True)
def _solve(Aoff, cp, inv, rhs, x, m):
    x[0] = rhs[0] * inv[0]
    for i in range(1, m):
        x[i] = (rhs[i] - Aoff[i - 1] * x[i - 1]) * inv[i]
    for i in range(m - 2, -1, -1):
        x[i] -= cp[i] * x[i + 1]


@njit(cache=True)
def _update_conductances(g, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, Tfull):
    """Link conductance = mean of lambda(T) over the temperatures of its two nodes.

    That is the Kirchhoff-transform conductance (U(T_a) - U(T_b)) / (T_a - T_b) / dx with
    U = integral of lambda dT, which makes the discrete steady state exact at the nodes:
    in closed form for the exponential law, by Simpson's rule for a table.
    """
    for lnk in range(g.shape[0]):
        k = kind[lnk]
        if k == 0:
            continue
        ta = Tfull[lnk]
        tb = Tfull[lnk + 1]
        if k == 1:
            f = coef[lnk]
            d = f * (ta - tb)
            if abs(d) > 1e-4:
                fac = (np.exp(f * (ta - tref[lnk])) - np.exp(f * (tb - tref[lnk]))) / d
            else:
                fac = np.exp(f * (0.5 * (ta + tb) - tref[lnk])) * (1.0 + d * d / 24.0)
        else:
            fa = _link_factor(k, coef[lnk], tref[lnk], tab_start[lnk], tab_len[lnk], tab_T, tab_v, ta)
            fb = _link_factor(k, coef[lnk], tref[lnk], tab_start[lnk], tab_len[lnk], tab_T, tab_v, tb)
            fm = _link_factor(k, coef[lnk], tref[lnk], tab_start[lnk], tab_len[lnk], tab_T, tab_v,
                              0.5 * (ta + tb))
            fac = (fa + 4.0 * fm + fb) / 6.0
        g[lnk] = g_ref[lnk] * fac


@njit(cache=True)
def _steady(cap, g, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, nonlinear,
            bc_type, bc_h, ue0, ui0, j0, m, Tfull):
    """Steady state for the first boundary values (Picard iterations when lambda(T))."""
    n_nodes = Tfull.shape[0]
    ones = np.ones(g.shape[0])
    one2 = np.ones(2)
    zc = np.zeros(n_nodes)
    Ad = np.zeros(max(m, 1))
    Aoff = np.zeros(max(m, 1))
    Bd = np.zeros(max(m, 1))
    Boff = np.zeros(max(m, 1))
    cp = np.zeros(max(m, 1))
    inv = np.zeros(max(m, 1))
    rhs = np.zeros(max(m, 1))
    x = np.zeros(max(m, 1))
    p = np.zeros(4)
    # first guess: uniform at the mean of the temperature-like inputs
    guess = 0.5 * (ue0 + ui0)
    if bc_type[0] == 2:
        guess = ui0
    if bc_type[1] == 2:
        guess = ue0
    for j in range(n_nodes):
        Tfull[j] = guess
    if bc_type[0] == 0:
        Tfull[0] = ue0
    if bc_type[1] == 0:
        Tfull[n_nodes - 1] = ui0
    n_iter = 60 if nonlinear else 1
    for _ in range(n_iter):
        if nonlinear:
            _update_conductances(g, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, Tfull)
        if m == 0:
            break
        _assemble(zc, g, ones, bc_type, bc_h, one2, 1.0, j0, m, Ad, Aoff, Bd, Boff, p)
        for i in range(m):
            rhs[i] = 0.0
        rhs[0] += p[0] * ue0
        rhs[m - 1] += p[2] * ui0
        _factor(Ad, Aoff, m, cp, inv)
        _solve(Aoff, cp, inv, rhs, x, m)
        change = 0.0
        for i in range(m):
            change = max(change, abs(x[i] - Tfull[j0 + i]))
            Tfull[j0 + i] = x[i]
        if change < 1e-12:
            break


@njit(cache=True)
def _probes(Tfull, pa, pb, pw, dst):
    for k in range(pa.shape[0]):
        dst[k] = (1.0 - pw[k]) * Tfull[pa[k]] + pw[k] * Tfull[pb[k]]


@njit(cache=True)
def _face_flux(F, j, n_steps, u, is_flux_bc):
    """Instantaneous face flux at grid time j from the step-average fluxes F[j] = F^{j+1/2} (ring of 4).

    q^j = (F^{j-1/2} + F^{j+1/2}) / 2, one-sided at the ends: the energy-consistent face flux of
    the scheme (the surface half-node balance averaged over the two steps around t_j). A
    heat-flux boundary reports its imposed value.
    """
    if is_flux_bc:
        return u[j]
    if j == 0:
        return F[0]
    if j >= n_steps:
        return F[(n_steps - 1) % 4]
    return 0.5 * (F[(j - 1) % 4] + F[j % 4])


@njit(cache=True)
def _run_one(cap, g_ref, theta, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, nonlinear,
             bc_type, bc_h, bc_theta, ue, ui, dt, out_step, out_w, pa, pb, pw, out, energy, Tinit):
    n_nodes = cap.shape[0]
    n_steps = ue.shape[0] - 1
    j0 = 1 if bc_type[0] == 0 else 0
    j1 = n_nodes - 2 if bc_type[1] == 0 else n_nodes - 1
    m = j1 - j0 + 1
    mm = max(m, 1)
    g = g_ref.copy()
    Ad = np.zeros(mm)
    Aoff = np.zeros(mm)
    Bd = np.zeros(mm)
    Boff = np.zeros(mm)
    cp = np.zeros(mm)
    inv = np.zeros(mm)
    rhs = np.zeros(mm)
    x = np.zeros(mm)
    p = np.zeros(4)
    T = np.zeros(n_nodes)
    Tprev = np.zeros(n_nodes)
    Tlin = np.zeros(n_nodes)

    if Tinit.shape[0] == n_nodes:
        for j in range(n_nodes):
            T[j] = Tinit[j]
        if bc_type[0] == 0:
            T[0] = ue[0]
        if bc_type[1] == 0:
            T[n_nodes - 1] = ui[0]
    else:
        _steady(cap, g, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, nonlinear,
                bc_type, bc_h, ue[0], ui[0], j0, m, T)
    for j in range(n_nodes):
        Tprev[j] = T[j]
    e_start = 0.0
    for j in range(n_nodes):
        e_start += cap[j] * T[j]

    if nonlinear:
        _update_conductances(g, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, T)
    if m > 0:
        _assemble(cap, g, theta, bc_type, bc_h, bc_theta, dt, j0, m, Ad, Aoff, Bd, Boff, p)
        _factor(Ad, Aoff, m, cp, inv)

    e_in = 0.0
    e_out = 0.0
    n_out = out_step.shape[0]
    n_pr = pa.shape[0]
    # rings of the last four grid times: probe values P[j % 4] and step fluxes F[j % 4] = F^{j+1/2}
    P = np.zeros((4, n_pr))
    Fe = np.zeros(4)
    Fi = np.zeros(4)
    flux_e = bc_type[0] == 2
    flux_i = bc_type[1] == 2
    _probes(T, pa, pb, pw, P[0])
    k_out = 0
    while k_out < n_out and out_step[k_out] < 0:
        k_out += 1
    for n in range(n_steps):
        if nonlinear and m > 0:
            # conductances at the extrapolated mid-step temperature (second order for CN)
            for j in range(n_nodes):
                Tlin[j] = 1.5 * T[j] - 0.5 * Tprev[j] if n > 0 else T[j]
            _update_conductances(g, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, Tlin)
            _assemble(cap, g, theta, bc_type, bc_h, bc_theta, dt, j0, m, Ad, Aoff, Bd, Boff, p)
            _factor(Ad, Aoff, m, cp, inv)
        for j in range(n_nodes):
            Tprev[j] = T[j]
        if m > 0:
            for i in range(m):
                v = Bd[i] * T[j0 + i]
                if i > 0:
                    v += Boff[i - 1] * T[j0 + i - 1]
                if i < m - 1:
                    v += Boff[i] * T[j0 + i + 1]
                rhs[i] = v
            rhs[0] += p[0] * ue[n + 1] + p[1] * ue[n]
            rhs[m - 1] += p[2] * ui[n + 1] + p[3] * ui[n]
            _solve(Aoff, cp, inv, rhs, x, m)
            for i in range(m):
                T[j0 + i] = x[i]
        if bc_type[0] == 0:
            T[0] = ue[n + 1]
        if bc_type[1] == 0:
            T[n_nodes - 1] = ui[n + 1]
        # step-average face fluxes F^{n+1/2} (the scheme's own, so energy is conserved exactly)
        if bc_type[0] == 0:
            th = theta[0]
            fe = g[0] * (th * (T[0] - T[1]) + (1.0 - th) * (Tprev[0] - Tprev[1])) + cap[0] * (T[0] - Tprev[0]) / dt
        elif bc_type[0] == 1:
            th = bc_theta[0]
            fe = bc_h[0] * (th * (ue[n + 1] - T[0]) + (1.0 - th) * (ue[n] - Tprev[0]))
        else:
            fe = bc_theta[0] * ue[n + 1] + (1.0 - bc_theta[0]) * ue[n]
        if bc_type[1] == 0:
            lk = n_nodes - 2
            th = theta[lk]
            fi = g[lk] * (th * (T[lk] - T[lk + 1]) + (1.0 - th) * (Tprev[lk] - Tprev[lk + 1]))
            fi -= cap[n_nodes - 1] * (T[n_nodes - 1] - Tprev[n_nodes - 1]) / dt
        elif bc_type[1] == 1:
            th = bc_theta[1]
            fi = bc_h[1] * (th * (T[n_nodes - 1] - ui[n + 1]) + (1.0 - th) * (Tprev[n_nodes - 1] - ui[n]))
        else:
            fi = bc_theta[1] * ui[n + 1] + (1.0 - bc_theta[1]) * ui[n]
        e_in += dt * fe
        e_out += dt * fi
        Fe[n % 4] = fe
        Fi[n % 4] = fi
        _probes(T, pa, pb, pw, P[(n + 1) % 4])
        # outputs between grid nk and nk + 1 are complete once F^{nk+3/2} is known (nk = n - 1)
        while k_out < n_out and out_step[k_out] <= n - 1:
            nk = out_step[k_out]
            w = out_w[k_out]
            for q in range(n_pr):
                out[q, k_out] = (1.0 - w) * P[nk % 4, q] + w * P[(nk + 1) % 4, q]
            out[n_pr, k_out] = ((1.0 - w) * _face_flux(Fe, nk, n_steps, ue, flux_e)
                                + w * _face_flux(Fe, nk + 1, n_steps, ue, flux_e))
            out[n_pr + 1, k_out] = ((1.0 - w) * _face_flux(Fi, nk, n_steps, ui, flux_i)
                                    + w * _face_flux(Fi, nk + 1, n_steps, ui, flux_i))
            k_out += 1
    while k_out < n_out:  # outputs in the last step
        nk = out_step[k_out]
        w = out_w[k_out]
        for q in range(n_pr):
            out[q, k_out] = (1.0 - w) * P[nk % 4, q] + w * P[(nk + 1) % 4, q]
        out[n_pr, k_out] = ((1.0 - w) * _face_flux(Fe, nk, n_steps, ue, flux_e)
                            + w * _face_flux(Fe, nk + 1, n_steps, ue, flux_e))
        out[n_pr + 1, k_out] = ((1.0 - w) * _face_flux(Fi, nk, n_steps, ui, flux_i)
                                + w * _face_flux(Fi, nk + 1, n_steps, ui, flux_i))
        k_out += 1
    e_end = 0.0
    for j in range(n_nodes):
        e_end += cap[j] * T[j]
    energy[0] = e_end - e_start
    energy[1] = e_in
    energy[2] = e_out
    # final state is returned through Tinit's companion in run_batch
    return T


@njit(parallel=True, cache=True)
def run_batch(cap, g_ref, theta, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, nonlinear,
              bc_type, bc_h, bc_theta, ue, ui, dt, out_step, out_w, pa, pb, pw, Tinit):
    """Run every candidate wall of a batch.

    Parameters (c = candidate, j = node, l = link, k = output time, p = probe)
    ----------
    cap : (c, j) node heat capacities [J/(m2K)]
    g_ref : (c, l) link conductances at the reference temperature [W/(m2K)]
    theta : (c, l) theta of each link [-]
    kind, coef, tref, tab_start, tab_len : (c, l) conductivity law per link
    tab_T, tab_v : concatenated normalised lambda(T) tables
    nonlinear : bool
    bc_type : (2,) boundary codes; bc_h : (c, 2) surface coefficients [W/(m2K)];
    bc_theta : (c, 2) theta of the boundary terms
    ue, ui : (n_steps + 1,) boundary inputs [degC or W/m2]
    dt : time step [s]
    out_step, out_w : (k,) output time = grid (out_step + out_w); out_step -1 never used
    pa, pb, pw : (c, p) probe interpolation
    Tinit : (c, j) initial node temperatures, or shape (c, 0) for the steady start

    Returns
    -------
    out : (c, p + 2, k) probe temperatures [degC], then exterior and interior face flux [W/m2]
    energy : (c, 3) stored-energy change, energy in at the exterior, energy out at the interior [J/m2]
    Tend : (c, j) final node temperatures [degC]
    """
    nc = cap.shape[0]
    n_q = pa.shape[1] + 2
    out = np.full((nc, n_q, out_step.shape[0]), np.nan)
    energy = np.zeros((nc, 3))
    Tend = np.zeros(cap.shape)
    for c in prange(nc):
        Tend[c] = _run_one(cap[c], g_ref[c], theta[c], kind[c], coef[c], tref[c], tab_start[c], tab_len[c],
                           tab_T, tab_v, nonlinear, bc_type, bc_h[c], bc_theta[c], ue, ui, dt,
                           out_step, out_w, pa[c], pb[c], pw[c], out[c], energy[c], Tinit[c])
    return out, energy, Tend
