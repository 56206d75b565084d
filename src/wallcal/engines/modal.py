"""The exact fast path for walls with constant properties: the theta scheme, diagonalised.

For a wall whose conductances do not depend on temperature, a step of the scheme

    M T^{n+1} = N T^n + p s^n,   M = Cap/dt + K_theta,   N = Cap/dt - K_{1-theta}

(``K_w`` the conductance matrix of the unknown nodes with each term weighted by ``w``, boundary
coefficients included (:func:`wallcal.engines.operator.assemble_operator`); ``p`` the input
coupling, one column per boundary input; ``s^n = theta u^{n+1} + (1 - theta) u^n`` with the theta of
the term through which each input enters) is diagonalised by the symmetric generalized
eigenproblem ``N v = mu M v`` with ``V^T M V = I``. Each mode then follows the real first-order
recursion

    z_k^{n+1} = mu_k z_k^n + r_k . s^n,   z = V^T M T,   r = V^T p,

which is the same linear algebra as the tridiagonal solve (results agree to round-off). Since
``M - N = K`` (the weights of each term add up to one), ``N v = mu M v`` is ``K v = nu M v`` with
``mu = 1 - nu``: one symmetric-definite pencil of two tridiagonal matrices for every candidate, whatever
its thetas (theta raised by the theta rule, nodes without capacity), and ``1 - mu = nu`` comes without the
cancellation of slow modes (``mu`` close to 1). The kernel runs the recursion on the state scaled by the
interior coupling, ``y_k = z_k / r_{k,i}``, so that the interior input enters unscaled:
``y <- mu y + (alpha s_e + s_i)``, two multiply-adds per mode and step. The modes
are independent, so the loop over them vectorises, and the state stays in
registers for several steps per pass, so the recursion runs at the machine's
multiply-add throughput.

Outputs. An output at grid time ``nk + w`` is a probe row over
``(1 - w) T^nk + w T^{nk+1}``, or a face-flux row over the energy-consistent
two-step average of the states ``nk - 1 .. nk + 2`` (see
:mod:`wallcal.engines.kernels`), plus terms in the boundary inputs. It is formed
from the state at its *anchor* ``base = max(nk - 1, 0)``: the later states are
``mu^j z + (inputs)``, so each output row is

    y = Ge . z^base + H . (s^base, s^base+1, s^base+2) + D . feat,

where ``Ge = G diag(P(mu))`` (times the state's scale in the kernel, see
above) and ``H`` depend on the candidate and on the output's weight *pattern*
(a few: interior, first and last output times; an output between grid times
combines two) and are computed once per candidate.
An output then costs one multiply-add per mode and requested row, fused into
the pass over the modes that steps on to the next anchor.

Per candidate (everything inside the numba batch loop; a batch is split over threads by the caller):

1. ``K``, ``p`` and the output rows are assembled from the node capacities, the
   link conductances and the probe interpolation weights (no Python per candidate).
2. LAPACK reduces the pencil to a standard problem of the same bandwidth (:mod:`wallcal.engines.lapack`:
   ``dpbstf``, the split Cholesky factor of ``M``, and ``dsbgst``): ``C = X^T K X`` tridiagonal with
   ``X^T M X = I``, O(m^2). The eigenvalues ``nu`` of ``C`` come from implicit QL with Wilkinson shifts
   (:func:`tridiag_ql`); its plane rotations are applied only to a few columns (the couplings ``p_e``,
   ``p_i``, the requested output rows and the initial state, mapped by ``X^T`` first), which gives them in
   modal coordinates, ``V^T x = W^T X^T x`` (the initial state as ``W^T X^T M T``), and recorded, so that
   the final state can be mapped back (``T = X W z``). O(m^2) instead of the O(m^3) of a dense ``eigh``;
   LAPACK's own eigensolvers with eigenvectors (``dstevr``: MRRR) took about twice as long as this QL on
   these matrices. The LAPACK routines called here use only level-1 and level-2 BLAS on arrays this small,
   which OpenBLAS runs in the calling thread (no threads inside ours).
3. The output-pattern coefficients (:func:`_pattern_coefficients`), then one pass
   over the steps (:func:`_recursion`): between two anchors five steps apart (5-minute
   data at 1-minute steps), one loop over the modes forms the anchor's output rows and
   steps five times; otherwise the rows are formed by dot products and the state is
   stepped four steps per pass. The input terms of all outputs are added afterwards
   (:func:`_input_terms`).
   Memory does not depend on the number of steps.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..jit import inner, kernel
from . import boundary, lapack, operator

#: columns of the per-output input features (see :func:`output_plan`)
N_FEAT = 6
#: output rows formed in the fused pass of :func:`_recursion` (more requested rows are formed by dot products)
N_FUSED = 5
#: weights per output pattern: probe rows (4 states), exterior and interior face flux (4 + 4), the new and
#: old levels of a step quantity (4 + 4; depth-flux rows)
N_PAT_W = 20


@inner()
def tridiag_ql(d, e, zt, rot_i, rot_cs):
    """Eigenvalues of a symmetric tridiagonal matrix by implicit QL with Wilkinson shifts.

    d : (m,) diagonal, overwritten by the eigenvalues (unsorted);
    e : (m,) off-diagonal, e[i] couples i and i + 1 (e[m-1] is workspace); overwritten.
    zt : (m, r) columns to map to eigenvector coordinates: on return ``W^T zt`` (a column that is
        the unit vector of node i then holds the components at node i of every eigenvector).
    rot_i, rot_cs : storage for the plane rotations (index, (c, s)); the eigenvector matrix is
        ``W = R_1 R_2 ... R_n`` (see :func:`apply_w`). Grown when full.

    Returns (n_rotations, rot_i, rot_cs), n_rotations = -1 if an eigenvalue failed to converge.
    This is EISPACK's tql2 (Numerical Recipes' tqli) with the rotations recorded instead of
    accumulated into a full m x m matrix: only the few columns the outputs need are mapped, and
    the final state is mapped back with the recorded rotations, so the whole decomposition costs
    O(m^2) instead of O(m^3).
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
                for t in range(nrot):  # (loops: a slice copy compiles numba's shape-error formatting)
                    ri[t] = rot_i[t]
                    rc[t, 0] = rot_cs[t, 0]
                    rc[t, 1] = rot_cs[t, 1]
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


