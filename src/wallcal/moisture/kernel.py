"""The numba kernel of the heat-and-moisture engine: implicit finite volumes, Newton, adaptive step.

Unknowns per cell: temperature ``T`` [degC] and the moisture potential ``u = ln(pc)`` (see
:mod:`wallcal.moisture.materials`). Backward Euler in time; each step is solved by Newton's method on the
block-tridiagonal system (2x2 blocks). The Jacobian is analytic: each cell's properties and their
derivatives once per iteration (:func:`cell_props`), the face fluxes by the chain rule
(:func:`face_flux`; :func:`contact_flux` at a contact between two materials); only the two boundary faces
are differentiated by one-sided differences.

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
from numba import njit

from ..jit import FLAGS, inner, kernel
from .materials import C_WATER, DU, KELVIN, N_TABLE, T_REF, U_GRID, U_MAX, U_MIN

#: the decorator of the functions the Newton loop calls (scalar arguments: as calls with array arguments or
#: views, each cost two atomic reference count operations, most of the run time before), inlined into the loop
#: by numba: the study wall's year 0.243-0.249 s CPU against 0.26 s with only `cell_props` and `face_flux`
#: inlined, for a first compile of 22 s instead of 12 s once per install (bench/ham.py; docs/moisture.md, "Speed")
hot = njit(**FLAGS, inline="always", no_cpython_wrapper=True)

H_V0 = 2.501e6  # J/kg, latent heat at 0 degC
C_VAP = 1870.0  # J/(kg K)
HALF = 0.5

NB_COLS = 6
INV_DU = 1.0 / DU
INV_KELVIN = 1.0 / KELVIN
DPHI_STEP = 0.05  # a step's target change of RH where it is a smaller measure than the change of ln pc
DAMP_U = 2.0  # largest Newton update of ln pc (a larger one took more iterations in the rain year)


@hot
def segment(u):
    """Index ``i`` of the table segment holding ``u`` and the fraction ``f`` along it (the end segments
    extended)."""
    s = (u - U_MIN) * INV_DU
    i = int(math.floor(s))
    if i < 0:
        i = 0
    elif i > N_TABLE - 2:
        i = N_TABLE - 2
    return i, s - i


@hot
def interp(tab, m, u):
    """Table value and slope at ``u`` (linear; extrapolated with the end segments)."""
    i, f = segment(u)
    a = tab[m, i]
    b = tab[m, i + 1]
    return a + (b - a) * f, (b - a) * INV_DU


@inner()
def psat_formula(t, ice):
    """Saturation vapour pressure [Pa] at ``t`` [degC] and its slope [Pa/K] (EN ISO 13788), over ice or
    over water."""
    if ice:
        r = 1.0 / (265.5 + t)
        p = 610.5 * math.exp(21.875 * t * r)
        return p, p * 21.875 * 265.5 * r * r
    r = 1.0 / (237.3 + t)
    p = 610.5 * math.exp(17.269 * t * r)
    return p, p * 17.269 * 237.3 * r * r


@inner()
def psat_exact(t):
    """:func:`psat_formula` over ice below 0 degC."""
    return psat_formula(t, t < 0.0)


@inner()
def kelvin_exact(u):
    """Relative humidity ``phi = exp(-pc / KELVIN)`` at ``u = ln pc`` and its slope dphi/du."""
    x = math.exp(u) * INV_KELVIN
    phi = math.exp(-x)
    return phi, -phi * x


# Tables of the two closed forms that every cell evaluates each Newton iteration (their exp calls were
# about an eighth of the run time): cubic Hermite interpolation from the values and slopes at the nodes, so
# the interpolant and its slope are continuous (no kink for Newton) and within 1e-11 (relative) of the
# closed forms (tests/test_moisture_ham.py); outside the tables the closed forms. Each segment holds its
# cubic's coefficients in the fraction f along it, ``y = c0 + f (c1 + f (c2 + f c3))``.
T_LO = -80.0  # degC
T_HI = 120.0
DT_TAB = 0.05  # K (a node at 0 degC, where the formula changes)
N_T = int(round((T_HI - T_LO) / DT_TAB)) + 1
INV_DT_TAB = 1.0 / DT_TAB


@hot
def hermite_coefficients(ya, yb, sa, sb, h, out, k):
    """Row ``k`` of ``out``: the cubic in the fraction f of a segment of width ``h`` with end values ``ya``,
    ``yb`` and end slopes ``sa``, ``sb``."""
    out[k, 0] = ya
    out[k, 1] = h * sa
    out[k, 2] = 3.0 * (yb - ya) - h * (2.0 * sa + sb)
    out[k, 3] = 2.0 * (ya - yb) + h * (sa + sb)


def _tables(u_grid):
    """The Hermite coefficients of phi(ln pc) on ``u_grid`` and of p_sat(T) on ``T_LO..T_HI``, from the compiled
    functions' own Python code (about 8,000 calls, milliseconds): importing this module compiles nothing."""
    y, s = np.vectorize(kelvin_exact.py_func, otypes=[float, float])(u_grid)
    phi = np.empty((u_grid.shape[0] - 1, 4))
    hermite_coefficients.py_func(y[:-1], y[1:], s[:-1], s[1:], DU, phi, slice(None))
    ps = np.empty((N_T - 1, 4))
    zero = int(round(-T_LO / DT_TAB))
    nodes = T_LO + DT_TAB * np.arange(N_T)
    nodes[zero] = 0.0
    psat_of = np.vectorize(psat_formula.py_func, otypes=[float, float])
    yi, si = psat_of(nodes[: zero + 1], True)  # each segment the formula of its side of 0 degC
    yw, sw = psat_of(nodes[zero:], False)
    hermite_coefficients.py_func(yi[:-1], yi[1:], si[:-1], si[1:], DT_TAB, ps, slice(0, zero))
    hermite_coefficients.py_func(yw[:-1], yw[1:], sw[:-1], sw[1:], DT_TAB, ps, slice(zero, None))
    return phi, ps


