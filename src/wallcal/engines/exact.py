"""The exact scheme (``fd-exact``) for walls with constant properties: the semi-discrete system solved exactly in time.

On its grid a wall is the linear system

    Cap T' = -K T + p u(t)

(``K`` the conductance matrix over the unknown nodes, face terms included, ``p`` the input couplings,
:func:`wallcal.engines.operator.assemble_operator`; ``u = (u_e, u_i)``). The inputs are linear between
their samples (the grid times), and for such inputs this system has an exact discrete solution: neither
the time step nor a theta enters the result, only the grid's spatial error remains.

Modes. ``K v = lambda M v`` with ``M = Cap/dt + K`` (positive definite even where a node has no heat
capacity) and ``V^T M V = I`` is the pencil of the modal path (:mod:`wallcal.engines.modal`: LAPACK's
``dpbstf``/``dsbgst`` and the QL with recorded rotations) with theta = 1 on every term. Since
``V^T Cap V = dt (I - Lambda)`` and ``V^T K V = Lambda``, the coordinates ``z = V^T M T`` obey

    z_k' = -nu_k z_k + r_k . u / (dt (1 - lambda_k)),   nu_k = lambda_k / (dt (1 - lambda_k)),  r = V^T p,

one first-order equation per mode (``0 < lambda_k < 1``; a mode of nodes without capacity has
``lambda_k = 1``: ``nu_k`` infinite, the mode algebraic). Split ``z = r u / lambda + zeta``: the first
part is the steady response to the input at that instant (``K T = p u``), and the lag ``zeta`` obeys
``zeta' = -nu zeta - (r / lambda) . u'``, with ``u'`` constant over each step. Its exact step is

    zeta^{n+1} = E zeta^n - beta r . (u^{n+1} - u^n) / dt,   E = exp(-nu dt),
    beta = dt (1 - lambda) (1 - E) / lambda^2

(``1 - E`` by ``expm1``: no cancellation as ``nu dt -> 0``; an algebraic mode has ``E = beta = 0``).
Between grid times, at ``t_n + w dt``, the same formulas with ``w dt``: outputs between grid times are
exact too. The steady start is ``zeta = 0``.

Outputs are instantaneous at the output times: probes linear between nodes; face fluxes
``h (u - T_s)``, ``g (u - T_1) + c_0 du/dt`` on a face with an imposed temperature (``du/dt`` the
central difference at grid times, linear in between, as on the theta paths) and the imposed flux on a
heat-flux face; the flux through an inner plane is the link flux ``g (T_a - T_b)``, on a node ``k`` the
flux into the next link plus the heat stored by the node's part on the interior side,
``F_k + c_k^+ dT_k/dt`` with ``c_k dT_k/dt = F_{k-1} - F_k`` (the node's balance), i.e.
``(1 - f) F_k + f F_{k-1}`` with ``f = c_k^+ / c_k``. These are the exact system's own fluxes: the stored
energy changes at the rate ``q_e - q_i`` at every instant (the balance closes;
``fd-reference`` integrates it, :func:`wallcal.engines.reference.solve_exact`).

Cost per candidate: the decomposition of the modal path (O(m^2)), then three multiply-adds per mode and
step and one dot product per mode, output and requested row.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..jit import inner, kernel
from . import boundary, lapack, operator
from .modal import apply_w, tridiag_ql

#: lambda_k above 1 - this: a mode of nodes without heat capacity (algebraic)
ALGEBRAIC = 1e-13


class ExactPlan(NamedTuple):
    """What the exact kernel needs besides the candidate (the same for every candidate).

    ``out_step`` (k,), ``out_w`` (k,): output ``k`` at grid time ``out_step + out_w``; ``feat`` (4, k): the inputs
    ``u_e, u_i`` and their rates ``du_e/dt, du_i/dt`` at the output times; ``slope`` (n_steps, 2): the inputs'
    rate over each step [unit/s].
    """

    out_step: np.ndarray
    out_w: np.ndarray
    feat: np.ndarray
    slope: np.ndarray


def exact_plan(out_step, out_w, ue, ui, dt) -> ExactPlan:
    """The plan of :func:`exact_kernel` for one prepared simulation."""
    u = np.column_stack([np.asarray(ue, dtype=float), np.asarray(ui, dtype=float)])
    nk = np.asarray(out_step, dtype=np.int64)
    w = np.asarray(out_w, dtype=float)
    rate = np.empty_like(u)  # central differences at grid times (one-sided at the ends)
    rate[1:-1] = (u[2:] - u[:-2]) / (2.0 * dt)
    rate[0] = (u[1] - u[0]) / dt
    rate[-1] = (u[-1] - u[-2]) / dt
    feat = np.empty((4, len(nk)))
    for f in range(2):
        feat[f] = (1.0 - w) * u[nk, f] + w * u[nk + 1, f]
        feat[2 + f] = (1.0 - w) * rate[nk, f] + w * rate[nk + 1, f]
    if len(nk) > 1 and (np.diff(nk) < 0).any():
        raise ValueError("output times must be in increasing order")
    slope = np.ascontiguousarray((u[1:] - u[:-1]) / dt)
    return ExactPlan(nk, np.ascontiguousarray(w), np.ascontiguousarray(feat), slope)


@inner()
def _exact_rows(cap, g, pa, pb, pw, dl, dfr, bc_type, bc_h, j0, m, G_nodes, D):
    """Output rows over the unknown temperatures ``G_nodes`` (n_q, m) and their input coefficients ``D`` (n_q, 4)
    (columns: ``u_e``, ``u_i``, ``du_e/dt``, ``du_i/dt`` at the output time): probes, the two face fluxes, then
    the flux through each inner plane ``(1 - f) F_l + f F_{l-1}`` (``dl`` its link, ``dfr`` its ``f``)."""
    n_nodes = cap.shape[0]
    n_links = g.shape[0]
    npr = pa.shape[0]
    for q in range(G_nodes.shape[0]):
        for i in range(m):
            G_nodes[q, i] = 0.0
        for c in range(4):
            D[q, c] = 0.0
    for q in range(npr):
        for node, wgt in ((pa[q], 1.0 - pw[q]), (pb[q], pw[q])):
            _add(G_nodes, D, q, node, wgt, j0, m)
    for f in range(2):
        q = npr + f
        side = 1.0 if f == 0 else -1.0
        i = 0 if f == 0 else m - 1
        a, b, c, d = boundary.flux_row(
            bc_type[f], bc_h[f], g[0 if f == 0 else n_links - 1], cap[0 if f == 0 else n_nodes - 1], side
        )
        G_nodes[q, i] += a
        D[q, f] += b + d
        D[q, 2 + f] += c
    for dd in range(dl.shape[0]):
        q = npr + 2 + dd
        lnk = dl[dd]
        fr = dfr[dd]
        wl = (1.0 - fr) * g[lnk]
        _add(G_nodes, D, q, lnk, wl, j0, m)
        _add(G_nodes, D, q, lnk + 1, -wl, j0, m)
        if fr != 0.0:
            wp = fr * g[lnk - 1]
            _add(G_nodes, D, q, lnk - 1, wp, j0, m)
            _add(G_nodes, D, q, lnk, -wp, j0, m)


@inner()
def _add(G_nodes, D, q, node, wgt, j0, m):
    """Add ``wgt`` times node ``node``'s temperature to row ``q`` (a known face node through its input)."""
    i = node - j0
    if 0 <= i < m:
        G_nodes[q, i] += wgt
    elif node < j0:
        D[q, 0] += wgt
    else:
        D[q, 1] += wgt


