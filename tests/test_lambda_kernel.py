"""The lambda(T) step of the general kernel against a plain numpy transcription of the scheme
(docs/engine.md, "lambda(T)"): Kirchhoff-mean conductances g* at the extrapolated mid-step
temperature evaluated in closed form, the explicit correction against the factorised g0, the
refactorisation rule, dense solves. The kernel evaluates g* with polynomials (the closed form and
exact exp beyond their ranges) and updates the link factors incrementally; the regimes and the
switches between them must not be visible beyond round-off."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from wallcal.engines import boundary, kernels
from wallcal.grid import LAMBDA_CONSTANT, LAMBDA_EXPONENTIAL

DT = 60.0


def _kirchhoff(g_ref, f, tref, ta, tb):
    """g_ref exp(f (T_m - T_ref)) sinh(x) / x, x = f (T_a - T_b) / 2 (Kirchhoff mean, closed form)."""
    x = 0.5 * f * (ta - tb)
    sx = np.where(x == 0.0, 1.0, np.sinh(x) / np.where(x == 0.0, 1.0, x))
    return g_ref * np.exp(f * (0.5 * (ta + tb) - tref)) * sx


def _reference(cap, g_ref, f, tref, ue, ui, T0, drift=0.02, theta=0.5):
    """Node temperatures at every grid time, both faces with imposed temperatures."""
    n_nodes = cap.size
    n_steps = ue.size - 1
    inv_c = np.where(np.arange(n_nodes) % (n_nodes - 1) == 0, 0.0, 1.0 / cap)  # faces: known
    lim = 0.05 / (theta * DT * (inv_c[:-1] + inv_c[1:]))
    T_prev = T0.copy()
    T = T0.copy()
    g0 = _kirchhoff(g_ref, f, tref, T[:-1], T[1:])
    tol = np.minimum(drift * g0, lim)
    out = [T.copy()]
    stats = {"u_max": 0.0, "x_max": 0.0}  # largest x^2 and |f dT_m| of the steps
    tmid_old = T.copy()
    for n in range(n_steps):
        tmid = 1.5 * T - 0.5 * T_prev if n > 0 else T.copy()
        pred = 2.0 * T - T_prev if n > 0 else T.copy()
        pred[0], pred[-1] = ue[n + 1], ui[n + 1]
        gs = _kirchhoff(g_ref, f, tref, tmid[:-1], tmid[1:])
        if n > 0:
            dtm = tmid - tmid_old
            stats["x_max"] = max(stats["x_max"], np.abs(f * 0.5 * (dtm[:-1] + dtm[1:])).max())
        stats["u_max"] = max(stats["u_max"], ((0.5 * f * (tmid[:-1] - tmid[1:])) ** 2).max())
        tmid_old = tmid
        if np.any(np.abs(gs - g0) > tol):
            g0 = gs.copy()
            tol = np.minimum(drift * g0, lim)
        dp = pred[:-1] - pred[1:]
        E = gs * (theta * dp + (1 - theta) * (T[:-1] - T[1:])) - theta * g0 * dp
        # (cap/dt) (T1 - T) = E_{j-1} - E_j + theta g0_{j-1} (T1_{j-1} - T1_j) - theta g0_j (T1_j - T1_{j+1})
        m = n_nodes - 2
        A = np.zeros((m, m))
        r = cap[1:-1] / DT * T[1:-1] + E[:-1] - E[1:]
        for i in range(m):
            j = i + 1
            A[i, i] = cap[j] / DT + theta * (g0[j - 1] + g0[j])
            if i > 0:
                A[i, i - 1] = -theta * g0[j - 1]
            if i < m - 1:
                A[i, i + 1] = -theta * g0[j]
        r[0] += theta * g0[0] * ue[n + 1]
        r[-1] += theta * g0[-1] * ui[n + 1]
        T_new = np.empty(n_nodes)
        T_new[0], T_new[-1] = ue[n + 1], ui[n + 1]
        T_new[1:-1] = np.linalg.solve(A, r)
        T_prev, T = T, T_new
        out.append(T.copy())
    return np.array(out).T, stats


def _kernel(cap, g_ref, f, tref, ue, ui, T0, drift=0.02):
    """The kernel's run; links with f = 0 get the constant law (the lambda(T) pass skips those at the ends)."""
    n_nodes = cap.size
    n_links = n_nodes - 1
    n_steps = ue.size - 1
    one = lambda a: np.ascontiguousarray(a, dtype=float)[None, :]  # noqa: E731
    nodes = np.arange(n_nodes, dtype=np.int64)[None, :]
    wall = (one(cap), one(g_ref), one(np.full(n_links, 0.5)))
    laws = (
        np.where(f != 0.0, LAMBDA_EXPONENTIAL, LAMBDA_CONSTANT).astype(np.int64),
        one(f),
        np.ascontiguousarray(tref, dtype=float),
        np.zeros(n_links, dtype=np.int64),
        np.zeros(n_links, dtype=np.int64),
        np.zeros(1),
        np.zeros(1),
    )
    faces = (np.full(2, boundary.SURFACE_TEMPERATURE, dtype=np.int64), np.zeros((1, 2)), np.full((1, 2), 0.5), ue, ui)
    no_planes = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((1, 0)))  # no flux at depths
    outputs = (np.arange(n_steps + 1, dtype=np.int64), np.zeros(n_steps + 1), nodes, nodes, np.zeros((1, n_nodes)))
    outputs += no_planes
    results = (np.full((1, n_nodes + 2, n_steps + 1), np.nan), np.zeros((1, 3)), np.zeros((1, n_nodes)))
    out, energy, _ = kernels.run_batch(wall, laws, faces, outputs, DT, drift, one(T0), results)
    return out[0, :n_nodes]