PHI_TAB, PSAT_TAB = _tables(U_GRID)


@hot
def cubic(c, k, f, inv_h):
    """Value and slope of segment ``k`` of table ``c`` at fraction ``f`` (segment width ``1 / inv_h``)."""
    c1 = c[k, 1]
    c2 = c[k, 2]
    c3 = c[k, 3]
    return c[k, 0] + f * (c1 + f * (c2 + f * c3)), (c1 + f * (2.0 * c2 + 3.0 * f * c3)) * inv_h


@hot
def psat_slope(t):
    """Saturation vapour pressure [Pa] at ``t`` [degC] and its slope [Pa/K], from the table."""
    if not (T_LO <= t < T_HI):
        return psat_exact(t)
    s = (t - T_LO) * INV_DT_TAB
    k = min(int(s), N_T - 2)
    return cubic(PSAT_TAB, k, s - k, INV_DT_TAB)


@hot
def kelvin(u):
    """Relative humidity at ``u = ln pc`` and its slope dphi/du, from the table."""
    if not (U_MIN <= u <= U_MAX):
        return kelvin_exact(u)
    i, f = segment(u)
    return cubic(PHI_TAB, i, f, INV_DU)


@hot
def psat(t):
    return psat_slope(t)[0]


@hot
def vapour_pressure(t, u):
    return kelvin(u)[0] * psat(t)


@hot
def node_props(t, u, m, tw, td, thermal):
    """``(w, lambda, delta_p, p_v)`` of a cell."""
    w, _ = interp(tw, m, u)
    lam = thermal[m, 0] + thermal[m, 1] * w + thermal[m, 3] * t
    d, _ = interp(td, m, u)
    d = d * T_REF / (t + 273.15)
    return w, lam, d, vapour_pressure(t, u)


@hot
def cell_props(t, u, half, lam_dry, lam_w, lam_t, w_a, w_b, d_a, d_b, k_a, k_b, f):
    """A cell's properties and their derivatives from its table segment's end values (``*_a``, ``*_b``,
    fraction ``f``) and its half width ``half`` [m]: ``(w, dw/du, dlambda/du, dlambda/dT, half/lambda,
    half/lambda^2, delta_p, ddelta/dT, ddelta/du, half/delta_p, half/delta_p^2, p_v, dp_v/dT, dp_v/du, Phi,
    dPhi/du)`` (the half-cell resistances as :func:`face_flux` takes them; 0 for a vapour-tight cell).
    Scalars only: an array passed to a compiled function costs two atomic reference count operations a
    call, which were most of the kernel's time; and one division per quantity, reused by both faces."""
    w = w_a + (w_b - w_a) * f
    dw = (w_b - w_a) * INV_DU
    inv_lam = 1.0 / (lam_dry + lam_w * w + lam_t * t)
    r_lam = half * inv_lam
    inv_tk = 1.0 / (t + 273.15)
    scale = T_REF * inv_tk
    d = (d_a + (d_b - d_a) * f) * scale
    r_d = 0.0
    g_d = 0.0
    if d > 0.0:
        inv_d = 1.0 / d
        r_d = half * inv_d
        g_d = r_d * inv_d
    phi, phi_u = kelvin(u)
    ps, ps_t = psat_slope(t)
    return (
        w,
        dw,
        lam_w * dw,
        lam_t,
        r_lam,
        r_lam * inv_lam,
        d,
        -d * inv_tk,
        (d_b - d_a) * INV_DU * scale,
        r_d,
        g_d,
        phi * ps,
        phi * ps_t,
        phi_u * ps,
        k_a + (k_b - k_a) * f,
        (k_b - k_a) * INV_DU,
    )


