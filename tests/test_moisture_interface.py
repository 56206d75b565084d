"""The heat-and-moisture kernel at a contact between two materials (:func:`wallcal.moisture.kernel.contact_flux`):
one contact state, the total moisture flux continuous through it, vapour on one side going on as liquid on the
other."""

from __future__ import annotations

import numpy as np
import pytest

from wallcal.moisture.materials import KELVIN, HygricMaterial, saturation_pressure, suction_from_rh
from wallcal.moisture.solver import Boundary, Layer, make_grid, solve

DAY = 86400.0


def _vapour_only(lambda_dry=1e4, delta=1.9e-10):
    """Vapour permeability ``delta`` [s], no liquid transport (a mineral wool's hygric behaviour)."""
    return HygricMaterial(
        "vapour only",
        lambda pc: 2.0 / (1.0 + pc / 1e8),
        lambda_dry=lambda_dry,
        rho_c_dry=3e4,
        vapour_permeability=delta,
    )


def _liquid_only(lambda_dry=1e4, k=5e-16):
    """A constant liquid conductivity ``k`` [s] (``Phi = k pc``), vapour-tight."""
    return HygricMaterial(
        "liquid only",
        lambda pc: 200.0 / (1.0 + pc / 1e7),
        lambda_dry=lambda_dry,
        rho_c_dry=1.5e6,
        vapour_permeability=0.0,
        liquid_conductivity=lambda w: np.full_like(w, k),
    )


def _contact_suction(delta, la, pv_left, k, lb, pc_right, ps):
    """The contact's suction [Pa] with ``delta (pv_left - pv(pc_f)) / la = k (pc_right - pc_f) / lb``, the
    vapour flux through layer A equal to the liquid flux through layer B (both towards +x); the left side
    rises with ``pc_f``, the right side falls: bisection."""
    lo, hi = 0.0, pc_right
    for _ in range(200):
        pc = 0.5 * (lo + hi)
        if delta * (pv_left - np.exp(-pc / KELVIN) * ps) / la > k * (pc_right - pc) / lb:
            hi = pc
        else:
            lo = pc
    return pc


def test_steady_flux_from_a_vapour_only_into_a_liquid_only_layer_is_the_analytic_one():
    """Layer A carries only vapour, layer B only liquid: every kilogram crossing the contact changes from
    vapour to liquid there. Isothermal (conductivities so high that the latent heat released at the contact
    leaves no temperature difference worth 1e-6 of the flux), surface states imposed: in steady state the
    vapour pressure is linear through A, the suction through B, and the flux is the root of
    ``delta_A (p_v,L - p_v(pc_f)) / L_A = K_B (pc_R - pc_f) / L_B``. The two layers' half cells in series
    (the former kernel) passed nothing: no liquid path in A, no vapour path in B."""
    delta, k, la, lb = 1.9e-10, 5e-16, 0.05, 0.02
    rh_left, rh_right = 0.95, 0.5
    ps = float(saturation_pressure(20.0))
    pc_right = float(suction_from_rh(rh_right))
    pc_f = _contact_suction(delta, la, rh_left * ps, k, lb, pc_right, ps)
    flux = k * (pc_right - pc_f) / lb
    assert 0.7 < np.exp(-pc_f / KELVIN) < 0.85  # the contact between the two surface humidities
    grid = make_grid([Layer(_vapour_only(), la), Layer(_liquid_only(), lb)], first=5e-4, ratio=1.2, max_cell=2e-3)
    res = solve(
        grid,
        Boundary("surface", 20.0, rh_left),
        Boundary("surface", 20.0, rh_right),
        20.0,
        0.7,
        [100 * DAY, 200 * DAY],
        dt_max=DAY,
    )
    # steady (no change over the last 100 days) and continuous: what enters on the left leaves on the right
    assert res.face_flux[-1, :, 0] == pytest.approx(res.face_flux[-2, :, 0], rel=1e-9)
    assert -res.face_flux[-1, 1, 0] == pytest.approx(res.face_flux[-1, 0, 0], rel=1e-9)
    # the table interpolation of Phi (linear in u on 4096 segments) is within 5e-6 of K pc
    assert res.face_flux[-1, 0, 0] == pytest.approx(flux, rel=1e-4)
    # the profiles: p_v linear through A from the left face to the contact, pc linear through B
    a = grid.mat == 0
    pc = np.exp(res.potential[-1])
    pv = np.exp(-pc[a] / KELVIN) * ps
    assert np.allclose(pv, rh_left * ps + (np.exp(-pc_f / KELVIN) * ps - rh_left * ps) * grid.x[a] / la, rtol=1e-5)
    assert np.allclose(pc[~a], pc_f + (pc_right - pc_f) * (grid.x[~a] - la) / lb, rtol=1e-4)