def _wall(n_nodes, f):
    """A 20 cm insulation-like layer (lambda 0.04 W/(m K) at 10 degC, rho c = 6e4 J/(m3 K))."""
    dx = 0.2 / (n_nodes - 1)
    cap = np.full(n_nodes, 6e4 * dx)
    cap[0] = cap[-1] = 3e4 * dx
    g_ref = np.full(n_nodes - 1, 0.04 / dx)
    return cap, g_ref, np.full(n_nodes - 1, f), np.full(n_nodes - 1, 10.0)


@pytest.mark.parametrize(
    "case",
    [
        "smooth",  # every argument small: the polynomials throughout
        "steep",  # steep profile, large f: x^2 across the sinh(x)/x polynomial's range and beyond
        "jumps",  # 8 K jumps of the surface temperature: exact steps, then the polynomials again
        "layers",  # lambda(T) layers with different f and T_ref beside a constant one
        "constant ends",  # constant layers at both faces, outside the lambda(T) pass's range of links
    ],
)
def test_lambda_step_equals_closed_form_scheme(case):
    n_steps = 3000  # three exact resynchronisations (every 1024 steps)
    t = np.arange(n_steps + 1) * DT
    if case == "smooth":
        n_nodes, f = 13, 0.0046
        ue = 5.0 + 8.0 * np.sin(2 * np.pi * t / 86400.0)
        ui = np.full(n_steps + 1, 20.0)
    elif case == "steep":
        n_nodes, f = 9, 0.03
        ue = -15.0 + 10.0 * np.sin(2 * np.pi * t / 43200.0)
        ui = np.full(n_steps + 1, 45.0)
    else:
        n_nodes, f = 13, 0.0046
        ue = 5.0 + 8.0 * ((t // 7200.0) % 2) if case == "jumps" else 5.0 + 8.0 * np.sin(2 * np.pi * t / 86400.0)
        ui = np.full(n_steps + 1, 20.0)
    cap, g_ref, coef, tref = _wall(n_nodes, f)
    if case == "constant ends":
        coef[:3] = 0.0
        coef[-2:] = 0.0
        g_ref[:3] *= 5.0
    if case == "layers":
        coef[4:8] = 0.0
        coef[8:] = 0.012
        tref[8:] = 25.0
        g_ref[4:8] *= 20.0
    T0 = np.linspace(ue[0], ui[0], n_nodes)
    ref, stats = _reference(cap, g_ref, coef, tref, ue, ui, T0)
    got = _kernel(cap, g_ref, coef, tref, ue, ui, T0)
    # the regime the case is meant to exercise (polynomial ranges: |f dT_m| <= 0.01, x^2 <= SINHC_U_MAX)
    if case == "smooth":
        assert stats["u_max"] < 1e-3 and stats["x_max"] < 0.01
    elif case == "steep":
        assert stats["u_max"] > 1e-3  # polynomial and closed form of sinh(x)/x
    elif case == "jumps":
        assert stats["x_max"] > 0.01  # beyond even the long polynomial: exact steps
    # round-off: the differences are a few hundred ulps of the temperatures
    np.testing.assert_allclose(got, ref, rtol=0, atol=2e-12)


def test_step_polynomials_within_their_ranges():
    """The polynomials of a lambda(T) step against extended-precision exp and sinh, over their ranges:
    within the relative errors their docstrings state (2e-15 for exp, a few units in the last place for
    sinh(x)/x)."""
    # (compiled for calls from compiled code only: called through a jitted wrapper)
    exp_step = njit(lambda v: kernels._exp_step(v))
    sinhc = njit(lambda u: kernels._sinhc(u))
    x = np.linspace(-0.01, 0.01, 2001)
    got = np.array([exp_step(v) for v in x])
    rel = np.abs(got / np.exp(x.astype(np.longdouble)) - 1)
    assert rel.max() < 2e-15, rel.max()
    for fn, umax in ((sinhc, kernels.SINHC_U_MAX),):
        u = np.linspace(0.0, umax, 2001)
        got = np.array([fn(v) for v in u])
        r = np.sqrt(u.astype(np.longdouble))
        exact = np.where(r == 0, 1, np.sinh(r) / np.where(r == 0, 1, r))
        rel = np.abs(got / exact - 1)
        assert rel.max() < 5e-16, (fn, rel.max())
