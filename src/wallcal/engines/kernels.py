"""Numba kernels of the finite-volume engine's general path. They see only arrays and scalars.

The theta scheme on the unknown nodes ``T`` (faces with an imposed temperature are known) reads

    (Cap/dt + K_theta) T^{n+1} = (Cap/dt - K_{1-theta}) T^n + (face inputs)

where ``K_theta = sum_l theta_l K_l`` sums the link conductance matrices weighted by each link's
theta (:func:`wallcal.engines.operator.link_thetas`), assembled by
:func:`wallcal.engines.operator.assemble_operator`, with the faces' terms from
:mod:`wallcal.engines.boundary`. Every link flux is evaluated identically for the two nodes it
joins, so the scheme conserves energy exactly; :func:`run_batch` reports the balance.

The loop is written as link fluxes: ``F_l = E_l + theta_l g0_l (T^{n+1}_a - T^{n+1}_b)`` with the
explicit part ``E_l`` computed first, the right-hand side ``Cap/dt T^n + sum of E`` and one
tridiagonal solve with a matrix factorised at conductances ``g0`` (a twisted LU: two chains from
both ends, each taking two rows per multiply-add). For constant conductances the matrix is
factorised once. For lambda(T) (see :func:`_run_one`) the conductances of the step ``g*``
(Kirchhoff means at the extrapolated mid-step temperature) differ from ``g0``; the difference is
applied explicitly to the predicted ``T^{n+1}``, and the matrix is refactorised only when ``g*``
drifts from ``g0``. The exponential law's Kirchhoff mean is evaluated as ``Gm sinh(x)/x`` with
``x = f (T_a - T_b) / 2`` and one factor per link at its mean temperature,
``Gm = g_ref exp(f ((T_a + T_b)/2 - T_ref))``: equal to ``g_ref (E_a - E_b)/(f (T_a - T_b))`` but
without the division or the cancellation of ``E_a - E_b``. ``Gm`` is updated multiplicatively with
a polynomial of ``f dT_m`` (exact ``exp`` when a step changes a temperature a lot, and every 1024
steps); ``sinh(x)/x`` is a polynomial in ``x^2`` (closed form beyond ``|x| = 1/4``).

Speed notes: each pass over the links or nodes reads and writes few arrays, which keeps LLVM's
run-time aliasing checks under its limit so that the pass vectorises; the twisted solve is written
out in the step loop with unsigned indices (a call would pass array structs and spill its chains).
Probe values are formed only at the steps whose outputs need them.

Conductivity laws per link: :data:`~wallcal.grid.LAMBDA_CONSTANT`, ``LAMBDA_EXPONENTIAL``
(``exp(f (T - T_ref))``), ``LAMBDA_TABLE`` (piecewise linear, normalised to 1 at the reference
temperature).
"""

from __future__ import annotations

import numpy as np
from numba import uint64

from ..conductivity import exponential_factor_inner
from ..grid import LAMBDA_CONSTANT, LAMBDA_EXPONENTIAL, LAMBDA_TABLE
from ..jit import inner, kernel
from . import boundary, operator


@inner()
def _link_factor(kind, coef, tref, tab_start, tab_len, tab_T, tab_v, temp):
    if kind == LAMBDA_CONSTANT:
        return 1.0
    if kind == LAMBDA_EXPONENTIAL:
        return exponential_factor_inner(coef, temp - tref)
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


@inner()
def _table_mean(tab_start, tab_len, tab_T, tab_v, ta, tb):
    """Mean of the normalised piecewise-linear table (constant beyond its ends) over [min, max] of ta and
    tb: the exact integral, segment by segment between the table points inside the interval, over its
    length (the Kirchhoff mean; Simpson's rule is not exact when a table point lies inside)."""
    lo = min(ta, tb)
    hi = max(ta, tb)
    v_lo = _link_factor(LAMBDA_TABLE, 0.0, 0.0, tab_start, tab_len, tab_T, tab_v, lo)
    if hi <= lo:
        return v_lo
    acc = 0.0
    t_prev = lo
    v_prev = v_lo
    for k in range(tab_start, tab_start + tab_len):
        t = tab_T[k]
        if t > lo and t < hi:
            acc += (t - t_prev) * 0.5 * (v_prev + tab_v[k])
            t_prev = t
            v_prev = tab_v[k]
    v_hi = _link_factor(LAMBDA_TABLE, 0.0, 0.0, tab_start, tab_len, tab_T, tab_v, hi)
    acc += (hi - t_prev) * 0.5 * (v_prev + v_hi)
    return acc / (hi - lo)


@inner()
def _update_conductances(g, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, Tfull):
    """Link conductance = mean of lambda(T) over the temperatures of its two nodes.

    That is the Kirchhoff-transform conductance (U(T_a) - U(T_b)) / (T_a - T_b) / dx with
    U = integral of lambda dT, which makes the discrete steady state exact at the nodes:
    in closed form for the exponential law, exactly segment by segment for a table (:func:`_table_mean`).
    """
    for lnk in range(g.shape[0]):
        k = kind[lnk]
        if k == LAMBDA_CONSTANT:
            continue
        ta = Tfull[lnk]
        tb = Tfull[lnk + 1]
        if k == LAMBDA_EXPONENTIAL:
            f = coef[lnk]
            d = f * (ta - tb)
            if abs(d) > 1e-4:
                fac = (exponential_factor_inner(f, ta - tref[lnk]) - exponential_factor_inner(f, tb - tref[lnk])) / d
            else:
                fac = exponential_factor_inner(f, 0.5 * (ta + tb) - tref[lnk]) * (1.0 + d * d / 24.0)
        else:
            fac = _table_mean(tab_start[lnk], tab_len[lnk], tab_T, tab_v, ta, tb)
        g[lnk] = g_ref[lnk] * fac


