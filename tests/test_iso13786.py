"""Tests of wallcal.standards.iso13786.

Independent references used:
- the closed-form solution of the periodic heat equation in one slab,
  theta(x) = [theta_e sinh(k (L - x)) + theta_i sinh(k x)] / sinh(k L), k = (1 + i) / delta
  (Carslaw & Jaeger, Conduction of Heat in Solids, 2nd ed., section 2.6, periodic
  surface temperature), written out here with numpy;
- ISO 13786:2017 Annex A layer matrix in its real-trigonometric form (eq. A.2-A.5),
  typed in from the standard's expressions;
- the quasi-steady limit (period -> infinity): series resistances (Wall.steady_profile);
- a second-order finite-volume solution of the same complex boundary-value problem,
  built in this file, converging to the analytic one;
- energy conservation q(0) - q(L) = i w sum(rho c integral theta dx) and reciprocity.
"""

import numpy as np
import pytest

from wallcal.errors import StudyError
from wallcal.standards import iso13786
from wallcal.wall import Layer, Wall

DAY = 86400.0


def study_wall_3_to_9():
    """Layers #3..#9 of the paper's wall, Table II base case (the modelled wall)."""
    return Wall(
        (
            Layer("3", 0.10, 0.04, 135, 1030, "High density mineral wool"),
            Layer("4", 0.0125, 0.2, 530, 1600, "LVL panel"),
            Layer("5", 0.04, 0.035, 40, 1030, "Low density mineral wool"),
            Layer("6", 0.0125, 0.2, 530, 1600, "LVL panel"),
            Layer("7", 0.095, 0.035, 40, 1030, "Low density mineral wool"),
            Layer("8", 0.055, 0.035, 40, 1030, "Low density mineral wool"),
            Layer("9", 0.025, 0.21, 900, 1000, "Plasterboard"),
        )
    )


def concrete(d=0.2):
    return Layer("c", d, 1.8, 2400, 1000, "concrete")


# --------------------------------------------------------------------------- layer matrix


def test_penetration_depth_hand_value():
    # concrete: sqrt(1.8 * 86400 / (pi * 2400 * 1000)) = sqrt(0.0206265) = 0.143619 m
    assert iso13786.penetration_depth(1.8, 2400, 1000) == pytest.approx(0.143619, rel=1e-5)
    with pytest.raises(StudyError, match="period_s"):
        iso13786.penetration_depth(1.8, 2400, 1000, period_s=0)


@pytest.mark.parametrize("d", [0.001, 0.05, 0.2, 1.0])
def test_layer_matrix_matches_hyperbolic_closed_form(d):
    lam, rho, c = 1.8, 2400.0, 1000.0
    delta = np.sqrt(lam * DAY / (np.pi * rho * c))
    k = (1 + 1j) / delta
    z = iso13786.layer_matrix(d, lam, rho, c)
    np.testing.assert_allclose(z[0, 0], np.cosh(k * d), rtol=1e-12)
    np.testing.assert_allclose(z[1, 1], np.cosh(k * d), rtol=1e-12)
    np.testing.assert_allclose(z[0, 1], -np.sinh(k * d) / (lam * k), rtol=1e-12)
    np.testing.assert_allclose(z[1, 0], -lam * k * np.sinh(k * d), rtol=1e-12)
    assert np.linalg.det(z) == pytest.approx(1.0, abs=1e-9 * abs(z[0, 0]) ** 2)


def test_layer_matrix_real_trig_form_of_the_standard():
    lam, rho, c, d = 0.2, 530.0, 1600.0, 0.0125
    delta = np.sqrt(lam * DAY / (np.pi * rho * c))
    xi = d / delta
    ch, sh, co, si = np.cosh(xi), np.sinh(xi), np.cos(xi), np.sin(xi)
    z11 = complex(ch * co, sh * si)
    z12 = -delta / (2 * lam) * complex(sh * co + ch * si, ch * si - sh * co)
    z21 = -lam / delta * complex(sh * co - ch * si, sh * co + ch * si)
    z = iso13786.layer_matrix(d, lam, rho, c)
    np.testing.assert_allclose([z[0, 0], z[0, 1], z[1, 0]], [z11, z12, z21], rtol=1e-13)


def test_thin_layer_limit_is_lumped():
    # xi -> 0: Z12 -> -d/lambda, Z21 -> -i w rho c d (lumped capacity)
    lam, rho, c, d = 0.2, 530.0, 1600.0, 1e-4
    z = iso13786.layer_matrix(d, lam, rho, c)
    w = 2 * np.pi / DAY
    assert z[0, 1] == pytest.approx(-d / lam, rel=1e-6)
    assert z[1, 0] == pytest.approx(-1j * w * rho * c * d, rel=1e-6)


def test_vectorised_layer_matrix():
    z = iso13786.layer_matrix(np.array([0.1, 0.2]), 1.8, 2400, 1000)
    assert z.shape == (2, 2, 2)
    np.testing.assert_allclose(z[1], iso13786.layer_matrix(0.2, 1.8, 2400, 1000))


# --------------------------------------------------------------------------- wall characteristics