@inner()
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


def input_thetas(theta, bc_theta, bc_type):
    """Per candidate (c, 2), the theta of the term through which each face's input enters: the face
    link's for a face with an imposed temperature, the face term's otherwise (the inputs of a step
    are ``s = theta u^{n+1} + (1 - theta) u^n`` with these, see :func:`modal_plan`)."""
    out = np.array(bc_theta, dtype=float, copy=True)
    if boundary.is_known(bc_type[0]):
        out[:, 0] = theta[:, 0]
    if boundary.is_known(bc_type[1]):
        out[:, 1] = theta[:, -1]
    return out


class ModalPlan(NamedTuple):
    """What the modal kernel needs besides the candidate: the same for every candidate.

    For k outputs: ``base`` (k,) anchor step; ``opat`` (k, 2) and ``ow`` (k, 2), the weight
    patterns of the grid times ``nk`` and ``nk + 1`` and their weights ``1 - w`` and ``w``; ``wp``,
    ``wf`` (n_pat, 4) and (n_pat, 16), the weights of the states ``base + 0 .. 3`` in probe rows and in the
    two face-flux rows and the two level rows of a depth flux for each pattern; ``feat`` (6, k), the input
    terms of :func:`output_plan`; ``sw`` (6, k), the theta-weighted inputs ``s`` of the steps
    ``base .. base + 2`` (channels interleaved);
    ``pmain`` (1,), the pattern of most outputs and ``mainw`` (k,) its weight in each output, and
    the other (output, pattern, weight) contributions ``xk, xp, xw``; ``s`` (n_steps, 2), the
    theta-weighted inputs of every step. (Per-output arrays are stored output-last, so that the
    input terms of all outputs are added in one vectorised pass.)
    """

    base: np.ndarray
    opat: np.ndarray
    ow: np.ndarray
    wp: np.ndarray
    wf: np.ndarray
    feat: np.ndarray
    sw: np.ndarray
    pmain: np.ndarray
    mainw: np.ndarray
    xk: np.ndarray
    xp: np.ndarray
    xw: np.ndarray
    s: np.ndarray