@inner()
def _factor_folded(a, b, m, sc, f1, f2):
    """LU of the symmetric tridiagonal (a diagonal, b off-diagonal) with the pivots folded in:
    sc = 1/pivot scales the right-hand side, f1_i = b_{i-1}/p_i (forward), f2_i = b_i/p_i (backward)."""
    piv = a[0]
    sc[0] = 1.0 / piv
    f1[0] = 0.0
    for i in range(1, m):
        piv = a[i] - b[i - 1] * b[i - 1] / piv
        sc[i] = 1.0 / piv
        f1[i] = b[i - 1] * sc[i]
    for i in range(m - 1):
        f2[i] = b[i] * sc[i]
    f2[m - 1] = 0.0


@inner()
def _solve_folded(sc, f1, f2, x, m):
    """Solve in place with the factors of :func:`_factor_folded` (x: right-hand side in, solution out)."""
    x[0] *= sc[0]
    for i in range(1, m):
        x[i] = x[i] * sc[i] - f1[i] * x[i - 1]
    for i in range(m - 2, -1, -1):
        x[i] -= f2[i] * x[i + 1]


@inner()
def _steady(cap, g, g_ref, laws, bc_type, bc_h, ue0, ui0, j0, m, Tfull):
    """Steady state ``K T = p u`` for the first boundary values (Picard iterations when lambda(T)); writes
    Tfull (every node) and leaves the conductances of the last iteration in g."""
    kind, coef, tref, tab_start, tab_len, tab_T, tab_v = laws
    n_nodes = Tfull.shape[0]
    nonlinear = False
    for lnk in range(kind.shape[0]):
        if kind[lnk] != LAMBDA_CONSTANT:
            nonlinear = True
    mm = max(m, 1)
    diag = np.zeros(mm)
    off = np.zeros(mm)
    sc = np.zeros(mm)
    f1 = np.zeros(mm)
    f2 = np.zeros(mm)
    x = np.zeros(mm)
    ones = np.ones(g.shape[0])
    one2 = np.ones(2)
    # first guess: uniform at the mean of the inputs that set the temperature level
    guess = 0.5 * (ue0 + ui0)
    if boundary.imposes_flux(bc_type[0]):
        guess = ui0
    if boundary.imposes_flux(bc_type[1]):
        guess = ue0
    for j in range(n_nodes):
        Tfull[j] = guess
    if boundary.is_known(bc_type[0]):
        Tfull[0] = ue0
    if boundary.is_known(bc_type[1]):
        Tfull[n_nodes - 1] = ui0
    n_iter = 60 if nonlinear else 1
    for _ in range(n_iter):
        if nonlinear:
            _update_conductances(g, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, Tfull)
        if m == 0:
            break
        pe, pi = operator.assemble_operator(g, ones, bc_type, bc_h, one2, j0, m, diag, off)
        _factor_folded(diag, off, m, sc, f1, f2)
        x[0] = 0.0
        for i in range(m):
            x[i] = 0.0
        x[0] += pe * ue0
        x[m - 1] += pi * ui0
        _solve_folded(sc, f1, f2, x, m)
        change = 0.0
        for i in range(m):
            change = max(change, abs(x[i] - Tfull[j0 + i]))
            Tfull[j0 + i] = x[i]
        if change < 1e-12:
            break


@inner()
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


@inner()
def _factor_lean(cap, g0, theta, bc_type, bc_h, bc_theta, dt, j0, m, a, b, inv, f1, f2):
    """Twisted ("burn at both ends") LU of A0 = Cap/dt + K_theta(g0) over the unknowns.

    Rows above the twist k = m // 2 are eliminated downwards (pivots p), rows below it upwards
    (pivots q), so that a solve runs two independent dependency chains of length m/2 instead of
    one of length m. Stored per row i: inv = 1/pivot, and
    i < k: f1 = b_{i-1}/p_i (forward coupling), f2 = b_i/p_i (back substitution);
    i > k: f1 = b_i/q_i, f2 = b_{i-1}/q_i; i = k: 1/gamma and the two couplings b_{k-1}, b_k.
    (a: diagonal, b_i: off-diagonal between i and i + 1; a and b are work arrays of length >= m,
    passed in so that the refactorisations of a lambda(T) run do not allocate.)
    """
    k = m // 2
    operator.assemble_operator(g0, theta, bc_type, bc_h, bc_theta, j0, m, a, b)
    for i in range(m):
        a[i] += cap[j0 + i] / dt
    for i in range(k):  # downwards
        piv = a[i]
        if i > 0:
            piv -= b[i - 1] * f2[i - 1]
        inv[i] = 1.0 / piv
        f1[i] = b[i - 1] * inv[i] if i > 0 else 0.0
        f2[i] = b[i] * inv[i]
    for i in range(m - 1, k, -1):  # upwards
        piv = a[i]
        if i < m - 1:
            piv -= b[i] * f2[i + 1]
        inv[i] = 1.0 / piv
        f1[i] = b[i] * inv[i] if i < m - 1 else 0.0
        f2[i] = b[i - 1] * inv[i]
    gam = a[k]
    if k > 0:
        gam -= b[k - 1] * f2[k - 1]
    if k < m - 1:
        gam -= b[k] * f2[k + 1]
    inv[k] = 1.0 / gam
    f1[k] = b[k - 1] if k > 0 else 0.0
    f2[k] = b[k] if k < m - 1 else 0.0


