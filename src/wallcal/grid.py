"""The finite-volume grid of a wall: nodes, links, and how properties map onto them.

Discretisation
--------------
Vertex-centred finite volumes with a node on every face and every layer
interface. A massive layer of thickness ``d`` is split into ``n`` equal
intervals ``dx = d / n``; every interval links its two end nodes with a
conductance ``lambda / dx`` [W/(m2K)] and gives each end node half its heat
capacity ``rho c dx / 2`` [J/(m2K)]. A no-mass layer is one link of
conductance ``1 / R``. A contact resistance adds a second node at the same
depth, linked by ``1 / R_contact``.

Node rules (``n`` per massive layer, with the layer's diffusivity ``alpha``,
the time step ``dt`` and the grid constant ``C = dx^2 / (alpha dt)``):

- ``"wallcal"`` (default): ``n = max(1, ceil(d / sqrt(C alpha dt)))``, i.e. the
  coarsest uniform grid whose spacing is *at most* the one C asks for
  (every layer at least as fine as requested).
- ``"energyplus"``: ``n = max(1, int(d / sqrt(C alpha dt)))``, EnergyPlus CondFD's
  rule (spacing *at least* the one asked for), so the two codes can be compared
  node for node.

The grid is built once from a reference wall; candidate walls of a batch (in
calibration) reuse it with their own properties, so that the simulated
outputs are smooth functions of the properties.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .engines.base import PropertyArrays  # the contract's type, taken by assemble()
from .errors import StudyError
from .jit import kernel
from .wall import Wall

NODE_RULES = ("wallcal", "energyplus")

# Layer-conductivity models in the kernel
LAMBDA_CONSTANT = 0
LAMBDA_EXPONENTIAL = 1
LAMBDA_TABLE = 2


@dataclass(frozen=True)
class Grid:
    """Node layout of a wall.

    Attributes
    ----------
    x : ndarray, shape (n_nodes,)
        Node depths from the exterior face [m] (two nodes share a depth at a contact resistance).
    nodes_per_layer : tuple of int
        Intervals per layer (0 for a no-mass layer).
    link_layer : ndarray of int, shape (n_links,)
        Layer index of each link; -1 for a contact-resistance link.
    link_contact_of : ndarray of int, shape (n_links,)
        For a contact link, the index of the layer whose ``contact_resistance`` it carries; else -1.
    link_intervals : ndarray of float, shape (n_links,)
        For a massive-layer link, the number of intervals of its layer (conductance = lambda n / d).
    layer_first_node : ndarray of int, shape (n_layers,)
        Node index of each layer's exterior face.
    layer_last_node : ndarray of int, shape (n_layers,)
        Node index of each layer's interior face.
    """

    x: np.ndarray
    nodes_per_layer: tuple[int, ...]
    link_layer: np.ndarray
    link_contact_of: np.ndarray
    link_intervals: np.ndarray
    layer_first_node: np.ndarray
    layer_last_node: np.ndarray
    time_step: float
    grid_constant: float
    rule: str

    @property
    def n_nodes(self) -> int:
        return len(self.x)

    @property
    def n_links(self) -> int:
        return len(self.link_layer)


def intervals_for_layer(
    thickness: float, diffusivity: float, time_step: float, grid_constant: float, rule: str = "wallcal"
) -> int:
    """Number of intervals in a massive layer under a node rule (see module docstring).

    Parameters
    ----------
    thickness : float
        Layer thickness [m].
    diffusivity : float
        Thermal diffusivity [m2/s].
    time_step : float
        [s].
    grid_constant : float
        C = dx^2 / (alpha dt) [-].
    rule : {"wallcal", "energyplus"}
    """
    dx_target = math.sqrt(grid_constant * diffusivity * time_step)
    ratio = thickness / dx_target
    if rule == "energyplus":
        n = int(ratio)
    elif rule == "wallcal":
        # tolerate round-off so that an exact multiple is not bumped up one interval
        n = math.ceil(ratio - 1e-9)
    else:
        raise StudyError([f"simulation.node_rule: must be one of {NODE_RULES}, got {rule!r}"])
    return max(1, n)


def build_grid(
    wall: Wall,
    time_step: float,
    grid_constant: float,
    rule: str = "wallcal",
    contact_layers: set[int] | frozenset[int] = frozenset(),
    intervals: list[int] | None = None,
) -> Grid:
    """Build the node layout of ``wall``.

    Parameters
    ----------
    wall : Wall
    time_step : float
        [s].
    grid_constant : float
        C [-].
    rule : {"wallcal", "energyplus"}
    contact_layers : set of int
        Layer indices that get a contact link even when their contact resistance is 0
        (because a calibration may change it).
    intervals : list of int, optional
        Intervals per layer instead of the node rule's (massive layers only; e.g. a fine grid for a
        time constant).
    """
    xs = [0.0]
    link_layer: list[int] = []
    link_contact: list[int] = []
    link_n: list[float] = []
    first = []
    last = []
    npl = []
    depth = 0.0
    for i, layer in enumerate(wall.layers):
        first.append(len(xs) - 1)
        if layer.is_massless:
            depth += layer.thickness
            xs.append(depth)
            link_layer.append(i)
            link_contact.append(-1)
            link_n.append(0.0)
            npl.append(0)
        else:
            if intervals is not None:
                n = max(1, int(intervals[i]))
            else:
                n = intervals_for_layer(layer.thickness, layer.diffusivity, time_step, grid_constant, rule)
            dx = layer.thickness / n
            for k in range(1, n + 1):
                xs.append(depth + k * dx if k < n else depth + layer.thickness)
                link_layer.append(i)
                link_contact.append(-1)
                link_n.append(float(n))
            depth += layer.thickness
            npl.append(n)
        last.append(len(xs) - 1)
        if has_contact_link(wall, i, contact_layers):
            xs.append(depth)
            link_layer.append(-1)
            link_contact.append(i)
            link_n.append(0.0)
    return Grid(
        x=np.array(xs),
        nodes_per_layer=tuple(npl),
        link_layer=np.array(link_layer, dtype=np.int64),
        link_contact_of=np.array(link_contact, dtype=np.int64),
        link_intervals=np.array(link_n),
        layer_first_node=np.array(first, dtype=np.int64),
        layer_last_node=np.array(last, dtype=np.int64),
        time_step=float(time_step),
        grid_constant=float(grid_constant),
        rule=rule,
    )


# ---------------------------------------------------------------------------- properties on the grid
# PropertyArrays (the layer properties of a batch of walls) is part of the engine contract: wallcal.engines.base.


#: Smallest contact resistance represented [m2K/W]; a contact link calibrated down to 0 uses this.
MIN_CONTACT_RESISTANCE = 1e-7


def assemble(grid: Grid, props: PropertyArrays) -> tuple[np.ndarray, np.ndarray]:
    """Node capacities and link conductances for every candidate (:func:`assemble_lines` on the grid's links).

    Returns
    -------
    capacity : ndarray, shape (n_candidates, n_nodes)
        Node heat capacities [J/(m2K)].
    conductance : ndarray, shape (n_candidates, n_links)
        Link conductances at the reference temperature [W/(m2K)] (lambda(T) layers
        are re-evaluated in the kernel).
    """
    no_law = np.full(grid.n_links, -1, dtype=np.int64)
    cap, g, _, _ = assemble_lines(
        *(np.asarray(a, dtype=float) for a in props.line_arrays()),
        grid.link_layer,
        grid.link_contact_of,
        grid.link_intervals,
        no_law,
    )
    return cap, g


@kernel
def assemble_lines(
    thickness,
    conductivity,
    heat_capacity,
    contact_resistance,
    thermal_resistance,
    temperature_coefficient,
    link_layer,
    contact_of,
    intervals,
    law_layer,
):
    """Node capacities (c, j) [J/(m2K)], link conductances (c, l) [W/(m2K)] and temperature coefficients
    (c, l) [1/K] of candidate walls from their layer properties (c, n_layers), as :class:`PropertyArrays`
    gives them (:meth:`PropertyArrays.line_arrays`), on a grid's links (:attr:`Grid.link_layer`,
    :attr:`Grid.link_contact_of`, :attr:`Grid.link_intervals`), and whether they make a valid wall: every
    conductance finite and positive, every capacity finite and non-negative. A link's temperature
    coefficient is that of layer ``law_layer[l]`` (0 where it is -1: the links whose conductivity law
    does not take one).

    A massive layer's interval of ``dx = d / n`` conducts ``lambda / dx`` and gives each end node half its
    capacity ``rho c dx / 2``; a no-mass layer conducts ``1 / R`` (inf at R = 0); a contact link
    ``1 / max(R_contact, MIN_CONTACT_RESISTANCE)``. One call per batch: the per-call cost of many array
    operations on arrays of a few dozen links is what this saves. (Arrays by ``np.empty`` in the shapes the
    modal kernel allocates too, and no other numpy call: each compiles numpy's code on a fresh install.)
    """
    nc = thickness.shape[0]
    nl = link_layer.shape[0]
    cap = np.empty((nc, nl + 1))
    g = np.empty((nc, nl))
    coef = np.empty((nc, nl))
    valid = True
    for c in range(nc):
        for j in range(nl + 1):
            cap[c, j] = 0.0
        for lnk in range(nl):
            coef[c, lnk] = temperature_coefficient[c, law_layer[lnk]] if law_layer[lnk] >= 0 else 0.0
            li = link_layer[lnk]
            if li < 0:
                r = contact_resistance[c, contact_of[lnk]]
                g[c, lnk] = 1.0 / (r if not r < MIN_CONTACT_RESISTANCE else MIN_CONTACT_RESISTANCE)
            elif intervals[lnk] == 0.0:
                g[c, lnk] = 1.0 / thermal_resistance[c, li]
            else:
                dx = thickness[c, li] / intervals[lnk]
                g[c, lnk] = conductivity[c, li] / dx
                half = 0.5 * heat_capacity[c, li] * dx
                cap[c, lnk] += half
                cap[c, lnk + 1] += half
            valid &= 0.0 < g[c, lnk] < np.inf
        for j in range(nl + 1):
            valid &= 0.0 <= cap[c, j] < np.inf
    return cap, g, coef, valid


def node_tolerance(thickness: float) -> float:
    """Distance [m] within which :func:`probe_weights` reads a probe on a node, for a wall ``thickness`` [m]."""
    return 1e-12 * max(1.0, float(thickness))


def has_contact_link(wall: Wall, i: int, contact_layers: set[int] | frozenset[int] = frozenset()) -> bool:
    """Whether :func:`build_grid` places a contact link (a double node) behind layer ``i``: a contact
    resistance on the layer, or the layer among ``contact_layers`` (a calibrated contact); never behind the
    last layer."""
    return i < len(wall.layers) - 1 and (wall.layers[i].contact_resistance > 0 or i in contact_layers)


def contact_node_depths(wall: Wall, contact_layers: set[int] | frozenset[int] = frozenset()) -> dict[int, float]:
    """Depths [m] of the double nodes that :func:`build_grid` places at contact links, by the index of the layer
    whose contact resistance the link carries (accumulated as :func:`build_grid` does).

    A probe within :func:`node_tolerance` of one of them reads a side of the contact or the mean of both
    (:func:`probe_weights`): its reading jumps when its depth moves off the node to either side.
    """
    out: dict[int, float] = {}
    depth = 0.0
    for i, layer in enumerate(wall.layers[:-1]):
        depth += layer.thickness
        if has_contact_link(wall, i, contact_layers):
            out[i] = depth
    return out


def probe_weights(grid: Grid, depths: np.ndarray, sides: list[str | None]) -> tuple[np.ndarray, ...]:
    """Interpolation of probe temperatures between nodes.

    Parameters
    ----------
    depths : ndarray, shape (n_candidates, n_probes)
        Probe depths from the exterior face [m].
    sides : list of str or None
        Per probe, at a double node (contact resistance): ``"exterior"``,
        ``"interior"`` or None (mean of both).

    Returns
    -------
    node_a, node_b : ndarray of int, shape (n_candidates, n_probes)
    weight_b : ndarray, shape (n_candidates, n_probes)
        T = (1 - w) T[a] + w T[b]: exact on a node, linear between nodes.
    """
    side = np.array([{"exterior": 0, "interior": 1}.get(sd, 2) for sd in sides], dtype=np.int64)[None, :]
    x = grid.x
    n = len(x)
    d = np.clip(np.atleast_2d(np.asarray(depths, dtype=float)), 0.0, x[-1])
    tol = node_tolerance(x[-1])
    first = np.searchsorted(x, d - tol, side="left")  # first node at or after d
    last = np.searchsorted(x, d + tol, side="right") - 1  # last node at or before d
    # between two nodes: linear
    j = np.clip(last, 0, n - 2)
    span = x[j + 1] - x[j]
    a, b = j.copy(), j + 1
    w = np.where(span > 0, (d - x[j]) / np.where(span > 0, span, 1.0), 0.0)
    # on a node (at a double node: exterior side, interior side, or the mean of both)
    on = first <= last
    double = on & (last > first)
    a[on], b[on], w[on] = first[on], first[on], 0.0
    inner = double & (side == 1)
    a[inner], b[inner] = last[inner], last[inner]
    mean = double & (side == 2)
    b[mean], w[mean] = last[mean], 0.5
    return a.astype(np.int64), b.astype(np.int64), w


# ---------------------------------------------------------------------------- sub-steps in time
def substeps(time_step: float, grid_time_step: float | None) -> int:
    """Sub-steps per run step for the time step the grid was built for: ``ceil(time_step / grid_time_step)``
    (1 without a grid step, or when the grid's step is not shorter). The exact scheme runs lambda(T) walls
    with Crank-Nicolson at ``time_step / substeps`` (see :func:`refine_in_time`)."""
    if not grid_time_step or grid_time_step >= time_step:
        return 1
    return int(math.ceil(time_step / grid_time_step - 1e-9))


def refine_in_time(values: np.ndarray, n_sub: int) -> np.ndarray:
    """A series at grid times ``k dt`` as values at ``j dt / n_sub``, linear between grid times (the inputs'
    own interpolation): shape ``(n_sub * (n - 1) + 1,)`` for ``n`` values."""
    v = np.asarray(values, dtype=float)
    if n_sub == 1:
        return v
    fine = np.arange(n_sub * (len(v) - 1) + 1) / n_sub
    return np.interp(fine, np.arange(len(v)), v)