def _wool():
    """Mineral wool: mu 1.3, no liquid transport, 0.5 kg/m3 at 80 % RH and 50 kg/m3 at saturation."""
    return HygricMaterial(
        "wool",
        lambda pc: 0.5 / (1.0 + pc / 1e8) + 50.0 / (1.0 + pc / 1e3),
        lambda_dry=0.04,
        rho_c_dry=4e4,
        resistance_factor=1.3,
    )


def _sealed():
    """Vapour-tight and without liquid transport (a metal or plastic sheet)."""
    return HygricMaterial(
        "sealed", lambda pc: 5.0 / (1.0 + pc / 1e8), lambda_dry=1.0, rho_c_dry=2e6, vapour_permeability=0.0
    )


def _cold_outside_humid_room(grid, days):
    t = np.arange(0, days + 1) * DAY
    ext = Boundary("air", -5.0 + 3.0 * np.sin(t / DAY), 0.8, times=t, h=25.0, beta=2e-7)
    inn = Boundary("air", 20.0, 0.7, h=8.0, beta=2e-8)
    return ext, inn


def test_balances_close_with_condensate_passing_from_wool_into_a_capillary_layer():
    """Interior mineral wool (no liquid transport) on a capillary, vapour-tight layer, a sealed layer behind:
    room vapour crosses the wool and goes on as liquid from the contact. Mass and energy balances close to
    the Newton tolerance; the water does not pile up in the wool's cell at the contact (it did when each path
    was taken in series: neither vapour nor liquid could cross); nothing crosses the sealed layer."""
    grid = make_grid(
        [Layer(_sealed(), 0.02), Layer(_liquid_only(lambda_dry=0.8, k=1e-13), 0.05), Layer(_wool(), 0.06)],
        first=5e-4,
        ratio=1.3,
        max_cell=5e-3,
    )
    ext, inn = _cold_outside_humid_room(grid, 10)
    res = solve(grid, ext, inn, 10.0, 0.6, [2 * DAY, 10 * DAY], dt_max=3600.0)
    assert np.all(res.mass_balance_error < 1e-9)
    assert np.all(res.energy_balance_error < 1e-9)
    w0 = np.array([grid.materials[m].water_content_from_rh(0.6) for m in grid.mat])
    gained = (res.water_content[-1] - w0) * grid.dx
    # the room's vapour crossed the wool and went into the capillary layer
    assert res.inflow[-1, 1, 0] > 0.5  # kg/m2 in through the interior face
    assert gained[grid.mat == 1].sum() > 0.9 * res.inflow[-1, 1, 0]
    # ... and the wool's cell at the contact stays below 95 % RH
    first_wool = np.flatnonzero(grid.mat == 2)[0]
    assert res.relative_humidity[-1, first_wool] < 0.95
    # the sealed layer exchanges moisture with the exterior air only
    assert gained[grid.mat == 0].sum() == pytest.approx(res.inflow[-1, 0, 0], rel=1e-9, abs=1e-12)


def test_condensate_at_a_sealed_contact_stays_in_the_wool():
    """Wool against a cold sealed layer: the room's vapour reaches the contact, which saturates (no contact
    suction balances the fluxes: the condensing side has the only transport); the condensate stays in the
    wool's cell at the contact and none enters the sealed layer."""
    grid = make_grid([Layer(_sealed(), 0.02), Layer(_wool(), 0.06)], first=2e-3, ratio=1.3, max_cell=5e-3)
    ext, inn = _cold_outside_humid_room(grid, 1)
    res = solve(grid, ext, inn, 10.0, 0.6, [2 * 3600.0, 6 * 3600.0], dt_max=600.0)
    assert np.all(res.mass_balance_error < 1e-9)
    assert np.all(res.energy_balance_error < 1e-9)
    first_wool = np.flatnonzero(grid.mat == 1)[0]
    assert res.relative_humidity[-1, first_wool] > 0.999  # condensing at the contact
    w0 = np.array([grid.materials[m].water_content_from_rh(0.6) for m in grid.mat])
    gained = (res.water_content[-1] - w0) * grid.dx
    assert gained[first_wool] > 0.7 * res.inflow[-1, 1, 0]
    assert gained[grid.mat == 0].sum() == pytest.approx(res.inflow[-1, 0, 0], rel=1e-9, abs=1e-12)
