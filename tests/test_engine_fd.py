"""Physics verification of the fd engine: steady state, periodic regime, convergence order,
energy balance, lambda(T), boundary types, batches, ringing."""

from __future__ import annotations

import numpy as np
import pytest

from analytic import periodic_solution
from conftest import make_input, three_layer_wall
from wallcal.engines.fd import FDEngine
from wallcal.grid import PropertyArrays, assemble
from wallcal.wall import Layer, Probe, Wall


def run(inp, scheme=None, path="auto"):
    return FDEngine(scheme or inp.scheme).run(inp, path=path)


# ---------------------------------------------------------------------------- steady state
@pytest.mark.parametrize("scheme", ["cn", "implicit"])
def test_steady_state_series_resistance(scheme):
    wall = three_layer_wall()
    n = 50
    inp = make_input(wall, np.full(n + 1, -5.0), np.full(n + 1, 20.0), 600.0, scheme=scheme)
    out = run(inp)
    expect = wall.steady_profile(-5.0, 20.0, [p.depth for p in wall.probes])
    got = np.array([out.temperatures[p.name] for p in wall.probes])
    # round-off only: the discrete steady state of a piecewise-linear profile is exact
    np.testing.assert_allclose(got, expect[:, None] * np.ones((1, n + 1)), atol=1e-10)
    q = (-5.0 - 20.0) / wall.resistance  # towards the interior: negative, heat leaves outwards
    np.testing.assert_allclose(out.fluxes["exterior"], q, rtol=1e-10)
    np.testing.assert_allclose(out.fluxes["interior"], q, rtol=1e-10)


def test_steady_state_with_contact_and_massless_layers():
    layers = (
        Layer("a", 0.1, conductivity=0.5, density=1500.0, specific_heat=900.0, contact_resistance=0.2),
        Layer("air", 0.02, thermal_resistance=0.17),
        Layer("b", 0.1, conductivity=0.04, density=30.0, specific_heat=1400.0),
    )
    wall = Wall(
        layers,
        (
            Probe("in_a", 0.05),
            Probe("face_a", 0.1, side="exterior"),
            Probe("face_a_in", 0.1, side="interior"),
            Probe("mid_air", 0.11),
            Probe("mid_b", 0.17),
        ),
    )
    inp = make_input(wall, np.full(11, 0.0), np.full(11, 20.0), 300.0)
    out = run(inp)
    r_tot = 0.2 + 0.2 + 0.17 + 2.5
    q = 20.0 / r_tot
    expect = {
        "in_a": q * 0.1,
        "face_a": q * 0.2,
        "face_a_in": q * 0.4,
        "mid_air": q * (0.4 + 0.085),
        "mid_b": q * (0.57 + 0.05 / 0.04),
    }
    for k, v in expect.items():
        np.testing.assert_allclose(out.temperatures[k], v, atol=1e-10, err_msg=k)
    np.testing.assert_allclose(out.fluxes["interior"], -q, rtol=1e-10)  # heat flows outwards


@pytest.mark.parametrize(
    "ext,intr",
    [("air_temperature", "air_temperature"), ("heat_flux", "air_temperature"), ("surface_temperature", "heat_flux")],
)
def test_steady_state_other_boundaries(ext, intr):
    wall = three_layer_wall()
    h_e, h_i = 25.0, 7.7
    R = wall.resistance
    # q: flux density towards the interior; ts_e: exterior surface temperature; T(x) = ts_e - q R(x)
    if ext == "air_temperature":
        ue, ui = -10.0, 20.0
        q = (ue - ui) / (1 / h_e + R + 1 / h_i)
        ts_e = ue - q / h_e
    elif ext == "heat_flux":
        q, ui = -8.0, 20.0  # 8 W/m2 leave through the exterior face; interior air at 20 degC
        ue = q
        ts_e = ui + q / h_i + q * R
    else:
        ue, q = -10.0, -4.0  # exterior surface at -10 degC, 4 W/m2 leave the room through the wall
        ui = q
        ts_e = ue
    inp = make_input(wall, np.full(21, ue), np.full(21, ui), 600.0, ext=ext, intr=intr, h_e=h_e, h_i=h_i)
    out = run(inp)
    r_frac = wall.steady_profile(0.0, 1.0, [p.depth for p in wall.probes])
    for p, frac in zip(wall.probes, r_frac, strict=True):
        np.testing.assert_allclose(out.temperatures[p.name], ts_e - q * frac * R, atol=1e-9)
    np.testing.assert_allclose(out.fluxes["exterior"], q, rtol=1e-9)
    np.testing.assert_allclose(out.fluxes["interior"], q, rtol=1e-9)