def output_plan(out_step, out_w, n_steps, theta, ue, ui, dt):
    """Per-output weight patterns and input features (the same for every candidate).

    Output k lies between grid times ``nk`` and ``nk + 1`` (``nk + w``). It depends on the states
    ``base .. base + 3`` with ``base = max(nk - 1, 0)``, through the patterns of the two grid times
    (weights ``1 - w`` and ``w``): probe rows are linear in time, face-flux rows use the
    energy-consistent average ``q^j = (F^{j-1/2} + F^{j+1/2}) / 2`` (one-sided at the ends).

    ``theta`` = (theta_e, theta_i): the theta of the term through which each face's input enters.

    Returns
    -------
    base : (k,) int
    opat, ow : (k, 2) int, (k, 2) float
        The patterns of grid times ``nk`` and ``nk + 1`` and their weights.
    wp : (n_pat, 4), wf : (n_pat, 16)
        Weights of the states ``base + 0 .. 3`` in probe rows, in the exterior (``wf[:, :4]``)
        and interior (``wf[:, 4:8]``) face-flux rows, and in the new (``wf[:, 8:12]``) and old
        (``wf[:, 12:]``) level rows of a step quantity (depth fluxes), per pattern.
    feat : (k, 6)
        Input terms: ``u_e, u_i`` interpolated in time (probe rows on a known face node), then the
        same two-step averages of ``u_e, u_i`` and of their central differences ``du/dt`` (flux rows).
    """
    nk = np.asarray(out_step, dtype=np.int64)
    w = np.asarray(out_w, dtype=float)
    n_out = len(nk)
    base = np.maximum(nk - 1, 0)
    feat = np.zeros((n_out, N_FEAT))
    rows = np.arange(n_out)
    feat[:, 0] = (1.0 - w) * ue[nk] + w * ue[nk + 1]
    feat[:, 1] = (1.0 - w) * ui[nk] + w * ui[nk + 1]
    pats = np.zeros((2, n_out, N_PAT_W))  # per grid time nk + jj: probe (4), face flux (4 + 4), new, old (4 + 4)
    keys = np.zeros((2, n_out), dtype=np.int64)  # what the weights depend on: offset and kind
    for jj in (0, 1):
        j = nk + jj
        wt = (1.0 - w) if jj == 0 else w
        pats[jj, rows, j - base] = 1.0
        jm = np.maximum(j - 1, 0)
        jp = np.minimum(j + 1, n_steps)
        for f, (th, u) in enumerate(((theta[0], ue), (theta[1], ui))):
            a = np.where(j == 0, 0.0, np.where(j >= n_steps, 1.0 - th, 0.5 * (1.0 - th)))
            b = np.where(j == 0, 1.0 - th, np.where(j >= n_steps, th, 0.5))
            c = np.where(j == 0, th, np.where(j >= n_steps, 0.0, 0.5 * th))
            for coef, jx in ((a, jm), (b, j), (c, jp)):  # one entry per row: no repeated index
                pats[jj, rows, 4 + 4 * f + jx - base] += coef
            feat[:, 2 + f] += wt * (a * u[jm] + b * u[j] + c * u[jp])
        # the two levels of a step quantity ``F^{n+1/2} = alpha . T^{n+1} + beta . T^n`` (depth-flux rows):
        # its grid-time value (F^{j-1/2} + F^{j+1/2}) / 2 (one-sided at the ends) weighs the new levels
        # T^j, T^{j+1} ("new") and the old levels T^{j-1}, T^j ("old")
        first, end = j == 0, j >= n_steps
        for off, (wm, w0, wp_) in (
            (12, (0.0, np.where(first, 0.0, np.where(end, 1.0, 0.5)), np.where(first, 1.0, np.where(end, 0.0, 0.5)))),
            (16, (np.where(first, 0.0, np.where(end, 1.0, 0.5)), np.where(first, 1.0, np.where(end, 0.0, 0.5)), 0.0)),
        ):
            for coef, jx in ((wm, jm), (w0, j), (wp_, jp)):
                pats[jj, rows, off + jx - base] += coef
        keys[jj] = (j - base) * 3 + np.where(j == 0, 1, np.where(j >= n_steps, 2, 0))
        inv = 1.0 / ((jp - jm) * dt)
        feat[:, 4] += wt * (ue[jp] - ue[jm]) * inv
        feat[:, 5] += wt * (ui[jp] - ui[jm]) * inv
    # the distinct patterns (the weights are a function of the key)
    ukeys, first_of, inv_idx = np.unique(keys.reshape(-1), return_index=True, return_inverse=True)
    uniq = pats.reshape(2 * n_out, N_PAT_W)[first_of]
    opat = np.ascontiguousarray(inv_idx.reshape(2, n_out).T, dtype=np.int64)
    ow = np.ascontiguousarray(np.column_stack([1.0 - w, w]))
    wp = np.ascontiguousarray(uniq[:, :4])
    wf = np.ascontiguousarray(uniq[:, 4:])
    return base, opat, ow, wp, wf, feat