def test_single_layer_transmittance_closed_form():
    lam, rho, c, d = 1.8, 2400.0, 1000.0, 0.2
    wall = Wall((Layer("c", d, lam, rho, c),))
    dc = iso13786.dynamic_characteristics(wall, rsi=0.0, rse=0.0)
    k = (1 + 1j) / np.sqrt(lam * DAY / (np.pi * rho * c))
    assert dc.Y12 == pytest.approx(lam * k / np.sinh(k * d), rel=1e-12)
    assert dc.Y11 == pytest.approx(lam * k / np.tanh(k * d), rel=1e-12)
    assert dc.Y21 == pytest.approx(dc.Y12, rel=1e-12)
    # positive lag = -arg(Y12) T / 2 pi
    assert dc.time_shift_h == pytest.approx(-np.angle(lam * k / np.sinh(k * d)) * 24 / (2 * np.pi), rel=1e-9)


def test_steady_limit():
    wall = study_wall_3_to_9()
    dc = iso13786.dynamic_characteristics(wall, period_s=1e12)
    assert dc.decrement_factor == pytest.approx(1.0, abs=1e-6)
    assert abs(dc.Y12) == pytest.approx(wall.u_value(), rel=1e-6)
    assert dc.time_shift_h / (1e12 / 3600) < 1e-4
    # single layer, no surface resistance: kappa1 = kappa2 = C / 2 in the quasi-steady limit
    one = Wall((concrete(),))
    dc1 = iso13786.dynamic_characteristics(one, period_s=1e12, rsi=0.0, rse=0.0)
    assert dc1.kappa1 == pytest.approx(0.5 * 2400 * 1000 * 0.2, rel=1e-6)
    assert dc1.kappa2 == pytest.approx(0.5 * 2400 * 1000 * 0.2, rel=1e-6)


def test_time_shift_is_unwrapped_beyond_half_a_period():
    lags = [iso13786.dynamic_characteristics(Wall((concrete(d),))).time_shift_h for d in (0.1, 0.3, 0.5, 1.0)]
    assert np.all(np.diff(lags) > 0)
    assert lags[-2] > 12 and lags[-1] > 24  # 1 m of concrete: more than a full period of lag
    # lag modulo the period agrees with the standard's arg formula
    dc = iso13786.dynamic_characteristics(Wall((concrete(1.0),)))
    assert (dc.time_shift_h + 24 * np.angle(dc.Y12) / (2 * np.pi)) % 24 == pytest.approx(0.0, abs=1e-9)


def test_study_wall_figures_regression():
    # regression values for the layers #3..#9 wall (Table II base case), T = 24 h, Rsi 0.13, Rse 0.04;
    # U checked by hand: 1 / (0.13 + 8.17262 + 0.04) = 0.119866
    dc = iso13786.dynamic_characteristics(study_wall_3_to_9())
    assert dc.u_value == pytest.approx(0.119866, rel=1e-5)
    assert abs(dc.Y12) == pytest.approx(0.02542, rel=1e-3)
    assert dc.decrement_factor == pytest.approx(0.2121, rel=1e-3)
    assert dc.time_shift_h == pytest.approx(10.88, abs=0.01)
    assert abs(dc.Y11) == pytest.approx(1.666, rel=1e-3)
    assert abs(dc.Y22) == pytest.approx(0.614, rel=1e-3)
    assert dc.kappa1 == pytest.approx(24.86e3, rel=1e-3)
    assert dc.kappa2 == pytest.approx(8.98e3, rel=1e-3)


def test_wall_matrix_order_and_surfaces():
    a, b = Layer("a", 0.1, 0.04, 30, 1000), concrete(0.15)
    wall = Wall((a, b))  # a exterior
    z = iso13786.wall_matrix(wall, rsi=0.13, rse=0.04)
    za = iso13786.layer_matrix(0.1, 0.04, 30, 1000)
    zb = iso13786.layer_matrix(0.15, 1.8, 2400, 1000)
    expected = iso13786.resistance_matrix(0.04) @ za @ zb @ iso13786.resistance_matrix(0.13)
    np.testing.assert_allclose(z, expected, rtol=1e-13)
    # insulation outside: the interior admittance is much larger than the exterior one
    dc = iso13786.dynamic_characteristics(wall)
    assert abs(dc.Y11) > 3 * abs(dc.Y22)
    assert dc.kappa1 > dc.kappa2


def test_air_layer_handled_via_iso6946():
    wall = Wall(
        (
            Layer("1", 0.015, 0.13, 500, 1600, "Wood panel"),
            Layer("2", 0.035, material="air gap"),
            *study_wall_3_to_9().layers,
        )
    )
    well = iso13786.dynamic_characteristics(wall, air_layers={"2": "well_ventilated"})
    ref = iso13786.dynamic_characteristics(study_wall_3_to_9(), rse=0.13)
    assert well.Y12 == pytest.approx(ref.Y12, rel=1e-12)
    with pytest.raises(StudyError, match="air_layers"):
        iso13786.dynamic_characteristics(wall)


# --------------------------------------------------------------------------- periodic profile