@hot
def face_flux(
    ti, lam_ui, lam_ti, rl_i, gl_i, d_ti, d_ui, rd_i, gd_i, pv_i, pv_ti, pv_ui,
    tj, lam_uj, lam_tj, rl_j, gl_j, d_tj, d_uj, rd_j, gd_j, pv_j, pv_tj, pv_uj,
    gl, gl_ui, gl_uj,
):  # fmt: skip
    """Flux ``(G, Q)`` between two cells from their properties (:func:`cell_props`: the half-cell thermal
    resistance ``rl = a / lambda`` and ``gl = a / lambda^2`` with ``a`` the half width, the derivatives of
    lambda, the same ``rd``, ``gd`` of delta_p, its derivatives, p_v and its derivatives in T and u; ``rd``
    0 for a vapour-tight cell) and the liquid flux ``gl`` with its derivatives in ``ui``, ``uj``; then the
    derivatives of G and of Q in ``Ti, ui, Tj, uj``."""
    # conduction
    inv_rh = 1.0 / (rl_i + rl_j)
    q = (ti - tj) * inv_rh
    qr = q * inv_rh
    ci = qr * gl_i
    cj = qr * gl_j
    q_ti = inv_rh + ci * lam_ti
    q_tj = -inv_rh + cj * lam_tj
    q_ui = ci * lam_ui
    q_uj = cj * lam_uj
    # vapour
    gv = 0.0
    gv_ti = 0.0
    gv_ui = 0.0
    gv_tj = 0.0
    gv_uj = 0.0
    if rd_i > 0.0 and rd_j > 0.0:
        inv_rv = 1.0 / (rd_i + rd_j)
        gv = (pv_i - pv_j) * inv_rv
        gr = gv * inv_rv
        ci = gr * gd_i
        cj = gr * gd_j
        gv_ti = pv_ti * inv_rv + ci * d_ti
        gv_ui = pv_ui * inv_rv + ci * d_ui
        gv_tj = -pv_tj * inv_rv + cj * d_tj
        gv_uj = -pv_uj * inv_rv + cj * d_uj
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
def contact_partials(
    tf_x, bi_x, bj_x, pvi_x, pvj_x, phi_x, phj_x, q_x,
    bi, bj, ci, cj, dpi, dpj, pvf_t, pvf_u, g_uf, fu, gvm, g, hv, hl, wi, wj, vi, vj,
):  # fmt: skip
    """The derivatives of a contact's ``G`` and ``Q`` (:func:`contact_flux`) in one of the two cells' states
    ``x``, from the derivatives in ``x`` at a fixed contact suction: of ``T_f``, of the two vapour
    conductances ``b``, of the two cells' ``p_v`` and ``Phi`` and of the conduction; ``dpi = p_v,i - p_v,f``,
    ``dpj = p_v,f - p_v,j``; ``G = wi G_i + wj G_j``, ``g_uf`` its derivative in ``u_f``, the vapour part
    of the enthalpy ``vi g_v,i + vj g_v,j``. The contact state follows by the implicit function theorem."""
    pvf_x = pvf_t * tf_x
    gvi = bi_x * dpi + bi * (pvi_x - pvf_x)
    gvj = bj_x * dpj + bj * (pvf_x - pvj_x)
    f_x = gvi - ci * phi_x - gvj - cj * phj_x
    uf_x = -f_x / fu if fu > 0.0 else 0.0
    g_x = wi * (gvi - ci * phi_x) + wj * (gvj + cj * phj_x) + g_uf * uf_x
    gvm_x = vi * gvi + vj * gvj + (vj * bj - vi * bi) * pvf_u * uf_x
    q = q_x + gvm_x * (hv - hl) + g_x * hl + (gvm * (C_VAP - C_WATER) + g * C_WATER) * tf_x
    return g_x, q


@hot
def half_cell_vapour(rd, gd, d_t, d_u):
    """A half cell's vapour conductance ``1 / rd`` and its derivatives in T and u (``gd`` the derivative of
    ``rd`` in the permeability, ``d_t``, ``d_u`` the permeability's in T and u); 0 for a vapour-tight half cell
    (``rd`` 0)."""
    if rd > 0.0:
        b = 1.0 / rd
        return b, gd * d_t * b * b, gd * d_u * b * b
    return 0.0, 0.0, 0.0