def modal_plan(out_step, out_w, theta, ue, ui, dt) -> ModalPlan:
    """The plan of the modal kernel (:class:`ModalPlan`) for one prepared simulation; ``theta`` =
    (theta_e, theta_i), the theta of the terms through which the inputs enter (see :func:`input_thetas`)."""
    ue = np.asarray(ue, dtype=float)
    ui = np.asarray(ui, dtype=float)
    n_steps = len(ue) - 1
    s = np.empty((n_steps, 2))
    s[:, 0] = theta[0] * ue[1:] + (1.0 - theta[0]) * ue[:-1]
    s[:, 1] = theta[1] * ui[1:] + (1.0 - theta[1]) * ui[:-1]
    base, opat, ow, wp, wf, feat = output_plan(out_step, out_w, n_steps, theta, ue, ui, dt)
    if len(base) > 1 and (np.diff(base) < 0).any():
        raise ValueError("output times must be in increasing order")
    sw = np.zeros((len(base), 6))
    if n_steps:
        for i in range(3):
            j = np.minimum(base + i, n_steps - 1)  # beyond the end the weights are 0
            sw[:, 2 * i] = s[j, 0]
            sw[:, 2 * i + 1] = s[j, 1]
    # the pattern of most outputs is handled densely, the others (first and last outputs, outputs
    # between grid times) as a short list of (output, pattern, weight)
    n_out = len(base)
    ks = np.concatenate([np.arange(n_out), np.arange(n_out)])
    ps = np.concatenate([opat[:, 0], opat[:, 1]])
    ws = np.concatenate([ow[:, 0], ow[:, 1]])
    used = ws != 0.0
    main = int(np.bincount(ps[used], minlength=1).argmax()) if used.any() else 0
    mainw = np.zeros(n_out)
    is_main = used & (ps == main)
    np.add.at(mainw, ks[is_main], ws[is_main])
    rest = used & (ps != main)
    return ModalPlan(
        base,
        opat,
        ow,
        wp,
        wf,
        np.ascontiguousarray(feat.T),
        np.ascontiguousarray(sw.T),
        np.array([main], dtype=np.int64),
        mainw,
        ks[rest].astype(np.int64),
        ps[rest].astype(np.int64),
        ws[rest],
        s,
    )


@inner()
def _rows(cap, g, pa, pb, pw, dl, dw, bc_type, bc_h, j0, m, kd, ko, G_nodes, D):
    """K over the unknowns (kd, ko), output rows over nodes and their input coefficients.

    dl : (n_d,) link of each depth-flux plane; dw : (n_d, 4) the weights of its two nodes ``dl, dl + 1``
    in the new level (``dw[:, :2]``) and the old level (``dw[:, 2:]``) of the step flux (a known face
    node's weights are left to the caller: they multiply the input).
    G_nodes : (n_q, m) output rows over the unknown temperatures (probes, q_e, q_i, then the new and the
    old level of each depth flux);
    D : (n_q, 6) coefficients of the input features of :func:`output_plan`.
    Returns the input couplings (p_e at unknown 0, p_i at unknown m - 1).
    """
    n_nodes = cap.shape[0]
    n_links = g.shape[0]
    npr = pa.shape[0]
    w_links = np.empty(n_links)  # (np.empty in few shapes only: each numpy call compiles numpy's code)
    w_faces = np.empty(2)
    w_links[:] = 1.0
    w_faces[:] = 1.0
    pe, pi = operator.assemble_operator(g, w_links, bc_type, bc_h, w_faces, j0, m, kd, ko)
    for q in range(G_nodes.shape[0]):
        for i in range(m):
            G_nodes[q, i] = 0.0
        for c in range(N_FEAT):
            D[q, c] = 0.0
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
    # face fluxes (positive towards the interior): a T_face + b u + c du/dt + d u_interp (boundary.flux_row);
    # feature columns of u_e: 0 interpolated, 2 two-step average, 4 rate; of u_i: 1, 3, 5
    for f in range(2):
        q = npr + f
        side = 1.0 if f == 0 else -1.0
        i = 0 if f == 0 else m - 1
        a, b, c, d = boundary.flux_row(
            bc_type[f], bc_h[f], g[0 if f == 0 else n_links - 1], cap[0 if f == 0 else n_nodes - 1], side
        )
        G_nodes[q, i] += a
        D[q, 2 + f] = b
        D[q, 4 + f] = c
        D[q, f] = d
    for dd in range(dl.shape[0]):
        for lev in range(2):
            q = npr + 2 + 2 * dd + lev
            for e in range(2):
                i = dl[dd] + e - j0
                if 0 <= i < m:
                    G_nodes[q, i] += dw[dd, 2 * lev + e]
    return pe, pi