# ---------------------------------------------------------------------------- periodic regime
def periodic_case(dt, C, scheme, days=6, period=86400.0, rule="wallcal"):
    wall = three_layer_wall()
    t = np.arange(int(days * 86400 / dt) + 1) * dt
    w = 2 * np.pi / period
    amp_e, amp_i = 10.0, 2.0 * np.exp(1j * 0.7)
    ue = 5.0 + np.real(amp_e * np.exp(1j * w * t))
    ui = 20.0 + np.real(amp_i * np.exp(1j * w * t))
    inp = make_input(wall, ue, ui, dt, scheme=scheme, C=C, rule=rule)
    out = run(inp)
    amps, qe, qi = periodic_solution(wall, period, amp_e, amp_i, [p.depth for p in wall.probes])
    R = wall.resistance
    last = t >= (days - 1) * 86400
    errs = {}
    for p, a, frac in zip(
        wall.probes, amps, wall.steady_profile(0.0, 1.0, [p.depth for p in wall.probes]), strict=True
    ):
        exact = 5.0 + 15.0 * frac + np.real(a * np.exp(1j * w * t))
        errs[p.name] = np.abs(out.temperatures[p.name] - exact)[last].max()
    q_mean = (5.0 - 20.0) / R  # towards the interior
    errs["qe"] = np.abs(out.fluxes["exterior"] - (q_mean + np.real(qe * np.exp(1j * w * t))))[last].max()
    errs["qi"] = np.abs(out.fluxes["interior"] - (q_mean + np.real(qi * np.exp(1j * w * t))))[last].max()
    return errs


def test_periodic_regime_matches_transfer_matrix_solution():
    # fine grid: dt = 30 s, C = 1 -> every probe within 0.01 degC of the analytic periodic solution
    errs = periodic_case(30.0, 1.0, "cn")
    for k in ("P0", "P1", "P2", "P3"):
        assert errs[k] < 0.01, errs
    # face fluxes within 0.1 % of the exterior flux amplitude (|q_e| = 95.8 W/m2 through the brick here);
    # what remains is the O(dx^2) error of the surface half-cell's storage term
    assert errs["qe"] < 0.1 and errs["qi"] < 0.01, errs


def test_periodic_regime_default_grid_is_close():
    errs = periodic_case(60.0, 2.0, "cn")
    assert max(errs[k] for k in ("P0", "P1", "P2", "P3")) < 0.05, errs


# ---------------------------------------------------------------------------- order of convergence
def _conv_errors(scheme, dts, ref_dt, wall, nonlinear=False):
    days = 2
    horizon = days * 86400

    def series(dt):
        t = np.arange(int(horizon / dt) + 1) * dt
        ue = 5 + 10 * np.sin(2 * np.pi * t / 86400) + 3 * np.sin(2 * np.pi * t / 21600 + 1)
        ui = 20 + 2 * np.sin(2 * np.pi * t / 86400 + 0.5)
        return ue, ui

    def sim(dt):
        ue, ui = series(dt)
        every = int(round(3600 / dt))
        inp = make_input(wall, ue, ui, dt, scheme=scheme, out_every=every, C=2.0, grid_time_step=600.0)
        return np.array([v for v in run(inp).temperatures.values()])

    ref = sim(ref_dt)
    return [np.abs(sim(dt) - ref).max() for dt in dts]


@pytest.mark.parametrize("scheme,order", [("cn", 2.0), ("implicit", 1.0)])
def test_observed_order_in_time(scheme, order):
    """On the grid built for 600 s (steps up to 600 s keep every node's stiffness below 2: CN on every link)."""
    wall = three_layer_wall()
    dts = [600.0, 300.0, 150.0]
    errs = _conv_errors(scheme, dts, 37.5 if scheme == "cn" else 9.375, wall)
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    # observed order within 0.25 of the theoretical one
    assert np.all(np.abs(orders - order) < 0.25), (errs, orders)


