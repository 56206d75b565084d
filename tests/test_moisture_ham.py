"""The heat-and-moisture engine (wallcal.moisture): material functions, balances, EN 15026 Annex A,
HAMSTAD 2 and ``wallcal verify``."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import assert_clean_error
from wallcal.cli import main
from wallcal.errors import StudyError
from wallcal.moisture import cases
from wallcal.moisture.materials import (
    U_GRID,
    HygricMaterial,
    potential_from_rh,
    resistance_factor_hamstad,
    suction_from_rh,
    van_genuchten,
)
from wallcal.moisture.solver import Boundary, Layer, make_grid, solve

ALL_MATERIALS = [cases.en15026_material(), cases.hamstad2_material(), *cases.hamstad5_materials()]


# ============================================================================ material functions
@pytest.mark.parametrize("m", ALL_MATERIALS, ids=lambda m: m.name)
def test_storage_is_monotone_from_dry_to_capillary_saturation(m):
    assert np.all(np.diff(m.w) <= 0)  # w falls as the suction rises
    assert m.w[-1] < 0.01 * m.w[0]  # dry at 1e11 Pa
    assert np.all(np.diff(m.kirchhoff) >= 0)


def test_en15026_storage_and_permeability_match_the_published_values():
    m = cases.en15026_material()
    assert m.water_content_from_rh(0.5) == pytest.approx(42.92, abs=0.01)
    assert m.water_content_from_rh(0.95) == pytest.approx(129.02, abs=0.01)
    # mu = 200 / f(w): 211.8 at phi 0.5 and 866.4 at phi 0.95 (setup.md)
    for phi, mu in ((0.5, 211.8), (0.95, 866.4)):
        delta = np.interp(potential_from_rh(phi), U_GRID, m.delta_ref)
        assert 26.1e-6 / (461.888 * 293.15) / delta == pytest.approx(mu, rel=2e-3)
    assert cases.hamstad2_material().water_content_from_rh(0.95) == pytest.approx(84.7687, abs=1e-3)


@pytest.mark.parametrize("m", [cases.en15026_material(), *cases.hamstad5_materials()], ids=lambda m: m.name)
def test_kirchhoff_potential_derivative_is_the_liquid_conductivity(m):
    """dPhi/du = K_l(w(pc)) pc, checked by central differences of the table against the material's K_l."""
    for phi in (0.5, 0.8, 0.95, 0.99):
        u = float(potential_from_rh(phi))
        h = 0.01
        lo, hi = np.interp([u - h, u + h], U_GRID, m.kirchhoff)
        pc = np.exp(u)
        expected = float(m.liquid_conductivity(m.storage(pc))) * pc
        assert (hi - lo) / (2 * h) == pytest.approx(expected, rel=2e-3)


def test_storage_derivative_matches_finite_differences_of_the_function():
    m = cases.en15026_material()
    for phi in (0.3, 0.7, 0.95):
        pc = float(suction_from_rh(phi))
        u = np.log(pc)
        k = int((u - U_GRID[0]) / (U_GRID[1] - U_GRID[0]))
        slope_table = (m.w[k + 1] - m.w[k]) / (U_GRID[k + 1] - U_GRID[k])
        eps = 1e-6
        exact = (m.storage(pc * np.exp(eps)) - m.storage(pc * np.exp(-eps))) / (2 * eps)
        assert slope_table == pytest.approx(exact, rel=1e-2)


def test_a_non_monotone_storage_function_is_refused_in_one_line():
    with pytest.raises(StudyError, match="not monotone") as e:
        HygricMaterial(
            "bumpy", lambda pc: 50 + 10 * np.sin(np.log(pc)), lambda_dry=1.0, rho_c_dry=1e6, resistance_factor=10
        )
    assert "\n" not in str(e.value) and "bumpy" in str(e.value)


@pytest.mark.parametrize("mu", [0.5, resistance_factor_hamstad(0.8, 100.0, 0.5)])
def test_a_vapour_resistance_factor_below_one_is_refused_in_one_line(mu):
    with pytest.raises(StudyError, match="vapour resistance factor must be >= 1") as e:
        HygricMaterial("leaky", van_genuchten(100.0, [(1.0, 1e-6, 2.0, 0.5)]), 1.0, 1e6, resistance_factor=mu)
    assert "\n" not in str(e.value)


# ============================================================================ balances
def _wet_wall():
    brick, mortar, insulation = cases.hamstad5_materials()
    return make_grid([Layer(brick, 0.1), Layer(mortar, 0.01), Layer(insulation, 0.04)], first=2e-4, ratio=1.3)