@inner()
def _pattern_coefficients(mu, r0, r1, rho, G, npr, rq, wp, wf, Gs, H):
    """Per output pattern and requested row: ``Gs = G P(mu) rho`` over the anchor's scaled state
    ``y = z / rho`` and ``H``, the coefficients of ``s`` at steps base .. base + 2 (channels
    interleaved); see the module docstring."""
    m = mu.shape[0]
    P = np.empty(m)
    Q = np.empty((3, m))
    for p in range(wp.shape[0]):
        for q in rq:
            if q < npr:  # probe rows
                w = wp[p]
            elif q < npr + 2:  # face fluxes
                w = wf[p, 4 * (q - npr) : 4 * (q - npr) + 4]
            else:  # depth-flux rows: the new level, then the old level of each
                w = wf[p, 8 + 4 * ((q - npr) % 2) : 12 + 4 * ((q - npr) % 2)]
            for k in range(m):
                u = mu[k]
                P[k] = w[0] + u * (w[1] + u * (w[2] + u * w[3]))
                Q[0, k] = w[1] + u * (w[2] + u * w[3])
                Q[1, k] = w[2] + u * w[3]
                Q[2, k] = w[3]
            for k in range(m):
                Gs[p, q, k] = G[q, k] * P[k] * rho[k]
            for i in range(3):
                h0 = 0.0
                h1 = 0.0
                for k in range(m):
                    gq = G[q, k] * Q[i, k]
                    h0 += gq * r0[k]
                    h1 += gq * r1[k]
                H[p, q, 2 * i] = h0
                H[p, q, 2 * i + 1] = h1


@inner(fastmath=True)
def _input_terms(out, rq, H, D, feat, sw, pmain, mainw, xk, xp, xw):
    """Add the input terms of every output, ``sum_p w_p H[p, q] . sw + D[q] . feat``: the main
    pattern and the non-zero ``D`` coefficients in passes vectorised over the outputs, the other
    patterns' few contributions one by one."""
    n_out = out.shape[1]
    p = pmain[0]
    for q in rq:
        oq = out[q]
        h0, h1, h2, h3, h4, h5 = H[p, q, 0], H[p, q, 1], H[p, q, 2], H[p, q, 3], H[p, q, 4], H[p, q, 5]
        for k in range(n_out):
            oq[k] += mainw[k] * (
                (h0 * sw[0, k] + h1 * sw[1, k]) + (h2 * sw[2, k] + h3 * sw[3, k]) + (h4 * sw[4, k] + h5 * sw[5, k])
            )
        for c in range(N_FEAT):
            d = D[q, c]
            if d != 0.0:
                for k in range(n_out):
                    oq[k] += d * feat[c, k]
        for j in range(xk.shape[0]):
            k = xk[j]
            acc = 0.0
            for i in range(6):
                acc += H[xp[j], q, i] * sw[i, k]
            oq[k] += xw[j] * acc