def test_observed_order_lambda_T_cn():
    layers = (
        Layer(
            "wool",
            0.12,
            conductivity=0.04,
            density=60.0,
            specific_heat=1030.0,
            conductivity_temperature_coefficient=0.02,
            reference_temperature=10.0,
        ),
        Layer("brick", 0.10, conductivity=0.8, density=1800.0, specific_heat=840.0),
    )
    wall = Wall(layers, (Probe("a", 0.06), Probe("b", 0.17)))
    dts = [1200.0, 600.0, 300.0]
    errs = _conv_errors("cn", dts, 37.5, wall)
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 1.75), (errs, orders)


# ---------------------------------------------------------------------------- lambda(T)
def test_lambda_T_steady_state_matches_kirchhoff_solution():
    f, lam0, tr, L = 0.02, 0.04, 10.0, 0.1
    wall = Wall(
        (
            Layer(
                "w",
                L,
                conductivity=lam0,
                density=50.0,
                specific_heat=1000.0,
                conductivity_temperature_coefficient=f,
                reference_temperature=tr,
            ),
        ),
        tuple(Probe(f"x{i}", x) for i, x in enumerate([0.025, 0.05, 0.075])),
    )
    t1, t2 = -10.0, 40.0
    # C such that dx = 2.5 mm exactly (40 intervals): the probes sit on nodes
    C = 0.0025**2 / (lam0 / 50e3 * 60.0)
    inp = make_input(wall, np.full(6, t1), np.full(6, t2), 60.0, C=C)
    out = run(inp)

    def U(T):  # Kirchhoff transform
        return lam0 / f * np.exp(f * (T - tr))

    for p in wall.probes:
        u = U(t1) + (U(t2) - U(t1)) * p.depth / L
        exact = tr + np.log(u * f / lam0) / f
        # link conductances are Kirchhoff means of lambda(T): the discrete steady state is exact at nodes
        np.testing.assert_allclose(out.temperatures[p.name], exact, atol=1e-9)
    q = (U(t1) - U(t2)) / L
    np.testing.assert_allclose(out.fluxes["interior"], q, rtol=1e-9)


def test_lambda_table_equals_exponential_when_dense():
    f = 0.01
    temps = np.linspace(-30, 80, 400)
    table = tuple((float(T), float(0.04 * np.exp(f * (T - 10)))) for T in temps)
    mk = [dict(conductivity_temperature_coefficient=f), dict(conductivity_table=table, conductivity=None)]
    res = []
    for kw in mk:
        wall = Wall(
            (
                Layer(
                    "w",
                    0.1,
                    density=50.0,
                    specific_heat=1000.0,
                    reference_temperature=10.0,
                    **({"conductivity": 0.04} | kw),
                ),
            ),
            (Probe("m", 0.05),),
        )
        t = np.arange(1441) * 60.0
        inp = make_input(wall, 10 + 20 * np.sin(2 * np.pi * t / 86400), np.full(1441, 20.0), 60.0)
        res.append(run(inp).temperatures["m"])
    np.testing.assert_allclose(res[0], res[1], atol=2e-4)


# ---------------------------------------------------------------------------- energy balance
def daily_inputs(ext, intr, days=2, dt=60.0):
    """Two days of 24-h sine boundary inputs at dt [s]: temperatures [degC] or heat fluxes [W/m2]."""
    t = np.arange(int(days * 86400 / dt) + 1) * dt
    s = np.sin(2 * np.pi * t / 86400)
    ue = 20 * s if ext == "heat_flux" else 5 + 10 * s
    ui = -3 + s if intr == "heat_flux" else 20 + s
    return ue, ui


@pytest.mark.parametrize("scheme", ["cn", "implicit"])
@pytest.mark.parametrize(
    "ext,intr",
    [
        ("surface_temperature", "surface_temperature"),
        ("air_temperature", "air_temperature"),
        ("heat_flux", "air_temperature"),
    ],
)
def test_energy_balance_closes(scheme, ext, intr):
    wall = three_layer_wall()
    wall = wall.replace_layer("wool", conductivity_temperature_coefficient=0.005)
    ue, ui = daily_inputs(ext, intr)
    inp = make_input(wall, ue, ui, 60.0, scheme=scheme, ext=ext, intr=intr, h_e=25.0, h_i=7.7)
    out = run(inp, path="general")
    assert abs(out.info["energy_residual_J_m2"]) < 1e-9 * out.info["energy_throughput_J_m2"]