def test_profile_single_layer_closed_form():
    lam, rho, c, d = 1.8, 2400.0, 1000.0, 0.2
    wall = Wall((Layer("c", d, lam, rho, c),))
    x = np.linspace(0, d, 41)
    te, ti = 3.0 * np.exp(0.3j), 1.0 - 0.5j
    p = iso13786.periodic_profile(wall, DAY, te, ti, x)
    k = (1 + 1j) / np.sqrt(lam * DAY / (np.pi * rho * c))
    theta = (te * np.sinh(k * (d - x)) + ti * np.sinh(k * x)) / np.sinh(k * d)
    q = -lam * k * (-te * np.cosh(k * (d - x)) + ti * np.cosh(k * x)) / np.sinh(k * d)
    np.testing.assert_allclose(p.temperature, theta, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(p.heat_flux, q, rtol=1e-11, atol=1e-13)
    assert p.q_exterior == pytest.approx(q[0], rel=1e-12)
    assert p.q_interior == pytest.approx(q[-1], rel=1e-12)


def mixed_wall():
    return Wall(
        (
            Layer("a", 0.05, 1.0, 2000, 900, contact_resistance=0.02),
            Layer("gap", 0.03, thermal_resistance=0.17, material="no-mass"),
            Layer("b", 0.12, 0.04, 40, 1030),
            Layer("c", 0.0125, 0.21, 900, 1000),
        )
    )


def test_profile_steady_limit():
    wall = mixed_wall()
    x = np.array([0.0, 0.01, 0.03, 0.06, 0.07, 0.1, 0.15, 0.2, 0.205, wall.thickness])
    p = iso13786.periodic_profile(wall, 1e13, 5.0, 20.0, x)
    np.testing.assert_allclose(p.temperature.real, wall.steady_profile(5.0, 20.0, x), atol=1e-6)
    np.testing.assert_allclose(p.temperature.imag, 0.0, atol=1e-5)
    r = wall.resistance
    np.testing.assert_allclose(p.heat_flux.real, (5.0 - 20.0) / r, rtol=1e-6)


def test_profile_reciprocity_and_transmittance():
    wall = study_wall_3_to_9()
    x = [0.0, wall.thickness]
    from_ext = iso13786.periodic_profile(wall, DAY, 1.0, 0.0, x)
    from_int = iso13786.periodic_profile(wall, DAY, 0.0, 1.0, x)
    assert from_ext.q_interior == pytest.approx(-from_int.q_exterior, rel=1e-12)
    dc = iso13786.dynamic_characteristics(wall, rsi=0.0, rse=0.0)
    assert from_ext.q_interior == pytest.approx(dc.Y12, rel=1e-12)
    assert from_ext.q_exterior == pytest.approx(dc.Y22, rel=1e-12)
    assert -from_int.q_interior == pytest.approx(dc.Y11, rel=1e-12)


def test_profile_energy_conservation():
    from scipy.integrate import simpson

    wall = mixed_wall()
    te, ti = 2.0 + 1.0j, -0.7j
    p0 = iso13786.periodic_profile(wall, DAY, te, ti, [0.0])
    w = 2 * np.pi / DAY
    stored = 0.0
    x0 = 0.0
    for layer in wall.layers:
        if not layer.is_massless:
            x = np.linspace(x0, x0 + layer.thickness, 2001)
            th = iso13786.periodic_profile(wall, DAY, te, ti, x, interface_side="interior").temperature
            # endpoints: take the value inside this layer
            th[0] = iso13786.periodic_profile(wall, DAY, te, ti, [x0], interface_side="interior").temperature[0]
            th[-1] = iso13786.periodic_profile(
                wall, DAY, te, ti, [x0 + layer.thickness], interface_side="exterior"
            ).temperature[0]
            stored += layer.volumetric_heat_capacity * simpson(th, x=x)
        x0 += layer.thickness
    assert p0.q_exterior - p0.q_interior == pytest.approx(1j * w * stored, rel=1e-8)


def test_profile_contact_resistance_jump():
    wall = mixed_wall()
    xc = 0.05
    kw = dict(period_s=DAY, t_ext_amplitude=1.0, t_int_amplitude=0.3j, depths_m=[xc])
    ext = iso13786.periodic_profile(wall, interface_side="exterior", **kw)
    intr = iso13786.periodic_profile(wall, interface_side="interior", **kw)
    mean = iso13786.periodic_profile(wall, **kw)
    assert ext.temperature[0] - intr.temperature[0] == pytest.approx(0.02 * ext.heat_flux[0], rel=1e-12)
    assert mean.temperature[0] == pytest.approx(0.5 * (ext.temperature[0] + intr.temperature[0]), rel=1e-14)


def fv_solution(wall, period_s, te, ti, n_per_layer):
    """Second-order finite-volume solution of i w rho c theta = d/dx(lambda dtheta/dx), Dirichlet faces."""
    w = 2 * np.pi / period_s
    xs, cap, half_r, jump = [], [], [], []
    x0 = 0.0
    for layer in wall.layers:
        if layer.is_massless:
            jump.append((len(xs), layer.thermal_resistance))
        else:
            dx = layer.thickness / n_per_layer
            for j in range(n_per_layer):
                xs.append(x0 + (j + 0.5) * dx)
                cap.append(layer.volumetric_heat_capacity * dx)
                half_r.append(dx / (2 * layer.conductivity))
        if layer.contact_resistance:
            jump.append((len(xs), layer.contact_resistance))
        x0 += layer.thickness
    n = len(xs)
    extra = np.zeros(n + 1)  # resistance at face i (between cell i-1 and i)
    for idx, r in jump:
        extra[idx] += r
    half_r = np.array(half_r)
    r_face = np.empty(n + 1)
    r_face[0] = half_r[0] + extra[0]
    r_face[n] = half_r[-1] + extra[n]
    r_face[1:n] = half_r[:-1] + half_r[1:] + extra[1:n]
    g = 1 / r_face
    a = np.zeros((n, n), complex)
    rhs = np.zeros(n, complex)
    for i in range(n):
        a[i, i] = 1j * w * cap[i] + g[i] + g[i + 1]
        if i > 0:
            a[i, i - 1] = -g[i]
        if i < n - 1:
            a[i, i + 1] = -g[i + 1]
    rhs[0] += g[0] * te
    rhs[-1] += g[n] * ti
    th = np.linalg.solve(a, rhs)
    q_ext = g[0] * (te - th[0])
    q_int = g[n] * (th[-1] - ti)
    return np.array(xs), th, q_ext, q_int


def test_profile_against_finite_volumes_second_order():
    wall = Wall(
        (
            Layer("a", 0.05, 1.0, 2000, 900, contact_resistance=0.02),
            Layer("b", 0.12, 0.04, 40, 1030),
            Layer("c", 0.0125, 0.21, 900, 1000),
        )
    )
    te, ti = 1.0, 0.4j
    errs = []
    for n in (10, 20, 40):
        xs, th, q_ext, q_int = fv_solution(wall, 6 * 3600.0, te, ti, n)
        p = iso13786.periodic_profile(wall, 6 * 3600.0, te, ti, xs)
        errs.append(max(np.max(np.abs(th - p.temperature)), abs(q_ext - p.q_exterior) / abs(p.q_exterior)))
    assert errs[-1] < 2e-3
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 1.8), orders


