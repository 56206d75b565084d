"""The theta rule (wallcal.engines.operator.link_thetas: node stiffness, theta per term) against hand computations.

A wall of four nodes and three links, each number chosen so that one rule decides it:

    node capacities c = [1000, 0.5, 2000, 800] J/(m2K)   (node 1: a foil of 0.5 J/(m2K), below 1)
    link conductances g = [10, 40, 5] W/(m2K),  dt = 60 s

The stiffness ``s_j = dt (sum of the conductances at node j, face term included) / c_j`` and
``theta = max(theta0, 1 - (1 - theta0) L / max(s_a, s_b))`` with ``L = 1 / (1 - theta0)`` are worked out
below for Crank-Nicolson (theta0 = 1/2, L = 2: a term keeps 1/2 while its stiffest node has s <= 2).
"""

from __future__ import annotations

import numpy as np
import pytest

from wallcal.engines import boundary, operator

CAP = np.array([[1000.0, 0.5, 2000.0, 800.0]])
G = np.array([[10.0, 40.0, 5.0]])
DT = 60.0
SURF, AIR, FLUX = boundary.SURFACE_TEMPERATURE, boundary.AIR_TEMPERATURE, boundary.HEAT_FLUX


def test_node_stiffness_by_hand():
    """The stiffness of each node, seen through the thetas of a limit so small that every term with a
    stiff node is raised: ``theta = 1 - (1 - theta0) L / max(s_a, s_b)``, i.e. ``max(s_a, s_b) = 0.5 L /
    (1 - theta)``."""
    bc_type = np.array([SURF, AIR])
    bc_h = np.array([[0.0, 0.8]])  # an interior air face with h = 0.8 W/(m2K) (below 1)
    s = [
        0.0,  # a known face node has no stiffness
        60 * (10 + 40) / 0.5,  # 6000: the foil
        60 * (40 + 5) / 2000,  # 1.35
        60 * (5 + 0.8) / 800,  # 0.435: the air face's h counts at its node
    ]
    limit = 0.1  # below every stiffness of a term (the smallest is 0.435), so every term is raised
    theta, bc_theta, n_raised = operator.link_thetas(CAP, G, bc_type, bc_h, 0.5, DT, limit)
    seen = 0.5 * limit / (1.0 - np.concatenate([theta[0], bc_theta[0, 1:]]))
    # 1 - theta is formed in the rule: its round-off relative to 1 - theta is ~1e-16 / 8e-6 (7e-12) at the foil
    np.testing.assert_allclose(seen, [max(s[0], s[1]), max(s[1], s[2]), max(s[2], s[3]), s[3]], rtol=1e-10)
    assert bc_theta[0, 0] == 0.5 and n_raised[0] == 4  # the known face has no term
    # a node without capacity is infinitely stiff: its links take theta 1
    cap = CAP.copy()
    cap[0, 2] = 0.0
    theta, _, _ = operator.link_thetas(cap, G, bc_type, bc_h, 0.5, DT, 2.0)
    assert theta[0, 1] == 1.0 and theta[0, 2] == 1.0 and theta[0, 0] == pytest.approx(1 - 1 / 6000)


def test_link_thetas_by_hand():
    """Two candidates: the wall above, and the same wall without its foil (capacity 900 at node 1)."""
    cap = np.vstack([CAP, CAP])
    cap[1, 1] = 900.0
    g = np.vstack([G, G])
    bc_type = np.array([SURF, AIR])
    bc_h = np.array([[0.0, 0.8], [0.0, 0.8]])
    theta, bc_theta, n_raised = operator.link_thetas(cap, g, bc_type, bc_h, 0.5, DT, 2.0)
    # candidate 0: links 0 and 1 touch the foil (s = 6000): theta = 1 - 1 / 6000; link 2: s = max(1.35, 0.435)
    np.testing.assert_allclose(theta[0], [1 - 1 / 6000, 1 - 1 / 6000, 0.5], rtol=1e-15)
    # candidate 1: s = [0, 60 x 50 / 900 = 3.33, 1.35, 0.435]: links 0 and 1 raised to 1 - 1 / 3.33 = 0.7
    np.testing.assert_allclose(theta[1], [0.7, 0.7, 0.5], rtol=1e-14)
    # the air face keeps theta0 (its node, s = 0.435, is not stiff); the known face has no term
    np.testing.assert_array_equal(bc_theta, [[0.5, 0.5], [0.5, 0.5]])
    assert list(n_raised) == [2, 2]


def test_a_stiff_air_face_node_raises_its_face_term_even_with_h_below_1():
    cap = np.array([[1000.0, 1600.0, 2000.0, 0.5]])  # the interior face node is a foil; s_1 = 1.875
    bc_type = np.array([SURF, AIR])
    theta, bc_theta, n_raised = operator.link_thetas(cap, G, bc_type, np.array([[0.0, 0.8]]), 0.5, DT, 2.0)
    s3 = 60 * (5 + 0.8) / 0.5  # 696
    assert bc_theta[0, 1] == pytest.approx(1 - 1 / s3) and bc_theta[0, 0] == 0.5
    assert theta[0, 2] == pytest.approx(1 - 1 / s3)
    assert n_raised[0] == 2  # link 2 and the interior face term


def test_no_raise_at_the_limit_and_counts_per_candidate():
    """A node exactly at s = L keeps theta0; counts are per candidate, not over the batch."""
    bc_type = np.array([FLUX, FLUX])
    bc_h = np.zeros((3, 2))
    # one link between two nodes: s = 60 g / c; c = 600, g = 20 gives s = 2 exactly
    cap = np.array([[600.0, 600.0], [600.0, 600.0], [600.0, 300.0]])
    g = np.array([[20.0], [20.0], [20.0]])
    theta, bc_theta, n_raised = operator.link_thetas(cap, g, bc_type, bc_h, 0.5, DT, 2.0)
    np.testing.assert_allclose(theta[:, 0], [0.5, 0.5, 1 - 1 / 4.0])
    assert list(n_raised) == [0, 0, 1]
    np.testing.assert_array_equal(bc_theta, np.full((3, 2), 0.5))  # a heat-flux face has no conductance
    # implicit: nothing to raise; an infinite limit keeps theta0 except at a node without capacity
    theta, _, n_raised = operator.link_thetas(cap, g, bc_type, bc_h, 1.0, DT, 2.0)
    assert (theta == 1.0).all() and (n_raised == 0).all()
    cap0 = np.array([[600.0, 0.0]])
    theta, bc_theta, n_raised = operator.link_thetas(cap0, g[:1], bc_type, bc_h[:1], 0.5, DT, np.inf)
    # the link and the face term of that node (a face node without capacity is algebraic: theta 1)
    assert theta[0, 0] == 1.0 and list(bc_theta[0]) == [0.5, 1.0] and n_raised[0] == 2
    assert n_raised.dtype == np.int64