def test_mass_and_energy_balances_close_with_rain_runoff_and_varying_air():
    grid = _wet_wall()
    t = np.arange(0, 49) * 3600.0
    t_air = 5 + 5 * np.sin(2 * np.pi * t / 86400)
    rain = np.where((t > 6 * 3600) & (t < 12 * 3600), 5e-3, 0.0)  # 18 kg/m2/h: more than the brick takes up
    ext = Boundary("air", t_air, 0.9, times=t, h=25.0, beta=2e-7, rain=rain, heat_flux=100.0)
    inn = Boundary("air", 20.0, 0.5, h=8.0, beta=6e-8)
    res = solve(grid, ext, inn, 15.0, 0.6, [6 * 3600.0, 12 * 3600.0, 48 * 3600.0], dt_max=1800.0)
    assert res.runoff[-1, 0] > 1.0  # the surface saturated and the excess ran off
    assert res.inflow[-1, 0, 0] > 1.0  # ... after taking up kilograms of water
    assert np.all(res.mass_balance_error < 1e-9)
    assert np.all(res.energy_balance_error < 1e-9)
    # the stored change equals what came in (absolute, not only relative)
    w0 = np.array([grid.materials[m].water_content_from_rh(0.6) for m in grid.mat])
    stored = (res.water_content[-1] - w0) @ grid.dx
    assert stored == pytest.approx(res.inflow[-1, :, 0].sum(), rel=1e-9)
    assert res.relative_humidity[1, 0] > 0.999  # saturated face at the end of the shower
    # the flux through each face over the last step: in steady rain it is the uptake at saturation
    assert 0 < res.face_flux[1, 0, 0] < 5e-3


def test_rain_taken_up_plus_runoff_is_the_rain_supplied_whatever_the_steps():
    """Boundary data are averaged over each step: hourly rain samples are integrated exactly (trapezoid),
    not sampled at the end of the (adaptive) steps."""
    grid = make_grid([Layer(cases.en15026_material(), 0.1)], first=2e-4, ratio=1.3)
    t = np.arange(0, 25) * 3600.0
    rain = np.zeros(t.size)
    rain[[3, 9, 10, 17]] = [2e-3, 6e-3, 1e-3, 4e-3]  # kg/(m2 s): isolated hourly showers
    ext = Boundary("air", 10.0, 0.8, times=t, h=25.0, beta=0.0, rain=rain)  # sealed to vapour
    inn = Boundary("air", 20.0, 0.5, h=8.0, beta=0.0)
    supplied = float(np.sum(0.5 * (rain[1:] + rain[:-1]) * np.diff(t)))
    for dt_max in (3600.0, 300.0):
        res = solve(grid, ext, inn, 15.0, 0.6, [24 * 3600.0], dt_max=dt_max)
        assert res.runoff[-1, 0] > 0.1 * supplied
        assert res.inflow[-1, 0, 0] + res.runoff[-1, 0] == pytest.approx(supplied, rel=1e-9)


def test_evaporation_cools_a_drying_wall_by_its_latent_heat():
    """A wet wall in dry air at its own temperature dries and cools: the energy it loses is the latent heat
    of the water that left (the wet-bulb effect), which only the enthalpy of the vapour flux produces."""
    brick = cases.hamstad5_materials()[0]
    grid = make_grid([Layer(brick, 0.05)], first=5e-4, ratio=1.3, max_cell=5e-3)
    ext = Boundary("air", 20.0, 0.3, h=10.0, beta=2e-8)
    inn = Boundary("air", 20.0, 0.3)  # sealed and adiabatic
    res = solve(grid, ext, inn, 20.0, 0.99, [6 * 3600.0], dt_max=600.0)
    assert res.temperature[-1, 0] < 19.0  # the face cools below the air
    evaporated = -res.inflow[-1, 0, 0]
    assert evaporated > 0.05  # kg/m2 left as vapour
    # the energy that came in through the face: convection towards the cool face minus the latent heat
    latent = 2.45e6 * evaporated
    convected = res.inflow[-1, 0, 1] + latent
    assert convected > 0 and res.inflow[-1, 0, 1] < 0


def test_heat_alone_reaches_the_steady_conduction_profile():
    """A sealed wall with no moisture gradient: the temperature tends to the series-resistance profile."""
    m = cases.hamstad2_material()
    grid = make_grid([Layer(m, 0.05)], first=1e-3, ratio=1.0, max_cell=1e-3)
    res = solve(
        grid, Boundary("surface", 0.0, 0.5), Boundary("surface", 20.0, 0.5), 10.0, 0.5, [30 * 86400.0], dt_max=3600.0
    )
    assert np.allclose(res.temperature[-1], 20.0 * grid.x / 0.05, atol=0.05)
    # 60 W/m2 leave through the exterior face and enter through the interior one (0.15 W/(m K) * 20 K / 0.05 m)
    assert res.face_flux[-1, :, 1] == pytest.approx([-60.0, 60.0], rel=1e-3)


