"""The general path's tridiagonal solve by parallel cyclic reduction in vector registers (pcr.py)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_input
from wallcal.engines.fd import FDEngine
from wallcal.engines.pcr import PCR_MAX_LEVELS, PCR_MAX_ROWS, pcr_coefficients, pcr_work, solve_reference
from wallcal.wall import Layer, Probe, Wall


def _matrix(m, rng, margin):
    """Symmetric tridiagonal M-matrix: off-diagonal -g < 0, diagonal = sum of |g| + margin * uniform."""
    g = rng.uniform(0.1, 1.0, m)
    off = -g.copy()
    off[m - 1] = 0.0
    diag = np.zeros(m)
    for i in range(m):
        diag[i] = (g[i - 1] if i > 0 else 0.0) + (g[i] if i < m - 1 else 0.0)
    diag += margin * rng.uniform(0.0, 1.0, m)
    diag[0] += 0.05  # at least one strictly dominant row: nonsingular
    return diag, off


def _dense(diag, off):
    m = diag.shape[0]
    return np.diag(diag) + np.diag(off[: m - 1], 1) + np.diag(off[: m - 1], -1)


@pytest.mark.parametrize("m", [1, 2, 3, 7, 8, 9, 16, 17, 31, 48, 63, 64])
@pytest.mark.parametrize("margin", [0.0, 0.3, 3.0])
def test_solve_matches_dense_solve(m, margin):
    rng = np.random.default_rng(m * 10 + int(margin * 10))
    diag, off = _matrix(m, rng, margin)
    r = rng.normal(20.0, 10.0, m)
    x = solve_reference(diag, off, r)
    A = _dense(diag, off)
    exact = np.linalg.solve(A, r)
    # forward error within the conditioning; with a diagonal margin (the engine's matrices have
    # Cap/dt) also a residual at rounding level. Without a margin the matrix is nearly singular
    # (condition number up to 2e4 here) and the reduction's error grows with its levels: 1e-13
    # relative at 64 rows, against 1e-14 for banded LU.
    assert np.max(np.abs(x - exact)) <= 1e-15 * np.linalg.cond(A) * np.max(np.abs(exact))
    if margin > 0:
        assert np.max(np.abs(A @ x - r)) <= 1e-14 * np.max(np.abs(diag)) * np.max(np.abs(x))


def _levels(diag, off):
    m = diag.shape[0]
    n_regs = (m + 7) // 8
    n = 8 * n_regs
    return pcr_coefficients(
        diag, off, m, n_regs, np.zeros(PCR_MAX_LEVELS * n), np.zeros(PCR_MAX_LEVELS * n), np.zeros(n), pcr_work(m)
    )


def test_reduction_stops_when_couplings_are_negligible():
    rng = np.random.default_rng(5)
    # weak dominance: the couplings decay slowly, the reduction runs to the end (stride >= rows)
    diag, off = _matrix(PCR_MAX_ROWS, rng, 0.0)
    assert _levels(diag, off) == PCR_MAX_LEVELS
    # strong dominance (the engine's matrices at C = 2: coupling / diagonal ~ 1/6): fewer levels
    diag, off = _matrix(48, rng, 3.0)
    assert _levels(diag, off) < 6


def _wall(thickness_m):
    return Wall(
        (
            Layer("render", 0.02, conductivity=0.9, density=1800.0, specific_heat=900.0),
            Layer("wool", thickness_m, conductivity=0.04, density=60.0, specific_heat=1030.0),
            Layer("brick", 0.10, conductivity=0.8, density=1800.0, specific_heat=840.0),
        ),
        (Probe("P1", 0.06), Probe("P2", 0.02 + thickness_m)),
    )


@pytest.mark.parametrize("thickness_m", [0.10, 0.80])
def test_general_path_matches_modal_path_on_both_solves(thickness_m):
    """Up to PCR_MAX_ROWS unknowns the general path solves by reduction, beyond by the twisted scalar
    solve: both agree with the exact modal path to 1e-9 K."""
    t = np.arange(1441) * 60.0
    inp = make_input(_wall(thickness_m), 5 + 10 * np.sin(2 * np.pi * t / 86400), np.full(1441, 20.0), 60.0)
    modal = FDEngine("cn").run(inp, path="modal")
    general = FDEngine("cn").run(inp, path="general")
    assert (modal.info["path"], general.info["path"]) == ("modal", "general")
    n_unknowns = general.info["nodes"] - 2
    assert (n_unknowns <= PCR_MAX_ROWS) == (thickness_m < 0.2), n_unknowns
    for name in modal.temperatures:
        np.testing.assert_allclose(general.temperatures[name], modal.temperatures[name], atol=1e-9, rtol=0)


def _thomas(diag, off, r, dtype):
    """Tridiagonal LU solve (no pivoting) in the given float type."""
    m = diag.shape[0]
    d, o, rr = diag.astype(dtype), off.astype(dtype), r.astype(dtype)
    for i in range(1, m):
        f = o[i - 1] / d[i - 1]
        d[i] -= f * o[i - 1]
        rr[i] -= f * rr[i - 1]
    x = np.zeros(m, dtype)
    x[m - 1] = rr[m - 1] / d[m - 1]
    for i in range(m - 2, -1, -1):
        x[i] = (rr[i] - o[i] * x[i + 1]) / d[i]
    return x.astype(float)


@pytest.mark.parametrize("dt", [60.0, 3600.0])
@pytest.mark.parametrize("name", ["steel_sheet_0.5mm", "alu_foil_50um", "air_layer_at_face", "five_decades"])
def test_reduction_on_stiff_and_massless_walls(name, dt):
    """The engine's own matrices for metal sheets (fully implicit stiff links: rows barely dominant,
    condition numbers up to 1e7) and no-mass air layers (rows without Cap/dt), which the modal path
    cannot check: against an extended-precision solve, the reduction's error is no larger than that of
    tridiagonal LU (Thomas) in double precision."""
    from test_extreme_walls import WALLS
    from wallcal.engines import kernels
    from wallcal.grid import PropertyArrays, assemble

    wall = WALLS[name]
    t = np.arange(3) * dt
    prep = FDEngine("cn").prepare(make_input(wall, 5 + 0 * t, 20 + 0 * t, dt))
    cap, g = assemble(prep.grid, PropertyArrays.from_walls([wall]))
    theta, bc_theta, _ = prep._thetas(cap, g)
    m = cap.shape[1] - 2  # both faces imposed
    assert m <= PCR_MAX_ROWS
    diag, off = np.zeros(m), np.zeros(m)
    lu = [np.zeros(m) for _ in range(3)]  # not formed (lu=False): the matrix only
    kernels._factor_lean(cap[0], g[0], theta[0], prep.bc_type, prep.bc_h, bc_theta[0], dt, 1, m, diag, off, *lu, False)
    rng = np.random.default_rng(1)
    err, err_lu = 0.0, 0.0  # worst over 50 right-hand sides
    for _ in range(50):
        r = _dense(diag, off) @ rng.normal(15.0, 10.0, m)
        exact = _thomas(diag, off, r, np.longdouble)
        err = max(err, np.max(np.abs(solve_reference(diag, off, r) - exact)))
        err_lu = max(err_lu, np.max(np.abs(_thomas(diag, off, r, np.float64) - exact)))
    # observed: 0.6-2x LU's worst case (1e-14 K .. 1.2e-8 K at condition numbers 3e1 .. 1.4e7)
    assert err <= 3 * err_lu + 1e-13 * 40.0, (err, err_lu)
