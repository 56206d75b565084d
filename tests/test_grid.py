"""The Python side of wallcal.grid, by hand: link conductances and node capacities (``assemble``), probe
interpolation (``probe_weights``), imposed interval counts and candidate selection.

Every expected number is worked out in the comments from the layer data (no engine run), so these tests are
fast and independent of the kernels that consume the arrays.
"""

from __future__ import annotations

import numpy as np
import pytest

from wallcal.grid import MIN_CONTACT_RESISTANCE, PropertyArrays, assemble, build_grid, probe_weights
from wallcal.wall import Layer, Wall

# A: 0.10 m, lambda 1.0, rho c 2e6 -> alpha 5e-7; dt 100 s, C 2: dx target 0.01 m -> 10 intervals of 0.01 m,
#    contact resistance 0.1 to the next layer (a second node at 0.10 m)
# gap: no mass, 0.02 m, R 0.17 (one link)
# B: 0.05 m, lambda 0.04, rho c 5e4 -> alpha 8e-7, dx target 0.012649 m -> 4 intervals of 0.0125 m
# nodes: 0..10 at 0.00..0.10, 11 at 0.10 (contact twin), 12 at 0.12, 13..16 at 0.1325..0.17
WALL = Wall(
    (
        Layer("A", 0.10, conductivity=1.0, density=2000.0, specific_heat=1000.0, contact_resistance=0.1),
        Layer("gap", 0.02, thermal_resistance=0.17),
        Layer("B", 0.05, conductivity=0.04, density=50.0, specific_heat=1000.0),
    )
)


def test_conductances_and_capacities_by_hand():
    grid = build_grid(WALL, 100.0, 2.0)
    # candidate 2: no contact resistance (the smallest represented one instead), B's conductivity 0.05
    other = WALL.replace_layer("A", contact_resistance=0.0).replace_layer("B", conductivity=0.05)
    cap, g = assemble(grid, PropertyArrays.from_walls([WALL, other]))
    # links: A's 10 intervals lambda / dx = 1.0 / 0.01; the contact 1 / 0.1; the gap 1 / 0.17; B 0.04 / 0.0125
    g1 = [100.0] * 10 + [10.0, 1 / 0.17] + [3.2] * 4
    g2 = [100.0] * 10 + [1 / MIN_CONTACT_RESISTANCE, 1 / 0.17] + [4.0] * 4
    np.testing.assert_allclose(g, [g1, g2], rtol=1e-14)
    # nodes: half of rho c dx from each side: A 0.5 * 2e6 * 0.01 = 1e4, B 0.5 * 5e4 * 0.0125 = 312.5;
    # the contact twin and the gap carry none
    c = [1e4] + [2e4] * 9 + [1e4, 0.0, 312.5] + [625.0] * 3 + [312.5]
    np.testing.assert_allclose(cap, [c, c], rtol=1e-14)


def test_a_leading_no_mass_layer_a_one_interval_layer_and_a_zero_resistance():
    # film (no mass, R 0.04) | C: 0.01 m of lambda 0.5, rho c 1e6 in one interval (intervals imposed)
    wall = Wall(
        (
            Layer("film", 0.0, thermal_resistance=0.04),
            Layer("C", 0.01, conductivity=0.5, density=1000.0, specific_heat=1000.0),
        )
    )
    grid = build_grid(wall, 100.0, 2.0, intervals=[0, 1])
    zero = wall.replace_layer("film", thermal_resistance=0.0)
    cap, g = assemble(grid, PropertyArrays.from_walls([wall, zero]))
    # a no-mass layer of R = 0 is an infinite conductance, computed without a division warning
    np.testing.assert_array_equal(g, [[25.0, 50.0], [np.inf, 50.0]])
    np.testing.assert_allclose(cap, [[0.0, 5000.0, 5000.0]] * 2, rtol=1e-14)


def test_imposed_intervals_replace_the_node_rule_and_are_at_least_one():
    # the node rule would give A 10 and B 4 intervals; the imposed counts are truncated to integers, at least 1,
    # and ignored for a no-mass layer
    grid = build_grid(WALL, 100.0, 2.0, intervals=[1, 7, 2.7])
    assert grid.nodes_per_layer == (1, 0, 2)
    np.testing.assert_allclose(grid.x, [0.0, 0.1, 0.1, 0.12, 0.145, 0.17], atol=1e-15)
    assert build_grid(WALL, 100.0, 2.0, intervals=[0, 0, 3]).nodes_per_layer == (1, 0, 3)