# ---------------------------------------------------------------------------- batches
def test_batch_equals_single_runs():
    wall = three_layer_wall()
    t = np.arange(1441) * 60.0
    inp = make_input(wall, 5 + 10 * np.sin(2 * np.pi * t / 86400), np.full(1441, 20.0), 60.0, out_every=5)
    walls = [wall.replace_layer("wool", conductivity=c) for c in (0.035, 0.04, 0.045)]
    walls.append(wall.replace_probe("P1", depth=0.13))
    prep = FDEngine("cn").prepare(inp)
    batch = prep.run_walls(walls)
    for i, w in enumerate(walls):
        single = prep.run_walls([w])
        np.testing.assert_array_equal(batch.out[i], single.out[0])
    # a different probe depth changes that probe only
    assert not np.allclose(batch.out[3, 1], batch.out[1, 1])
    np.testing.assert_array_equal(batch.out[3, 0], batch.out[1, 0])
    props = PropertyArrays.from_walls(walls)
    assert props.conductivity.shape == (4, 3)


# ---------------------------------------------------------------------------- ringing
@pytest.mark.parametrize("C", [1.0, 2.0, 3.0])
def test_cn_does_not_ring_after_a_step_change(C):
    """A 20 K step on the exterior face: probe responses rise monotonically (no overshoot)."""
    wall = three_layer_wall(probes=(0.0025, 0.01, 0.05, 0.1, 0.2))
    n = 600
    ue = np.where(np.arange(n + 1) >= 10, 20.0, 0.0)
    inp = make_input(wall, ue, np.zeros(n + 1), 60.0, C=C)
    out = run(inp)
    for p in wall.probes:
        d = np.diff(out.temperatures[p.name])
        assert d.min() > -1e-6 * 20, (p.name, d.min())


def test_cn_does_not_ring_with_a_thin_metal_sheet():
    """A 1 mm steel sheet on the exterior face is far too stiff for CN at dt = 600 s; the stiff
    link is made implicit, so the sheet's inner face follows the step without oscillating."""
    layers = (
        Layer("steel", 0.001, conductivity=50.0, density=7800.0, specific_heat=450.0),
        Layer("wool", 0.1, conductivity=0.04, density=60.0, specific_heat=1030.0),
    )
    wall = Wall(layers, (Probe("sheet_in", 0.001), Probe("wool", 0.01)))
    n = 200
    ue = np.where(np.arange(n + 1) >= 5, 20.0, 0.0)
    inp = make_input(wall, ue, np.zeros(n + 1), 600.0)
    out = run(inp)
    assert out.info["implicit_links"] >= 1
    for p in wall.probes:
        assert np.diff(out.temperatures[p.name]).min() > -1e-6


# ---------------------------------------------------------------------------- fast path
@pytest.mark.parametrize("scheme", ["cn", "implicit"])
@pytest.mark.parametrize(
    "ext,intr",
    [
        ("surface_temperature", "surface_temperature"),
        ("air_temperature", "air_temperature"),
        ("heat_flux", "air_temperature"),
        ("surface_temperature", "heat_flux"),
    ],
)
def test_modal_fast_path_equals_general_path(scheme, ext, intr):
    wall = three_layer_wall()
    # a contact resistance (0.5 m2K/W: with 0.05 the wool's half-cell next to it would be a stiff node, whose
    # links get a raised theta and the general path)
    wall = wall.replace_layer("brick", contact_resistance=0.5)
    ue, ui = daily_inputs(ext, intr)
    inp = make_input(wall, ue, ui, 60.0, scheme=scheme, ext=ext, intr=intr, h_e=25.0, h_i=7.7, out_every=5)
    inp = inp.__class__(**{**inp.__dict__, "output_positions": inp.output_positions + 0.4})
    inp = inp.__class__(**{**inp.__dict__, "output_positions": inp.output_positions[:-1]})
    prep = FDEngine(scheme).prepare(inp)
    walls = [wall, wall.replace_layer("wool", conductivity=0.05), wall.replace_probe("P2", depth=0.21)]
    fast = prep.run_walls(walls, path="modal")
    slow = prep.run_walls(walls, path="general")
    assert fast.path == "modal" and slow.path == "general"
    # the same linear algebra: agreement to round-off (the bound is 1e-9 degC)
    np.testing.assert_allclose(fast.out, slow.out, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.final_state, slow.final_state, rtol=0, atol=1e-9)