def test_profile_thick_wall_is_stable():
    # 1.5 m of concrete at a 6 h period: xi ~ 21; near the exterior face the solution is the
    # semi-infinite one theta_e exp(-k x); the interior response is tiny but finite
    wall = Wall((concrete(1.5),))
    x = np.linspace(0, 0.3, 7)
    p = iso13786.periodic_profile(wall, 6 * 3600.0, 1.0, 0.0, x)
    k = (1 + 1j) / iso13786.penetration_depth(1.8, 2400, 1000, 6 * 3600.0)
    np.testing.assert_allclose(p.temperature, np.exp(-k * x), rtol=1e-9, atol=1e-15)
    assert np.isfinite(p.q_interior) and 0 < abs(p.q_interior) < 1e-6
    with pytest.raises(StudyError, match="penetration depths"):
        iso13786.periodic_profile(Wall((concrete(30.0),)), 3600.0, 1.0, 0.0, [0.0])


def test_profile_bad_arguments_and_times():
    wall = study_wall_3_to_9()
    with pytest.raises(StudyError, match="depths_m"):
        iso13786.periodic_profile(wall, DAY, 1.0, 0.0, [-0.01])
    with pytest.raises(StudyError, match="interface_side"):
        iso13786.periodic_profile(wall, DAY, 1.0, 0.0, [0.0], interface_side="left")
    p = iso13786.periodic_profile(wall, DAY, 2.0, 0.0, [0.0, 0.1])
    t = p.at_times([0.0, DAY / 4])
    assert t.shape == (2, 2)
    assert t[0, 0] == pytest.approx(2.0) and t[1, 0] == pytest.approx(0.0, abs=1e-12)


# --------------------------------------------------------------------------- every figure of a mixed wall, by hand
def _hand_layer(d, lam, rho, c, period):
    delta = np.sqrt(lam * period / (np.pi * rho * c))
    k = (1 + 1j) / delta
    return np.array([[np.cosh(k * d), -np.sinh(k * d) / (lam * k)], [-lam * k * np.sinh(k * d), np.cosh(k * d)]]), delta


def _r(res):
    return np.array([[1.0, -res], [0.0, 1.0]], dtype=complex)