@inner()
def _solve_coefficients(inv, f1, f2, k, m, sc, S):
    """Per-row coefficients of the step loop's twisted solve, from the factors of :func:`_factor_lean`:
    sc, the scale of right-hand side row i (1/pivot; 1/gamma at the twist row k), and, packed per
    row (one base pointer for the chains), S[4 i: 4 i + 4] = (f1_i, c1_i, f2_i, c2_i) with the pair
    products c1 (elimination) and c2 (substitution) that let each chain take two rows per
    multiply-add: c1_t = f1_t f1_{t-1} (top, 2 <= t < k), c1_i = f1_i f1_{i+1} (bottom,
    k < i <= m - 3), c2_i = f2_i f2_{i+1} (top, i <= k - 2), c2_i = f2_i f2_{i-1} (bottom, i >= k + 2);
    at the twist row, c1_k = f1_k / gamma and c2_k = f2_k / gamma (its couplings b_{k-1}, b_k scaled)."""
    for i in range(m):
        sc[i] = inv[i]
        S[4 * i] = f1[i]
        S[4 * i + 1] = 0.0
        S[4 * i + 2] = f2[i]
        S[4 * i + 3] = 0.0
    S[4 * k + 1] = f1[k] * inv[k]  # twist row: couplings to rows k - 1 and k + 1, scaled by 1/gamma
    S[4 * k + 3] = f2[k] * inv[k]
    for i in range(2, k):
        S[4 * i + 1] = f1[i] * f1[i - 1]
    for i in range(k + 1, m - 2):
        S[4 * i + 1] = f1[i] * f1[i + 1]
    for i in range(0, k - 1):
        S[4 * i + 3] = f2[i] * f2[i + 1]
    for i in range(k + 2, m):
        S[4 * i + 3] = f2[i] * f2[i - 1]


@inner(fastmath=True)
def _exp_step(x):
    """exp(x) for |x| <= 0.01 (degree-5 Taylor polynomial, relative error < 2e-15)."""
    return 1.0 + x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0)))))


@inner()
def _exact_factors(coef, tref, g_ref, Tmid, Gm):
    """Link factors g_ref exp(f (T_m - T_ref)) at the link's mean temperature T_m = (T_a + T_b) / 2."""
    for lnk in range(Gm.shape[0]):
        Gm[lnk] = g_ref[lnk] * exponential_factor_inner(coef[lnk], 0.5 * (Tmid[lnk] + Tmid[lnk + 1]) - tref[lnk])


@inner(fastmath=True)
def _sinhc(u):
    """sinh(x) / x for u = x^2 <= SINHC_U_MAX (degree-10 Taylor polynomial, relative error < 4e-18)."""
    return 1.0 + u * (
        1.0 / 6.0 + u * (1.0 / 120.0 + u * (1.0 / 5040.0 + u * (1.0 / 362880.0 + u * (1.0 / 39916800.0))))
    )


SINHC_U_MAX = 0.0625  # |x| <= 0.25, i.e. |f (T_a - T_b)| <= 0.5


@inner()
def _nonlinear_conductances(gs, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, has_table, Tmid, Gm):
    """Kirchhoff-mean conductances g = g_ref (E_a - E_b) / (f (T_a - T_b)) of the exponential law
    E = exp(f (T - T_ref)), written with the link's mean-temperature factor Gm = g_ref E_m
    (:func:`_exact_factors`) as g = Gm sinh(x) / x, x = f (T_a - T_b) / 2 (no cancellation, no
    division; the closed form beyond the polynomial's range). A constant link has f = 0, so
    g = g_ref exactly. Table links take the exact mean (:func:`_table_mean`)."""
    n_links = gs.shape[0]
    for lnk in range(n_links):
        d = coef[lnk] * (Tmid[lnk] - Tmid[lnk + 1])
        u = 0.25 * d * d
        if u <= SINHC_U_MAX:
            gs[lnk] = Gm[lnk] * _sinhc(u)
        else:
            ea = exponential_factor_inner(coef[lnk], Tmid[lnk] - tref[lnk])
            eb = exponential_factor_inner(coef[lnk], Tmid[lnk + 1] - tref[lnk])
            gs[lnk] = g_ref[lnk] * ((ea - eb) / d)
    if not has_table:
        return
    for lnk in range(n_links):
        if kind[lnk] == LAMBDA_TABLE:
            ta = Tmid[lnk]
            tb = Tmid[lnk + 1]
            gs[lnk] = g_ref[lnk] * _table_mean(tab_start[lnk], tab_len[lnk], tab_T, tab_v, ta, tb)


@inner()
def _step_conductance(fh, dtm_a, dtm_b, gm, tm_a, tm_b):
    """One link's step of :func:`_run_one`'s first lambda(T) pass (``fh = f / 2``): its factor Gm brought
    to the new mid-step temperatures, ``Gm exp(f (dtm_a + dtm_b) / 2)`` (polynomial), the
    Kirchhoff-mean conductance ``g* = Gm sinh(x)/x`` with ``x = f (tm_a - tm_b) / 2`` (polynomial), and
    1 when either argument is beyond its polynomial's range (else 0). Inlined into the vectorised pass."""
    x = fh * (dtm_a + dtm_b)
    gm = gm * _exp_step(x)
    d = fh * (tm_a - tm_b)
    u = d * d
    return gm, gm * _sinhc(u), 1 if (u > SINHC_U_MAX) | (abs(x) > 0.01) else 0