def test_temperature_dependent_conductivity_gives_the_kirchhoff_steady_profile():
    """lambda = l0 + lt T: in steady state l0 T + lt T^2 / 2 is linear in x."""
    m = cases.hamstad2_material()
    hot = HygricMaterial("lambda(T)", m.storage, 0.15, 4.2e5, lambda_t=0.01, vapour_permeability=1e-15)
    grid = make_grid([Layer(hot, 0.05)], first=1e-3, ratio=1.0, max_cell=1e-3)
    res = solve(
        grid, Boundary("surface", 0.0, 0.5), Boundary("surface", 40.0, 0.5), 20.0, 0.5, [60 * 86400.0], dt_max=3600.0
    )
    kirchhoff = 0.15 * res.temperature[-1] + 0.005 * res.temperature[-1] ** 2
    expected = (0.15 * 40 + 0.005 * 1600) * grid.x / 0.05
    assert np.allclose(kirchhoff, expected, atol=1e-3 * expected.max())
    assert not np.allclose(res.temperature[-1], 40 * grid.x / 0.05, atol=0.5)  # lambda(T) mattered


def test_an_initial_water_content_profile_is_kept_at_time_zero():
    brick, mortar, insulation = cases.hamstad5_materials()
    grid = make_grid([Layer(brick, 0.05), Layer(insulation, 0.04)], first=1e-3, ratio=1.2)
    w0 = np.where(grid.x < 0.05, np.linspace(5.0, 50.0, grid.x.size), 3.0)
    res = solve(
        grid,
        Boundary("air", 5.0, 0.8, h=25.0, beta=2e-7),
        Boundary("air", 20.0, 0.5, h=8.0),
        np.linspace(5.0, 20.0, grid.x.size),
        output_times=[0.0, 3600.0],
        initial_water_content=w0,
    )
    assert np.allclose(res.water_content[0], w0, rtol=1e-4)
    assert np.allclose(res.temperature[0], np.linspace(5.0, 20.0, grid.x.size))
    assert np.all(res.mass_balance_error < 1e-9)


@pytest.mark.parametrize(
    ("kwargs", "fragment"),
    [
        ({"relative_humidity": 1.2}, "exterior.relative_humidity: must be in (0, 1]"),
        ({"kind": "wind"}, "exterior.kind: must be 'surface' or 'air'"),
        ({"beta": -1.0}, "exterior.beta: must be >= 0"),
    ],
)
def test_bad_boundaries_are_refused_in_one_line(kwargs, fragment):
    grid = make_grid([Layer(cases.hamstad2_material(), 0.05)])
    ext = Boundary(**{"kind": "air", "temperature": 5.0, "relative_humidity": 0.8, "h": 25.0, **kwargs})
    with pytest.raises(StudyError) as e:
        solve(grid, ext, Boundary("air", 20.0, 0.5), 20.0, 0.5, [3600.0])
    assert fragment in str(e.value) and "\n" not in str(e.value)


# ============================================================================ benchmarks
def _assert_all_pass(run):
    bad = run.checks[~run.checks["passed"]]
    assert bad.empty, bad.to_string()


def test_hamstad2_matches_the_analytical_solution_within_1_kg_m3():
    run = cases.run_case("hamstad2")
    w = run.checks[run.checks["quantity"] == "water_content"]
    assert len(w) == 3 * 19
    _assert_all_pass(run)
    assert (w["value"] - 0.5 * (w["lower"] + w["upper"])).abs().max() < 0.2  # in fact much closer than 1


def test_en15026_annex_a_every_cell_inside_its_limits():
    run = cases.run_case("en15026")
    assert sorted(set(run.checks["day"])) == [7.0, 30.0, 365.0]
    assert (run.checks["quantity"] == "water_content").sum() == 19
    assert (run.checks["quantity"] == "temperature").sum() == 24
    _assert_all_pass(run)