def test_every_characteristic_of_a_wall_with_contact_and_no_mass_layers_by_hand():
    """Plaster (a 0.1 m2K/W contact after it), a no-mass layer of 0.2 m2K/W, brick (its contact resistance
    of 0.3 m2K/W is the last layer's: outside the wall, ignored), a 12 h period and surface resistances
    other than the defaults: the transfer matrices, admittances, leads, U, decrement, areal capacities with
    and without surfaces, penetration depths and xi, all formed here from the closed-form layer matrix."""
    period = 12 * 3600.0
    wall = Wall(
        (
            Layer("p", 0.02, 0.7, 1400.0, 1000.0, contact_resistance=0.1),
            Layer("m", 0.01, thermal_resistance=0.2),
            Layer("b", 0.24, 0.9, 1800.0, 850.0, contact_resistance=0.3),
        )
    )
    dc = iso13786.dynamic_characteristics(wall, period, rsi=0.17, rse=0.06)
    zp, dp = _hand_layer(0.02, 0.7, 1400.0, 1000.0, period)
    zb, db = _hand_layer(0.24, 0.9, 1800.0, 850.0, period)
    zs = zp @ _r(0.1) @ _r(0.2) @ zb
    z = _r(0.06) @ zs @ _r(0.17)
    np.testing.assert_allclose(dc.Z, z, rtol=1e-12)
    np.testing.assert_allclose(dc.Z_surface, zs, rtol=1e-12)
    assert dc.period_s == period
    y11, y12, y22 = -z[0, 0] / z[0, 1], -1 / z[0, 1], -z[1, 1] / z[0, 1]
    assert dc.Y11 == pytest.approx(y11, rel=1e-12) and dc.Y22 == pytest.approx(y22, rel=1e-12)
    assert dc.Y12 == pytest.approx(y12, rel=1e-12) and dc.Y21 == pytest.approx(y12, rel=1e-9)
    u = 1 / (0.17 + 0.06 + 0.02 / 0.7 + 0.1 + 0.2 + 0.24 / 0.9)
    assert dc.u_value == pytest.approx(u, rel=1e-14)
    assert dc.decrement_factor == pytest.approx(abs(y12) / u, rel=1e-12)
    w = period / (2 * np.pi)
    assert dc.admittance_time_lead_interior_h == pytest.approx(np.angle(y11) * w / 3600, rel=1e-12)
    assert dc.admittance_time_lead_exterior_h == pytest.approx(np.angle(y22) * w / 3600, rel=1e-12)
    assert dc.kappa1 == pytest.approx(w * abs((zs[0, 0] - 1) / zs[0, 1]), rel=1e-12)
    assert dc.kappa2 == pytest.approx(w * abs((zs[1, 1] - 1) / zs[0, 1]), rel=1e-12)
    assert dc.kappa1_with_surfaces == pytest.approx(w * abs((z[0, 0] - 1) / z[0, 1]), rel=1e-12)
    assert dc.kappa2_with_surfaces == pytest.approx(w * abs((z[1, 1] - 1) / z[0, 1]), rel=1e-12)
    assert dc.penetration_depths_m == pytest.approx({"p": dp, "b": db}, rel=1e-14)
    assert dc.xi == pytest.approx({"p": 0.02 / dp, "b": 0.24 / db}, rel=1e-14)
    # the lag: the phase of 1 / Y12, unwrapped (the brick alone is more than a 12 h period's quarter)
    assert abs(np.exp(1j * (dc.time_shift_h * 3600 / w + np.angle(y12))) - 1) < 1e-9
    assert 0 < dc.time_shift_h < 12
    assert iso13786.penetration_depth(0.9, 1800.0, 850.0, period) == pytest.approx(db, rel=1e-14)
    assert isinstance(iso13786.penetration_depth(0.9, 1800.0, 850.0, period), float)
    np.testing.assert_allclose(iso13786.penetration_depth([0.7, 0.9], [1400, 1800], [1000, 850], period), [dp, db])
    text = dc.summary()
    assert text.startswith(f"period 12 h: U = {u:.4f} W/(m2K), |Y12| = {abs(y12):.5f} W/(m2K), ")
    assert f"|Y11| = {abs(y11):.3f} W/(m2K) (lead {np.angle(y11) * w / 3600:.2f} h)" in text
    assert f"|Y22| = {abs(y22):.3f} W/(m2K) (lead {np.angle(y22) * w / 3600:.2f} h)" in text
    assert text.endswith(f"kappa1 = {dc.kappa1 / 1000:.2f} kJ/(m2K), kappa2 = {dc.kappa2 / 1000:.2f} kJ/(m2K)")


def test_periods_must_be_positive_and_finite():
    wall = Wall((concrete(),))
    for bad in (0.0, -1.0, float("inf"), float("nan")):
        with pytest.raises(StudyError, match="period"):
            iso13786.dynamic_characteristics(wall, bad)
    foil = Wall((Layer("f", 1e-4, 50.0, 7800.0, 500.0),))  # 0.1 mm of steel: penetration depth 1.4 mm at 0.5 s
    assert iso13786.dynamic_characteristics(foil, 0.5).period_s == 0.5  # half a second is a period too


def _propagate(segments, theta0, q0, x_want, period, side):
    """The periodic field by transfer from the exterior face (x inwards, q positive inwards): a layer is
    theta(x) = theta0 cosh(k x) - q0 sinh(k x) / (lam k), q = q0 cosh(k x) - lam k theta0 sinh(k x); a jump
    of resistance R drops theta by R q; a no-mass layer of thickness t drops it linearly."""
    out_t, out_q = [], []
    for xw in x_want:
        th, q, x = theta0, q0, 0.0
        for kind, a, b in segments:
            if kind == "layer":
                t, (lam, rho, c) = a, b
                k = (1 + 1j) / np.sqrt(lam * period / (np.pi * rho * c))
                s = min(max(xw - x, 0.0), t)
                th, q = (
                    th * np.cosh(k * s) - q * np.sinh(k * s) / (lam * k),
                    q * np.cosh(k * s) - lam * k * th * np.sinh(k * s),
                )
                x += t
                if xw < x - 1e-12:  # (at the layer's end: on to a jump there, if any)
                    break
            elif kind == "linear":
                t, r = a, b
                s = min(max(xw - x, 0.0), t)
                th = th - r * (s / t) * q
                x += t
                if xw < x - 1e-12:
                    break
            else:  # a jump at x
                r = a
                at = abs(xw - x) < 1e-12
                if at and side == "exterior":
                    break
                th_after = th - r * q
                if at and side == "mean":
                    th = 0.5 * (th + th_after)
                    break
                th = th_after
                if at:
                    break
        out_t.append(th)
        out_q.append(q)
    return np.array(out_t), np.array(out_q)


