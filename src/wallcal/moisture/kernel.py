"""The numba kernel of the heat-and-moisture engine: implicit finite volumes, Newton, adaptive step.

Unknowns per cell: temperature ``T`` [degC] and the moisture potential ``u = ln(pc)`` (see
:mod:`wallcal.moisture.materials`). Backward Euler in time; each step is solved by Newton's method on the
block-tridiagonal system (2x2 blocks). The Jacobian is analytic: each cell's properties and their
derivatives once per iteration (:func:`cell_props`), the face fluxes by the chain rule
(:func:`face_flux`); only the liquid flux across an interface between two materials and the two
boundary faces are differentiated by one-sided differences.

Balances per cell (per m2 of wall, ``dx`` the cell width)::

    dx (w - w_old) / dt + G_e - G_w = 0                       moisture, G [kg/(m2 s)] towards +x
    dx (E - E_old) / dt + Q_e - Q_w = 0                       energy,  E = (rho c_dry + c_w w) T

with ``Q = -lambda dT/dx + h_v(T) g_v + c_w T g_l``: conduction plus the enthalpy the vapour and liquid
fluxes carry (``h_v = 2.501e6 + 1870 T`` J/kg, so a vapour flux that condenses releases its latent heat).
Both balances are conservative: what the boundaries let in over a run equals the stored change to the
Newton tolerance, and the kernel returns the integrated boundary fluxes so that the caller can check it.

Boundary array ``bc[side, k, col]`` at times ``tb[k]`` (linear in time, averaged over each step),
``side`` 0 the exterior face (x = 0), 1 the interior face; ``kind[side]`` 0 imposes the surface state
(``col 0`` T [degC], ``col 1`` u), 1 couples to air (``col 0`` air T, ``col 1`` air vapour pressure [Pa],
``col 2`` heat transfer coefficient [W/(m2 K)], ``col 3`` vapour transfer coefficient [s/m], ``col 4`` liquid
water supply (rain) [kg/(m2 s)], ``col 5`` further heat flux into the face [W/m2], e.g. absorbed solar minus
long-wave loss). The rain the surface cannot take up (the flux that would bring the face to saturation,
``pc = 1 Pa``) runs off and is returned.
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import inner, kernel
from .materials import C_WATER, DU, KELVIN, N_TABLE, T_REF, U_MIN

H_V0 = 2.501e6  # J/kg, latent heat at 0 degC
C_VAP = 1870.0  # J/(kg K)
HALF = 0.5

NB_COLS = 6
DAMP_U = 2.0  # largest Newton update of ln pc (a larger one took more iterations in the rain year)


@inner()
def segment(u):
    """Index ``i`` of the table segment holding ``u`` and the fraction ``f`` along it (the end segments
    extended)."""
    s = (u - U_MIN) / DU
    i = int(math.floor(s))
    if i < 0:
        i = 0
    elif i > N_TABLE - 2:
        i = N_TABLE - 2
    return i, s - i


@inner()
def interp(tab, m, u):
    """Table value and slope at ``u`` (linear; extrapolated with the end segments)."""
    i, f = segment(u)
    a = tab[m, i]
    b = tab[m, i + 1]
    return a + (b - a) * f, (b - a) / DU


@inner()
def psat(t):
    if t >= 0.0:
        return 610.5 * math.exp(17.269 * t / (237.3 + t))
    return 610.5 * math.exp(21.875 * t / (265.5 + t))


@inner()
def vapour_pressure(t, u):
    return math.exp(-math.exp(u) / KELVIN) * psat(t)


@inner()
def node_props(t, u, m, tw, td, thermal):
    """``(w, lambda, delta_p, p_v)`` of a cell."""
    w, _ = interp(tw, m, u)
    lam = thermal[m, 0] + thermal[m, 1] * w + thermal[m, 3] * t
    d, _ = interp(td, m, u)
    d = d * T_REF / (t + 273.15)
    return w, lam, d, vapour_pressure(t, u)


@inner()
def dln_psat_dt(t):
    if t >= 0.0:
        return 17.269 * 237.3 / ((237.3 + t) * (237.3 + t))
    return 21.875 * 265.5 / ((265.5 + t) * (265.5 + t))


@inner()
def cell_props(t, u, lam_dry, lam_w, lam_t, w_a, w_b, d_a, d_b, k_a, k_b, f):
    """A cell's properties and their derivatives from its table segment's end values (``*_a``, ``*_b``,
    fraction ``f``): ``(w, dw/du, lambda, dlambda/du, dlambda/dT, delta_p, ddelta/dT, ddelta/du, p_v, dp_v/dT,
    dp_v/du, Phi, dPhi/du)``. Scalars only: an array passed to a compiled function costs two atomic
    reference count operations a call, which were most of the kernel's time."""
    w = w_a + (w_b - w_a) * f
    dw = (w_b - w_a) / DU
    tk_ = t + 273.15
    d = (d_a + (d_b - d_a) * f) * T_REF / tk_
    dd = (d_b - d_a) / DU * T_REF / tk_
    pc = math.exp(u)
    pv = math.exp(-pc / KELVIN) * psat(t)
    return (
        w,
        dw,
        lam_dry + lam_w * w + lam_t * t,
        lam_w * dw,
        lam_t,
        d,
        -d / tk_,
        dd,
        pv,
        pv * dln_psat_dt(t),
        -pv * pc / KELVIN,
        k_a + (k_b - k_a) * f,
        (k_b - k_a) / DU,
    )


