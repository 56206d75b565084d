"""The operator of a wall on its grid: one assembly for every path.

The grid (:mod:`wallcal.grid`) gives node capacities ``c_j`` [J/(m2K)] and link conductances
``g_l`` [W/(m2K)] (link ``l`` joins nodes ``l`` and ``l + 1``); the faces (:mod:`.boundary`) add
their conductance to the face node and couple the inputs in. :func:`assemble_operator` forms, over
the unknown nodes ``j0 .. j0 + m - 1`` (a face with an imposed temperature is known), the
symmetric tridiagonal

    K_w = sum_l w_l g_l (e_a - e_b)(e_a - e_b)^T + w_e h_e e_0 e_0^T + w_i h_i e_m-1 e_m-1^T

with per-term weights ``w`` (1 for the operator ``K`` itself: steady state, modal path, time
constants; ``theta`` for the implicit part of a step), and the input couplings ``K T = p u``.
:func:`unknown_range` says which nodes are unknown; :func:`link_thetas` chooses theta per term.
"""

from __future__ import annotations

import numpy as np

from ..jit import kernel
from . import boundary


@kernel
def unknown_range(n_nodes, bc_type):
    """(j0, m): the first unknown node and the number of unknowns."""
    j0 = 1 if boundary.is_known(bc_type[0]) else 0
    j1 = n_nodes - 2 if boundary.is_known(bc_type[1]) else n_nodes - 1
    return j0, j1 - j0 + 1


@kernel
def assemble_operator(g, w, bc_type, bc_h, w_bc, j0, m, diag, off):
    """Fill ``diag`` (m,) and ``off`` (m,) with K_w over the unknowns (``off[i]`` couples i and i + 1,
    ``off[m - 1] = 0``); return the input couplings (p_e of unknown 0, p_i of unknown m - 1),
    unweighted (see :func:`wallcal.engines.boundary.input_coupling`)."""
    n_links = g.shape[0]
    for i in range(m):
        diag[i] = 0.0
        off[i] = 0.0
    for lnk in range(n_links):
        wg = w[lnk] * g[lnk]
        ia = lnk - j0
        ib = ia + 1
        if 0 <= ia < m:
            diag[ia] += wg
        if 0 <= ib < m:
            diag[ib] += wg
        if 0 <= ia and ib < m:
            off[ia] = -wg
    diag[0] += w_bc[0] * boundary.face_conductance(bc_type[0], bc_h[0])
    diag[m - 1] += w_bc[1] * boundary.face_conductance(bc_type[1], bc_h[1])
    pe = boundary.input_coupling(bc_type[0], bc_h[0], g[0], 1.0)
    pi = boundary.input_coupling(bc_type[1], bc_h[1], g[n_links - 1], -1.0)
    return pe, pi


@kernel
def link_thetas(cap, g, bc_type, bc_h, theta0, dt, stiff_limit):
    """theta per link (c, l) and per face term (c, 2), and the number of terms whose theta was raised (c,).

    The discrete maximum principle: a step ``T^{n+1} = A^-1 (B T^n + inputs)`` with the M-matrix
    ``A = Cap/dt + K_theta`` is monotone (the response to a step in an input is monotone and bounded by
    the inputs) when ``B = Cap/dt - K_{1-theta}`` has no negative entry, i.e. at every unknown node
    ``sum (1 - theta) g dt <= c_j`` over its terms. With the node stiffness

        s_j = dt (sum of the conductances at node j, face term included) / c_j

    (:func:`wallcal.engines.boundary.face_conductance`; inf for a node without capacity, 0 for a known
    face node), a link between nodes a and b gets

        theta_l = max(theta0, 1 - (1 - theta0) L / max(s_a, s_b)),   L = stiff_limit,

    and an air face's term the same with its face node's stiffness (any face term whose node has no
    capacity: 1). With ``L = 1 / (1 - theta0)`` (2 for Crank-Nicolson, the default) this is exactly
    the condition, met with equality at the stiff nodes; terms between nodes with ``s <= L`` keep
    theta0. ``L = inf`` keeps theta0 except at nodes without capacity (theta 1).

    ``bc_h`` (c, 2): the faces' surface coefficients of each candidate. numba, one function without
    callees of its own and arrays by ``np.empty`` only: it runs on every call of the engine, and each
    jitted callee or other numpy call would add to what a fresh install compiles.
    """
    nc, nl = g.shape
    theta = np.empty((nc, nl))
    bc_theta = np.empty((nc, 2))
    n_raised = np.empty(nc, dtype=np.int64)
    s = np.empty(nl + 1)  # the node stiffness of one candidate
    budget = (1.0 - theta0) * stiff_limit
    for c in range(nc):
        h_e = boundary.face_conductance(bc_type[0], bc_h[c, 0])
        h_i = boundary.face_conductance(bc_type[1], bc_h[c, 1])
        for j in range(nl + 1):
            total = 0.0
            if j < nl:
                total += g[c, j]
            if j > 0:
                total += g[c, j - 1]
            if j == 0:
                total += h_e
            if j == nl:
                total += h_i
            s[j] = total * dt / cap[c, j] if cap[c, j] > 0.0 else np.inf
        if boundary.is_known(bc_type[0]):
            s[0] = 0.0
        if boundary.is_known(bc_type[1]):
            s[nl] = 0.0
        n_raised[c] = 0
        for k in range(nl + 2):  # the links, then the exterior and the interior face term
            if k < nl:
                sk = s[k] if s[k] > s[k + 1] else s[k + 1]
                applies = True
            else:  # a face term enters B through h; a face node without capacity is algebraic
                sk = s[0] if k == nl else s[nl]
                applies = (h_e if k == nl else h_i) > 0.0 or not sk < np.inf
            th = theta0
            if applies and theta0 < 1.0:
                if not sk < np.inf:
                    th = 1.0  # a node without capacity
                elif sk * (1.0 - theta0) > budget:
                    th = 1.0 - budget / sk
            if k < nl:
                theta[c, k] = th
            else:
                bc_theta[c, k - nl] = th
            if th > theta0:
                n_raised[c] += 1
    return theta, bc_theta, n_raised
