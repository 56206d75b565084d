"""The exact fast path for walls with constant properties: the theta scheme, diagonalised.

For a wall whose conductances do not depend on temperature, whose unknown nodes
all store heat and whose links all share one theta, the scheme

    (Cap/dt + theta K) T^{n+1} = (Cap/dt - (1 - theta) K) T^n + p (theta u^{n+1} + (1 - theta) u^n)

(``K`` the conductance matrix of the unknown nodes, boundary coefficients
included; ``p`` the input coupling, one column per boundary input) is
diagonalised by the symmetric generalized eigenproblem ``K v = lambda Cap v``
with ``V^T Cap V = I``. Each mode then follows the real first-order recursion

    z_k^{n+1} = mu_k z_k^n + r_k . s^n,   mu_k = (1/dt - (1 - theta) lambda_k) / (1/dt + theta lambda_k),
    r_k = (V^T p)_k / (1/dt + theta lambda_k),  s^n = theta u^{n+1} + (1 - theta) u^n,

which is the same linear algebra as the tridiagonal solve (results agree to
round-off), at two multiply-adds per mode and step (the modes are independent,
so the loop over modes vectorises).

Per candidate (everything inside the numba batch loop, in parallel over candidates):

1. ``K``, ``p`` and the output rows are assembled from the node capacities, the
   link conductances and the probe interpolation weights (no Python per candidate).
2. ``S = Cap^-1/2 K Cap^-1/2`` is symmetric *tridiagonal*. Its eigenvalues come
   from implicit QL with Wilkinson shifts (:func:`tridiag_ql`); the plane
   rotations are applied only to the few rows of the eigenvector matrix the
   outputs need (both ends, the probes' nodes) and recorded, so that the initial
   and final states can be mapped with them. O(m^2) instead of the O(m^3) of a
   dense ``eigh``, and no LAPACK/BLAS call (no threads of its own inside numba's).
3. The recursion runs from one output's base step to the next, four steps per
   pass over the modes (:func:`_advance`); at each output the states of the next
   three steps are stepped on mode by mode and combined with the output's weights
   (:func:`_form`). Memory does not depend on the number of steps.

Outputs: an output at grid time ``nk + w`` is a probe row over ``(1 - w) T^nk + w T^{nk+1}``
or a face-flux row over the energy-consistent two-step average of the states
``nk - 1 .. nk + 2`` (see :mod:`wallcal.engines.kernels`), plus terms in the
boundary inputs. These weights and input terms are the same for every candidate;
:func:`output_plan` computes them once per prepared simulation.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

#: columns of the per-output input features (see :func:`output_plan`)
N_FEAT = 6


@njit(cache=True)
def tridiag_ql(d, e, zt, rot_i, rot_cs):
    """Eigenvalues of a symmetric tridiagonal matrix by implicit QL with Wilkinson shifts.

    d : (m,) diagonal, overwritten by the eigenvalues (unsorted);
    e : (m,) off-diagonal, e[i] couples i and i + 1 (e[m-1] is workspace); overwritten.
    zt : (m, r) selected rows of the identity, transposed (zt[i, j] = 1 if row j is node i);
        on return zt[k, j] is the component at that node of eigenvector k.
    rot_i, rot_cs : storage for the plane rotations (index, (c, s)); the eigenvector matrix is
        ``W = R_1 R_2 ... R_n`` (see :func:`apply_w`, :func:`apply_wt`). Grown when full.

    Returns (n_rotations, rot_i, rot_cs), n_rotations = -1 if an eigenvalue failed to converge.
    This is EISPACK's tql2 (Numerical Recipes' tqli) with the rotations recorded instead of
    accumulated into a full m x m matrix: only the rows needed for the outputs are formed, and
    the initial and final states are mapped with the recorded rotations, so the whole
    decomposition costs O(m^2) instead of O(m^3).
    """
    m = d.shape[0]
    r = zt.shape[1]
    nrot = 0
    e[m - 1] = 0.0
    for lo in range(m):
        it = 0
        while True:
            mm = lo
            while mm < m - 1:
                dd = abs(d[mm]) + abs(d[mm + 1])
                if abs(e[mm]) + dd == dd:
                    break
                mm += 1
            if mm == lo:
                break
            it += 1
            if it > 60:
                return -1, rot_i, rot_cs
            g = (d[lo + 1] - d[lo]) / (2.0 * e[lo])
            rr = np.sqrt(g * g + 1.0)
            g = d[mm] - d[lo] + e[lo] / (g + (rr if g >= 0.0 else -rr))
            s = 1.0
            c = 1.0
            p = 0.0
            i = mm - 1
            early = False
            if nrot + mm - lo > rot_i.shape[0]:
                n_new = 2 * rot_i.shape[0] + m
                ri = np.empty(n_new, dtype=np.int64)
                rc = np.empty((n_new, 2))
                ri[:nrot] = rot_i[:nrot]
                rc[:nrot] = rot_cs[:nrot]
                rot_i = ri
                rot_cs = rc
            while i >= lo:
                f = s * e[i]
                b = c * e[i]
                rr = np.sqrt(f * f + g * g)
                e[i + 1] = rr
                if rr == 0.0:
                    d[i + 1] -= p
                    e[mm] = 0.0
                    early = True
                    break
                inv = 1.0 / rr
                s = f * inv
                c = g * inv
                g = d[i + 1] - p
                rr = (d[i] - g) * s + 2.0 * c * b
                p = s * rr
                d[i + 1] = g + p
                g = c * rr - b
                for j in range(r):
                    f = zt[i + 1, j]
                    zt[i + 1, j] = s * zt[i, j] + c * f
                    zt[i, j] = c * zt[i, j] - s * f
                rot_i[nrot] = i
                rot_cs[nrot, 0] = c
                rot_cs[nrot, 1] = s
                nrot += 1
                i -= 1
            if early:
                continue
            d[lo] -= p
            e[lo] = g
            e[mm] = 0.0
    return nrot, rot_i, rot_cs


@njit(cache=True)
def apply_w(nrot, rot_i, rot_cs, x):
    """x <- W x (eigenvector coordinates to node coordinates), W from :func:`tridiag_ql`."""
    for k in range(nrot - 1, -1, -1):
        i = rot_i[k]
        c = rot_cs[k, 0]
        s = rot_cs[k, 1]
        a = x[i]
        b = x[i + 1]
        x[i] = c * a + s * b
        x[i + 1] = c * b - s * a


@njit(cache=True)
def apply_wt(nrot, rot_i, rot_cs, x):
    """x <- W^T x (node coordinates to eigenvector coordinates)."""
    for k in range(nrot):
        i = rot_i[k]
        c = rot_cs[k, 0]
        s = rot_cs[k, 1]
        a = x[i]
        b = x[i + 1]
        x[i] = c * a - s * b
        x[i + 1] = s * a + c * b


def output_plan(out_step, out_w, n_steps, theta, ue, ui, dt):
    """Per-output state weights and input features (the same for every candidate).

    Output k lies between grid times ``nk`` and ``nk + 1`` (``nk + w``). It depends on the states
    ``base .. base + 3`` with ``base = max(nk - 1, 0)``.

    Returns
    -------
    base : (k,) int
    wp, wf : (k, 4)
        Weights of the states ``base + 0 .. 3`` in probe rows (linear in time) and in face-flux
        rows (energy-consistent average ``q^j = (F^{j-1/2} + F^{j+1/2}) / 2``, one-sided at the ends).
    feat : (k, 6)
        Input terms: ``u_e, u_i`` interpolated in time (probe rows on a known face node), then the
        same two-step averages of ``u_e, u_i`` and of their central differences ``du/dt`` (flux rows).
    """
    nk = np.asarray(out_step, dtype=np.int64)
    w = np.asarray(out_w, dtype=float)
    n_out = len(nk)
    base = np.maximum(nk - 1, 0)
    wp = np.zeros((n_out, 4))
    wf = np.zeros((n_out, 4))
    feat = np.zeros((n_out, N_FEAT))
    rows = np.arange(n_out)
    np.add.at(wp, (rows, nk - base), 1.0 - w)
    np.add.at(wp, (rows, nk + 1 - base), w)
    feat[:, 0] = (1.0 - w) * ue[nk] + w * ue[nk + 1]
    feat[:, 1] = (1.0 - w) * ui[nk] + w * ui[nk + 1]
    for jj in (0, 1):
        j = nk + jj
        wt = (1.0 - w) if jj == 0 else w
        a = np.where(j == 0, 0.0, np.where(j >= n_steps, 1.0 - theta, 0.5 * (1.0 - theta)))
        b = np.where(j == 0, 1.0 - theta, np.where(j >= n_steps, theta, 0.5))
        c = np.where(j == 0, theta, np.where(j >= n_steps, 0.0, 0.5 * theta))
        jm = np.maximum(j - 1, 0)
        jp = np.minimum(j + 1, n_steps)
        for coef, jx in ((a, jm), (b, j), (c, jp)):
            np.add.at(wf, (rows, jx - base), wt * coef)
        feat[:, 2] += wt * (a * ue[jm] + b * ue[j] + c * ue[jp])
        feat[:, 3] += wt * (a * ui[jm] + b * ui[j] + c * ui[jp])
        inv = 1.0 / ((jp - jm) * dt)
        feat[:, 4] += wt * (ue[jp] - ue[jm]) * inv
        feat[:, 5] += wt * (ui[jp] - ui[jm]) * inv
    return base, wp, wf, feat


@njit(cache=True)
def _rows(cap, g, pa, pb, pw, bc_type, bc_h, j0, m, kd, ko, G_nodes, D):
    """K over the unknowns (kd, ko), output rows over nodes and their input coefficients.

    G_nodes : (n_q, m) output rows over the unknown temperatures (probes, q_e, q_i);
    D : (n_q, 6) coefficients of the input features of :func:`output_plan`.
    Returns the input couplings (p_e at unknown 0, p_i at unknown m - 1).
    """
    n_nodes = cap.shape[0]
    n_links = g.shape[0]
    npr = pa.shape[0]
    for i in range(m):
        kd[i] = 0.0
        ko[i] = 0.0
    for lnk in range(n_links):
        ia = lnk - j0
        ib = ia + 1
        if 0 <= ia < m:
            kd[ia] += g[lnk]
        if 0 <= ib < m:
            kd[ib] += g[lnk]
        if 0 <= ia and ib < m:
            ko[ia] = -g[lnk]
    G_nodes[:, :] = 0.0
    D[:, :] = 0.0
    # probes: node a with 1 - w, node b with w; a known face node enters through its input
    for q in range(npr):
        for node, wgt in ((pa[q], 1.0 - pw[q]), (pb[q], pw[q])):
            i = node - j0
            if 0 <= i < m:
                G_nodes[q, i] += wgt
            elif node == 0:
                D[q, 0] += wgt
            else:
                D[q, 1] += wgt
    qe = npr
    qi = npr + 1
    # exterior face: q_e = g_01 (T_0 - T_1) + c_0 dT_0/dt, h (T_air - T_s), or the imposed flux
    if bc_type[0] == 0:
        pe = g[0]
        D[qe, 2] = g[0]
        G_nodes[qe, 0] = -g[0]
        D[qe, 4] = cap[0]
    elif bc_type[0] == 1:
        kd[0] += bc_h[0]
        pe = bc_h[0]
        D[qe, 2] = bc_h[0]
        G_nodes[qe, 0] = -bc_h[0]
    else:
        pe = 1.0
        D[qe, 0] = 1.0
    # interior face (positive towards the interior)
    if bc_type[1] == 0:
        pi = g[n_links - 1]
        G_nodes[qi, m - 1] = g[n_links - 1]
        D[qi, 3] = -g[n_links - 1]
        D[qi, 5] = -cap[n_nodes - 1]
    elif bc_type[1] == 1:
        kd[m - 1] += bc_h[1]
        pi = bc_h[1]
        G_nodes[qi, m - 1] = bc_h[1]
        D[qi, 3] = -bc_h[1]
    else:
        pi = -1.0
        D[qi, 1] = 1.0
    return pe, pi


@njit(cache=True, fastmath=True)
def _modal_one(cap, g, pa, pb, pw, bc_type, bc_h, theta, dt, s, ue, ui, base, wp, wf, feat, want, out, t0, tend):
    """One candidate (see module docstring). Writes ``out`` (n_q, k) and ``tend`` (n_nodes,).

    ``want`` (n_q,) bool: the output rows to form (others are left NaN); fewer rows need fewer
    eigenvector components and less work per output time.
    """
    n_nodes = cap.shape[0]
    j0 = 1 if bc_type[0] == 0 else 0
    m = (n_nodes - 1 if bc_type[1] == 0 else n_nodes) - j0
    npr = pa.shape[0]
    n_q = npr + 2
    kd = np.empty(m)
    ko = np.empty(m)
    G_nodes = np.empty((n_q, m))
    D = np.empty((n_q, N_FEAT))
    pe, pi = _rows(cap, g, pa, pb, pw, bc_type, bc_h, j0, m, kd, ko, G_nodes, D)
    for q in range(n_q):
        if not want[q]:
            for i in range(m):
                G_nodes[q, i] = 0.0
    # S = Cap^-1/2 K Cap^-1/2 (tridiagonal)
    dinv = np.empty(m)
    for i in range(m):
        dinv[i] = 1.0 / np.sqrt(cap[j0 + i])
    lam = np.empty(m)
    ee = np.zeros(m)
    for i in range(m):
        lam[i] = kd[i] * dinv[i] * dinv[i]
    for i in range(m - 1):
        ee[i] = ko[i] * dinv[i] * dinv[i + 1]
    # unknowns whose eigenvector components are needed: both ends and the probes' nodes
    col = np.full(m, -1, dtype=np.int64)
    col[0] = 0
    r = 1
    for i in range(1, m):
        need = i == m - 1
        for q in range(n_q):
            if G_nodes[q, i] != 0.0:
                need = True
        if need:
            col[i] = r
            r += 1
    zt = np.zeros((m, r))
    for i in range(m):
        if col[i] >= 0:
            zt[i, col[i]] = 1.0
    rot_i = np.empty(2 * m * m, dtype=np.int64)
    rot_cs = np.empty((2 * m * m, 2))
    nrot, rot_i, rot_cs = tridiag_ql(lam, ee, zt, rot_i, rot_cs)
    if nrot < 0:
        out[:, :] = np.nan
        tend[:] = np.nan
        return
    # modal coefficients; V = Cap^-1/2 W, so V[i, k] = dinv[i] zt[k, col[i]]
    mu = np.empty(m)
    r0 = np.empty(m)
    r1 = np.empty(m)
    z = np.empty(m)  # modal state
    ce = col[0]
    ci = col[m - 1]
    for k in range(m):
        den = 1.0 / dt + theta * lam[k]
        mu[k] = (1.0 / dt - (1.0 - theta) * lam[k]) / den
        a0 = dinv[0] * zt[k, ce] * pe
        a1 = dinv[m - 1] * zt[k, ci] * pi
        r0[k] = a0 / den
        r1[k] = a1 / den
        # steady start: K T = p u^0 gives z = Lambda^-1 V^T p u^0 (V^T K V = Lambda)
        z[k] = (a0 * ue[0] + a1 * ui[0]) / lam[k]
    if t0.shape[0] == n_nodes:  # z = V^T Cap T = W^T (Cap^1/2 T)
        for i in range(m):
            z[i] = t0[j0 + i] / dinv[i]
        apply_wt(nrot, rot_i, rot_cs, z)
    # output rows in modal coordinates: G = G_nodes V
    G = np.zeros((n_q, m))
    for q in range(n_q):
        for i in range(m):
            h = G_nodes[q, i]
            if h != 0.0:
                h *= dinv[i]
                c = col[i]
                for k in range(m):
                    G[q, k] += h * zt[k, c]
    # the recursion only stops at each output's base step; the output is formed from that state
    n_out = base.shape[0]
    n_steps = s.shape[0]
    zp = np.empty(m)
    zf = np.empty(m)
    cur = 0
    for k_out in range(n_out):
        _advance(z, mu, r0, r1, s, cur, base[k_out])
        cur = base[k_out]
        nxt = base[k_out + 1] if k_out + 1 < n_out else n_steps
        move = cur + 3 <= nxt
        _form(k_out, cur, move, z, mu, r0, r1, s, wp, wf, feat, G, D, npr, want, zp, zf, out)
        if move:
            cur += 3
    _advance(z, mu, r0, r1, s, cur, n_steps)
    # final temperatures T = V z = Cap^-1/2 W z
    zl = z
    apply_w(nrot, rot_i, rot_cs, zl)
    for i in range(n_nodes):
        tend[i] = 0.0
    for i in range(m):
        tend[j0 + i] = dinv[i] * zl[i]
    if j0 == 1:
        tend[0] = ue[n_steps]
    if bc_type[1] == 0:
        tend[n_nodes - 1] = ui[n_steps]


@njit(cache=True, fastmath=True)
def _advance(z, mu, r0, r1, s, n_from, n_to):
    """Advance the modal state from grid time n_from to n_to (in place).

    Four steps per pass over the modes (the state stays in registers in between), then
    single steps; the loop over modes vectorises.
    """
    m = z.shape[0]
    n = n_from
    while n + 4 <= n_to:
        a0 = s[n, 0]
        a1 = s[n, 1]
        b0 = s[n + 1, 0]
        b1 = s[n + 1, 1]
        c0 = s[n + 2, 0]
        c1 = s[n + 2, 1]
        d0 = s[n + 3, 0]
        d1 = s[n + 3, 1]
        for k in range(m):
            u = mu[k]
            p = r0[k]
            q = r1[k]
            zk = u * z[k] + (p * a0 + q * a1)
            zk = u * zk + (p * b0 + q * b1)
            zk = u * zk + (p * c0 + q * c1)
            z[k] = u * zk + (p * d0 + q * d1)
        n += 4
    while n < n_to:
        a0 = s[n, 0]
        a1 = s[n, 1]
        for k in range(m):
            z[k] = mu[k] * z[k] + (r0[k] * a0 + r1[k] * a1)
        n += 1


@njit(cache=True, fastmath=True)
def _form(k_out, nb, move, z, mu, r0, r1, s, wp, wf, feat, G, D, npr, want, zp, zf, out):
    """Output k_out from the state z at its base step nb.

    The states nb + 1 .. nb + 3 are stepped on from z mode by mode (nothing is stored), and
    combined with the probe-row weights (zp) and the face-flux-row weights (zf); the output
    rows are then dot products with G plus the input terms. With ``move`` (the next output's
    base is at least nb + 3) z is left at step nb + 3.
    """
    m = z.shape[0]
    n_steps = s.shape[0]
    i0 = min(nb, n_steps - 1)  # beyond the end the weights are 0
    i1 = min(nb + 1, n_steps - 1)
    i2 = min(nb + 2, n_steps - 1)
    e0, e1, e2 = s[i0, 0], s[i1, 0], s[i2, 0]
    g0, g1, g2 = s[i0, 1], s[i1, 1], s[i2, 1]
    p0, p1, p2, p3 = wp[k_out, 0], wp[k_out, 1], wp[k_out, 2], wp[k_out, 3]
    f0, f1, f2, f3 = wf[k_out, 0], wf[k_out, 1], wf[k_out, 2], wf[k_out, 3]
    for k in range(m):
        u = mu[k]
        a = r0[k]
        b = r1[k]
        z0 = z[k]
        z1 = u * z0 + (a * e0 + b * g0)
        z2 = u * z1 + (a * e1 + b * g1)
        z3 = u * z2 + (a * e2 + b * g2)
        zp[k] = p0 * z0 + p1 * z1 + p2 * z2 + p3 * z3
        zf[k] = f0 * z0 + f1 * z1 + f2 * z2 + f3 * z3
        z[k] = z3 if move else z0
    for q in range(G.shape[0]):
        if not want[q]:
            out[q, k_out] = np.nan
            continue
        acc = 0.0
        if q < npr:
            for k in range(m):
                acc += G[q, k] * zp[k]
        else:
            for k in range(m):
                acc += G[q, k] * zf[k]
        for c in range(N_FEAT):
            acc += D[q, c] * feat[k_out, c]
        out[q, k_out] = acc


@njit(parallel=True, cache=True)
def modal_batch(cap, g, pa, pb, pw, bc_type, bc_h, theta, dt, s, ue, ui, base, wp, wf, feat, want, t0):
    """Run every candidate through its modal recursion (see module docstring).

    Parameters (c = candidate, j = node, l = link, p = probe, k = output time)
    ----------
    cap : (c, j) node heat capacities; g : (c, l) link conductances
    pa, pb, pw : (c, p) probe interpolation (see :func:`wallcal.grid.probe_weights`)
    bc_type : (2,) boundary codes; bc_h : (2,) surface coefficients
    theta, dt : scheme weight and time step [s]
    s : (n_steps, 2) theta-weighted inputs per step; ue, ui : (n_steps + 1,) inputs
    base, wp, wf, feat : output plan (:func:`output_plan`)
    want : (p + 2,) bool, the output rows to form (the others are NaN)
    t0 : (c, j) initial node temperatures, or shape (c, 0) for the steady state of the first inputs

    Returns out (c, p + 2, k) and the final node temperatures (c, j) (known face nodes included).
    """
    nc = cap.shape[0]
    out = np.empty((nc, pa.shape[1] + 2, base.shape[0]))
    tend = np.empty(cap.shape)
    for c in prange(nc):
        _modal_one(
            cap[c],
            g[c],
            pa[c],
            pb[c],
            pw[c],
            bc_type,
            bc_h,
            theta,
            dt,
            s,
            ue,
            ui,
            base,
            wp,
            wf,
            feat,
            want,
            out[c],
            t0[c],
            tend[c],
        )
    return out, tend


@njit(cache=True)
def modal_serial(cap, g, pa, pb, pw, bc_type, bc_h, theta, dt, s, ue, ui, base, wp, wf, feat, want, t0):
    """:func:`modal_batch` on the calling thread (small batches: no thread wake-up latency)."""
    nc = cap.shape[0]
    out = np.empty((nc, pa.shape[1] + 2, base.shape[0]))
    tend = np.empty(cap.shape)
    for c in range(nc):
        _modal_one(
            cap[c],
            g[c],
            pa[c],
            pb[c],
            pw[c],
            bc_type,
            bc_h,
            theta,
            dt,
            s,
            ue,
            ui,
            base,
            wp,
            wf,
            feat,
            want,
            out[c],
            t0[c],
            tend[c],
        )
    return out, tend