@inner()
def face_flux(
    ti,
    lam_i,
    lam_ti,
    lam_ui,
    d_i,
    d_ti,
    d_ui,
    pv_i,
    pv_ti,
    pv_ui,
    dxi,
    tj,
    lam_j,
    lam_tj,
    lam_uj,
    d_j,
    d_tj,
    d_uj,
    pv_j,
    pv_tj,
    pv_uj,
    dxj,
    gl,
    gl_ui,
    gl_uj,
):
    """Flux ``(G, Q)`` between two cells from their properties (:func:`cell_props`: lambda, delta_p and p_v
    with their derivatives in T and u) and the liquid flux ``gl`` with its derivatives in ``ui``, ``uj``;
    then the derivatives of G and of Q in ``Ti, ui, Tj, uj``."""
    a = HALF * dxi
    b = HALF * dxj
    # conduction
    rh = a / lam_i + b / lam_j
    q = (ti - tj) / rh
    ci = q / rh * a / (lam_i * lam_i)
    cj = q / rh * b / (lam_j * lam_j)
    q_ti = 1.0 / rh + ci * lam_ti
    q_tj = -1.0 / rh + cj * lam_tj
    q_ui = ci * lam_ui
    q_uj = cj * lam_uj
    # vapour
    gv = 0.0
    gv_ti = 0.0
    gv_ui = 0.0
    gv_tj = 0.0
    gv_uj = 0.0
    if d_i > 0.0 and d_j > 0.0:
        rv = a / d_i + b / d_j
        gv = (pv_i - pv_j) / rv
        ci = gv / rv * a / (d_i * d_i)
        cj = gv / rv * b / (d_j * d_j)
        gv_ti = pv_ti / rv + ci * d_ti
        gv_ui = pv_ui / rv + ci * d_ui
        gv_tj = -pv_tj / rv + cj * d_tj
        gv_uj = -pv_uj / rv + cj * d_uj
    tf = HALF * (ti + tj)
    hv = H_V0 + C_VAP * tf
    hl = C_WATER * tf
    carried = HALF * C_VAP * gv + HALF * C_WATER * gl
    return (
        gv + gl,
        q + gv * hv + gl * hl,
        gv_ti,
        gv_ui + gl_ui,
        gv_tj,
        gv_uj + gl_uj,
        q_ti + gv_ti * hv + carried,
        q_ui + gv_ui * hv + gl_ui * hl,
        q_tj + gv_tj * hv + carried,
        q_uj + gv_uj * hv + gl_uj * hl,
    )


@inner()
def liquid_interface(ui, mi, dxi, uj, mj, dxj, tk):
    """Liquid flux from cell i (material mi) to cell j (material mj): each half cell's secant conductance
    ``dPhi/dpc`` between the two suctions, in series."""
    pci = math.exp(ui)
    pcj = math.exp(uj)
    ai, si = interp(tk, mi, ui)
    bj, sj = interp(tk, mj, uj)
    if abs(uj - ui) > 1e-6:
        aj, _ = interp(tk, mi, uj)
        bi, _ = interp(tk, mj, ui)
        ka = (aj - ai) / (pcj - pci)
        kb = (bj - bi) / (pcj - pci)
    else:
        ka = si / pci
        kb = sj / pcj
    if ka > 0.0 and kb > 0.0:
        return (pcj - pci) / (HALF * dxi / ka + HALF * dxj / kb)
    return 0.0