def exact_batch(*args):
    """:func:`exact_kernel` once the LAPACK routines it calls are linked."""
    lapack.link()
    return exact_kernel(*args)


@kernel
def exact_kernel(caps, gs, pas, pbs, pws, dl, dfrs, bc_type, bc_h, dt, ue, ui, plan, want, t0s, pos, outs, tends):
    """Run every candidate through the exact modal solution (see the module docstring). Releases the GIL.

    Parameters (c = candidate, j = node, l = link, p = probe, d = inner depth plane, k = output time)
    ----------
    caps : (c, j) node heat capacities [J/(m2K)]; gs : (c, l) link conductances [W/(m2K)]
    pas, pbs, pws : (c, p) probe interpolation (:func:`wallcal.grid.probe_weights`)
    dl : (d,) link of each inner depth plane; dfrs : (c, d) its ``f`` (module docstring; 0 between nodes)
    bc_type, bc_h : (2,) boundary codes and surface coefficients; dt : time step [s]
    ue, ui : (n_steps + 1,) inputs; plan : :class:`ExactPlan`
    want : (p + 2 + d,) bool, the rows to form (the others are NaN)
    t0s : (c, j) initial node temperatures, or shape (c, 0) for the steady state of the first inputs
    pos : (c,) row of each candidate in ``outs`` (n, p + 2 + d, k) and ``tends`` (n, j) (final temperatures)

    A candidate whose pencil LAPACK cannot reduce or whose QL does not converge gets NaN.
    """
    iargs = np.empty(4, dtype=np.int32)
    iargs[1] = 1
    iargs[2] = 2
    n_arg = iargs[0:]
    one_arg = iargs[1:]
    two_arg = iargs[2:]
    info = iargs[3:]
    chars = np.empty(2, dtype=np.uint8)
    chars[0] = 86  # "V"
    chars[1] = 76  # "L"
    out_step, out_w, feat, slope = plan
    n_steps = ue.shape[0] - 1
    n_out = out_step.shape[0]
    for cand in range(caps.shape[0]):
        cap = caps[cand]
        g = gs[cand]
        t0 = t0s[cand]
        out = outs[pos[cand]]
        tend = tends[pos[cand]]
        n_nodes = cap.shape[0]
        j0, m = operator.unknown_range(n_nodes, bc_type)
        npr = pas.shape[1]
        n_q = npr + 2 + dl.shape[0]
        G_nodes = np.empty((n_q, m))
        D = np.empty((n_q, 4))
        _exact_rows(cap, g, pas[cand], pbs[cand], pws[cand], dl, dfrs[cand], bc_type, bc_h, j0, m, G_nodes, D)
        kd = np.empty(m)
        ko = np.empty(m)
        ones = np.empty(g.shape[0])
        ones[:] = 1.0
        ones2 = np.empty(2)
        ones2[:] = 1.0
        pe, pi = operator.assemble_operator(g, ones, bc_type, bc_h, ones2, j0, m, kd, ko)
        has_t0 = t0.shape[0] == n_nodes
        # the pencil K v = lambda M v, M = Cap/dt + K (banded storage: diagonal, subdiagonal)
        ab = np.empty((m, 2))
        bb = np.empty((m, 2))
        for i in range(m):
            ab[i, 0] = kd[i]
            ab[i, 1] = ko[i]
            bb[i, 0] = kd[i] + cap[j0 + i] / dt
            bb[i, 1] = ko[i]
        mt = np.empty(m)  # M T0 over the unknowns
        if has_t0:
            for i in range(m):
                mt[i] = bb[i, 0] * t0[j0 + i]
                if i > 0:
                    mt[i] += bb[i - 1, 1] * t0[j0 + i - 1]
                if i + 1 < m:
                    mt[i] += bb[i, 1] * t0[j0 + i + 1]
        x = np.empty((m, m))
        work = np.empty(2 * m)
        n_arg[0] = m
        info[0] = 0
        lapack.dpbstf(chars[1:].ctypes, n_arg.ctypes, one_arg.ctypes, bb.ctypes, two_arg.ctypes, info.ctypes)
        if info[0] == 0:
            lapack.dsbgst(
                chars[0:].ctypes, chars[1:].ctypes, n_arg.ctypes, one_arg.ctypes, one_arg.ctypes, ab.ctypes,
                two_arg.ctypes, bb.ctypes, two_arg.ctypes, x.ctypes, n_arg.ctypes, work.ctypes, info.ctypes,
            )  # fmt: skip
        if info[0] != 0:
            out[:, :] = np.nan
            tend[:] = np.nan
            continue
        d = np.empty(m)
        ee = np.empty(m)
        for i in range(m):
            d[i] = ab[i, 0]
            ee[i] = ab[i, 1]
        ncol = 3 + n_q
        zt = np.empty((m, ncol))  # (np.empty only: each other numpy call compiles numpy's code)
        zt[:, :] = 0.0
        for k in range(m):
            xrow = x[k]
            zt[k, 0] = xrow[0] * pe
            zt[k, 1] = xrow[m - 1] * pi
            for q in range(n_q):
                if want[q]:
                    acc = 0.0
                    gq = G_nodes[q]
                    for i in range(m):
                        acc += xrow[i] * gq[i]
                    zt[k, 2 + q] = acc
            if has_t0:
                acc = 0.0
                for i in range(m):
                    acc += xrow[i] * mt[i]
                zt[k, ncol - 1] = acc
        rot_i = np.empty(2 * m * m, dtype=np.int64)
        rot_cs = np.empty((2 * m * m, 2))
        nrot, rot_i, rot_cs = tridiag_ql(d, ee, zt, rot_i, rot_cs)
        if nrot < 0:
            out[:, :] = np.nan
            tend[:] = np.nan
            continue
        # per mode: decay E, lag coefficient beta, the rate h = nu dt, the input couplings and the steady
        # response per unit input (r / lambda)
        E = np.empty(m)
        h = np.empty(m)
        om = np.empty(m)
        ce = np.empty(m)
        ci = np.empty(m)
        se = np.empty(m)
        si = np.empty(m)
        zeta = np.empty(m)
        for k in range(m):
            lam = d[k]
            o = 1.0 - lam
            re = zt[k, 0]
            ri = zt[k, 1]
            se[k] = re / lam
            si[k] = ri / lam
            if o <= ALGEBRAIC:
                om[k] = 0.0
                h[k] = np.inf
                E[k] = 0.0
                ce[k] = 0.0
                ci[k] = 0.0
            else:
                om[k] = o
                h[k] = lam / o
                E[k] = np.exp(-h[k])
                beta = dt * o * (-np.expm1(-h[k])) / (lam * lam)
                ce[k] = -beta * re
                ci[k] = -beta * ri
            zeta[k] = (zt[k, ncol - 1] - se[k] * ue[0] - si[k] * ui[0]) if has_t0 else 0.0
        # output rows in modal coordinates and the steady response of each row per unit input
        G = np.empty((n_q, m))
        Dq = np.empty((n_q, 4))
        for q in range(n_q):
            ae = 0.0
            ai = 0.0
            for k in range(m):
                G[q, k] = zt[k, 2 + q]
                ae += G[q, k] * se[k]
                ai += G[q, k] * si[k]
            Dq[q, 0] = D[q, 0] + ae
            Dq[q, 1] = D[q, 1] + ai
            Dq[q, 2] = D[q, 2]
            Dq[q, 3] = D[q, 3]
            if not want[q]:
                out[q, :] = np.nan
        zw = np.empty(m)
        n = 0
        for o_ in range(n_out):
            nk = out_step[o_]
            while n < nk:
                a0 = slope[n, 0]
                a1 = slope[n, 1]
                for k in range(m):
                    zeta[k] = E[k] * zeta[k] + (ce[k] * a0 + ci[k] * a1)
                n += 1
            w = out_w[o_]
            if w == 0.0:
                for k in range(m):
                    zw[k] = zeta[k]
            else:
                a0 = slope[nk, 0]
                a1 = slope[nk, 1]
                for k in range(m):
                    if om[k] == 0.0:
                        zw[k] = 0.0
                        continue
                    lam = d[k]
                    bw = dt * om[k] * (-np.expm1(-w * h[k])) / (lam * lam)
                    zw[k] = np.exp(-w * h[k]) * zeta[k] - bw * (zt[k, 0] * a0 + zt[k, 1] * a1)
            for q in range(n_q):
                if not want[q]:
                    continue
                acc = 0.0
                for k in range(m):
                    acc += G[q, k] * zw[k]
                out[q, o_] = acc + (
                    Dq[q, 0] * feat[0, o_] + Dq[q, 1] * feat[1, o_] + Dq[q, 2] * feat[2, o_] + Dq[q, 3] * feat[3, o_]
                )
        while n < n_steps:
            a0 = slope[n, 0]
            a1 = slope[n, 1]
            for k in range(m):
                zeta[k] = E[k] * zeta[k] + (ce[k] * a0 + ci[k] * a1)
            n += 1
        # final temperatures T = X W z, z = zeta + (r / lambda) . u
        z = np.empty(m)
        for k in range(m):
            z[k] = zeta[k] + se[k] * ue[n_steps] + si[k] * ui[n_steps]
        apply_w(nrot, rot_i, rot_cs, z)
        for i in range(n_nodes):
            tend[i] = 0.0
        for k in range(m):
            xrow = x[k]
            zk = z[k]
            for i in range(m):
                tend[j0 + i] += xrow[i] * zk
        if j0 == 1:
            tend[0] = ue[n_steps]
        if boundary.is_known(bc_type[1]):
            tend[n_nodes - 1] = ui[n_steps]
