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
from numba import njit

from . import boundary


@njit(cache=True)
def unknown_range(n_nodes, bc_type):
    """(j0, m): the first unknown node and the number of unknowns."""
    j0 = 1 if boundary.is_known(bc_type[0]) else 0
    j1 = n_nodes - 2 if boundary.is_known(bc_type[1]) else n_nodes - 1
    return j0, j1 - j0 + 1


@njit(cache=True)
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


@njit(cache=True)
def node_stiffness(cap, g, bc_type, bc_h, dt):
    """``s_j = dt (sum of the conductances at node j) / c_j`` (face terms included,
    :func:`wallcal.engines.boundary.face_conductance`), shape (c, j): inf for a node without capacity, 0 for
    a known face node. ``bc_h`` (c, 2): the faces' surface coefficients of each candidate."""
    nc, n = cap.shape
    s = np.empty((nc, n))
    for c in range(nc):
        for j in range(n):
            total = 0.0
            if j < n - 1:
                total += g[c, j]
            if j > 0:
                total += g[c, j - 1]
            if j == 0:
                total += boundary.face_conductance(bc_type[0], bc_h[c, 0])
            if j == n - 1:
                total += boundary.face_conductance(bc_type[1], bc_h[c, 1])
            s[c, j] = total * dt / cap[c, j] if cap[c, j] > 0.0 else np.inf
        if boundary.is_known(bc_type[0]):
            s[c, 0] = 0.0
        if boundary.is_known(bc_type[1]):
            s[c, n - 1] = 0.0
    return s


@njit(cache=True)
def link_thetas(cap, g, bc_type, bc_h, theta0, dt, stiff_limit):
    """theta per link (c, l) and per face term (c, 2), and the number of terms whose theta was raised (c,).

    The discrete maximum principle: a step ``T^{n+1} = A^-1 (B T^n + inputs)`` with the M-matrix
    ``A = Cap/dt + K_theta`` is monotone (the response to a step in an input is monotone and bounded by
    the inputs) when ``B = Cap/dt - K_{1-theta}`` has no negative entry, i.e. at every unknown node
    ``sum (1 - theta) g dt <= c_j`` over its terms. With the node stiffness ``s_j``
    (:func:`node_stiffness`), a link between nodes a and b gets

        theta_l = max(theta0, 1 - (1 - theta0) L / max(s_a, s_b)),   L = stiff_limit,

    and an air face's term the same with its face node's stiffness (any face term whose node has no
    capacity: 1). With ``L = 1 / (1 - theta0)`` (2 for Crank-Nicolson, the default) this is exactly
    the condition, met with equality at the stiff nodes; terms between nodes with ``s <= L`` keep
    theta0. ``L = inf`` keeps theta0 except at nodes without capacity (theta 1).
    (numba: it runs on every call of the engine; ``bc_h`` (c, 2) as in :func:`node_stiffness`.)
    """
    t0 = float(theta0)
    nc, nl = g.shape
    theta = np.full((nc, nl), t0)
    bc_theta = np.full((nc, 2), t0)
    n_raised = np.zeros(nc, dtype=np.int64)
    if t0 >= 1.0:
        return theta, bc_theta, n_raised
    s = node_stiffness(cap, g, bc_type, bc_h, dt)
    budget = (1.0 - t0) * stiff_limit
    for c in range(nc):
        for lnk in range(nl):
            th = _raised_theta(t0, budget, max(s[c, lnk], s[c, lnk + 1]))
            theta[c, lnk] = th
            if th > t0:
                n_raised[c] += 1
        for f in range(2):  # a face term enters B through h; a face node without capacity is algebraic
            sf = s[c, 0 if f == 0 else nl]
            if boundary.face_conductance(bc_type[f], bc_h[c, f]) > 0.0 or not np.isfinite(sf):
                th = _raised_theta(t0, budget, sf)
                bc_theta[c, f] = th
                if th > t0:
                    n_raised[c] += 1
    return theta, bc_theta, n_raised


@njit(cache=True)
def _raised_theta(theta0, budget, s):
    """theta of a term whose stiffest node has stiffness s: (1 - theta) s <= budget."""
    if not np.isfinite(s):
        return 1.0  # a node without capacity
    if s * (1.0 - theta0) > budget:
        return 1.0 - budget / s
    return theta0