@inner(fastmath=True)
def _recursion(y, mu, al, s, base, opat, ow, pm0, n_rq, fq, gf, Gs, rq, out, n_steps):
    """The pass over the steps of one candidate, stopping at each output's anchor (see the module
    docstring): the hot loop, in one function compiled with fastmath (the candidate's set-up around it
    does not need it, and compiles faster without). The scaled modal state ``y = z / r1`` advances by
    ``y <- mu y + (alpha s0 + s1)``, two multiply-adds per mode and step, several steps per pass over
    the modes (the state stays in a register in between)."""
    m = y.shape[0]
    n_out = base.shape[0]
    n = np.int64(0)
    k_out = 0
    while True:
        # to the next anchor: four steps per pass over the modes, then single steps
        b = base[k_out] if k_out < n_out else np.int64(n_steps)
        while n + 4 <= b:
            a0, a1, a2, a3 = s[n, 0], s[n + 1, 0], s[n + 2, 0], s[n + 3, 0]
            b0, b1, b2, b3 = s[n, 1], s[n + 1, 1], s[n + 2, 1], s[n + 3, 1]
            for k in range(m):
                u = mu[k]
                f = al[k]
                yk = u * y[k] + (f * a0 + b0)
                yk = u * yk + (f * a1 + b1)
                yk = u * yk + (f * a2 + b2)
                y[k] = u * yk + (f * a3 + b3)
            n += 4
        while n < b:
            a0 = s[n, 0]
            b0 = s[n, 1]
            for k in range(m):
                y[k] = mu[k] * y[k] + (al[k] * a0 + b0)
            n += 1
        if k_out >= n_out:
            break
        k2 = k_out + 1
        while k2 < n_out and base[k2] == b:
            k2 += 1
        last = k2 - 1
        nxt = base[k2] if k2 < n_out else n_steps
        fused = nxt - b == 5 and ow[last, 1] == 0.0 and opat[last, 0] == pm0 and n_rq <= N_FUSED
        for kk in range(k_out, k2 - 1 if fused else k2):
            # an output from the state at its anchor: a dot product per requested row and pattern
            # (the input terms are added by _input_terms)
            for q in rq:
                acc = 0.0
                for c2 in range(2):
                    wgt = ow[kk, c2]
                    if wgt == 0.0:
                        continue
                    gq = Gs[opat[kk, c2], q]
                    dot = 0.0
                    for k in range(m):
                        dot += gq[k] * y[k]
                    acc += wgt * dot
                out[q, kk] = acc
        if fused:
            # the last output of the anchor (the dot products of the state with the five rows of gf,
            # padded with zero rows) and five steps on, in one pass over the modes. (The rows are one
            # 2-D array indexed by constants: separate arrays, or a 3-D array indexed by runtime rows,
            # need more runtime aliasing checks than LLVM accepts, and the loop then runs scalar.)
            a0, a1, a2, a3, a4 = s[b, 0], s[b + 1, 0], s[b + 2, 0], s[b + 3, 0], s[b + 4, 0]
            b0, b1, b2, b3, b4 = s[b, 1], s[b + 1, 1], s[b + 2, 1], s[b + 3, 1], s[b + 4, 1]
            d0 = 0.0
            d1 = 0.0
            d2 = 0.0
            d3 = 0.0
            d4 = 0.0
            for k in range(m):
                zk = y[k]
                d0 += gf[0, k] * zk
                d1 += gf[1, k] * zk
                d2 += gf[2, k] * zk
                d3 += gf[3, k] * zk
                d4 += gf[4, k] * zk
                u = mu[k]
                f = al[k]
                zk = u * zk + (f * a0 + b0)
                zk = u * zk + (f * a1 + b1)
                zk = u * zk + (f * a2 + b2)
                zk = u * zk + (f * a3 + b3)
                y[k] = u * zk + (f * a4 + b4)
            w0 = ow[last, 0]
            d5 = (d0, d1, d2, d3, d4)
            for i in range(n_rq):
                out[fq[i], last] = w0 * d5[i]
            n = b + 5
        k_out = k2


def modal_batch(*args):
    """Run every candidate through its modal recursion: :func:`modal_kernel` (its arguments), once the LAPACK
    routines it calls are linked (:func:`wallcal.engines.lapack.link`)."""
    lapack.link()
    return modal_kernel(*args)