@inner()
def boundary_flux(kind, b, t, u, m, dx, tw, tk, td, thermal):
    """Moisture and energy flux into the wall through one face, and the rain that runs off."""
    w, lam, d, pv = node_props(t, u, m, tw, td, thermal)
    half = HALF * dx
    if kind == 0:
        ts = b[0]
        us = b[1]
        q = lam / half * (ts - t)
        gv = d / half * (vapour_pressure(ts, us) - pv)
        phi_n, _ = interp(tk, m, u)
        phi_s, _ = interp(tk, m, us)
        gl = (phi_n - phi_s) / half
        tf = HALF * (ts + t)
        return gv + gl, q + gv * (H_V0 + C_VAP * tf) + gl * C_WATER * tf, 0.0
    ta = b[0]
    q = 0.0
    if b[2] > 0.0:
        q = (ta - t) / (1.0 / b[2] + half / lam)
    gv = 0.0
    if b[3] > 0.0 and d > 0.0:
        gv = (b[1] - pv) / (1.0 / b[3] + half / d)
    gl = 0.0
    runoff = 0.0
    if b[4] > 0.0:
        phi_n, _ = interp(tk, m, u)
        phi_sat, _ = interp(tk, m, U_MIN)
        gmax = (phi_n - phi_sat) / half
        if gmax < 0.0:
            gmax = 0.0
        gl = min(b[4], gmax)
        runoff = b[4] - gl
    return gv + gl, q + b[5] + gv * (H_V0 + C_VAP * t) + gl * C_WATER * ta, runoff


@inner()
def bc_integral(bc, cum, tb, side, c, time):
    """Integral of boundary column ``c`` from ``tb[0]`` to ``time`` (linear between samples, held beyond)."""
    n = tb.shape[0]
    if n == 1 or time <= tb[0]:
        return (time - tb[0]) * bc[side, 0, c]
    if time >= tb[n - 1]:
        return cum[side, n - 1, c] + (time - tb[n - 1]) * bc[side, n - 1, c]
    lo = 0
    hi = n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if tb[mid] <= time:
            lo = mid
        else:
            hi = mid
    h = time - tb[lo]
    f = h / (tb[hi] - tb[lo])
    v = bc[side, lo, c] * (1.0 - f) + bc[side, hi, c] * f
    return cum[side, lo, c] + 0.5 * h * (bc[side, lo, c] + v)


@inner()
def bc_mean(bc, cum, tb, side, t0, t1, out):
    """The boundary data averaged over the step ``[t0, t1]`` (so that a supplied flux such as rain is
    integrated exactly, whatever the steps)."""
    for c in range(NB_COLS):
        out[c] = (bc_integral(bc, cum, tb, side, c, t1) - bc_integral(bc, cum, tb, side, c, t0)) / (t1 - t0)


@inner()
def storage(t, u, m, tw, thermal):
    """Moisture ``w`` [kg/m3] and energy ``E`` [J/m3] of a cell, with dw/du."""
    w, dw = interp(tw, m, u)
    return w, (thermal[m, 2] + C_WATER * w) * t, dw