@pytest.mark.parametrize("side", ["mean", "exterior", "interior"])
def test_profile_through_jumps_and_no_mass_layers_by_hand(side):
    """A contact resistance (jump), a no-mass layer with thickness (linear drop over it) and one of zero
    thickness (jump), at depths inside layers and on every interface."""
    period = DAY
    wall = Wall(
        (
            Layer("a", 0.05, 1.0, 2000.0, 900.0, contact_resistance=0.02),
            Layer("gap", 0.03, thermal_resistance=0.17),
            Layer("b", 0.12, 0.04, 40.0, 1030.0),
            Layer("film", 0.0, thermal_resistance=0.05),
            Layer("c", 0.0125, 0.21, 900.0, 1000.0, contact_resistance=0.4),  # the last layer's: ignored
        )
    )
    segs = [
        ("layer", 0.05, (1.0, 2000.0, 900.0)),
        ("jump", 0.02, None),
        ("linear", 0.03, 0.17),
        ("layer", 0.12, (0.04, 40.0, 1030.0)),
        ("jump", 0.05, None),
        ("layer", 0.0125, (0.21, 900.0, 1000.0)),
    ]
    L = 0.05 + 0.03 + 0.12 + 0.0125
    te, ti = 2.0 * np.exp(0.4j), 0.7 - 0.2j
    # theta(L) is linear in q0: two propagations give it
    t0, _ = _propagate(segs, te, 0.0, [L], period, "interior")
    t1, _ = _propagate(segs, te, 1.0, [L], period, "interior")
    q0 = (ti - t0[0]) / (t1[0] - t0[0])
    x = np.array([0.0, 0.02, 0.05, 0.065, 0.08, 0.14, 0.2, 0.205, L])
    theta, q = _propagate(segs, te, q0, x, period, side)
    p = iso13786.periodic_profile(wall, period, te, ti, x, interface_side=side)
    np.testing.assert_allclose(p.temperature, theta, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(p.heat_flux, q, rtol=1e-10, atol=1e-12)
    assert p.q_exterior == pytest.approx(q0, rel=1e-10)


def test_profile_and_characteristics_refuse_bad_layers_with_every_problem_named():
    bad = Wall(
        (
            Layer("a", 0.0, 1.0, 2000.0, 900.0),
            Layer("b", 0.1, 0.0, -1.0, float("nan")),
            Layer("m", 0.01, thermal_resistance=-0.1),
        )
    )
    with pytest.raises(StudyError) as exc:
        iso13786.periodic_profile(bad, DAY, 1.0, 0.0, [0.0])
    msg = str(exc.value)
    for part in (
        "wall.layers['a'].thickness: must be > 0, got 0.0",
        "wall.layers['b'].conductivity: must be > 0, got 0.0",
        "wall.layers['b'].density: must be > 0, got -1.0",
        "wall.layers['b'].specific_heat: must be > 0, got nan",
        "wall.layers['m']: no-mass layer needs thermal_resistance >= 0",
    ):
        assert part in msg, part
    with pytest.raises(StudyError) as exc:
        iso13786.dynamic_characteristics(bad)
    msg = str(exc.value)
    for part in (
        "wall.layers['a'].thickness: must be > 0, got 0.0",
        "wall.layers['b'].conductivity: must be > 0 for ISO 13786, got 0.0",
        "wall.layers['b'].specific_heat: must be > 0 for ISO 13786, got nan",
        "wall.layers['m'].thermal_resistance: must be >= 0",
    ):
        assert part in msg, part
    with pytest.raises(StudyError, match="wall.layers: the wall has no layers"):
        iso13786.periodic_profile(Wall(()), DAY, 1.0, 0.0, [0.0])


# --------------------------------------------------------------------------- the checks at their documented edges
def test_profile_depths_within_rounding_of_the_faces_are_put_on_them():
    wall = Wall((concrete(0.2),))
    p = iso13786.periodic_profile(wall, DAY, 1.0, 0.5j, [-1e-14, 0.2 * (1 + 1e-13)])
    assert p.depths_m.tolist() == [0.0, 0.2]
    assert p.temperature == pytest.approx([1.0, 0.5j], abs=1e-12)  # the imposed face temperatures


@pytest.mark.parametrize(
    "depths",
    [[0.1, -1e-6], [0.1, 0.2002], [0.1, float("nan")], [[0.0, 0.1]]],
    ids=["outside the exterior face", "beyond the interior face", "nan", "two-dimensional"],
)
def test_profile_refuses_each_kind_of_bad_depth_naming_the_range(depths):
    with pytest.raises(StudyError) as exc:
        iso13786.periodic_profile(Wall((concrete(0.2),)), DAY, 1.0, 0.0, depths)
    assert exc.value.problems == [f"depths_m: depths must lie in [0, 0.2] m, got {np.asarray(depths)!r}"]


def test_profile_accepts_a_wall_of_exactly_max_xi_penetration_depths():
    delta = iso13786.penetration_depth(1.8, 2400, 1000, DAY)
    at = Wall((concrete(iso13786.MAX_XI * delta),))  # d / delta is 300.0 to the last bit
    p = iso13786.periodic_profile(at, DAY, 1.0, 0.0, [0.0])
    assert p.temperature[0] == pytest.approx(1.0)
    with pytest.raises(StudyError) as exc:
        iso13786.periodic_profile(Wall((concrete(301 * delta),)), DAY, 1.0, 0.0, [0.0])
    assert exc.value.problems == [
        "period_s: the wall is 301 penetration depths thick at this period (limit 300); "
        "the response is below rounding, use a longer period"
    ]


def test_at_times_is_the_real_part_of_the_rotating_amplitude_by_hand():
    wall = Wall((concrete(0.2),))
    te, ti = 2.0 * np.exp(0.3j), 0.5j
    p = iso13786.periodic_profile(wall, DAY, te, ti, [0.0, 0.07, 0.2])
    t = np.array([0.0, DAY / 8, DAY / 3, 0.9 * DAY])
    got = p.at_times(t)
    assert got.shape == (4, 3)
    w = 2 * np.pi / DAY
    # faces: the imposed signals 2 cos(w t + 0.3) and Re(0.5 i e^{i w t}) = -0.5 sin(w t)
    np.testing.assert_allclose(got[:, 0], 2.0 * np.cos(w * t + 0.3), rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, 2], -0.5 * np.sin(w * t), rtol=0, atol=1e-12)
    a = p.temperature[1]
    np.testing.assert_allclose(got[:, 1], a.real * np.cos(w * t) - a.imag * np.sin(w * t), rtol=0, atol=1e-12)