@inner()
def contact_flux(
    ti, ui, lam_ui, lam_ti, rl_i, gl_i, d_ti, d_ui, rd_i, gd_i, pv_i, pv_ti, pv_ui, ph_i, ph_ui, a_i, mi,
    tj, uj, lam_uj, lam_tj, rl_j, gl_j, d_tj, d_uj, rd_j, gd_j, pv_j, pv_tj, pv_uj, ph_j, ph_uj, a_j, mj,
    tk, uf,
):  # fmt: skip
    """Flux ``(G, Q)`` from cell i to cell j through a contact between two materials, its derivatives in ``Ti,
    ui, Tj, uj`` (as :func:`face_flux`), and the contact's suction ``u_f``.

    The contact has one state: its temperature ``T_f`` from the two half cells' thermal resistances in series,
    and its suction ``u_f`` from the continuity of the total moisture flux, ``G_i(u_f) = G_j(u_f)`` with
    ``G_i = (p_v,i - p_v(T_f, u_f)) / rd_i + (Phi_i(u_f) - Phi_i(u_i)) / a_i`` (vapour and liquid through the
    half cell of width ``a_i``, ``Phi_i`` the Kirchhoff potential of material i) and
    ``G_j = (p_v(T_f, u_f) - p_v,j) / rd_j + (Phi_j(u_j) - Phi_j(u_f)) / a_j``: vapour on one side may go on as
    liquid on the other. ``G_i - G_j`` rises with ``u_f``; it is solved by Newton's method inside a bracket
    (bisection when a step leaves it) from ``uf`` (the last value; nan for none). A vapour-tight half cell
    (``rd`` 0) carries no vapour. The energy flux is conduction plus the mean of the enthalpy the two sides
    carry (vapour ``h_v``, liquid ``c_w T_f``), so the latent heat of what condenses or evaporates at the
    contact goes half to each cell and the energy balance stays conservative (at an end of the table, the
    enthalpy on the side the flux was taken from)."""
    # conduction and the contact temperature
    inv_rh = 1.0 / (rl_i + rl_j)
    q = (ti - tj) * inv_rh
    qr = q * inv_rh
    q_ti = inv_rh + qr * gl_i * lam_ti
    q_tj = -inv_rh + qr * gl_j * lam_tj
    q_ui = qr * gl_i * lam_ui
    q_uj = qr * gl_j * lam_uj
    tf = ti - q * rl_i
    ps, ps_t = psat_slope(tf)
    # vapour conductances 1 / rd and liquid ones 1 / a
    bi, bi_ti, bi_ui = half_cell_vapour(rd_i, gd_i, d_ti, d_ui)
    bj, bj_tj, bj_uj = half_cell_vapour(rd_j, gd_j, d_tj, d_uj)
    ci = 1.0 / a_i
    cj = 1.0 / a_j
    # the contact suction: F(u_f) = G_i - G_j = 0, F rising. If F has no root inside the table (water
    # condenses at a contact already at capillary saturation faster than the two sides take it away, or the
    # reverse at the dry end), u_f stays at that end and the flux is the median of G_i, G_j and 0: what one
    # side brings and the other cannot take stays in the cell it came from
    end = False
    lo = U_MIN
    hi = U_MAX
    lo_seen = False
    hi_seen = False
    if not (lo < uf < hi):
        uf = min(max(HALF * (ui + uj), lo), hi)
    phi = 0.0
    phi_u = 0.0
    fi = 0.0
    fi_u = 0.0
    fj = 0.0
    fj_u = 0.0
    f = 0.0
    fu = 0.0
    for _ in range(60):
        phi, phi_u = kelvin(uf)
        fi, fi_u = interp(tk, mi, uf)
        fj, fj_u = interp(tk, mj, uf)
        pvf = phi * ps
        f = bi * (pv_i - pvf) + ci * (fi - ph_i) - bj * (pvf - pv_j) - cj * (ph_j - fj)
        fu = -(bi + bj) * phi_u * ps + ci * fi_u + cj * fj_u
        if f == 0.0:
            break
        if (f > 0.0 and uf <= U_MIN) or (f < 0.0 and uf >= U_MAX):
            end = True
            break
        if f > 0.0:
            hi = uf
            hi_seen = True
        else:
            lo = uf
            lo_seen = True
        nxt = uf - f / fu if fu > 0.0 else np.nan
        if not (lo < nxt < hi):
            if nxt <= lo and not lo_seen:
                nxt = lo
            elif nxt >= hi and not hi_seen:
                nxt = hi
            else:
                nxt = HALF * (lo + hi)
        if abs(nxt - uf) < 1e-6:  # the flux takes the last correction linearly: an error of order 1e-12
            break
        uf = nxt
    pvf = phi * ps
    pvf_t = phi * ps_t
    pvf_u = phi_u * ps
    dpi = pv_i - pvf
    dpj = pvf - pv_j
    gi = bi * dpi + ci * (fi - ph_i)
    gj = bj * dpj + cj * (ph_j - fj)
    gi_uf = -bi * pvf_u + ci * fi_u
    gj_uf = bj * pvf_u - cj * fj_u
    # G from one side (G_i = G_j at the root): the side less sensitive to u_f (a side that carries nothing
    # gives exactly 0), with the last Newton correction of u_f applied linearly
    corr = 0.0
    wi = 1.0
    wj = 0.0
    g_uf = gi_uf
    if abs(gj_uf) < abs(gi_uf):
        wi = 0.0
        wj = 1.0
        g_uf = gj_uf
    vi = HALF
    vj = HALF
    if end:
        fu = 0.0
        wi = 0.0
        wj = 0.0
        if gi * gj > 0.0:
            if abs(gi) < abs(gj):
                wi = 1.0
            else:
                wj = 1.0
        # the enthalpy of the flux as it is on the side it was taken from (none when it is 0)
        vi = wi
        vj = wj
    elif fu > 0.0:
        corr = -f / fu
    g = wi * gi + wj * gj + g_uf * corr
    gvm = vi * (bi * dpi - bi * pvf_u * corr) + vj * (bj * dpj + bj * pvf_u * corr)
    hv = H_V0 + C_VAP * tf
    hl = C_WATER * tf
    qt = q + gvm * (hv - hl) + g * hl
    # derivatives: T_f = T_i - q rl_i, rl = a / lambda
    tf_ti = 1.0 - q_ti * rl_i + q * gl_i * lam_ti
    tf_ui = -q_ui * rl_i + q * gl_i * lam_ui
    tf_tj = -q_tj * rl_i
    tf_uj = -q_uj * rl_i
    g_ti, q_ti = contact_partials(
        tf_ti, bi_ti, 0.0, pv_ti, 0.0, 0.0, 0.0, q_ti,
        bi, bj, ci, cj, dpi, dpj, pvf_t, pvf_u, g_uf, fu, gvm, g, hv, hl, wi, wj, vi, vj,
    )  # fmt: skip
    g_ui, q_ui = contact_partials(
        tf_ui, bi_ui, 0.0, pv_ui, 0.0, ph_ui, 0.0, q_ui,
        bi, bj, ci, cj, dpi, dpj, pvf_t, pvf_u, g_uf, fu, gvm, g, hv, hl, wi, wj, vi, vj,
    )  # fmt: skip
    g_tj, q_tj = contact_partials(
        tf_tj, 0.0, bj_tj, 0.0, pv_tj, 0.0, 0.0, q_tj,
        bi, bj, ci, cj, dpi, dpj, pvf_t, pvf_u, g_uf, fu, gvm, g, hv, hl, wi, wj, vi, vj,
    )  # fmt: skip
    g_uj, q_uj = contact_partials(
        tf_uj, 0.0, bj_uj, 0.0, pv_uj, 0.0, ph_uj, q_uj,
        bi, bj, ci, cj, dpi, dpj, pvf_t, pvf_u, g_uf, fu, gvm, g, hv, hl, wi, wj, vi, vj,
    )  # fmt: skip
    return g, qt, g_ti, g_ui, g_tj, g_uj, q_ti, q_ui, q_tj, q_uj, uf