@inner()
def solve_block(lo, di, up, r, n, x, dp, rp):
    """Block-tridiagonal (2x2) solve: lo[i] couples row i to i-1, up[i] to i+1. Returns False if singular."""
    for i in range(n):
        a = di[i, 0, 0]
        b = di[i, 0, 1]
        c = di[i, 1, 0]
        d = di[i, 1, 1]
        r0 = r[i, 0]
        r1 = r[i, 1]
        if i > 0:
            # m = lo[i] inv(dp[i-1])
            e = dp[i - 1, 0, 0]
            f = dp[i - 1, 0, 1]
            g = dp[i - 1, 1, 0]
            h = dp[i - 1, 1, 1]
            det = e * h - f * g
            if det == 0.0 or not math.isfinite(det):
                return False
            i00 = h / det
            i01 = -f / det
            i10 = -g / det
            i11 = e / det
            l00 = lo[i, 0, 0]
            l01 = lo[i, 0, 1]
            l10 = lo[i, 1, 0]
            l11 = lo[i, 1, 1]
            m00 = l00 * i00 + l01 * i10
            m01 = l00 * i01 + l01 * i11
            m10 = l10 * i00 + l11 * i10
            m11 = l10 * i01 + l11 * i11
            u00 = up[i - 1, 0, 0]
            u01 = up[i - 1, 0, 1]
            u10 = up[i - 1, 1, 0]
            u11 = up[i - 1, 1, 1]
            a -= m00 * u00 + m01 * u10
            b -= m00 * u01 + m01 * u11
            c -= m10 * u00 + m11 * u10
            d -= m10 * u01 + m11 * u11
            r0 -= m00 * rp[i - 1, 0] + m01 * rp[i - 1, 1]
            r1 -= m10 * rp[i - 1, 0] + m11 * rp[i - 1, 1]
        dp[i, 0, 0] = a
        dp[i, 0, 1] = b
        dp[i, 1, 0] = c
        dp[i, 1, 1] = d
        rp[i, 0] = r0
        rp[i, 1] = r1
    for i in range(n - 1, -1, -1):
        r0 = rp[i, 0]
        r1 = rp[i, 1]
        if i < n - 1:
            r0 -= up[i, 0, 0] * x[i + 1, 0] + up[i, 0, 1] * x[i + 1, 1]
            r1 -= up[i, 1, 0] * x[i + 1, 0] + up[i, 1, 1] * x[i + 1, 1]
        a = dp[i, 0, 0]
        b = dp[i, 0, 1]
        c = dp[i, 1, 0]
        d = dp[i, 1, 1]
        det = a * d - b * c
        if det == 0.0 or not math.isfinite(det):
            return False
        x[i, 0] = (d * r0 - b * r1) / det
        x[i, 1] = (a * r1 - c * r0) / det
    return True