def test_auto_path_choice():
    wall = three_layer_wall()
    t = np.arange(101) * 60.0
    inp = make_input(wall, 5 + np.sin(t), np.full(101, 20.0), 60.0)
    assert run(inp).info["path"] == "modal"
    nl = wall.replace_layer("wool", conductivity_temperature_coefficient=0.004)
    inp2 = inp.__class__(**{**inp.__dict__, "wall": nl})
    assert run(inp2).info["path"] == "general"


@pytest.mark.parametrize("path", ["modal", "general"])
def test_batch_equals_single_runs_each_path(path):
    wall = three_layer_wall()
    t = np.arange(1441) * 60.0
    inp = make_input(wall, 5 + 10 * np.sin(2 * np.pi * t / 86400), np.full(1441, 20.0), 60.0, out_every=5)
    walls = [wall.replace_layer("wool", conductivity=c) for c in (0.035, 0.04, 0.045)]
    walls += [wall.replace_probe("P1", depth=0.13), wall.replace_layer("brick", density=1500.0)]
    prep = FDEngine("cn").prepare(inp)
    batch = prep.run_walls(walls, path=path)
    assert batch.path == path
    for i, w in enumerate(walls):
        single = prep.run_walls([w], path=path)
        np.testing.assert_allclose(batch.out[i], single.out[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(batch.final_state[i], single.final_state[0], rtol=0, atol=1e-12)


def test_lambda_T_batch_equals_single_runs():
    wall = three_layer_wall().replace_layer("wool", conductivity_temperature_coefficient=0.01)
    t = np.arange(1441) * 60.0
    inp = make_input(wall, 5 + 15 * np.sin(2 * np.pi * t / 86400), np.full(1441, 20.0), 60.0, out_every=5)
    walls = [wall.replace_layer("wool", conductivity=c) for c in (0.035, 0.04)]
    walls.append(wall.replace_layer("wool", conductivity_temperature_coefficient=0.02))
    prep = FDEngine("cn").prepare(inp)
    batch = prep.run_walls(walls)
    assert batch.path == "general"
    for i, w in enumerate(walls):
        np.testing.assert_allclose(batch.out[i], prep.run_walls([w]).out[0], rtol=0, atol=1e-12)
    # a larger temperature coefficient changes the result
    assert np.abs(batch.out[2] - batch.out[1]).max() > 1e-3


def test_modal_equals_general_from_a_given_initial_state():
    wall = three_layer_wall()
    t = np.arange(721) * 60.0
    inp = make_input(wall, 5 + 10 * np.sin(2 * np.pi * t / 86400), np.full(721, 20.0), 60.0, out_every=5)
    prep = FDEngine("cn").prepare(inp)
    props = PropertyArrays.from_walls([wall, wall.replace_layer("wool", conductivity=0.05)])
    n = prep.grid.n_nodes
    t0 = np.vstack([np.linspace(0.0, 30.0, n), 10 + 5 * np.sin(np.arange(n))])
    fast = prep.run_batch(props, initial_state=t0, path="modal")
    slow = prep.run_batch(props, initial_state=t0, path="general")
    np.testing.assert_allclose(fast.out, slow.out, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.final_state, slow.final_state, rtol=0, atol=1e-9)


def test_lambda_T_refactorisation_is_invisible():
    """The frozen factorisation with explicit drift correction against refactorising every step:
    the two differ by O(dt^2) terms far below the discretisation error."""
    wall = three_layer_wall().replace_layer("wool", conductivity_temperature_coefficient=0.02)
    t = np.arange(2881) * 60.0
    inp = make_input(wall, 5 + 20 * np.sin(2 * np.pi * t / 86400), np.full(2881, 20.0), 60.0, out_every=5)
    ref = FDEngine("cn").prepare(inp).run_walls([wall])
    assert ref.path == "general"
    inp_every = inp.replace(options=inp.options.replace(refactor_drift=0.0))
    every = FDEngine("cn").prepare(inp_every).run_walls([wall])
    diff = np.abs(every.out[0, :4] - ref.out[0, :4]).max()
    assert diff < 1e-4, diff


@pytest.mark.parametrize(
    "positions",
    [
        "every5",  # the fused five-step pass (5-minute outputs at 1-minute steps)
        "every1",  # an output at every grid time
        "irregular",  # uneven spacing, two outputs on one grid time, fractional times
    ],
)
@pytest.mark.parametrize("rows", [None, (0, 2), (5,), (0, 1, 2, 3, 4, 5, 6, 7)])
def test_modal_output_plan_equals_general_path(positions, rows):
    """Every way the modal kernel forms outputs (fused pass, separate dot products, several
    patterns, subsets of rows, more rows than the fused pass takes) against the general path."""
    wall = three_layer_wall(probes=(0.0, 0.05, 0.1, 0.17, 0.22, 0.25))  # 6 probes: 8 rows
    ue, ui = daily_inputs("surface_temperature", "surface_temperature", days=1)
    n = len(ue) - 1
    # piecewise-linear inputs (5-minute data at 1-minute steps), as the data preparation makes them
    ue = np.interp(np.arange(n + 1), np.arange(0, n + 1, 5), ue[::5])
    inp = make_input(wall, ue, ui, 60.0, faces=("exterior", "interior"))
    if positions == "every5":
        pos = np.arange(0, n + 1, 5, dtype=float)
    elif positions == "every1":
        pos = np.arange(0, n + 1, dtype=float)
    else:
        rng = np.random.default_rng(3)
        pos = np.sort(np.concatenate([[0.0, 0.0, 1.5, n - 0.25, float(n)], rng.uniform(0, n, 60), [300.0, 300.0]]))
    inp = inp.__class__(**{**inp.__dict__, "output_positions": pos})
    prep = FDEngine("cn").prepare(inp)
    props = PropertyArrays.from_walls([wall, wall.replace_layer("wool", conductivity=0.05)])
    mask = None
    if rows is not None:
        mask = np.zeros(len(wall.probes) + 2, dtype=bool)
        mask[list(rows)] = True
    fast = prep.run_batch(props, path="modal", rows=mask)
    slow = prep.run_batch(props, path="general")
    assert fast.path == "modal"
    want = np.ones(len(wall.probes) + 2, dtype=bool) if mask is None else mask
    np.testing.assert_allclose(fast.out[:, want], slow.out[:, want], rtol=0, atol=1e-9)
    assert np.isnan(fast.out[:, ~want]).all()
    np.testing.assert_allclose(fast.final_state, slow.final_state, rtol=0, atol=1e-9)


def test_raised_theta_stays_on_the_modal_path():
    """Candidates for which the theta rule raises theta (at the exterior input's link, and on inner links
    only) run on the modal path - the generalized eigenproblem - in one batch with candidates that keep
    Crank-Nicolson everywhere, each equal to its general-path run to round-off."""
    wall = three_layer_wall()
    t = np.arange(1441) * 60.0
    inp = make_input(wall, 5 + 15 * np.sin(2 * np.pi * t / 86400), np.full(1441, 20.0), 60.0, out_every=5)
    prep = FDEngine("cn").prepare(inp)
    first, middle = wall.layers[0], wall.layers[1]
    walls = [
        wall,
        wall.replace_layer(first.id, conductivity=first.conductivity * 400.0),  # theta raised at the input link
        wall.replace_layer(middle.id, conductivity=middle.conductivity * 400.0),  # raised on inner links only
        wall.replace_layer(first.id, conductivity=first.conductivity * 1.1),
    ]
    batch = prep.run_walls(walls)
    assert batch.path == "modal"
    assert list(batch.implicit_links > 0) == [False, True, True, False]
    cap, g = assemble(prep.grid, PropertyArrays.from_walls(walls))
    theta, bc_theta, _ = prep._thetas(cap, g)
    assert theta[1, 0] > 0.5 and theta[2, 0] == 0.5  # (the exterior face has an imposed temperature)
    general = prep.run_walls(walls, path="general")
    scale = np.abs(general.out).max(axis=2, keepdims=True)
    np.testing.assert_allclose(batch.out / scale, general.out / scale, rtol=0, atol=1e-11)
    np.testing.assert_allclose(batch.final_state, general.final_state, rtol=0, atol=1e-10)
    for i, w in enumerate(walls):  # a batch equals its single runs
        np.testing.assert_array_equal(batch.out[i], prep.run_walls([w]).out[0])
