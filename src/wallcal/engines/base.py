"""The engine interface: what every engine receives and returns.

An engine turns a :class:`SimulationInput` (a wall, boundary series already on
the engine's time grid, the times at which outputs are wanted) into an
:class:`EngineOutput` (probe temperatures and face heat fluxes at those times).
Data preparation (reading files, interpolating, choosing the period) happens
once, outside the engines, in :mod:`wallcal.simulation`.

Sign convention: heat flux densities are positive towards the interior at both
faces (see :mod:`wallcal.wall`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..wall import Wall

BOUNDARY_TYPES = ("surface_temperature", "air_temperature", "heat_flux")
FACES = ("exterior", "interior")


@dataclass(frozen=True)
class BoundaryInput:
    """One face's boundary condition on the engine time grid.

    Parameters
    ----------
    type : str
        ``"surface_temperature"`` (values: surface temperature [degC]),
        ``"air_temperature"`` (values: air temperature [degC], with
        ``surface_coefficient`` [W/(m2K)]), or ``"heat_flux"`` (values: heat
        flux density at this face [W/m2], positive towards the interior as
        everywhere in wallcal: at the exterior face that is the flux entering
        the wall, at the interior face the flux leaving it into the room).
    values : ndarray, shape (n_steps + 1,)
        Values at grid times ``t0 + k * time_step``.
    surface_coefficient : float or None
        Combined surface heat transfer coefficient [W/(m2K)] for ``air_temperature``.
    """

    type: str
    values: np.ndarray
    surface_coefficient: float | None = None


@dataclass(frozen=True)
class SimulationInput:
    """Everything an engine needs for one run (and for a batch of candidate walls).

    Parameters
    ----------
    wall : Wall
        The wall (probe depths included).
    t0 : pandas.Timestamp
        Time of grid point 0 (start of the warm-up), naive local standard time.
    time_step : float
        Engine time step [s].
    exterior, interior : BoundaryInput
        Boundary conditions, each with ``n_steps + 1`` values.
    output_positions : ndarray
        Output times as fractional grid positions ``(t - t0) / time_step``
        (float, increasing, within ``[0, n_steps]``).
    probes : tuple of str
        Probe names whose temperatures are wanted.
    flux_faces : tuple of str
        Faces (``"exterior"``/``"interior"``) whose heat flux densities are wanted.
    grid_constant : float
        C = dx^2 / (alpha dt) [-].
    node_rule : str
        ``"wallcal"`` or ``"energyplus"`` (see :mod:`wallcal.grid`).
    scheme : str
        ``"cn"`` (Crank-Nicolson) or ``"implicit"`` (fully implicit).
    initial : str
        ``"steady"``: start from the steady profile of the first boundary values.
    """

    wall: Wall
    t0: pd.Timestamp
    time_step: float
    exterior: BoundaryInput
    interior: BoundaryInput
    output_positions: np.ndarray
    probes: tuple[str, ...]
    flux_faces: tuple[str, ...] = ()
    grid_constant: float = 2.0
    node_rule: str = "wallcal"
    scheme: str = "cn"
    initial: str = "steady"
    options: dict = field(default_factory=dict)

    @property
    def n_steps(self) -> int:
        return len(self.exterior.values) - 1


@dataclass
class EngineOutput:
    """What an engine returns for one wall.

    Attributes
    ----------
    temperatures : dict[str, ndarray]
        Probe name -> temperature [degC] at the output times.
    fluxes : dict[str, ndarray]
        Face -> heat flux density [W/m2], positive towards the interior, at the output times.
    info : dict
        Engine facts worth reporting (path used, node count, energy-balance residual...).
    """

    temperatures: dict[str, np.ndarray]
    fluxes: dict[str, np.ndarray]
    info: dict = field(default_factory=dict)


class Engine:
    """Base class of engines. Subclasses set ``name`` and implement :meth:`run`."""

    name = "base"

    def run(self, inp: SimulationInput) -> EngineOutput:  # pragma: no cover - interface
        raise NotImplementedError