@hot
def boundary_flux(kind, bs, side, t, u, m, dx, tw, tk, td, thermal):
    """Moisture and energy flux into the wall through one face, and the rain that runs off (``bs[side]`` the
    face's boundary data over the step)."""
    w, lam, d, pv = node_props(t, u, m, tw, td, thermal)
    half = HALF * dx
    if kind == 0:
        ts = bs[side, 0]
        us = bs[side, 1]
        q = lam / half * (ts - t)
        gv = d / half * (vapour_pressure(ts, us) - pv)
        phi_n, _ = interp(tk, m, u)
        phi_s, _ = interp(tk, m, us)
        gl = (phi_n - phi_s) / half
        tf = HALF * (ts + t)
        return gv + gl, q + gv * (H_V0 + C_VAP * tf) + gl * C_WATER * tf, 0.0
    ta = bs[side, 0]
    q = 0.0
    if bs[side, 2] > 0.0:
        q = (ta - t) / (1.0 / bs[side, 2] + half / lam)
    gv = 0.0
    if bs[side, 3] > 0.0 and d > 0.0:
        gv = (bs[side, 1] - pv) / (1.0 / bs[side, 3] + half / d)
    gl = 0.0
    runoff = 0.0
    if bs[side, 4] > 0.0:
        phi_n, _ = interp(tk, m, u)
        phi_sat, _ = interp(tk, m, U_MIN)
        gmax = (phi_n - phi_sat) / half
        if gmax < 0.0:
            gmax = 0.0
        gl = min(bs[side, 4], gmax)
        runoff = bs[side, 4] - gl
    return gv + gl, q + bs[side, 5] + gv * (H_V0 + C_VAP * t) + gl * C_WATER * ta, runoff


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
def bc_mean(bc, cum, tb, t0, t1, out):
    """The boundary data averaged over the step ``[t0, t1]``, ``out[side]`` (so that a supplied flux such as
    rain is integrated exactly, whatever the steps)."""
    for side in range(2):
        for c in range(NB_COLS):
            out[side, c] = (bc_integral(bc, cum, tb, side, c, t1) - bc_integral(bc, cum, tb, side, c, t0)) / (t1 - t0)


