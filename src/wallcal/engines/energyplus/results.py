"""Reading EnergyPlus' outputs: node depths and temperatures, probe series, face heat fluxes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import EngineError
from ...wall import Wall
from .model import WALL_SURFACE


def read_node_depths(eio: Path, wall: Wall, construction: str = "WALLCAL") -> np.ndarray:
    """CondFD node depths [m] from the exterior face, from the .eio node report.

    EnergyPlus reports a fictitious thickness (0.1 m) for each no-mass layer; the interval
    between the two nodes bounding such a layer (no-mass layers and contact resistances) is
    given zero thickness here, so the depths are wallcal's.

    Parameters
    ----------
    eio : Path
        EnergyPlus' ``eplusout.eio``.
    wall : Wall
    construction : str
        Construction name used in the model.

    Returns
    -------
    ndarray
        Node depths [m], non-decreasing (several nodes share a depth around no-mass layers).

    Raises
    ------
    EngineError
        When the report is missing or inconsistent with the wall.
    """
    from ...idf import material_names

    names = material_names(wall, f"{construction}_")
    resistive = set()
    k = 0
    for i, layer in enumerate(wall.layers):
        if layer.is_massless:
            resistive.add(names[k].upper())
        k += 1
        if layer.contact_resistance and i < len(wall.layers) - 1:
            resistive.add(names[k].upper())
            k += 1
    dist, outward, inward = [], [], []
    for ln in Path(eio).read_text(errors="replace").splitlines():
        parts = [p.strip() for p in ln.split(",")]
        if len(parts) >= 6 and parts[0] == "ConductionFiniteDifference Node" and parts[3].upper() == construction:
            dist.append(float(parts[2]))
            outward.append(parts[4].upper())
            inward.append(parts[5].upper())
    if not dist:
        raise EngineError(f"no 'ConductionFiniteDifference Node' lines for the wall in {eio}")
    x = np.zeros(len(dist))
    for i in range(1, len(dist)):
        in_resistive = outward[i] == inward[i - 1] and outward[i] in resistive
        x[i] = x[i - 1] + (0.0 if in_resistive else dist[i] - dist[i - 1])
    if abs(x[-1] - wall.thickness) > 1e-6 * max(1.0, wall.thickness):
        raise EngineError(f"EnergyPlus node depths span 0..{x[-1]} m, the wall is {wall.thickness} m thick")
    return x


def read_node_temperatures(csv: Path, n_nodes: int) -> np.ndarray:
    """Node temperatures [degC], shape (n_rows, n_nodes), from EnergyPlus' CSV output."""
    import pandas as pd

    df = pd.read_csv(csv)
    cols = []
    for j in range(1, n_nodes + 1):
        key = f"{WALL_SURFACE}:CondFD Surface Temperature Node {j} [C](TimeStep)"
        if key not in df.columns:
            raise EngineError(f"EnergyPlus output lacks column {key!r}")
        cols.append(key)
    return df[cols].to_numpy(dtype=float)


def probe_series(x: np.ndarray, temps: np.ndarray, depth: float, side: str | None, thickness: float) -> np.ndarray:
    """Temperature [degC] at ``depth`` [m], linear between nodes.

    Where several nodes share a depth (both faces of a contact or no-mass layer),
    ``side`` picks the exterior one, the interior one, or (None) their mean.
    """
    if not -1e-9 <= depth <= thickness + 1e-9:
        raise EngineError(f"probe depth {depth} m lies outside the wall (0..{thickness} m)")
    same = np.flatnonzero(np.abs(x - depth) < 1e-9)
    if len(same) >= 2:
        if side == "exterior":
            return temps[:, same[0]]
        if side == "interior":
            return temps[:, same[-1]]
        return temps[:, [same[0], same[-1]]].mean(axis=1)
    if len(same) == 1:
        return temps[:, same[0]]
    j = int(np.searchsorted(x, depth))  # x[j-1] < depth < x[j]
    w = (depth - x[j - 1]) / (x[j] - x[j - 1])
    return (1 - w) * temps[:, j - 1] + w * temps[:, j]


def half_step_flux(layer, t_face, t_next, dx: float, dt: float, theta: float) -> np.ndarray:
    """Mean heat flux density [W/m2] entering a face half-node over each step, from its energy balance.

    ``q_(n-1/2) = (rho c dx/2) (T0^n - T0^(n-1)) / dt + lambda (T0 - T1) / dx``, the conduction
    term weighted ``theta`` on the new level and ``1 - theta`` on the old one. For a no-mass
    face layer: ``(T0 - T1) / R`` with the same weighting.

    Parameters
    ----------
    layer : Layer
        The face layer.
    t_face, t_next : ndarray, shape (M,)
        Face node and next node temperatures [degC] on consecutive timesteps.
    dx : float
        Distance between the two nodes [m].
    dt : float
        Timestep [s].
    theta : float
        0.5 (Crank-Nicolson) or 1 (fully implicit).

    Returns
    -------
    ndarray, shape (M - 1,)
        Positive from the face into the wall.
    """
    t_face = np.asarray(t_face, dtype=float)
    t_next = np.asarray(t_next, dtype=float)
    if layer.is_massless:
        cond = (t_face - t_next) / float(layer.thermal_resistance)
        return theta * cond[1:] + (1 - theta) * cond[:-1]
    if layer.is_temperature_dependent:
        lam = layer.conductivity_at(0.5 * (t_face + t_next))
    else:
        lam = layer.conductivity_at(layer.reference_temperature)
    cond = lam * (t_face - t_next) / dx
    return layer.volumetric_heat_capacity * dx / 2 * np.diff(t_face) / dt + theta * cond[1:] + (1 - theta) * cond[:-1]


def face_fluxes(wall: Wall, x: np.ndarray, temps: np.ndarray, dt: float, scheme: str):
    """Heat flux densities [W/m2] at both faces, positive towards the interior, at the node rows.

    The surface half-node energy balance of each step gives the mean face flux over that step
    (:func:`half_step_flux`, conduction weighted like the scheme); the value at row ``n`` is the
    mean of the steps on either side of it (a centred formula; the first and last rows take their
    one step). At the interior face the signs are mirrored.

    Parameters
    ----------
    wall : Wall
    x : ndarray
        Node depths [m].
    temps : ndarray, shape (n_rows, n_nodes)
        Node temperatures [degC] on consecutive timesteps (at least 2 rows).
    dt : float
        Timestep [s].
    scheme : str
        ``"cn"`` or ``"implicit"``.

    Returns
    -------
    (ndarray, ndarray)
        Exterior and interior face heat flux densities, shape (n_rows,).
    """
    theta = 0.5 if scheme == "cn" else 1.0

    def centred(half):
        q = np.empty(len(half) + 1)
        q[1:-1] = 0.5 * (half[1:] + half[:-1])
        q[0], q[-1] = half[0], half[-1]
        return q

    q_e = centred(half_step_flux(wall.layers[0], temps[:, 0], temps[:, 1], x[1] - x[0], dt, theta))
    q_i = -centred(half_step_flux(wall.layers[-1], temps[:, -1], temps[:, -2], x[-1] - x[-2], dt, theta))
    return q_e, q_i