def test_no_mass_layers_of_zero_thickness_or_zero_resistance_are_accepted():
    # a membrane (d = 0, a jump) and a zero-resistance no-mass layer between two concrete layers
    wall = Wall(
        (
            Layer("c1", 0.1, 1.8, 2400, 1000),
            Layer("m", 0.0, thermal_resistance=0.05),
            Layer("z", 0.01, thermal_resistance=0.0),
            Layer("c2", 0.1, 1.8, 2400, 1000),
        )
    )
    kw = dict(period_s=DAY, t_ext_amplitude=1.0, t_int_amplitude=0.0, depths_m=[0.1, 0.11])
    ext = iso13786.periodic_profile(wall, interface_side="exterior", **kw)
    intr = iso13786.periodic_profile(wall, interface_side="interior", **kw)
    q = intr.heat_flux[0]
    assert abs(q) > 1.0 and intr.heat_flux[1] == pytest.approx(q, rel=1e-12)  # no storage in no-mass layers
    assert ext.temperature[0] - intr.temperature[0] == pytest.approx(0.05 * q, rel=1e-12)  # the membrane's jump
    assert intr.temperature[1] == pytest.approx(intr.temperature[0], rel=1e-12)  # no drop across R = 0
    dc = iso13786.dynamic_characteristics(wall, rsi=0.0, rse=0.0)
    assert dc.u_value == pytest.approx(1 / (0.1 / 1.8 + 0.05 + 0.0 + 0.1 / 1.8))


def test_layer_checks_look_past_a_good_no_mass_layer_and_refuse_bad_ones():
    wall = Wall(
        (
            Layer("m", 0.0, thermal_resistance=0.05),
            Layer("n", -0.01, thermal_resistance=0.1),
            Layer("r", 0.0, thermal_resistance=float("nan")),
            Layer("c", 0.1, 1.8, 0.0, 1000),
        )
    )
    with pytest.raises(StudyError) as exc:
        iso13786.periodic_profile(wall, DAY, 1.0, 0.0, [0.0])
    assert exc.value.problems == [
        "wall.layers['n']: no-mass layer needs thermal_resistance >= 0 and thickness >= 0, got 0.1 m2K/W and -0.01 m",
        "wall.layers['r']: no-mass layer needs thermal_resistance >= 0 and thickness >= 0, got nan m2K/W and 0.0 m",
        "wall.layers['c'].density: must be > 0, got 0.0",
    ]
    with pytest.raises(StudyError) as exc:
        iso13786.dynamic_characteristics(wall)
    assert exc.value.problems == [
        "wall.layers['r'].thermal_resistance: must be >= 0",
        "wall.layers['c'].density: must be > 0 for ISO 13786, got 0.0",
    ]


def test_a_wall_of_jumps_only_or_of_no_layers_is_refused_by_name():
    with pytest.raises(StudyError) as exc:
        iso13786.periodic_profile(Wall(()), DAY, 1.0, 0.0, [0.0])
    assert exc.value.problems == ["wall.layers: the wall has no layers"]
    membrane = Wall((Layer("m", 0.0, thermal_resistance=0.1),))
    with pytest.raises(StudyError) as exc:
        iso13786.periodic_profile(membrane, DAY, 1.0, 0.0, [0.0])
    assert exc.value.problems == ["wall: the wall has no finite-thickness layer to evaluate depths in"]


def test_max_xi_counts_every_layer():
    delta = iso13786.penetration_depth(1.8, 2400, 1000, DAY)
    half = Layer("c1", 160 * delta, 1.8, 2400, 1000)
    two = Wall((half, half.replace(id="c2")))  # 160 + 160 = 320 penetration depths
    with pytest.raises(StudyError, match="the wall is 320 penetration depths thick"):
        iso13786.periodic_profile(two, DAY, 1.0, 0.0, [0.0])


def _slab(te, ti, x, x0, x1, k):
    """Carslaw & Jaeger's periodic slab with imposed face amplitudes te at x0 and ti at x1."""
    return (te * np.sinh(k * (x1 - x)) + ti * np.sinh(k * (x - x0))) / np.sinh(k * (x1 - x0))


