"""Heat flux density at a depth inside the wall, from temperatures around that depth (the ``energyplus`` engine).

The fd engines give the scheme's own flux through the plane instead (:func:`wallcal.engines.fd.depth_plane`,
docs/engine.md). An engine that gives only temperatures anywhere in the wall (linear between its nodes)
reads the flux at depth ``x`` from three temperatures at ``x - h``, ``x`` and ``x + h`` (h = 1 mm, each half
kept inside the wall and inside its layer):
each half gives the flux of the link it lies in, ``q_l = lambda_l (T(x-h) - T(x)) / h`` and
``q_r = lambda_r (T(x) - T(x+h)) / h``, lambda at the half-interval's mean temperature. Inside a layer
``q = (q_l + q_r) / 2`` (a central difference at a node). At a layer interface the heat stored in the
two half cells between the links is shared out: ``q = (b_r q_l + b_l q_r) / (b_l + b_r)`` with ``b``
each layer's effusivity sqrt(lambda rho c), to which the half cells' capacities are proportional on a
C-rule grid (b = 0 for a no-mass layer). Positive towards the interior.

At an interface that carries a contact resistance ``R_c`` (a contact link of the grid) the
temperature jumps across the interface, so no gradient can be read there: the three temperatures
are taken at the interface itself, on its exterior side, as the mean and on its interior side, and
the flux is the contact link's own, ``q = (T_ext_side - T_int_side) / R_c``.
"""

from __future__ import annotations

import numpy as np

from ..conductivity import conductivity
from ..grid import MIN_CONTACT_RESISTANCE
from ..wall import Wall
from .base import PropertyArrays

#: Half-distance [m] of the three temperatures that give a heat flux inside the wall
FLUX_PROBE_SPACING = 1e-3


def _ends(wall: Wall, depth: float) -> tuple[tuple[float, str | None], tuple[float, str | None]]:
    """(depth [m], side) of the outer ends of the two halves: depth - h and depth + h (h = 1 mm), each half
    kept inside the wall and inside the layer it starts in (a half never reads a gradient across a layer
    interface, where a contact resistance or a thin, very different layer would make it meaningless). An
    end cut back to an interior interface reads the side of its half's own layer."""
    h = FLUX_PROBE_SPACING
    bounds = wall.interfaces
    last = len(wall.layers) - 1
    tol = 1e-12 * max(wall.thickness, 1.0)
    left = _layer_index(wall, depth - tol)
    right = _layer_index(wall, depth + tol)
    minus, plus = (depth, None), (depth, None)
    if depth > tol:
        cut = bounds[left] >= depth - h
        minus = (max(depth - h, bounds[left], 0.0), "interior" if cut and left > 0 else None)
    if depth < wall.thickness - tol:
        cut = bounds[right + 1] <= depth + h
        plus = (min(depth + h, bounds[right + 1], wall.thickness), "exterior" if cut and right < last else None)
    return minus, plus


def depth_triplet(wall: Wall, depth: float) -> tuple[float, float, float]:
    """Depths [m] of the three temperatures: depth - h, depth, depth + h (see :func:`_ends`)."""
    (xm, _), (xp, _) = _ends(wall, depth)
    return (xm, depth, xp)


def contact_at(wall: Wall, depth: float, contact_layers=frozenset()) -> int | None:
    """Index of the layer whose contact resistance sits at ``depth`` [m] (the interface after it carries a
    contact link: a contact resistance > 0, or a layer in ``contact_layers``); None elsewhere."""
    tol = 1e-9 * max(wall.thickness, 1.0)
    for i in range(len(wall.layers) - 1):
        has_link = wall.layers[i].contact_resistance > 0 or i in contact_layers
        if has_link and abs(wall.interfaces[i + 1] - depth) <= tol:
            return i
    return None


def depth_probes(wall: Wall, depth: float, contact_layers=frozenset()) -> tuple[tuple[float, str | None], ...]:
    """(depth [m], side) of the three temperatures that give the flux at ``depth``: :func:`depth_triplet`,
    or at a contact interface the interface's exterior side, its mean and its interior side."""
    if contact_at(wall, depth, contact_layers) is not None:
        return ((depth, "exterior"), (depth, None), (depth, "interior"))
    minus, plus = _ends(wall, depth)
    return (minus, (depth, None), plus)


def _layer_index(wall: Wall, x: float) -> int:
    return int(np.clip(np.searchsorted(wall.interfaces, x, side="right") - 1, 0, len(wall.layers) - 1))


def _conductivity(wall: Wall, props: PropertyArrays, li: int, temperature: np.ndarray) -> np.ndarray:
    """Conductivity [W/(m K)] of layer ``li`` of every candidate at ``temperature`` (nc, nt)."""
    layer = wall.layers[li]
    if layer.is_massless:
        return layer.thickness / props.thermal_resistance[:, li, None] if layer.thickness > 0 else np.inf
    return conductivity(
        props.conductivity[:, li, None],
        props.temperature_coefficient[:, li, None],
        props.reference_temperature[:, li, None],
        temperature,
        layer.conductivity_table,  # the candidate's conductivity scales the table
    )


def flux_at_depth(
    wall: Wall, props: PropertyArrays, depth: float, t_minus, t_at, t_plus, contact_layer: int | None = None
) -> np.ndarray:
    """Heat flux density [W/m2] at ``depth`` [m], positive towards the interior (see the module docstring).

    Parameters
    ----------
    wall : Wall
        The layer structure (and lambda(T) tables).
    props : PropertyArrays
        Every candidate's layer properties, shape (n_candidates, n_layers).
    depth : float
    t_minus, t_at, t_plus : ndarray, shape (n_candidates, n_times)
        Temperatures [degC] at the three depths of :func:`depth_triplet` (of :func:`depth_probes`).
    contact_layer : int, optional
        The layer whose contact resistance sits at ``depth`` (:func:`contact_at`): the temperatures are
        the interface's two sides and the flux is the contact link's.

    Returns
    -------
    ndarray, shape (n_candidates, n_times)
    """
    t_minus, t_at, t_plus = (np.asarray(v, dtype=float) for v in (t_minus, t_at, t_plus))
    if contact_layer is not None:
        r_c = np.maximum(props.contact_resistance[:, contact_layer, None], MIN_CONTACT_RESISTANCE)
        return (t_minus - t_plus) / r_c
    xm, x0, xp = depth_triplet(wall, depth)
    halves = []
    for xa, xb, ta, tb in ((xm, x0, t_minus, t_at), (x0, xp, t_at, t_plus)):
        if xb > xa:
            li = _layer_index(wall, 0.5 * (xa + xb))
            halves.append((li, _conductivity(wall, props, li, 0.5 * (ta + tb)) * (ta - tb) / (xb - xa)))
    if len(halves) == 1:
        return halves[0][1]
    (ll, ql), (lr, qr) = halves
    if ll == lr:
        return 0.5 * (ql + qr)

    def effusivity(li):
        if wall.layers[li].is_massless:
            return np.zeros((props.n_candidates, 1))
        return np.sqrt(props.conductivity[:, li, None] * props.volumetric_heat_capacity[:, li, None])

    bl, br = effusivity(ll), effusivity(lr)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = (br * ql + bl * qr) / (bl + br)
    return np.where(bl + br == 0, 0.5 * (ql + qr), q)