@inner()
def storage(t, u, m, tw, thermal):
    """Moisture ``w`` [kg/m3] and energy ``E`` [J/m3] of a cell, with dw/du."""
    w, dw = interp(tw, m, u)
    return w, (thermal[m, 2] + C_WATER * w) * t, dw


@hot
def inverse(a, b, c, d):
    """The inverse of the 2x2 matrix ``[[a, b], [c, d]]`` (nan entries when singular)."""
    det = a * d - b * c
    if det == 0.0:
        return np.nan, np.nan, np.nan, np.nan
    inv = 1.0 / det
    return d * inv, -b * inv, -c * inv, a * inv


@hot
def eliminate(dn, ln, un, xinv, y0, y1, r0, r1):
    """One block row of an elimination sweep: ``D - L inv(X) U`` and ``r - L inv(X) y`` (``dn``, ``ln``, ``un``
    the row's diagonal block, the block coupling it to the eliminated row and that row's block back; ``xinv``
    the eliminated row's inverse pivot, ``y`` its right-hand side), each block a tuple ``(00, 01, 10, 11)``."""
    m00 = ln[0] * xinv[0] + ln[1] * xinv[2]
    m01 = ln[0] * xinv[1] + ln[1] * xinv[3]
    m10 = ln[2] * xinv[0] + ln[3] * xinv[2]
    m11 = ln[2] * xinv[1] + ln[3] * xinv[3]
    a = dn[0] - (m00 * un[0] + m01 * un[2])
    b = dn[1] - (m00 * un[1] + m01 * un[3])
    c = dn[2] - (m10 * un[0] + m11 * un[2])
    d = dn[3] - (m10 * un[1] + m11 * un[3])
    return (a, b, c, d), r0 - (m00 * y0 + m01 * y1), r1 - (m10 * y0 + m11 * y1)