def test_profile_of_two_layers_with_a_large_contact_resistance_by_hand():
    """0.1 m concrete, a 0.5 m2K/W contact (larger than any depth in metres), 0.1 m brick: in each layer the
    slab solution between its face temperatures, a jump of R q at the contact, q continuous across it."""
    wall = Wall((Layer("c", 0.1, 1.8, 2400, 1000, contact_resistance=0.5), Layer("b", 0.1, 0.7, 1800, 900)))
    te, ti = 1.0, 0.4j
    x = np.array([0.0, 0.03, 0.07, 0.1, 0.13, 0.18, 0.2])
    ext = iso13786.periodic_profile(wall, DAY, te, ti, x, interface_side="exterior")
    intr = iso13786.periodic_profile(wall, DAY, te, ti, x, interface_side="interior")
    q = ext.heat_flux[3]
    assert ext.temperature[3] - intr.temperature[3] == pytest.approx(0.5 * q, rel=1e-12)
    assert intr.heat_flux[3] == pytest.approx(q, rel=1e-12)
    kc = (1 + 1j) / iso13786.penetration_depth(1.8, 2400, 1000, DAY)
    kb = (1 + 1j) / iso13786.penetration_depth(0.7, 1800, 900, DAY)
    np.testing.assert_allclose(ext.temperature[:4], _slab(te, ext.temperature[3], x[:4], 0.0, 0.1, kc), rtol=1e-12)
    np.testing.assert_allclose(intr.temperature[3:], _slab(intr.temperature[3], ti, x[3:], 0.1, 0.2, kb), rtol=1e-12)
    assert intr.temperature[-1] == pytest.approx(ti, abs=1e-14)
    # away from the contact both readings agree, whichever side's segment evaluated the depth first
    np.testing.assert_allclose(ext.temperature[4:], intr.temperature[4:], rtol=1e-12)
    np.testing.assert_allclose(ext.temperature[:3], intr.temperature[:3], rtol=1e-12)
    np.testing.assert_allclose(ext.heat_flux, intr.heat_flux, rtol=1e-12)


def test_contact_resistance_of_the_next_to_last_layer_counts():
    # no-mass layers only: Z = [[1, -R_T], [0, 1]] with R_T summed by hand; the default surfaces 0.13 and 0.04
    wall = Wall(
        (
            Layer("a", 0.0, thermal_resistance=0.5, contact_resistance=0.2),
            Layer("b", 0.0, thermal_resistance=0.3, contact_resistance=0.7),  # the last layer's: outside the wall
        )
    )
    np.testing.assert_allclose(iso13786.wall_matrix(wall), [[1, -(0.04 + 0.5 + 0.2 + 0.3 + 0.13)], [0, 1]], atol=1e-15)
    assert iso13786.dynamic_characteristics(wall).u_value == pytest.approx(1 / (0.13 + 0.5 + 0.2 + 0.3 + 0.04))


def test_the_heat_flow_direction_reaches_the_air_layer_table():
    # 35 mm unventilated air: Table 8 horizontal 0.18, downward 0.19 + 10/25 * 0.02 = 0.198
    wall = Wall((Layer("gap", 0.035, material="air, unventilated"), Layer("m", 0.0, thermal_resistance=0.5)))
    np.testing.assert_allclose(iso13786.wall_matrix(wall), [[1, -(0.04 + 0.18 + 0.5 + 0.13)], [0, 1]], atol=1e-15)
    down = iso13786.wall_matrix(wall, direction="downward")
    np.testing.assert_allclose(down, [[1, -(0.04 + 0.198 + 0.5 + 0.13)], [0, 1]], atol=1e-15)
    dc = iso13786.dynamic_characteristics(wall, direction="downward")  # Rsi 0.17 for downward heat flow
    np.testing.assert_allclose(dc.Z, [[1, -(0.04 + 0.198 + 0.5 + 0.17)], [0, 1]], atol=1e-15)
    np.testing.assert_allclose(dc.Z_surface, [[1, -(0.198 + 0.5)], [0, 1]], atol=1e-15)
    assert dc.u_value == pytest.approx(1 / (0.17 + 0.198 + 0.5 + 0.04), rel=1e-12)


def test_a_well_ventilated_air_layer_makes_rse_equal_rsi_in_u():
    wall = Wall(
        (
            Layer("1", 0.015, 0.13, 500, 1600, "Wood panel"),
            Layer("2", 0.035, material="air gap"),
            *study_wall_3_to_9().layers,
        )
    )
    r = 0.10 / 0.04 + 0.0125 / 0.2 + 0.04 / 0.035 + 0.0125 / 0.2 + 0.095 / 0.035 + 0.055 / 0.035 + 0.025 / 0.21
    well = iso13786.dynamic_characteristics(wall, air_layers={"2": "well_ventilated"})
    assert well.u_value == pytest.approx(1 / (0.13 + r + 0.13), rel=1e-12)


@pytest.mark.parametrize("period_s", [DAY, 600.0])
def test_time_shift_of_a_wall_100_penetration_depths_thick(period_s):
    """Y12 = lambda k / sinh(k L) without surfaces; for xi = L / delta = 100, sinh(k L) = e^{k L} / 2 to 1e-87, so
    the lag unwrapped from zero frequency is xi - pi/4 radians (about 15.8 periods): the phase path must be
    sampled finely enough for the unwrapping, at a long and a short period."""
    delta = iso13786.penetration_depth(1.8, 2400, 1000, period_s)
    dc = iso13786.dynamic_characteristics(Wall((concrete(100 * delta),)), period_s, rsi=0.0, rse=0.0)
    expected_h = (100 - np.pi / 4) / (2 * np.pi) * period_s / 3600
    assert dc.time_shift_h == pytest.approx(expected_h, rel=1e-9)
    assert dc.xi == pytest.approx({"c": 100.0}, rel=1e-12)


def test_penetration_depth_is_a_plain_float_for_numbers():
    d = iso13786.penetration_depth(1.8, 2400, 1000)
    assert type(d) is float  # prints as a number in reports, not as np.float64(...)
    arr = iso13786.penetration_depth(np.array([1.8, 0.04]), 2400, 1000)
    assert arr.shape == (2,) and arr[0] == pytest.approx(d)