@kernel
def modal_kernel(
    caps, gs, thetas, bc_thetas, pas, pbs, pws, dl, dws, bc_type, bc_h, theta, dt, ue, ui, plan, want, t0s,
    pos, outs, tends,
):  # fmt: skip
    """Run every candidate through its modal recursion (see module docstring). Releases the GIL: a
    caller runs parts of a batch in threads (:func:`wallcal.engines.fd.in_threads`). Call it through
    :func:`modal_batch` (which links the LAPACK routines it calls).

    Parameters (c = candidate, j = node, l = link, p = probe, k = output time)
    ----------
    cap : (c, j) node heat capacities; g : (c, l) link conductances
    pa, pb, pw : (c, p) probe interpolation (see :func:`wallcal.grid.probe_weights`)
    dl : (d,) link of each depth-flux plane; dws : (c, d, 4) the weights of its nodes in the step flux's
        new and old level (see :func:`_rows`)
    bc_type : (2,) boundary codes; bc_h : (2,) surface coefficients
    thetas : (c, l), bc_thetas : (c, 2) theta of each link and face term
        (:func:`wallcal.engines.operator.link_thetas`); the terms through which the inputs enter must
        have the thetas the plan was made with (:func:`input_thetas`); theta : the scheme's theta;
        dt : time step [s]
    ue, ui : (n_steps + 1,) inputs
    plan : :class:`ModalPlan` (a tuple of arrays, the same for every candidate)
    want : (p + 2,) bool, the output rows to form (the others are NaN)
    t0 : (c, j) initial node temperatures, or shape (c, 0) for the steady state of the first inputs
    pos : (c,) the row of each candidate in ``outs`` and ``tends``, the caller's arrays that the run fills:
        outs (n, p + 2 + 2 d, k) the outputs, tends (n, j) the final node temperatures (known face nodes
        included), n >= c

    ``want`` (p + 2 + 2 d,) bool: the output rows to form (others are left NaN); fewer rows need fewer
    eigenvector components and less work per output time. A candidate whose pencil LAPACK cannot reduce
    or whose QL does not converge gets NaN outputs. (One function with the candidate loop around the
    body: each level of njit calls re-optimises its callees, so a wrapper costs compile time.)
    """
    # LAPACK's scalar arguments (Fortran: by reference): n, 1 (ka = kb = 1), 2 (ldab = ldbb), info
    iargs = np.empty(4, dtype=np.int32)
    iargs[1] = 1
    iargs[2] = 2
    n_arg = iargs[0:]
    one_arg = iargs[1:]
    two_arg = iargs[2:]
    info = iargs[3:]
    chars = np.empty(2, dtype=np.uint8)
    chars[0] = 86  # "V": form X
    chars[1] = 76  # "L": band storage of the lower triangle
    for cand in range(caps.shape[0]):
        cap = caps[cand]
        g = gs[cand]
        pa = pas[cand]
        pb = pbs[cand]
        pw = pws[cand]
        dw = dws[cand]
        t0 = t0s[cand]
        out = outs[pos[cand]]
        tend = tends[pos[cand]]
        base, opat, ow, wp, wf, feat, sw, pmain, mainw, xk, xp, xw, s = plan
        n_nodes = cap.shape[0]
        j0, m = operator.unknown_range(n_nodes, bc_type)
        npr = pa.shape[0]
        n_q = npr + 2 + 2 * dl.shape[0]
        n_steps = ue.shape[0] - 1
        kd = np.empty(m)
        ko = np.empty(m)
        G_nodes = np.empty((n_q, m))
        D = np.empty((n_q, N_FEAT))
        pe, pi = _rows(cap, g, pa, pb, pw, dl, dw, bc_type, bc_h, j0, m, kd, ko, G_nodes, D)
        n_rq = np.int64(0)  # (not a literal 0: numba would compile _recursion for Literal[int](0) too)
        for q in range(n_q):
            if want[q]:
                n_rq += 1
        rq = np.empty(n_rq, dtype=np.int64)
        fq = np.empty(N_FUSED, dtype=np.int64)  # fused rows, padded with the zero row n_q
        fq[:] = n_q
        n_rq = np.int64(0)
        for q in range(n_q):
            if want[q]:
                rq[n_rq] = q
                if n_rq < N_FUSED:
                    fq[n_rq] = q
                n_rq += 1
            else:
                out[q, :] = np.nan
        has_t0 = t0.shape[0] == n_nodes
        # (work arrays by np.empty in a few shapes only: each other numpy call compiles numpy's code)
        mu = np.empty(m)
        r0 = np.empty(m)
        r1 = np.empty(m)
        z = np.empty(m)  # modal state
        G = np.empty((n_q, m))  # output rows in modal coordinates
        rot_i = np.empty(2 * m * m, dtype=np.int64)
        rot_cs = np.empty((2 * m * m, 2))
        # The step M T^{n+1} = N T^n + p s^n, M = Cap/dt + K_theta, N = Cap/dt - K_{1-theta} = M - K (both
        # symmetric tridiagonal, M positive definite): K v = nu M v with V^T M V = I diagonalises it with
        # mu = 1 - nu (and 1 - mu = nu without cancellation for slow modes). LAPACK reduces the pencil to
        # C = X^T K X (tridiagonal) with X^T M X = I (split Cholesky factor of M and plane rotations:
        # dpbstf, dsbgst; O(m^2)); the QL of C gives C = W diag(nu) W^T, so V = X W.
        md = np.empty(m)
        mo = np.empty(m)
        operator.assemble_operator(g, thetas[cand], bc_type, bc_h, bc_thetas[cand], j0, m, md, mo)
        ab = np.empty((m, 2))  # K, then C (Fortran band storage (2, m): diagonal, subdiagonal)
        bb = np.empty((m, 2))  # M, then its split Cholesky factor
        for i in range(m):
            md[i] += cap[j0 + i] / dt
            ab[i, 0] = kd[i]
            ab[i, 1] = ko[i]
            bb[i, 0] = md[i]
            bb[i, 1] = mo[i]
        x = np.empty((m, m))  # X^T (C order): x[k] is column k of X
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
        # the tridiagonal eigenproblem of C (d, ee) and the columns zt its QL rotations map to modal
        # coordinates: V^T x = W^T X^T x for the couplings p_e, p_i and the requested output rows, then
        # (with an initial state) z = V^T M T = W^T X^T M T
        d = np.empty(m)
        ee = np.empty(m)
        for i in range(m):
            d[i] = ab[i, 0]
            ee[i] = ab[i, 1]
        ncol = 3 + n_q if has_t0 else 2 + n_q
        zt = np.empty((m, ncol))
        mt = np.empty(m)  # M T (unknowns)
        if has_t0:
            for i in range(m):
                mt[i] = md[i] * t0[j0 + i]
                if i > 0:
                    mt[i] += mo[i - 1] * t0[j0 + i - 1]
                if i + 1 < m:
                    mt[i] += mo[i] * t0[j0 + i + 1]
        for k in range(m):
            xrow = x[k]
            zt[k, 0] = xrow[0] * pe
            zt[k, 1] = xrow[m - 1] * pi
            for q in range(n_q):
                acc = 0.0
                if want[q]:
                    gq = G_nodes[q]
                    for i in range(m):
                        acc += xrow[i] * gq[i]
                zt[k, 2 + q] = acc
            if has_t0:
                acc = 0.0
                for i in range(m):
                    acc += xrow[i] * mt[i]
                zt[k, ncol - 1] = acc
        nrot, rot_i, rot_cs = tridiag_ql(d, ee, zt, rot_i, rot_cs)
        if nrot < 0:
            out[:, :] = np.nan
            tend[:] = np.nan
            continue
        for k in range(m):
            mu[k] = 1.0 - d[k]
            r0[k] = zt[k, 0]
            r1[k] = zt[k, 1]
            # steady start: the fixed point of z <- mu z + r u^0 (that of M T = N T + p u^0: K T = p u^0)
            z[k] = zt[k, ncol - 1] if has_t0 else (r0[k] * ue[0] + r1[k] * ui[0]) / d[k]
            for q in range(n_q):
                G[q, k] = zt[k, 2 + q]
        # the state scaled by the interior coupling, y = z / r1: the interior input then enters unscaled
        # and a step costs two multiply-adds per mode instead of three (a mode the interior does not
        # reach gets a negligible stand-in coupling instead of a zero, 1e-150 of the largest)
        rmax = 0.0
        for k in range(m):
            if abs(r0[k]) > rmax:
                rmax = abs(r0[k])
            if abs(r1[k]) > rmax:
                rmax = abs(r1[k])
        tiny = 1e-150 * rmax if rmax > 0.0 else 1e-150
        rho = np.empty(m)
        al = np.empty(m)
        y = np.empty(m)
        for k in range(m):
            rk = r1[k]
            if abs(rk) < tiny:
                rk = tiny
            rho[k] = rk
            al[k] = r0[k] / rk
            y[k] = z[k] / rk
        # per output pattern: Gs = G P(mu) rho over the scaled state and H (the requested rows; row n_q
        # is zero: the padding of the fused rows)
        n_pat = wp.shape[0]
        Gs = np.empty((n_pat, n_q + 1, m))
        H = np.empty((n_pat, n_q + 1, 6))
        for p in range(n_pat):
            for k in range(m):
                Gs[p, n_q, k] = 0.0
        _pattern_coefficients(mu, r0, r1, rho, G, npr, rq, wp, wf, Gs, H)
        # the fused rows of the main pattern, extracted once (a view per output would cost reference
        # counting in the loop; other patterns are formed by dot products)
        pm0 = pmain[0]
        gf = np.empty((N_FUSED, m))  # one array: LLVM checks its rows against the state as one object
        for i in range(N_FUSED):
            for k in range(m):
                gf[i, k] = Gs[pm0, fq[i], k]
        # one pass over the steps, stopping at each anchor
        _recursion(y, mu, al, s, base, opat, ow, pm0, n_rq, fq, gf, Gs, rq, out, n_steps)
        _input_terms(out, rq, H, D, feat, sw, pmain, mainw, xk, xp, xw)
        for k in range(m):
            z[k] = rho[k] * y[k]
        # final temperatures T = V z = X W z
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