def test_property_arrays_of_integer_layer_data_are_floats():
    # a study file may give whole numbers (TOML integers): the arrays handed to the kernels are still float64
    wall = Wall((Layer("a", 1, 2, 1000, 1000, contact_resistance=0, reference_temperature=20),))
    p = PropertyArrays.from_walls([wall])
    for name in ("thickness", "conductivity", "volumetric_heat_capacity", "reference_temperature"):
        assert getattr(p, name).dtype == np.float64, name
    assert p.contact_resistance.dtype == np.float64 and p.thermal_resistance.dtype == np.float64


def test_take_selects_candidates_by_index_or_mask():
    walls = [WALL.replace_layer("B", conductivity=lam) for lam in (0.03, 0.04, 0.05)]
    p = PropertyArrays.from_walls(walls)
    sub = p.take(np.array([2, 0]))
    np.testing.assert_array_equal(sub.conductivity[:, 2], [0.05, 0.03])
    np.testing.assert_array_equal(sub.thickness, [[0.10, 0.02, 0.05]] * 2)
    np.testing.assert_array_equal(sub.contact_resistance, [[0.1, 0.0, 0.0]] * 2)
    masked = p.take(np.array([False, True, False]))
    assert masked.n_candidates == 1 and masked.conductivity[0, 2] == 0.04
    np.testing.assert_array_equal(masked.thermal_resistance, [[0.0, 0.17, 0.0]])
    np.testing.assert_array_equal(masked.volumetric_heat_capacity, p.volumetric_heat_capacity[1:2])
    np.testing.assert_array_equal(masked.temperature_coefficient, [[0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(masked.reference_temperature, [[10.0, 10.0, 10.0]])


# (depth, side, node_a, node_b, weight_b): T = (1 - w) T[a] + w T[b]
PROBES = [
    (0.0, None, 0, 0, 0.0),  # the exterior face node
    (-0.01, None, 0, 0, 0.0),  # outside the wall: put on the face
    (0.005, None, 0, 1, 0.5),  # between the first two nodes
    (0.035, None, 3, 4, 0.5),
    (0.0375, None, 3, 4, 0.75),
    (0.04, None, 4, 4, 0.0),  # on a node
    (0.04 + 1e-14, None, 4, 4, 0.0),  # on a node up to round-off
    (0.10, "exterior", 10, 10, 0.0),  # the contact: the exterior side's node
    (0.10, "interior", 11, 11, 0.0),  # the interior side's node
    (0.10, None, 10, 11, 0.5),  # the mean of both
    (0.11, None, 11, 12, 0.5),  # inside the no-mass gap: linear
    (0.165, None, 15, 16, 0.6),  # between the last two nodes
    (0.17, "interior", 16, 16, 0.0),  # the interior face node
    (0.2, None, 16, 16, 0.0),  # beyond the wall: put on the face
]


def test_probe_weights_by_hand():
    grid = build_grid(WALL, 100.0, 2.0)
    depths = np.array([[p[0] for p in PROBES]] * 2)
    a, b, w = probe_weights(grid, depths, [p[1] for p in PROBES])
    for k, (depth, side, ea, eb, ew) in enumerate(PROBES):
        assert (a[0, k], b[0, k]) == (ea, eb), (depth, side)
        assert w[0, k] == pytest.approx(ew, abs=1e-12), (depth, side)
    assert a.shape == b.shape == w.shape == (2, len(PROBES))
    assert a.dtype == np.int64 and b.dtype == np.int64
    np.testing.assert_array_equal(a[1], a[0])


def test_probe_weights_per_candidate_and_at_a_face_with_a_zero_thickness_layer():
    grid = build_grid(WALL, 100.0, 2.0)
    a, b, w = probe_weights(grid, np.array([[0.035], [0.11]]), [None])
    assert a.tolist() == [[3], [11]] and b.tolist() == [[4], [12]] and w == pytest.approx(np.array([[0.5], [0.5]]))
    # an interior film of zero thickness puts two nodes at the interior face; a probe there reads the inner one
    # (or the mean), without a division by the zero spacing (warnings are errors in the tests)
    filmed = Wall((*WALL.layers, Layer("film", 0.0, thermal_resistance=0.13)))
    g2 = build_grid(filmed, 100.0, 2.0)
    assert g2.x[-1] == g2.x[-2] == pytest.approx(0.17)
    a, b, w = probe_weights(g2, np.array([[0.17, 0.17, 0.17]]), ["exterior", "interior", None])
    assert a.tolist() == [[16, 17, 16]] and b.tolist() == [[16, 17, 17]] and w.tolist() == [[0.0, 0.0, 0.5]]