@inner()
def _drift_limits(cap, theta, dt, bc_type, lim):
    """The part of the drift tolerance that does not depend on ``g0`` (see :func:`_set_factorised`):
    0.05 / (theta dt (1/c_a + 1/c_b)) (known face nodes count as infinite capacity; inf for a link
    between two known nodes), and 0 for a link touching an unknown node without capacity."""
    n_links = lim.shape[0]
    n_nodes = cap.shape[0]
    for lnk in range(n_links):
        known_a = lnk == 0 and boundary.is_known(bc_type[0])
        known_b = lnk + 1 == n_nodes - 1 and boundary.is_known(bc_type[1])
        if (cap[lnk] <= 0.0 and not known_a) or (cap[lnk + 1] <= 0.0 and not known_b):
            lim[lnk] = 0.0
            continue
        ia = 0.0 if known_a else 1.0 / cap[lnk]
        ib = 0.0 if known_b else 1.0 / cap[lnk + 1]
        stiff = theta[lnk] * dt * (ia + ib)
        lim[lnk] = 0.05 / stiff if stiff > 0.0 else np.inf


@inner()
def _set_factorised(g0, gs, theta, drift, lim, thg, glo, ghi):
    """Take ``g*`` as the factorised conductances ``g0``: ``thg = theta g0`` and the band
    ``[glo, ghi] = g0 -+ tol`` that a conductance may drift in before refactoring, with the drift
    tolerance ``tol = min(drift g0, lim)``: the fraction ``drift`` of it (default 2 %), and at most
    ``lim`` (:func:`_drift_limits`) so that the explicit correction stays far inside its stability limit."""
    for lnk in range(g0.shape[0]):
        g0[lnk] = gs[lnk]
        thg[lnk] = theta[lnk] * g0[lnk]
        tol = min(drift * g0[lnk], lim[lnk])
        glo[lnk] = g0[lnk] - tol
        ghi[lnk] = g0[lnk] + tol