@hot
def solve_block(lo, di, up, r, n, x, dinv, rp):
    """Block-tridiagonal (2x2) solve: lo[i] couples row i to i-1, up[i] to i+1. A singular system gives nan
    in ``x`` (the caller checks).

    Eliminated from both ends at once towards the middle row ``k`` (two independent chains of half the
    length, which the processor overlaps: the sweep's cost is the latency of one row after another):
    ``dinv[i]`` receives the inverse pivot of row i and ``rp[i]`` its eliminated right-hand side. Each
    direction's row is written out: behind a shared row helper numba no longer overlaps the two chains (a year
    of bench/ham.py's walls takes 1.5 times as long)."""
    k = n // 2
    for s in range(k):
        # downwards, row s from row s - 1
        i = s
        if i == 0:
            p = inverse(di[0, 0, 0], di[0, 0, 1], di[0, 1, 0], di[0, 1, 1])
            y0 = r[0, 0]
            y1 = r[0, 1]
        else:
            q, y0, y1 = eliminate(
                (di[i, 0, 0], di[i, 0, 1], di[i, 1, 0], di[i, 1, 1]),
                (lo[i, 0, 0], lo[i, 0, 1], lo[i, 1, 0], lo[i, 1, 1]),
                (up[i - 1, 0, 0], up[i - 1, 0, 1], up[i - 1, 1, 0], up[i - 1, 1, 1]),
                (dinv[i - 1, 0, 0], dinv[i - 1, 0, 1], dinv[i - 1, 1, 0], dinv[i - 1, 1, 1]),
                rp[i - 1, 0],
                rp[i - 1, 1],
                r[i, 0],
                r[i, 1],
            )
            p = inverse(q[0], q[1], q[2], q[3])
        dinv[i, 0, 0], dinv[i, 0, 1], dinv[i, 1, 0], dinv[i, 1, 1] = p
        rp[i, 0] = y0
        rp[i, 1] = y1
        # upwards, row n - 1 - s from row n - s
        i = n - 1 - s
        if i > k:
            if s == 0:
                p = inverse(di[i, 0, 0], di[i, 0, 1], di[i, 1, 0], di[i, 1, 1])
                y0 = r[i, 0]
                y1 = r[i, 1]
            else:
                q, y0, y1 = eliminate(
                    (di[i, 0, 0], di[i, 0, 1], di[i, 1, 0], di[i, 1, 1]),
                    (up[i, 0, 0], up[i, 0, 1], up[i, 1, 0], up[i, 1, 1]),
                    (lo[i + 1, 0, 0], lo[i + 1, 0, 1], lo[i + 1, 1, 0], lo[i + 1, 1, 1]),
                    (dinv[i + 1, 0, 0], dinv[i + 1, 0, 1], dinv[i + 1, 1, 0], dinv[i + 1, 1, 1]),
                    rp[i + 1, 0],
                    rp[i + 1, 1],
                    r[i, 0],
                    r[i, 1],
                )
                p = inverse(q[0], q[1], q[2], q[3])
            dinv[i, 0, 0], dinv[i, 0, 1], dinv[i, 1, 0], dinv[i, 1, 1] = p
            rp[i, 0] = y0
            rp[i, 1] = y1
    # the middle row, from both sides
    a = di[k, 0, 0]
    b = di[k, 0, 1]
    c = di[k, 1, 0]
    d = di[k, 1, 1]
    y0 = r[k, 0]
    y1 = r[k, 1]
    if k > 0:
        (a, b, c, d), y0, y1 = eliminate(
            (a, b, c, d),
            (lo[k, 0, 0], lo[k, 0, 1], lo[k, 1, 0], lo[k, 1, 1]),
            (up[k - 1, 0, 0], up[k - 1, 0, 1], up[k - 1, 1, 0], up[k - 1, 1, 1]),
            (dinv[k - 1, 0, 0], dinv[k - 1, 0, 1], dinv[k - 1, 1, 0], dinv[k - 1, 1, 1]),
            rp[k - 1, 0],
            rp[k - 1, 1],
            y0,
            y1,
        )
    if k < n - 1:
        (a, b, c, d), y0, y1 = eliminate(
            (a, b, c, d),
            (up[k, 0, 0], up[k, 0, 1], up[k, 1, 0], up[k, 1, 1]),
            (lo[k + 1, 0, 0], lo[k + 1, 0, 1], lo[k + 1, 1, 0], lo[k + 1, 1, 1]),
            (dinv[k + 1, 0, 0], dinv[k + 1, 0, 1], dinv[k + 1, 1, 0], dinv[k + 1, 1, 1]),
            rp[k + 1, 0],
            rp[k + 1, 1],
            y0,
            y1,
        )
    a, b, c, d = inverse(a, b, c, d)
    x[k, 0] = a * y0 + b * y1
    x[k, 1] = c * y0 + d * y1
    # back substitution outwards from the middle row, both directions at once
    for s in range(1, max(k, n - 1 - k) + 1):
        i = k - s
        if i >= 0:
            r0 = rp[i, 0] - (up[i, 0, 0] * x[i + 1, 0] + up[i, 0, 1] * x[i + 1, 1])
            r1 = rp[i, 1] - (up[i, 1, 0] * x[i + 1, 0] + up[i, 1, 1] * x[i + 1, 1])
            x[i, 0] = dinv[i, 0, 0] * r0 + dinv[i, 0, 1] * r1
            x[i, 1] = dinv[i, 1, 0] * r0 + dinv[i, 1, 1] * r1
        i = k + s
        if i < n:
            r0 = rp[i, 0] - (lo[i, 0, 0] * x[i - 1, 0] + lo[i, 0, 1] * x[i - 1, 1])
            r1 = rp[i, 1] - (lo[i, 1, 0] * x[i - 1, 0] + lo[i, 1, 1] * x[i - 1, 1])
            x[i, 0] = dinv[i, 0, 0] * r0 + dinv[i, 0, 1] * r1
            x[i, 1] = dinv[i, 1, 0] * r0 + dinv[i, 1, 1] * r1


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
    dinv = np.zeros((n, 2, 2))
    rp = np.zeros((n, 2))
    props = np.empty((n, 16))
    inv_dist = np.zeros(n)  # 1 / the distance between the centres of cells f - 1 and f
    u_face = np.full(n, np.nan)  # the suction at each contact between materials (face f between cells f - 1, f)
    for f in range(1, n):
        inv_dist[f] = 1.0 / (HALF * (dx[f - 1] + dx[f]))
    cum_bc = np.zeros(bc.shape)
    for side in range(2):
        for kb in range(1, tb.shape[0]):
            for c in range(NB_COLS):
                cum_bc[side, kb, c] = cum_bc[side, kb - 1, c] + 0.5 * (tb[kb] - tb[kb - 1]) * (
                    bc[side, kb - 1, c] + bc[side, kb, c]
                )
    b_now = np.empty((2, NB_COLS))  # the boundary data averaged over the step, per face
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
        bc_mean(bc, cum_bc, tb, time, tnew, b_now)
        # initial guess: the last step's rate of change carried on over at most twice its length (the last
        # state after a rejection)
        ratio = min(step / prev_step, 2.0) if prev_step > 0.0 else 0.0
        for i in range(n):
            tn[i] = tc[i] + ratio * rate_t[i]
            un[i] = uc[i] + ratio * rate_u[i]
        converged = False
        it = 0
        inv_step = 1.0 / step
        while it < max_iter:
            it += 1
            for i in range(n):
                m = mat[i]
                ks, fr = segment(un[i])
                p = cell_props(
                    tn[i],
                    un[i],
                    HALF * dx[i],
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
                (
                    props[i, 0],
                    props[i, 1],
                    props[i, 2],
                    props[i, 3],
                    props[i, 4],
                    props[i, 5],
                    props[i, 6],
                    props[i, 7],
                    props[i, 8],
                    props[i, 9],
                    props[i, 10],
                    props[i, 11],
                    props[i, 12],
                    props[i, 13],
                    props[i, 14],
                    props[i, 15],
                ) = p
                w = p[0]
                dw = p[1]
                rc = thermal[m, 2] + C_WATER * w
                c = dx[i] * inv_step
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
                    gl = (props[j, 14] - props[i, 14]) * inv_dist[f]
                    gl_ui = -props[i, 15] * inv_dist[f]
                    gl_uj = props[j, 15] * inv_dist[f]
                else:  # a contact between two materials: contact_flux below
                    gl = 0.0
                    gl_ui = 0.0
                    gl_uj = 0.0
                g0, q0, a00, a01, b00, b01, a10, a11, b10, b11 = face_flux(
                    tn[i], props[i, 2], props[i, 3], props[i, 4], props[i, 5], props[i, 7], props[i, 8],
                    props[i, 9], props[i, 10], props[i, 11], props[i, 12], props[i, 13],
                    tn[j], props[j, 2], props[j, 3], props[j, 4], props[j, 5], props[j, 7], props[j, 8],
                    props[j, 9], props[j, 10], props[j, 11], props[j, 12], props[j, 13],
                    gl, gl_ui, gl_uj,
                )  # fmt: skip
                if mat[i] != mat[j]:
                    g0, q0, a00, a01, b00, b01, a10, a11, b10, b11, u_face[f] = contact_flux(
                        tn[i], un[i], props[i, 2], props[i, 3], props[i, 4], props[i, 5], props[i, 7], props[i, 8],
                        props[i, 9], props[i, 10], props[i, 11], props[i, 12], props[i, 13], props[i, 14],
                        props[i, 15], HALF * dx[i], mat[i],
                        tn[j], un[j], props[j, 2], props[j, 3], props[j, 4], props[j, 5], props[j, 7], props[j, 8],
                        props[j, 9], props[j, 10], props[j, 11], props[j, 12], props[j, 13], props[j, 14],
                        props[j, 15], HALF * dx[j], mat[j],
                        tk, u_face[f],
                    )  # fmt: skip
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
                g0 = 0.0
                q0 = 0.0
                for pert in range(3):  # the flux, then with T and with u perturbed (one call site)
                    ti = tn[i] + ht if pert == 1 else tn[i]
                    ui = un[i] + hu if pert == 2 else un[i]
                    g, q, _ = boundary_flux(kind[side], b_now, side, ti, ui, mat[i], dx[i], tw, tk, td, thermal)
                    if pert == 0:
                        g0 = g
                        q0 = q
                        res[i, 0] -= g
                        res[i, 1] -= q
                    elif pert == 1:
                        di[i, 0, 0] -= (g - g0) / ht
                        di[i, 1, 0] -= (q - q0) / ht
                    else:
                        di[i, 0, 1] -= (g - g0) / hu
                        di[i, 1, 1] -= (q - q0) / hu
            for i in range(n):
                res[i, 0] = -res[i, 0]
                res[i, 1] = -res[i, 1]
            solve_block(lo, di, up, res, n, x, dinv, rp)
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
            g0, q0, ro = boundary_flux(kind[side], b_now, side, tn[i], un[i], mat[i], dx[i], tw, tk, td, thermal)
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
            # the change of ln pc, or near saturation (RH above about 0.95) the change of RH / DPHI_STEP
            # if smaller: there ln pc swings by whole units for RH changes of 1e-6 (condensation on a
            # vapour-tight layer), which held the steps to seconds for no accuracy
            big_u = max(big_u, min(abs(un[i] - uc[i]), abs(kelvin(un[i])[0] - kelvin(uc[i])[0]) / DPHI_STEP))
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
        # and 1 in ln pc, or DPHI_STEP in RH where that is less) and the Newton effort
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