def test_hamstad5_checks_balances_bounds_and_refinement():
    run = cases.run_case("hamstad5")
    q = set(run.checks["quantity"])
    assert {"min_relative_humidity", "max_relative_humidity", "min_water_content", "max_saturation_ratio"} <= q
    assert {"refinement_water_content", "refinement_relative_humidity", "refinement_temperature"} <= q
    assert {"mass_balance_error", "energy_balance_error"} <= q
    refine = run.checks[run.checks["quantity"] == "refinement_water_content"]
    assert len(refine) == len(cases.HAMSTAD5_POSITIONS)
    assert np.allclose(refine["upper"] - refine["lower"], 2 * 1.0)
    if cases.participants_file() is None:
        assert not {"water_content", "relative_humidity"} & q  # no envelope without the participants' file
    else:
        assert (run.checks["quantity"] == "water_content").sum() == 144
    _assert_all_pass(run)
    # the moisture gathers behind the insulation: the peak is in the insulation next to the mortar
    w = run.result.water_content[-1]
    assert 0.380 < run.result.x[np.argmax(w)] < 0.382 and 55 < w.max() < 65


def test_hamstad5_refinement_check_fails_on_a_coarse_grid(monkeypatch):
    """The self-check has teeth: a 10x coarser default grid fails it."""
    real = cases._hamstad5_run

    def coarse(refine=1):
        if refine == 1:
            b, m, i = cases.hamstad5_materials()
            from wallcal.moisture.solver import Boundary, Layer, make_grid, solve

            grid = make_grid([Layer(b, 0.365), Layer(m, 0.015), Layer(i, 0.04)], first=2e-3, ratio=1.5, max_cell=0.05)
            days = [1.0, 10.0, 30.0, 60.0]
            res = solve(
                grid,
                Boundary("air", 0.0, 0.8, h=25.0, beta=1.8382e-7),
                Boundary("air", 20.0, 0.6, h=8.0, beta=5.8823e-8),
                25.0,
                0.6,
                [d * 86400.0 for d in days],
                dt_max=3600.0,
            )
            return res, grid, days
        return real(refine)

    monkeypatch.setattr(cases, "_hamstad5_run", coarse)
    run = cases.run_case("hamstad5")
    assert not run.checks[run.checks["quantity"].str.startswith("refinement")]["passed"].all()


def test_en15026_with_a_scalar_resistance_factor_fails_table_a1():
    """The limits are tight enough to catch a physics error: mu = 200 instead of mu(w) (setup.md: a scalar mu
    cannot pass Table A.1) puts day 30, x = 0.01 m above its 85.3 kg/m3."""
    m = cases.en15026_material()
    scalar = HygricMaterial(
        "scalar mu",
        m.storage,
        1.5,
        1.824e6,
        lambda_w=15.8e-3,
        resistance_factor=200.0,
        liquid_conductivity=m.liquid_conductivity,
    )
    grid = make_grid([Layer(scalar, 40.0)], first=2e-4, ratio=1.04, max_cell=0.5)
    res = solve(
        grid, Boundary("surface", 30.0, 0.95), Boundary("air", 20.0, 0.5), 20.0, 0.5, [30 * 86400.0], dt_max=6 * 3600.0
    )
    assert float(np.interp(0.01, res.x, res.water_content[0])) > 85.3


# ============================================================================ wallcal verify
def test_verify_writes_the_tables_and_exits_0(tmp_path, capsys):
    out = tmp_path / "v"
    assert main(["verify", "hamstad2", "--out", str(out), "--plot"]) == 0
    assert (out / "hamstad2" / "profiles.png").stat().st_size > 10_000
    v = pd.read_csv(out / "verification.csv")
    assert list(v.columns) == ["case", "quantity", "day", "x_m", "value", "lower", "upper", "passed"]
    assert v["passed"].all() and set(v["case"]) == {"hamstad2"}
    p = pd.read_csv(out / "hamstad2" / "profiles.csv")
    assert list(p.columns) == ["time_s", "x_m", "temperature", "relative_humidity", "water_content"]
    assert sorted(set(p["time_s"])) == [360000.0, 1080000.0, 3600000.0]
    assert p["relative_humidity"].between(0, 1).all() and p["x_m"].between(0, 0.2).all()
    assert "hamstad2" in capsys.readouterr().out


def test_verify_exits_1_when_a_check_fails(tmp_path, monkeypatch, capsys):
    real = cases.CASES["hamstad2"]

    def failing():
        run = real()
        run.checks.loc[0, "passed"] = False
        return run

    monkeypatch.setitem(cases.CASES, "hamstad2", failing)
    assert main(["verify", "hamstad2", "--out", str(tmp_path / "v")]) == 1
    assert "outside their limits" in capsys.readouterr().out


@pytest.mark.parametrize(("case", "fragment"), [("hamstad9", "unknown")])  # hamstad1's data: test_verify_hamstad1
def test_verify_refuses_a_case_it_cannot_run_in_one_line(tmp_path, capsys, case, fragment):
    out = tmp_path / "v"
    assert_clean_error(main(["verify", case, "--out", str(out)]), capsys.readouterr(), out, case, fragment)