@inner(fastmath={"contract"})
def _run_one(wall, laws, faces, outputs, dt, drift, Tinit, out, energy):
    """One candidate of :func:`run_batch`.

    Each link's flux over a step is ``F_l = E_l + theta_l g0_l (T^{n+1}_a - T^{n+1}_b)``, applied with
    opposite signs to its two nodes (so energy is conserved exactly), where ``g0`` are the
    conductances of the factorised matrix and ``E_l`` the explicit part:

    - constant conductances: ``g0 = g`` and ``E_l = (1 - theta_l) g_l (T^n_a - T^n_b)``;
    - lambda(T): ``g*`` is the Kirchhoff mean at the mid-step temperature extrapolated from
      ``T^n, T^{n-1}``, ``T~ = 2 T^n - T^{n-1}`` predicts ``T^{n+1}``, and
      ``E_l = g*_l (theta_l dT~_l + (1 - theta_l) dT^n_l) - theta_l g0_l dT~_l``: the same flux as the
      scheme with ``g*`` implicit up to ``theta (g0 - g*) (dT^{n+1} - dT~) = O(dt^2)``, so second
      order is kept, the steady state is exact, and the matrix is refactorised only when ``g*``
      drifts from ``g0`` (see :func:`_set_factorised`).

    Layout of a step (see the module docstring for why): lambda(T) only, one vectorised pass over
    the links updating the link factors ``Gm``, forming ``g*`` and the two counts that trigger the
    rare branch (exact factors / closed form / table laws, refactorisation) and, when every link has
    the same theta, the explicit fluxes ``E`` without storing ``g*`` (else ``g*`` is stored and ``E``
    formed by a second pass, as after a rare branch); the right-hand side, scaled for the solve; the
    solve (written out: two chains, two rows per multiply-add);
    the scalar face fluxes, probes (only when an output needs them) and
    outputs; one pass over the nodes that shifts ``T^n <- T^{n+1}`` and, for lambda(T), prepares the
    next step: mid-step temperature, its change (from which the next step's first pass updates the
    link factors ``Gm``) and the predictor written into ``Tnew``.
    """
    cap, g_ref, theta = wall
    kind, coef, tref, tab_start, tab_len, tab_T, tab_v = laws
    bc_type, bc_h, bc_theta, ue, ui = faces
    out_step, out_w, pa, pb, pw, dl, dk, dc = outputs
    n_nodes = cap.shape[0]
    n_links = g_ref.shape[0]
    n_steps = ue.shape[0] - 1
    dir_e = boundary.is_known(bc_type[0])
    dir_i = boundary.is_known(bc_type[1])
    j0, m = operator.unknown_range(n_nodes, bc_type)
    mm = max(m, 1)
    nonlinear = False
    for lnk in range(n_links):
        if kind[lnk] != LAMBDA_CONSTANT:
            nonlinear = True
    g0 = g_ref.copy()  # conductances of the factorised matrix
    gs = g_ref.copy()  # conductances of the current step (lambda(T))
    thg = np.empty(n_links)  # theta g0: implicit part of the factorised link conductances
    omth = np.empty(n_links)  # 1 - theta
    glo = np.zeros(n_links)  # drift band of the factorised conductances (lambda(T), _set_factorised)
    ghi = np.zeros(n_links)
    lim = np.zeros(n_links)
    inv = np.zeros(mm)
    f1 = np.zeros(mm)
    f2 = np.zeros(mm)
    wa = np.zeros(mm)
    wb = np.zeros(mm)
    rhs = np.zeros(mm)
    sc = np.ones(mm)  # scale of the right-hand side rows (twisted solve: 1/pivot, 1/gamma at the twist row)
    S = np.zeros(4 * mm)  # packed per-row coefficients of the twisted solve (_solve_coefficients)
    k = m // 2  # twist row of the factorisation
    nb = m - 1 - k  # rows below it (k or k - 1)
    Epad = np.zeros(n_links + 2)  # Epad[l + 1] = E_l, zero beyond the ends (branch-free right-hand side)
    # the last pass of a lambda(T) step runs over n_pad >= n_nodes nodes, a multiple of 8 (the vector
    # width with 512-bit vectors, two vectors with 256-bit ones), on buffers padded with zeros: no
    # scalar or narrower remainder loop (multiples of 4 measured ~5 % slower)
    n_pad = (n_links // 8 + 1) * 8
    TnB = np.zeros(n_pad + 1)
    TnewB = np.zeros(n_pad + 1)
    TmidB = np.zeros(n_pad + 1)
    DB = np.zeros(n_pad + 1)  # change of the mid-step temperature over the last step (lambda(T))
    GmB = np.zeros(n_pad)
    Tn = TnB[:n_nodes]  # T^n
    Tnew = TnewB[:n_nodes]  # T^{n+1}; before the solve: the known faces and the predictor T~
    Tu = Tnew[j0 : j0 + m]  # its unknowns (view)
    Tmid = TmidB[:n_nodes]  # mid-step temperature of the step (lambda(T))
    Gm = GmB[:n_links]  # link factors g_ref exp(f (T_m - T_ref)) at the mean mid-step temperature
    for lnk in range(n_links):
        Gm[lnk] = g_ref[lnk]
    has_table = False
    fh = np.empty(n_links)  # f / 2 (exponential law; 0 for the other links)
    for lnk in range(n_links):
        fh[lnk] = 0.5 * coef[lnk]
    th0 = theta[0] if n_links > 0 else 0.5
    om0 = 1.0 - th0
    uniform_theta = True  # one theta for every link (the fused lambda(T) pass)
    n_big = 0  # link factor updates beyond the polynomial's range (lambda(T))
    for lnk in range(n_links):
        omth[lnk] = 1.0 - theta[lnk]
        thg[lnk] = theta[lnk] * g0[lnk]
        if kind[lnk] == LAMBDA_TABLE:
            has_table = True
        if theta[lnk] != th0:
            uniform_theta = False
    cdt = np.empty(n_nodes)
    for j in range(n_nodes):
        cdt[j] = cap[j] / dt

    if Tinit.shape[0] == n_nodes:
        for j in range(n_nodes):
            Tn[j] = Tinit[j]
        if dir_e:
            Tn[0] = ue[0]
        if dir_i:
            Tn[n_nodes - 1] = ui[0]
    else:
        _steady(cap, g0, g_ref, laws, bc_type, bc_h, ue[0], ui[0], j0, m, Tn)
    e_start = 0.0
    for j in range(n_nodes):
        Tnew[j] = Tn[j]  # predictor of the first step: T^0
        Tmid[j] = Tn[j]
        e_start += cap[j] * Tn[j]
    if nonlinear:
        _exact_factors(coef, tref, g_ref, Tmid, Gm)
        _nonlinear_conductances(gs, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, has_table, Tmid, Gm)
        _drift_limits(cap, theta, dt, bc_type, lim)
        _set_factorised(g0, gs, theta, drift, lim, thg, glo, ghi)
    # constant conductances: the explicit link fluxes are gex (T^n_a - T^n_b)
    gex = np.empty(n_links)
    for lnk in range(n_links):
        gex[lnk] = omth[lnk] * g0[lnk]
    if m > 0:
        _factor_lean(cap, g0, theta, bc_type, bc_h, bc_theta, dt, j0, m, wa, wb, inv, f1, f2)
        _solve_coefficients(inv, f1, f2, k, m, sc, S)

    e_in = 0.0
    e_out = 0.0
    n_out = out_step.shape[0]
    n_pr = pa.shape[0]
    # rings of the last four grid times: probe values P[j % 4] and step fluxes F[j % 4] = F^{j+1/2}
    P = np.zeros((4, n_pr))
    Fe = np.zeros(4)
    Fi = np.zeros(4)
    n_d = dl.shape[0]
    Fd = np.zeros((n_d, 4))  # step fluxes through the depth planes, Fd[d, j % 4] = F^{j+1/2}
    imposed_e = boundary.imposes_flux(bc_type[0])  # a heat-flux face reports its imposed value
    imposed_i = boundary.imposes_flux(bc_type[1])
    the = bc_theta[0]
    thi = bc_theta[1]
    for q in range(n_pr):
        P[0, q] = (1.0 - pw[q]) * Tn[pa[q]] + pw[q] * Tn[pb[q]]
    k_out = 0
    for n in range(n_steps):
        if dir_e:
            Tnew[0] = ue[n + 1]
        if dir_i:
            Tnew[n_nodes - 1] = ui[n + 1]
        # explicit part of the link fluxes
        if nonlinear:
            # E_l = g*_l (theta_l dT~_l + (1 - theta_l) dT^n_l) - theta_l g0_l dT~_l (Tnew: predictor)
            fresh = n == 0  # E still to be formed from the array gs (first step: g* = g0 from the start)
            if n > 0:
                # lambda(T): one pass over the links (vectorised: no branches, integer counts) brings
                # the link factors Gm to this step's mid-step temperature, Gm *= exp(f dT_m) (a
                # polynomial; dT_m: the change of the link's mean mid-step temperature, from the
                # previous step's last pass), forms the Kirchhoff-mean conductances g* = Gm sinh(x)/x
                # (as _nonlinear_conductances), counts the factor updates and the links beyond the
                # polynomials' ranges (n_big) and those whose g* left the drift band [glo, ghi] around
                # g0, and, when every link has the same theta (reading few arrays keeps the pass
                # vectorised), the explicit fluxes E too, without storing g*; the rare branches (exact
                # factors, table laws, refactorisation) store g* and form E afterwards.
                n_drift = 0
                if uniform_theta:
                    for lnk in range(n_links):
                        gmk, gk, big = _step_conductance(
                            fh[lnk], DB[lnk], DB[lnk + 1], Gm[lnk], Tmid[lnk], Tmid[lnk + 1]
                        )
                        Gm[lnk] = gmk
                        n_big += big
                        n_drift += 1 if (gk > ghi[lnk]) | (gk < glo[lnk]) else 0
                        dp = Tnew[lnk] - Tnew[lnk + 1]
                        Epad[lnk + 1] = gk * (th0 * dp + om0 * (Tn[lnk] - Tn[lnk + 1])) - thg[lnk] * dp
                else:
                    fresh = True
                    for lnk in range(n_links):
                        gmk, gk, big = _step_conductance(
                            fh[lnk], DB[lnk], DB[lnk + 1], Gm[lnk], Tmid[lnk], Tmid[lnk + 1]
                        )
                        Gm[lnk] = gmk
                        n_big += big
                        gs[lnk] = gk
                        n_drift += 1 if (gk > ghi[lnk]) | (gk < glo[lnk]) else 0
                if n % 1024 == 0 or n_big > 0 or has_table:  # exact factors (and closed form, table laws)
                    fresh = True
                    _exact_factors(coef, tref, g_ref, Tmid, Gm)
                    _nonlinear_conductances(
                        gs, g_ref, kind, coef, tref, tab_start, tab_len, tab_T, tab_v, has_table, Tmid, Gm
                    )
                    n_drift = 0
                    for lnk in range(n_links):
                        if (gs[lnk] > ghi[lnk]) | (gs[lnk] < glo[lnk]):
                            n_drift += 1
                elif n_drift > 0 and not fresh:  # g* of the fused pass, stored for the refactorisation
                    fresh = True
                    for lnk in range(n_links):
                        d = fh[lnk] * (Tmid[lnk] - Tmid[lnk + 1])
                        gs[lnk] = Gm[lnk] * _sinhc(d * d)
                if n_drift > 0 and m > 0:
                    _set_factorised(g0, gs, theta, drift, lim, thg, glo, ghi)
                    _factor_lean(cap, g0, theta, bc_type, bc_h, bc_theta, dt, j0, m, wa, wb, inv, f1, f2)
                    _solve_coefficients(inv, f1, f2, k, m, sc, S)
            if fresh:
                for lnk in range(n_links):
                    dp = Tnew[lnk] - Tnew[lnk + 1]
                    Epad[lnk + 1] = gs[lnk] * (theta[lnk] * dp + omth[lnk] * (Tn[lnk] - Tn[lnk + 1])) - thg[lnk] * dp
        else:
            for lnk in range(n_links):
                Epad[lnk + 1] = gex[lnk] * (Tn[lnk] - Tn[lnk + 1])
        if m > 0:
            # right-hand side, scaled for the solve (sc: the pivots' inverses of the twisted solve)
            for i in range(m):
                j = j0 + i
                rhs[i] = (cdt[j] * Tn[j] + Epad[j] - Epad[j + 1]) * sc[i]
            rhs[0] += boundary.step_input(bc_type[0], bc_h[0], the, 1.0, ue[n + 1], ue[n], Tn[0], thg[0]) * sc[0]
            rhs[m - 1] += (
                boundary.step_input(bc_type[1], bc_h[1], thi, -1.0, ui[n + 1], ui[n], Tn[n_nodes - 1], thg[n_links - 1])
                * sc[m - 1]
            )
            # solve A0 x = rhs with the twisted factors of _factor_lean: two independent dependency
            # chains (top and bottom half), interleaved, the running values in registers, each taking
            # two rows per multiply-add by recursive doubling (pair products c1, c2, packed with f1, f2
            # per row in S by _solve_coefficients): y_{t+1} = (r_{t+1} - f1_{t+1} r_t) + c1_{t+1} y_{t-1},
            # the row between off the chain. Written out here (a call, or numba's inline="always",
            # costs refcount operations and spills on the chain each step); needs FMA contraction.
            # Every index is unsigned (uint64(...)), which spares numba's negative-index wraparound
            # (a sign test and two integer instructions per access).
            # Elimination towards the twist (rows 0..k-1 downwards, rows m-1..k+1 upwards):
            # y_i = r_i - f1_i y_{i-1} (top), y_i = r_i - f1_i y_{i+1} (bottom), r = rhs / pivot
            yt = rhs[0]
            yb = rhs[m - 1]
            Tu[0] = yt
            Tu[m - 1] = yb
            n_pair = max((nb - 1) // 2, 0)
            for p in range(n_pair):
                i0 = uint64(1 + 2 * p)  # top rows i0, i1 = i0 + 1
                i1 = uint64(2 + 2 * p)
                r0 = rhs[i0]
                ytn = (rhs[i1] - S[uint64(4 * i1)] * r0) + S[uint64(4 * i1 + 1)] * yt
                Tu[i0] = r0 - S[uint64(4 * i0)] * yt
                Tu[i1] = ytn
                yt = ytn
                i0 = uint64(m - 2 - 2 * p)  # bottom rows i0, i1 = i0 - 1
                i1 = uint64(m - 3 - 2 * p)
                r0 = rhs[i0]
                ybn = (rhs[i1] - S[uint64(4 * i1)] * r0) + S[uint64(4 * i1 + 1)] * yb
                Tu[i0] = r0 - S[uint64(4 * i0)] * yb
                Tu[i1] = ybn
                yb = ybn
            for t in range(1 + 2 * n_pair, k):  # rows left in the top half (at most 2)
                i0 = uint64(t)
                yt = rhs[i0] - S[uint64(4 * i0)] * yt
                Tu[i0] = yt
            for t in range(m - 2 - 2 * n_pair, k, -1):  # row left in the bottom half (at most 1)
                i0 = uint64(t)
                yb = rhs[i0] - S[uint64(4 * i0)] * yb
                Tu[i0] = yb
            # twist row (its right-hand side and couplings pre-scaled by 1/gamma), from the chains'
            # last values still in registers
            xk = rhs[k]
            if k > 0:
                xk -= S[4 * k + 1] * yt
            if k < m - 1:
                xk -= S[4 * k + 3] * yb
            Tu[k] = xk
            # substitution away from the twist: x_i = y_i - f2_i x_{i+1} (top), x_i = y_i - f2_i x_{i-1}
            # (bottom), also two rows per multiply-add on the chains
            xt = xk
            xb = xk
            n_pair = nb // 2
            for p in range(n_pair):
                i0 = uint64(k - 1 - 2 * p)  # top rows i0, i1 = i0 - 1
                i1 = uint64(k - 2 - 2 * p)
                y0 = Tu[i0]
                xtn = (Tu[i1] - S[uint64(4 * i1 + 2)] * y0) + S[uint64(4 * i1 + 3)] * xt
                Tu[i0] = y0 - S[uint64(4 * i0 + 2)] * xt
                Tu[i1] = xtn
                xt = xtn
                i0 = uint64(k + 1 + 2 * p)  # bottom rows i0, i1 = i0 + 1
                i1 = uint64(k + 2 + 2 * p)
                y0 = Tu[i0]
                xbn = (Tu[i1] - S[uint64(4 * i1 + 2)] * y0) + S[uint64(4 * i1 + 3)] * xb
                Tu[i0] = y0 - S[uint64(4 * i0 + 2)] * xb
                Tu[i1] = xbn
                xb = xbn
            for t in range(k - 1 - 2 * n_pair, -1, -1):  # rows left in the top half (at most 2)
                i0 = uint64(t)
                xt = Tu[i0] - S[uint64(4 * i0 + 2)] * xt
                Tu[i0] = xt
            for t in range(k + 1 + 2 * n_pair, m):  # row left in the bottom half (at most 1)
                i0 = uint64(t)
                xb = Tu[i0] - S[uint64(4 * i0 + 2)] * xb
                Tu[i0] = xb
        # step-average face fluxes F^{n+1/2} (the scheme's own link fluxes: energy is conserved exactly)
        lk = n_links - 1
        half_e = Epad[1] + thg[0] * (Tnew[0] - Tnew[1]) + cdt[0] * (Tnew[0] - Tn[0]) if dir_e else 0.0
        half_i = (
            Epad[lk + 1]
            + thg[lk] * (Tnew[lk] - Tnew[lk + 1])
            - cdt[n_nodes - 1] * (Tnew[n_nodes - 1] - Tn[n_nodes - 1])
            if dir_i
            else 0.0
        )
        fe = boundary.step_flux(bc_type[0], bc_h[0], the, 1.0, ue[n + 1], ue[n], Tnew[0], Tn[0], half_e)
        fi = boundary.step_flux(
            bc_type[1], bc_h[1], thi, -1.0, ui[n + 1], ui[n], Tnew[n_nodes - 1], Tn[n_nodes - 1], half_i
        )
        e_in += dt * fe
        e_out += dt * fi
        Fe[n & 3] = fe
        Fi[n & 3] = fi
        # through a depth plane: its link's flux, plus on a node the storage of the node's part on the
        # interior side of the plane (dc: that capacity over dt)
        for d in range(n_d):
            lnk = dl[d]
            fd = Epad[lnk + 1] + thg[lnk] * (Tnew[lnk] - Tnew[lnk + 1])
            node = dk[d]
            if node >= 0:
                fd += dc[d] * (Tnew[node] - Tn[node])
            Fd[d, n & 3] = fd
        # probes at grid time n + 1, only when a pending output needs them (out_step is sorted)
        if k_out < n_out and out_step[k_out] <= n + 1:
            row = (n + 1) & 3
            for q in range(n_pr):
                P[row, q] = (1.0 - pw[q]) * Tnew[pa[q]] + pw[q] * Tnew[pb[q]]
        # outputs between grid nk and nk + 1 are complete once F^{nk+3/2} is known (nk = n - 1)
        while k_out < n_out and out_step[k_out] <= n - 1:
            _output(k_out, out_step[k_out], out_w[k_out], P, Fe, Fi, Fd, n_steps, ue, ui, imposed_e, imposed_i, out)
            k_out += 1
        # next time level: T^n <- T^{n+1}; for lambda(T) also the next step's mid-step temperature
        # 1.5 T^{n+1} - 0.5 T^n, its change, and the predictor 2 T^{n+1} - T^n (into Tnew)
        if nonlinear:
            # (DB; the next step's first pass updates the link factors from it). One pass over the
            # nodes; the padding nodes stay at 0.
            n_big = 0
            for j in range(n_pad):
                t0 = TnB[j]
                t1 = TnewB[j]
                tm = 1.5 * t1 - 0.5 * t0
                DB[j] = tm - TmidB[j]
                TnB[j] = t1
                TmidB[j] = tm
                TnewB[j] = 2.0 * t1 - t0
        else:
            for j in range(n_nodes):
                Tn[j] = Tnew[j]
    while k_out < n_out:  # outputs in the last step
        _output(k_out, out_step[k_out], out_w[k_out], P, Fe, Fi, Fd, n_steps, ue, ui, imposed_e, imposed_i, out)
        k_out += 1
    e_end = 0.0
    for j in range(n_nodes):
        e_end += cap[j] * Tn[j]
    energy[0] = e_end - e_start
    energy[1] = e_in
    energy[2] = e_out
    return Tn


@inner()
def _output(k, nk, w, P, Fe, Fi, Fd, n_steps, ue, ui, imposed_e, imposed_i, out):
    n_pr = P.shape[1]
    for q in range(n_pr):
        out[q, k] = (1.0 - w) * P[nk % 4, q] + w * P[(nk + 1) % 4, q]
    out[n_pr, k] = (1.0 - w) * _face_flux(Fe, nk, n_steps, ue, imposed_e) + w * _face_flux(
        Fe, nk + 1, n_steps, ue, imposed_e
    )
    out[n_pr + 1, k] = (1.0 - w) * _face_flux(Fi, nk, n_steps, ui, imposed_i) + w * _face_flux(
        Fi, nk + 1, n_steps, ui, imposed_i
    )
    for d in range(Fd.shape[0]):
        fd = Fd[d]
        out[n_pr + 2 + d, k] = (1.0 - w) * _face_flux(fd, nk, n_steps, ue, False) + w * _face_flux(
            fd, nk + 1, n_steps, ue, False
        )


@inner()
def _candidate(c, wall, laws, faces, outputs):
    """The arguments of :func:`_run_one` for candidate c of a batch (see :func:`run_batch`)."""
    cap, g_ref, theta = wall
    kind, coef, tref, tab_start, tab_len, tab_T, tab_v = laws
    bc_type, bc_h, bc_theta, ue, ui = faces
    out_step, out_w, pa, pb, pw, dl, dk, dc = outputs
    return (
        (cap[c], g_ref[c], theta[c]),
        (kind, coef[c], tref, tab_start, tab_len, tab_T, tab_v),
        (bc_type, bc_h[c], bc_theta[c], ue, ui),
        (out_step, out_w, pa[c], pb[c], pw[c], dl, dk, dc[c]),
    )


@kernel
def run_batch(wall, laws, faces, outputs, dt, drift, Tinit, results):
    """Run every candidate wall of a batch. Releases the GIL: a caller runs parts of a batch in threads
    (:func:`wallcal.engines.fd.in_threads`).

    Parameters (c = candidate, j = node, l = link, k = output time, p = probe)
    ----------
    wall : (cap (c, j) node heat capacities [J/(m2K)], g_ref (c, l) link conductances at the reference
        temperature [W/(m2K)], theta (c, l) theta of each link [-])
    laws : (kind (l,), coef (c, l), tref (l,), tab_start (l,), tab_len (l,), tab_T, tab_v): the conductivity
        law of each link (codes of :mod:`wallcal.grid`; tab_T, tab_v the concatenated normalised tables)
    faces : (bc_type (2,) codes of :mod:`wallcal.engines.boundary`, bc_h (c, 2) surface coefficients
        [W/(m2K)], bc_theta (c, 2) theta of the face terms, ue, ui (n_steps + 1,) inputs [degC or W/m2])
    outputs : (out_step, out_w (k,): output time = grid time out_step + out_w; pa, pb, pw (c, p): probe
        interpolation; dl, dk (d,), dc (c, d): the heat flux through depth planes: the flux of link dl,
        plus on node dk (>= 0) dc [W/(m2K)] times the node's temperature change over a step)
    dt : time step [s]
    drift : relative drift of a lambda(T) conductance that triggers a refactorisation (0: every step)
    Tinit : (c, j) initial node temperatures, or shape (c, 0) for the steady start
    results : (out, energy, Tend), the caller's arrays that the run fills (and returns):
        out (c, p + 2 + d, k) probe temperatures [degC], then exterior and interior face flux and the flux
        through each depth plane [W/m2]; energy (c, 3) stored-energy change, energy in at the exterior,
        energy out at the interior [J/m2]; Tend (c, j) final node temperatures [degC]
    """
    out, energy, Tend = results
    for c in range(out.shape[0]):
        w, lw, fc, op = _candidate(c, wall, laws, faces, outputs)
        Tend[c] = _run_one(w, lw, fc, op, dt, drift, Tinit[c], out[c], energy[c])
    return out, energy, Tend