@kernel
def run_ham(
    tw, tk, td, thermal, mat, dx, kind, tb, bc, t0, u0, t_out, dt_first, dt_max, tol_t, tol_u, max_iter, dt_min
):
    """Integrate from time 0 to ``t_out[-1]``; states at each ``t_out``.

    Returns ``(T_out, u_out, flux_out, stats, status)``: ``flux_out[k, side, 0:3]`` the moisture [kg/m2]
    and energy [J/m2] let in through each face and the rain run off [kg/m2] from time 0 to ``t_out[k]``,
    ``flux_out[k, side, 3:5]`` the moisture [kg/(m2 s)] and energy [W/m2] flux into the wall through the face
    over the step that ended at ``t_out[k]`` (nan at time 0);
    ``stats`` = steps, Newton iterations, rejected steps, then how many steps took 0, 1, ... 32 (or more)
    iterations; ``status`` 0 when done, 1 when the step fell
    below ``dt_min`` (the time reached is the last ``t_out`` filled).
    """
    n = dx.shape[0]
    n_out = t_out.shape[0]
    t_res = np.empty((n_out, n))
    u_res = np.empty((n_out, n))
    flux_out = np.full((n_out, 2, 5), np.nan)
    stats = np.zeros(3 + 33, dtype=np.int64)
    tc = t0.copy()
    uc = u0.copy()
    tn = np.empty(n)
    rate_t = np.zeros(n)
    rate_u = np.zeros(n)
    prev_step = 0.0
    un = np.empty(n)
    w_old = np.empty(n)
    e_old = np.empty(n)
    for i in range(n):
        w, e, _ = storage(tc[i], uc[i], mat[i], tw, thermal)
        w_old[i] = w
        e_old[i] = e
    lo = np.zeros((n, 2, 2))
    di = np.zeros((n, 2, 2))
    up = np.zeros((n, 2, 2))
    res = np.zeros((n, 2))
    x = np.zeros((n, 2))
    dp = np.zeros((n, 2, 2))
    rp = np.zeros((n, 2))
    props = np.empty((n, 13))
    cum_bc = np.zeros(bc.shape)
    for side in range(2):
        for kb in range(1, tb.shape[0]):
            for c in range(NB_COLS):
                cum_bc[side, kb, c] = cum_bc[side, kb - 1, c] + 0.5 * (tb[kb] - tb[kb - 1]) * (
                    bc[side, kb - 1, c] + bc[side, kb, c]
                )
    b_l = np.empty(NB_COLS)
    b_r = np.empty(NB_COLS)
    cum = np.zeros((2, 5))
    time = 0.0
    k = 0
    while k < n_out and t_out[k] <= 0.0:
        t_res[k, :] = tc
        u_res[k, :] = uc
        flux_out[k, :, 0:3] = 0.0
        k += 1
    dt = dt_first
    ht = 1e-6
    hu = 1e-7
    while k < n_out:
        step = min(dt, t_out[k] - time)
        last = step >= t_out[k] - time
        tnew = time + step
        bc_mean(bc, cum_bc, tb, 0, time, tnew, b_l)
        bc_mean(bc, cum_bc, tb, 1, time, tnew, b_r)
        # initial guess: the last step's rate of change carried on over at most twice its length (the last
        # state after a rejection)
        ratio = min(step / prev_step, 2.0) if prev_step > 0.0 else 0.0
        for i in range(n):
            tn[i] = tc[i] + ratio * rate_t[i]
            un[i] = uc[i] + ratio * rate_u[i]
        converged = False
        it = 0
        while it < max_iter:
            it += 1
            for i in range(n):
                m = mat[i]
                ks, fr = segment(un[i])
                p = cell_props(
                    tn[i],
                    un[i],
                    thermal[m, 0],
                    thermal[m, 1],
                    thermal[m, 3],
                    tw[m, ks],
                    tw[m, ks + 1],
                    td[m, ks],
                    td[m, ks + 1],
                    tk[m, ks],
                    tk[m, ks + 1],
                    fr,
                )
                for q in range(13):
                    props[i, q] = p[q]
                w = p[0]
                dw = p[1]
                rc = thermal[m, 2] + C_WATER * w
                c = dx[i] / step
                res[i, 0] = c * (w - w_old[i])
                res[i, 1] = c * (rc * tn[i] - e_old[i])
                for r in range(2):
                    for q in range(2):
                        lo[i, r, q] = 0.0
                        up[i, r, q] = 0.0
                di[i, 0, 0] = 0.0
                di[i, 0, 1] = c * dw
                di[i, 1, 0] = c * rc
                di[i, 1, 1] = c * C_WATER * tn[i] * dw
            # interior faces
            for f in range(1, n):
                i = f - 1
                j = f
                if mat[i] == mat[j]:
                    dist = HALF * (dx[i] + dx[j])
                    gl = (props[j, 11] - props[i, 11]) / dist
                    gl_ui = -props[i, 12] / dist
                    gl_uj = props[j, 12] / dist
                else:
                    gl = liquid_interface(un[i], mat[i], dx[i], un[j], mat[j], dx[j], tk)
                    gl_ui = (liquid_interface(un[i] + hu, mat[i], dx[i], un[j], mat[j], dx[j], tk) - gl) / hu
                    gl_uj = (liquid_interface(un[i], mat[i], dx[i], un[j] + hu, mat[j], dx[j], tk) - gl) / hu
                g0, q0, a00, a01, b00, b01, a10, a11, b10, b11 = face_flux(
                    tn[i],
                    props[i, 2],
                    props[i, 4],
                    props[i, 3],
                    props[i, 5],
                    props[i, 6],
                    props[i, 7],
                    props[i, 8],
                    props[i, 9],
                    props[i, 10],
                    dx[i],
                    tn[j],
                    props[j, 2],
                    props[j, 4],
                    props[j, 3],
                    props[j, 5],
                    props[j, 6],
                    props[j, 7],
                    props[j, 8],
                    props[j, 9],
                    props[j, 10],
                    dx[j],
                    gl,
                    gl_ui,
                    gl_uj,
                )
                res[i, 0] += g0
                res[i, 1] += q0
                res[j, 0] -= g0
                res[j, 1] -= q0
                di[i, 0, 0] += a00
                di[i, 0, 1] += a01
                di[i, 1, 0] += a10
                di[i, 1, 1] += a11
                up[i, 0, 0] += b00
                up[i, 0, 1] += b01
                up[i, 1, 0] += b10
                up[i, 1, 1] += b11
                lo[j, 0, 0] -= a00
                lo[j, 0, 1] -= a01
                lo[j, 1, 0] -= a10
                lo[j, 1, 1] -= a11
                di[j, 0, 0] -= b00
                di[j, 0, 1] -= b01
                di[j, 1, 0] -= b10
                di[j, 1, 1] -= b11
            # boundaries: the residual loses what flows in
            for side in range(2):
                i = 0 if side == 0 else n - 1
                b = b_l if side == 0 else b_r
                g0, q0, _ = boundary_flux(kind[side], b, tn[i], un[i], mat[i], dx[i], tw, tk, td, thermal)
                g1, q1, _ = boundary_flux(kind[side], b, tn[i] + ht, un[i], mat[i], dx[i], tw, tk, td, thermal)
                g2, q2, _ = boundary_flux(kind[side], b, tn[i], un[i] + hu, mat[i], dx[i], tw, tk, td, thermal)
                res[i, 0] -= g0
                res[i, 1] -= q0
                di[i, 0, 0] -= (g1 - g0) / ht
                di[i, 0, 1] -= (g2 - g0) / hu
                di[i, 1, 0] -= (q1 - q0) / ht
                di[i, 1, 1] -= (q2 - q0) / hu
            for i in range(n):
                res[i, 0] = -res[i, 0]
                res[i, 1] = -res[i, 1]
            if not solve_block(lo, di, up, res, n, x, dp, rp):
                break
            big_t = 0.0
            big_u = 0.0
            finite = True
            for i in range(n):
                if not (math.isfinite(x[i, 0]) and math.isfinite(x[i, 1])):
                    finite = False
                    break
                big_t = max(big_t, abs(x[i, 0]))
                big_u = max(big_u, abs(x[i, 1]))
            if not finite:
                break
            damp = 1.0
            if big_t > 10.0:
                damp = 10.0 / big_t
            if big_u * damp > DAMP_U:
                damp = DAMP_U / big_u
            for i in range(n):
                tn[i] += damp * x[i, 0]
                un[i] += damp * x[i, 1]
            if damp == 1.0 and big_t < tol_t and big_u < tol_u:
                converged = True
                break
        stats[1] += it
        if converged:
            stats[3 + min(it, 32)] += 1
        if not converged:
            stats[2] += 1
            prev_step = 0.0
            dt = step / 4.0
            if dt < dt_min:
                return t_res, u_res, flux_out, stats, 1
            continue
        # accept: integrate the boundary fluxes at the new state
        for side in range(2):
            i = 0 if side == 0 else n - 1
            b = b_l if side == 0 else b_r
            g0, q0, ro = boundary_flux(kind[side], b, tn[i], un[i], mat[i], dx[i], tw, tk, td, thermal)
            cum[side, 0] += g0 * step
            cum[side, 1] += q0 * step
            cum[side, 2] += ro * step
            cum[side, 3] = g0
            cum[side, 4] = q0
        big_t = 0.0
        big_u = 0.0
        big_w = 0.0
        for i in range(n):
            big_t = max(big_t, abs(tn[i] - tc[i]))
            big_u = max(big_u, abs(un[i] - uc[i]))
            rate_t[i] = tn[i] - tc[i]
            rate_u[i] = un[i] - uc[i]
            tc[i] = tn[i]
            uc[i] = un[i]
            w, e, _ = storage(tc[i], uc[i], mat[i], tw, thermal)
            big_w = max(big_w, abs(w - w_old[i]) / tw[mat[i], 0])
            w_old[i] = w
            e_old[i] = e
        time = tnew
        prev_step = step
        stats[0] += 1
        if last:
            time = t_out[k]
            t_res[k, :] = tc
            u_res[k, :] = uc
            flux_out[k, :, :] = cum
            k += 1
        # next step: by the change of this one (targets 2 K, 2 % of the capillary saturation's water content
        # and 1 in ln pc) and the Newton effort
        grow = 2.0
        if big_t > 0.0:
            grow = min(grow, 2.0 / big_t)
        if big_w > 0.0:
            grow = min(grow, 0.02 / big_w)
        if big_u > 0.0:
            grow = min(grow, 1.0 / big_u)
        if it > 5:
            grow = min(grow, 0.7)
        grow = max(grow, 0.5)
        if not last or step >= dt:
            dt = min(step * grow, dt_max)
    return t_res, u_res, flux_out, stats, 0
