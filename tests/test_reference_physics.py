"""Physics checks against references computed by hand, independent of the engine's own bookkeeping.

- the documented node rules (docs/engine.md, :mod:`wallcal.grid`), pinned node for node on the bundled example
  wall for both rules, through the grid and through what a user runs (the prepared study);
- steady state: the flux through a wall equals (T_e - T_i) / R with R summed by hand from the layers and a
  contact resistance, so a conductance error applied consistently (which the energy balance cannot see) shows;
- transient energy balance: the stored heat from the node temperatures and node capacities worked out by hand,
  against the time integral of the reported face fluxes;
- the discrete maximum principle with Dirichlet faces: every temperature stays between the extreme boundary and
  initial temperatures.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_input
from wallcal.engines.fd import FDEngine
from wallcal.grid import build_grid
from wallcal.wall import Layer, Probe, Wall

# ---------------------------------------------------------------------------- node rule on the example wall
# The example wall (src/wallcal/examples/campaign_a/study.toml), dt = 60 s, C = 2: the target spacing of a layer
# is dx = sqrt(C alpha dt) = sqrt(120 alpha), alpha = lambda / (rho c). By hand, layer by layer:
#   3: alpha = 0.04 / (135 * 1030)  = 2.8767e-7, dx = 5.8754e-3 m, d / dx = 0.1    / dx = 17.020
#   4: alpha = 0.20 / (530 * 1600)  = 2.3585e-7, dx = 5.3200e-3 m, d / dx = 0.0125 / dx =  2.350
#   5: alpha = 0.035 / (40 * 1030)  = 8.4951e-7, dx = 1.0097e-2 m, d / dx = 0.04   / dx =  3.962
#   6: as 4                                                       d / dx =  2.350
#   7: as 5                                                       d / dx = 0.095  / dx =  9.409
#   8: as 5                                                       d / dx = 0.055  / dx =  5.447
#   9: alpha = 0.21 / (900 * 1000)  = 2.3333e-7, dx = 5.2915e-3 m, d / dx = 0.025  / dx =  4.725
# "wallcal" rule: ceil (spacing at most the asked one); "energyplus" rule: int (CondFD's, spacing at least).
EXAMPLE_INTERVALS = {
    "wallcal": (18, 3, 4, 3, 10, 6, 5),  # 49 intervals, 50 nodes
    "energyplus": (17, 2, 3, 2, 9, 5, 4),  # 42 intervals, 43 nodes
}


@pytest.mark.parametrize("rule", ["wallcal", "energyplus"])
def test_node_rule_on_the_example_wall(example_study, rule):
    grid = build_grid(example_study.wall, 60.0, 2.0, rule)
    assert grid.nodes_per_layer == EXAMPLE_INTERVALS[rule]
    assert grid.n_nodes == sum(EXAMPLE_INTERVALS[rule]) + 1
    # equal spacing inside each layer, the last node of a layer exactly on its interface
    x = grid.x
    for i, layer in enumerate(example_study.wall.layers):
        a, b = grid.layer_first_node[i], grid.layer_last_node[i]
        np.testing.assert_allclose(np.diff(x[a : b + 1]), layer.thickness / EXAMPLE_INTERVALS[rule][i], rtol=1e-12)
        assert x[b] == pytest.approx(example_study.wall.interfaces[i + 1], abs=1e-15)


@pytest.mark.parametrize("rule", ["wallcal", "energyplus"])
def test_node_rule_reaches_the_user(example_study, rule):
    """What `wallcal simulate` runs: the prepared engine of the study uses the same grid."""
    import dataclasses

    from wallcal.simulation import prepare

    study = dataclasses.replace(example_study, simulation=dataclasses.replace(example_study.simulation, node_rule=rule))
    inp = prepare(study).inp
    assert inp.node_rule == rule
    grid = FDEngine(inp.scheme).prepare(inp).grid
    assert grid.nodes_per_layer == EXAMPLE_INTERVALS[rule]


def test_node_rule_exact_multiple_is_not_bumped():
    # d / dx = 10 exactly (up to round-off): both rules give 10 intervals, not 11 or 9
    layer = Layer("a", 0.1, conductivity=1.0, density=1000.0, specific_heat=2000.0)  # alpha = 5e-7
    grid = build_grid(Wall((layer,)), 100.0, 2.0, "wallcal")  # dx = sqrt(2 * 5e-7 * 100) = 0.01
    assert grid.nodes_per_layer == (10,)
    assert build_grid(Wall((layer,)), 100.0, 2.0, "energyplus").nodes_per_layer == (10,)
    # a layer thinner than one target spacing still gets one interval under both rules
    thin = Layer("t", 0.001, conductivity=1.0, density=1000.0, specific_heat=2000.0)
    assert build_grid(Wall((thin,)), 100.0, 2.0, "energyplus").nodes_per_layer == (1,)
    assert build_grid(Wall((thin,)), 100.0, 2.0, "wallcal").nodes_per_layer == (1,)


# ---------------------------------------------------------------------------- steady state against hand R
# the example wall's thermal resistance, summed by hand from d / lambda [m2K/W]
R_EXAMPLE = 0.1 / 0.04 + 0.0125 / 0.2 + 0.04 / 0.035 + 0.0125 / 0.2 + 0.095 / 0.035 + 0.055 / 0.035 + 0.025 / 0.21


@pytest.mark.parametrize("scheme", ["cn", "implicit"])
@pytest.mark.parametrize("rule", ["wallcal", "energyplus"])
def test_steady_flux_through_the_example_wall_equals_hand_R(example_study, scheme, rule):
    assert R_EXAMPLE == pytest.approx(8.172619, abs=1e-6)
    inp = make_input(example_study.wall, np.full(11, -10.0), np.full(11, 20.0), 60.0, scheme=scheme, rule=rule)
    out = FDEngine(scheme).run(inp)
    q = (-10.0 - 20.0) / R_EXAMPLE  # towards the interior [W/m2]: heat leaves outwards
    # the discrete steady state of a piecewise-linear profile is exact: round-off only
    np.testing.assert_allclose(out.fluxes["exterior"], q, rtol=1e-10)
    np.testing.assert_allclose(out.fluxes["interior"], q, rtol=1e-10)
    # T3A on interface 3|4: T = T_e - q R(0 -> 0.10 m), R = 0.1 / 0.04
    np.testing.assert_allclose(out.temperatures["T3A"], -10.0 - q * 2.5, atol=1e-9)


@pytest.mark.parametrize("scheme", ["cn", "implicit"])
def test_contact_resistance_enters_as_its_resistance(scheme):
    """A contact resistance of 0.5 m2K/W between two layers: the flux is dT / (R_a + 0.5 + R_b). A contact link
    whose conductance were doubled (1 / (2 R_c)) would give dT / 6.25 instead of dT / 6.5 (4 % off)."""
    a = Layer("a", 0.05, conductivity=0.5, density=1500.0, specific_heat=900.0, contact_resistance=0.5)
    b = Layer("b", 0.08, conductivity=0.04, density=30.0, specific_heat=1400.0)
    wall = Wall(
        (a, b),
        (Probe("a_side", 0.05, side="exterior"), Probe("b_side", 0.05, side="interior"), Probe("contact", 0.05)),
    )
    r_tot = 0.05 / 0.5 + 0.5 + 0.08 / 0.04  # 0.1 + 0.5 + 2.0 = 2.6 m2K/W
    inp = make_input(wall, np.full(11, 0.0), np.full(11, 26.0), 300.0, scheme=scheme)
    out = FDEngine(scheme).run(inp)
    q = -26.0 / r_tot  # -10 W/m2
    np.testing.assert_allclose(out.fluxes["exterior"], q, rtol=1e-10)
    np.testing.assert_allclose(out.fluxes["interior"], q, rtol=1e-10)
    # the temperature jump across the contact is q R_c = 5 K
    np.testing.assert_allclose(out.temperatures["a_side"], 0.0 - q * 0.1, atol=1e-9)
    np.testing.assert_allclose(out.temperatures["b_side"], 0.0 - q * 0.6, atol=1e-9)
    # a probe at the contact without a side reads the mean of both sides
    np.testing.assert_allclose(out.temperatures["contact"], 0.0 - q * 0.35, atol=1e-9)


def test_property_arrays_by_hand():
    from wallcal.grid import PropertyArrays

    w = Wall(
        (
            Layer("a", 0.1, 0.5, 1500.0, 900.0, conductivity_temperature_coefficient=0.004, reference_temperature=15.0),
            Layer("gap", 0.02, thermal_resistance=0.17),
            Layer("b", 0.1, 0.04, 30.0, 1400.0, contact_resistance=0.2),
        )
    )
    p = PropertyArrays.from_walls([w, w.replace_layer("b", conductivity=0.05)])
    assert p.n_candidates == 2
    np.testing.assert_array_equal(p.thickness, [[0.1, 0.02, 0.1]] * 2)
    np.testing.assert_array_equal(p.conductivity, [[0.5, 0.0, 0.04], [0.5, 0.0, 0.05]])
    np.testing.assert_array_equal(p.volumetric_heat_capacity, [[1.35e6, 0.0, 42000.0]] * 2)
    np.testing.assert_array_equal(p.temperature_coefficient, [[0.004, 0.0, 0.0]] * 2)
    np.testing.assert_array_equal(p.reference_temperature, [[15.0, 10.0, 10.0]] * 2)
    np.testing.assert_array_equal(p.contact_resistance, [[0.0, 0.0, 0.2]] * 2)
    np.testing.assert_array_equal(p.thermal_resistance, [[0.0, 0.17, 0.0]] * 2)
    assert p.conductivity.dtype == float


# ---------------------------------------------------------------------------- transient energy balance
# Two layers whose node layout is worked out by hand (dt = 100 s, C = 2):
#   A: d 0.10 m, lambda 1.0, rho c = 2e6 -> alpha 5e-7, dx target 0.01 m, 10 intervals of 0.01 m
#   B: d 0.05 m, lambda 0.04, rho c = 5e4 -> alpha 8e-7, dx target 0.012649 m, ceil(3.95) = 4 intervals of 0.0125 m
# Node capacities (half an interval's rho c dx from each side) [J/(m2K)]:
#   x = 0: 1e4; x = 0.01..0.09: 2e4; x = 0.10: 1e4 + 312.5; x = 0.1125..0.1375: 625; x = 0.15: 312.5
TWO_LAYER = Wall(
    (
        Layer("A", 0.10, conductivity=1.0, density=2000.0, specific_heat=1000.0),
        Layer("B", 0.05, conductivity=0.04, density=50.0, specific_heat=1000.0),
    )
)
NODES_X = np.concatenate([np.arange(11) * 0.01, 0.10 + np.arange(1, 5) * 0.0125])
NODES_C = np.array([1e4] + [2e4] * 9 + [1e4 + 312.5] + [625.0] * 3 + [312.5])


def _node_wall():
    return TWO_LAYER.replace(probes=tuple(Probe(f"n{i}", float(x)) for i, x in enumerate(NODES_X)))


def test_hand_node_layout():
    grid = build_grid(TWO_LAYER, 100.0, 2.0)
    np.testing.assert_allclose(grid.x, NODES_X, atol=1e-15)
    assert NODES_C.sum() == pytest.approx(2e6 * 0.1 + 5e4 * 0.05)  # the wall's areal heat capacity


@pytest.mark.parametrize("scheme", ["cn", "implicit"])
def test_stored_heat_from_node_temperatures_equals_integrated_face_fluxes(scheme):
    dt = 100.0
    t = np.arange(int(1.3 * 86400 / dt) + 1) * dt  # 1.3 days: the stored heat at the end differs from the start
    ue = 5.0 + 15.0 * np.sin(2 * np.pi * t / 86400)
    ui = 20.0 + 1.0 * np.cos(2 * np.pi * t / 86400)
    wall = _node_wall()
    inp = make_input(wall, ue, ui, dt, scheme=scheme)
    out = FDEngine(scheme).run(inp)
    T = np.array([out.temperatures[p.name] for p in wall.probes])  # (nodes, times): probes sit on the nodes
    stored = NODES_C @ (T[:, -1] - T[:, 0])  # [J/m2]
    qe, qi = out.fluxes["exterior"], out.fluxes["interior"]
    net_in = np.trapezoid(qe - qi, dx=dt)  # in at the exterior, out at the interior (both towards the interior)
    # Reference accuracy: the reported face flux at a grid time is the mean of the scheme's step fluxes on either
    # side, so the trapezoid rule over the reported fluxes equals the scheme's exact sum of step fluxes up to
    # dt/4 times the change of the step flux at each end (bounded by dt/2 max |dq| per step), plus round-off.
    dq = max(np.abs(np.diff(qe)).max(), np.abs(np.diff(qi)).max())
    tol = 0.5 * dt * dq + 1e-9 * np.trapezoid(np.abs(qe) + np.abs(qi), dx=dt)
    assert abs(stored) > 1e5  # a real change of stored heat, not 0 = 0
    assert abs(stored - net_in) < tol, (stored, net_in, tol)
    # a capacity error of 1 % in the engine would break the balance by ~1e3 J/m2, far above the tolerance
    assert tol < 0.01 * abs(stored)


# ---------------------------------------------------------------------------- maximum principle
def _monotone(wall, dt, C, rule="wallcal"):
    """Sufficient condition of the discrete maximum principle of Crank-Nicolson: every node's explicit weight
    Cap_i/dt - (g_left + g_right)/2 is >= 0 (the implicit half is an M-matrix for any dt)."""
    from wallcal.grid import PropertyArrays, assemble

    grid = build_grid(wall, dt, C, rule)
    cap, g = assemble(grid, PropertyArrays.from_walls([wall]))
    gsum = np.zeros(grid.n_nodes)
    gsum[:-1] += g[0]
    gsum[1:] += g[0]
    return bool(np.all(cap[0, 1:-1] / dt - 0.5 * gsum[1:-1] >= 0))


@pytest.mark.parametrize("scheme", ["cn", "implicit"])
def test_maximum_principle_with_dirichlet_faces(scheme):
    """Square waves of +-20 K on both faces: every node temperature stays within the extreme boundary values
    (the initial state is the steady state of the first values, inside them too). Here CN satisfies the
    sufficient condition (C = 2: alpha dt / dx^2 <= 1/2 .. 0.512 in each layer), so no overshoot at all."""
    dt = 100.0
    n = 2000
    k = np.arange(n + 1)
    ue = np.where((k // 150) % 2 == 0, -15.0, 25.0)
    ui = np.where((k // 230) % 2 == 0, 18.0, 22.0)
    wall = _node_wall()
    assert _monotone(TWO_LAYER, dt, 2.0)
    out = FDEngine(scheme).run(make_input(wall, ue, ui, dt, scheme=scheme))
    T = np.array([out.temperatures[p.name] for p in wall.probes])
    lo, hi = min(ue.min(), ui.min()), max(ue.max(), ui.max())
    assert T.min() >= lo - 1e-9 and T.max() <= hi + 1e-9, (T.min(), T.max())
    # and the interior nodes do move over (most of) the range: the check is not vacuous
    assert T[1].min() < -10.0 and T[1].max() > 20.0


def test_grid_layout_with_a_contact_and_a_no_mass_layer_by_hand():
    """Nodes and links of A (10 intervals, contact 0.1 to the next layer) | air gap (no mass, one link) | B (4
    intervals; a contact resistance on the last layer has no next layer and adds nothing)."""
    wall = Wall(
        (
            Layer("A", 0.10, conductivity=1.0, density=2000.0, specific_heat=1000.0, contact_resistance=0.1),
            Layer("gap", 0.02, thermal_resistance=0.17),
            Layer("B", 0.05, conductivity=0.04, density=50.0, specific_heat=1000.0, contact_resistance=0.3),
        )
    )
    g = build_grid(wall, 100.0, 2.0)
    x_a = np.arange(11) * 0.01
    np.testing.assert_allclose(g.x, np.concatenate([x_a, [0.10, 0.12], 0.12 + np.arange(1, 5) * 0.0125]), atol=1e-15)
    assert g.nodes_per_layer == (10, 0, 4)
    assert g.link_layer.tolist() == [0] * 10 + [-1, 1] + [2] * 4
    assert g.link_contact_of.tolist() == [-1] * 10 + [0, -1] + [-1] * 4
    assert g.link_intervals.tolist() == [10.0] * 10 + [0.0, 0.0] + [4.0] * 4
    assert g.layer_first_node.tolist() == [0, 11, 12] and g.layer_last_node.tolist() == [10, 12, 16]
    assert (
        g.link_layer.dtype == np.int64 and g.link_contact_of.dtype == np.int64 and g.layer_first_node.dtype == np.int64
    )
    assert g.layer_last_node.dtype == np.int64
    assert (g.time_step, g.grid_constant, g.rule, g.n_nodes, g.n_links) == (100.0, 2.0, "wallcal", 17, 16)
    # a calibration that may change layer B's contact to the gap keeps a link for it even at 0
    assert build_grid(wall, 100.0, 2.0, contact_layers={1}).link_contact_of.tolist()[12] == 1
    from wallcal.errors import StudyError
    from wallcal.grid import intervals_for_layer

    assert intervals_for_layer(0.1, 5e-7, 100.0, 2.0) == 10  # default rule: wallcal
    with pytest.raises(StudyError, match="simulation.node_rule: must be one of"):
        intervals_for_layer(0.1, 5e-7, 100.0, 2.0, "cubic")
