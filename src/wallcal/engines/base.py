"""The engine contract: what every engine receives, declares, and returns.

Every engine (``fd-cn``, ``fd-implicit``, ``energyplus``...) is an :class:`Engine`. An engine that runs
walls one at a time implements ``capabilities``, ``prepare`` and ``run_wall`` (and ``check_time_step``
when not every step is allowed); the default ``run`` does the rest. Callers use:

- ``engine.capabilities`` (:class:`Capabilities`) says what it can do: batches of
  candidate walls, lambda(T) laws, flux at a depth, contact resistances, no-mass
  layers, which boundary types; ``engine.check_time_step(dt)`` says why a time step
  is refused (None when allowed), and ``engine.problems(inp)`` lists everything in an
  input the engine cannot run (``engine.check(inp)`` raises them as one
  :class:`~wallcal.errors.EngineError`).
- ``prepared = engine.prepare(inp)`` does the work that depends only on the input
  (grids, boundary series, output plans); ``prepared.inp`` is the input.
- ``engine.run(prepared)`` runs the prepared wall and returns an :class:`EngineOutput`;
  ``engine.run(prepared, wall)`` another wall with the same layer structure;
  ``engine.run(prepared, walls)`` with a list of walls or a :class:`WallBatch` runs a
  batch and returns a :class:`BatchOutput` (engines without ``batches`` run the walls
  one after the other).

Typed options (:class:`EngineOptions`) replace free dictionaries. Data preparation
(reading files, interpolating, choosing the period) happens once, outside the
engines, in :mod:`wallcal.simulation`. Choosing an engine for a task that needs a
capability (calibration needs batches) happens in one place:
:func:`wallcal.engines.engine_for`.

Sign convention: heat flux densities are positive towards the interior at both
faces and inside the wall (see :mod:`wallcal.wall`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..errors import EngineError
from ..wall import Wall
from .boundary_types import BUILT_IN as BUILT_IN_BOUNDARY_TYPES
from .boundary_types import boundary_type_names

#: The built-in boundary types (the registry, :mod:`wallcal.engines.boundary_types`, has every one).
BOUNDARY_TYPES = BUILT_IN_BOUNDARY_TYPES
FACES = ("exterior", "interior")
#: Hygric layer properties a calibration may change (fields of :class:`~wallcal.wall.Layer`).
HYGRIC_PROPERTIES = (
    "vapour_resistance_factor",
    "moisture_conductivity_coefficient",
    "sorption_scale",
    "liquid_transport_scale",
)


@dataclass(frozen=True)
class BoundaryInput:
    """One face's boundary condition on the engine time grid.

    Parameters
    ----------
    type : str
        ``"surface_temperature"`` (values: surface temperature [degC]),
        ``"air_temperature"`` (values: air temperature [degC], with
        ``surface_coefficient`` [W/(m2K)]), ``"sol_air_temperature"`` (an exterior face in the
        weather: values the sol-air temperature [degC], with the combined exterior coefficient as
        ``surface_coefficient``; see :mod:`wallcal.engines.boundary`), ``"surface_temperature_humidity"`` /
        ``"air_temperature_humidity"`` (the same with ``relative_humidity``, and for air the
        ``vapour_coefficient``: engines with the ``moisture`` capability), or ``"heat_flux"`` (values: heat
        flux density at this face [W/m2], positive towards the interior as
        everywhere in wallcal: at the exterior face that is the flux entering
        the wall, at the interior face the flux leaving it into the room).
    values : ndarray, shape (n_steps + 1,)
        Values at grid times ``t0 + k * time_step``.
    surface_coefficient : float or None
        Combined surface heat transfer coefficient [W/(m2K)] for ``air_temperature`` and
        ``sol_air_temperature``.
    relative_humidity : ndarray or None
        Relative humidity (fraction) at the grid times, for the humidity boundary types.
    vapour_coefficient : float or None
        Surface vapour transfer coefficient beta [s/m] (``air_temperature_humidity``).
    """

    type: str
    values: np.ndarray
    surface_coefficient: float | None = None
    relative_humidity: np.ndarray | None = None
    vapour_coefficient: float | None = None


@dataclass(frozen=True)
class MoistureInput:
    """What an engine with the ``moisture`` capability needs beyond the heat input.

    Parameters
    ----------
    probes_relative_humidity, probes_water_content : tuple of str
        Probes whose relative humidity (fraction) and water content [kg/m3] are wanted.
    initial : str
        ``"constant"`` (``temperature`` [degC] and ``relative_humidity`` (fraction) or ``water_content``
        [kg/m3], each one value), ``"profile"`` (``depths`` [m] with ``temperature`` and
        ``relative_humidity`` one value per depth, interpolated between them: the first data row), or
        ``"periodic"`` (the run repeated from its own end state until it repeats).
    profiles : bool
        Return the cell states at the output times (:attr:`EngineOutput.profiles`).
    """

    probes_relative_humidity: tuple[str, ...] = ()
    probes_water_content: tuple[str, ...] = ()
    initial: str = "constant"
    depths: tuple[float, ...] = ()
    temperature: tuple[float, ...] = (20.0,)
    relative_humidity: tuple[float, ...] | None = (0.5,)
    water_content: float | None = None
    profiles: bool = False


@dataclass(frozen=True)
class EngineOptions:
    """Numerical options of a run (every engine receives them; each uses those that apply to it).

    Parameters
    ----------
    stiff_limit : float or None
        fd engines: node stiffness ``dt sum(g) / c`` [-] above which theta is raised on the node's links
        (see :func:`wallcal.engines.operator.link_thetas`); None: ``1 / (1 - theta)``, the discrete
        maximum principle (monotone step responses).
    refactor_drift : float
        fd engines, lambda(T): refactorise the matrix when a conductance drifts this much
        from the factorised one (fraction; 0: every step).
    exponential_layers : frozenset of int
        Layer indices run with the exponential lambda(T) law even at a zero coefficient
        (their coefficient is a calibration parameter).
    contact_layers : frozenset of int
        Layer indices whose interior interface gets a contact link even at zero contact
        resistance (the resistance is a calibration parameter).
    grid_time_step : float or None
        Build the spatial grid for this time step [s] instead of the run's (convergence in
        time on a fixed grid).
    """

    stiff_limit: float | None = None
    refactor_drift: float = 0.02
    exponential_layers: frozenset[int] = frozenset()
    contact_layers: frozenset[int] = frozenset()
    grid_time_step: float | None = None

    def replace(self, **changes) -> EngineOptions:
        import dataclasses

        return dataclasses.replace(self, **changes)


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
    flux_depths : tuple of (str, float)
        Heat flux densities wanted inside the wall: (name, depth from the exterior face [m]);
        the output's ``fluxes`` carries them under their names.
    grid_constant : float
        C = dx^2 / (alpha dt) [-].
    node_rule : str
        ``"wallcal"`` or ``"energyplus"`` (see :mod:`wallcal.grid`).
    scheme : str
        ``"cn"`` (Crank-Nicolson) or ``"implicit"`` (fully implicit).
    initial : str
        ``"steady"``: start from the steady profile of the first boundary values.
    options : EngineOptions
    moisture : MoistureInput or None
        Moisture outputs and initial state (None: a heat-only run).
    """

    wall: Wall
    t0: pd.Timestamp
    time_step: float
    exterior: BoundaryInput
    interior: BoundaryInput
    output_positions: np.ndarray
    probes: tuple[str, ...]
    flux_faces: tuple[str, ...] = ()
    flux_depths: tuple[tuple[str, float], ...] = ()
    grid_constant: float = 2.0
    node_rule: str = "wallcal"
    scheme: str = "cn"
    initial: str = "steady"
    options: EngineOptions = EngineOptions()
    moisture: MoistureInput | None = None

    @property
    def n_steps(self) -> int:
        return len(self.exterior.values) - 1

    def replace(self, **changes) -> SimulationInput:
        import dataclasses

        return dataclasses.replace(self, **changes)


@dataclass
class EngineOutput:
    """What an engine returns for one wall.

    Attributes
    ----------
    temperatures : dict[str, ndarray]
        Probe name -> temperature [degC] at the output times.
    fluxes : dict[str, ndarray]
        Face (``"exterior"``/``"interior"``) or flux-depth name -> heat flux density [W/m2],
        positive towards the interior, at the output times.
    info : dict
        Engine facts worth reporting (path used, node count, energy-balance residual...).
    final_state : ndarray or None
        Node temperatures [degC] on the engine's own grid at the end of the run (engines with the
        ``initial_state`` capability): what a later run may start from (a periodic year).
    relative_humidity, water_content : dict[str, ndarray]
        Probe name -> relative humidity (fraction) and water content [kg/m3] at the output times (engines
        with the ``moisture`` capability).
    profiles : DataFrame or None
        The cell states at the output times when asked for (:attr:`MoistureInput.profiles`).
    """

    temperatures: dict[str, np.ndarray]
    fluxes: dict[str, np.ndarray]
    info: dict = field(default_factory=dict)
    final_state: np.ndarray | None = None
    relative_humidity: dict[str, np.ndarray] = field(default_factory=dict)
    water_content: dict[str, np.ndarray] = field(default_factory=dict)
    profiles: pd.DataFrame | None = None


@dataclass
class BatchOutput:
    """What an engine returns for a batch of walls: the arrays of :class:`EngineOutput` with a
    leading candidate axis, shape (n_candidates, n_times) each (``final_state``: (n_candidates, n_nodes))."""

    temperatures: dict[str, np.ndarray]
    fluxes: dict[str, np.ndarray]
    info: dict = field(default_factory=dict)
    final_state: np.ndarray | None = None
    relative_humidity: dict[str, np.ndarray] = field(default_factory=dict)
    water_content: dict[str, np.ndarray] = field(default_factory=dict)

    def output(self, c: int) -> EngineOutput:
        """The :class:`EngineOutput` of candidate ``c``."""
        return EngineOutput(
            {k: v[c] for k, v in self.temperatures.items()},
            {k: v[c] for k, v in self.fluxes.items()},
            dict(self.info),
            None if self.final_state is None else self.final_state[c],
            {k: v[c] for k, v in self.relative_humidity.items()},
            {k: v[c] for k, v in self.water_content.items()},
        )


@dataclass
class PropertyArrays:
    """Layer properties of a batch of candidate walls, shape (n_candidates, n_layers).

    Units: thickness [m], conductivity [W/(m K)] at reference temperature,
    volumetric_heat_capacity [J/(m3 K)], temperature coefficient [1/K],
    reference temperature [degC], contact and thermal resistances [m2K/W]; ``hygric``: the hygric layer
    properties a calibration changes (:data:`HYGRIC_PROPERTIES` names -> arrays of the same shape; only the
    ``moisture`` engines read them).
    """

    thickness: np.ndarray
    conductivity: np.ndarray
    volumetric_heat_capacity: np.ndarray
    temperature_coefficient: np.ndarray
    reference_temperature: np.ndarray
    contact_resistance: np.ndarray
    thermal_resistance: np.ndarray
    hygric: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def n_candidates(self) -> int:
        return self.conductivity.shape[0]

    def take(self, index) -> PropertyArrays:
        """The candidates at ``index`` (an integer array or a boolean mask)."""
        out = {f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self) if f.name != "hygric"}
        return PropertyArrays(**out, hygric={k: v[index] for k, v in self.hygric.items()})

    def line_arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays :func:`assemble_lines` takes: thickness, conductivity, volumetric heat capacity, contact
        and thermal resistance, temperature coefficient."""
        return (
            self.thickness,
            self.conductivity,
            self.volumetric_heat_capacity,
            self.contact_resistance,
            self.thermal_resistance,
            self.temperature_coefficient,
        )

    @classmethod
    def from_walls(cls, walls: list[Wall]) -> PropertyArrays:
        """Stack the layer properties of walls with the same layer structure."""

        def arr(fn):
            return np.array([[fn(layer) for layer in w.layers] for w in walls], dtype=float)

        return cls(
            thickness=arr(lambda L: L.thickness),
            conductivity=arr(lambda L: 0.0 if L.is_massless else L.conductivity_at(L.reference_temperature)),
            volumetric_heat_capacity=arr(lambda L: L.volumetric_heat_capacity),
            temperature_coefficient=arr(lambda L: L.conductivity_temperature_coefficient),
            reference_temperature=arr(lambda L: L.reference_temperature),
            contact_resistance=arr(lambda L: L.contact_resistance),
            thermal_resistance=arr(lambda L: L.thermal_resistance if L.is_massless else 0.0),
            hygric={k: arr(lambda L, k=k: getattr(L, k) or 0.0) for k in HYGRIC_PROPERTIES},
        )


@dataclass(frozen=True)
class WallBatch:
    """Candidate walls with the prepared wall's layer structure, as arrays (fast to build in bulk).

    Attributes
    ----------
    properties : PropertyArrays
        Layer properties, shape (n_candidates, n_layers) each.
    probe_depths : ndarray, shape (n_candidates, n_probes) or None
        Depths [m] of the input's ``probes``, in that order; None: the prepared wall's.
    """

    properties: PropertyArrays
    probe_depths: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.properties.n_candidates

    @classmethod
    def from_walls(cls, walls: Sequence[Wall], probes: Sequence[str]) -> WallBatch:
        depths = np.array([[w.probe(p).depth for p in probes] for w in walls], dtype=float).reshape(len(walls), -1)
        return cls(PropertyArrays.from_walls(list(walls)), depths)

    def walls(self, base: Wall, probes: Sequence[str]) -> list[Wall]:
        """The candidates as :class:`Wall` objects built from ``base`` (for engines that run walls)."""
        pa = self.properties
        out = []
        for c in range(self.n):
            w = base
            for i, layer in enumerate(base.layers):
                if layer.is_massless:
                    w = w.replace_layer(layer.id, thermal_resistance=float(pa.thermal_resistance[c, i]))
                    continue
                changes = dict(
                    conductivity=float(pa.conductivity[c, i]),
                    conductivity_temperature_coefficient=float(pa.temperature_coefficient[c, i]),
                    reference_temperature=float(pa.reference_temperature[c, i]),
                    contact_resistance=float(pa.contact_resistance[c, i]),
                )
                for k, v in pa.hygric.items():
                    if v[c, i] != (getattr(layer, k) or 0.0):
                        changes[k] = float(v[c, i])
                rho_c = float(pa.volumetric_heat_capacity[c, i])
                if rho_c != layer.volumetric_heat_capacity:  # keep the density, move the specific heat
                    changes["specific_heat"] = rho_c / layer.density
                w = w.replace_layer(layer.id, **changes)
            if self.probe_depths is not None:
                for k, p in enumerate(probes):
                    w = w.replace_probe(p, depth=float(self.probe_depths[c, k]))
            out.append(w)
        return out


@dataclass(frozen=True)
class Capabilities:
    """What an engine can do (everything else about an input is checked by :meth:`Engine.problems`).

    Attributes
    ----------
    batches : bool
        Runs a batch of candidate walls in one call, in milliseconds per wall (calibration,
        sensitivity, identifiability, the posterior and the live page need it).
    conductivity_laws : bool
        lambda(T) laws (exponential coefficient and tables).
    flux_at_depth : bool
        Heat flux density inside the wall (:attr:`SimulationInput.flux_depths`).
    contact_resistance : bool
        Contact resistances between layers.
    massless_layers : bool
        No-mass (resistance-only) layers.
    boundary_types : tuple of str or None
        Boundary types accepted at both faces; None: every registered one
        (:mod:`wallcal.engines.boundary_types`).
    any_time_step : bool
        Every positive time step (otherwise see :meth:`Engine.check_time_step`).
    substitute : str or None
        Engine that runs what this one cannot (e.g. batches), verified against this one.
    substitute_verified : str
        How the substitute was verified against this engine (said wherever it is used).
    initial_state : bool
        A run may start from given node temperatures (``run(..., initial_state=...)``) and returns
        its end state (``final_state``): periodic runs such as a weather year repeated until it repeats.
    moisture : bool
        Coupled heat and moisture: humidity boundaries, ``relative_humidity`` and ``water_content``
        outputs (:class:`MoistureInput`).
    """

    batches: bool
    conductivity_laws: bool
    flux_at_depth: bool
    contact_resistance: bool
    massless_layers: bool
    boundary_types: tuple[str, ...] | None = None
    any_time_step: bool = True
    substitute: str | None = None
    substitute_verified: str = ""
    initial_state: bool = False
    moisture: bool = False

    def accepted_boundary_types(self) -> tuple[str, ...]:
        """The boundary types this engine accepts (every registered one unless it lists its own)."""
        return boundary_type_names() if self.boundary_types is None else self.boundary_types

    def lacks(self, needs: Sequence[str]) -> list[str]:
        """The capabilities among ``needs`` (attribute names) this engine does not have."""
        return [n for n in needs if not getattr(self, n)]


#: Words for capabilities in messages.
CAPABILITY_WORDS = {
    "batches": "batches of candidate walls",
    "conductivity_laws": "lambda(T) laws",
    "flux_at_depth": "heat fluxes inside the wall",
    "contact_resistance": "contact resistances",
    "massless_layers": "no-mass layers",
    "initial_state": "runs from a given state",
    "moisture": "moisture (relative humidity and water content)",
}


class Engine:
    """The engine contract (see the module docstring). Subclasses set ``name`` and ``capabilities`` and
    implement :meth:`prepare` and :meth:`run_wall` (or :meth:`run`, for batches in one call);
    :meth:`check_time_step` when not every time step is allowed."""

    name = "base"
    capabilities = Capabilities(
        batches=False, conductivity_laws=False, flux_at_depth=False, contact_resistance=False, massless_layers=False
    )

    def unavailable(self) -> str | None:
        """Why this engine cannot run on this machine (an optional dependency is missing); None when it can."""
        return None

    def check_time_step(self, dt: float) -> str | None:
        """Why this engine cannot run time step ``dt`` [s]; None when it can."""
        if not (dt > 0 and np.isfinite(dt)):
            return f"the time step must be a positive number of seconds, got {dt!r}"
        return None

    def problems(self, inp: SimulationInput) -> list[str]:
        """Everything in ``inp`` this engine cannot run (empty when it can), each in words: what its
        capabilities and :meth:`check_time_step` refuse. An engine with more rules extends the list
        (``super().problems(inp) + [...]``)."""
        cap, out = self.capabilities, []
        if not cap.moisture and (
            inp.moisture is not None or any(getattr(inp, f).relative_humidity is not None for f in FACES)
        ):
            out.append(
                f"the {self.name} engine computes heat only, and this input has moisture (humidity boundaries or "
                'relative_humidity / water_content outputs): use the engine "ham"'
            )
        for face in FACES:
            b = getattr(inp, face)
            accepted = cap.accepted_boundary_types()
            if b.type not in accepted:
                hint = f" (use the {cap.substitute} engine for it)" if cap.substitute else ""
                out.append(
                    f"the {self.name} engine supports only {' and '.join(map(repr, accepted))} "
                    f"boundaries; the {face} face has {b.type!r}{hint}"
                )
        why = self.check_time_step(float(inp.time_step))
        if why:
            out.append(why)
        if inp.flux_depths and not cap.flux_at_depth:
            out.append(f"the {self.name} engine gives no heat flux inside the wall")
        layers = inp.wall.layers
        # the options name the layers whose lambda(T) or contact resistance a batch varies (a calibration's
        # parameters): a batch wall is not checked again, so an engine without them must refuse here
        if not cap.conductivity_laws and (
            any(layer.is_temperature_dependent for layer in layers) or inp.options.exponential_layers
        ):
            out.append(f"the {self.name} engine has no lambda(T) law")
        if not cap.contact_resistance and (
            any(layer.contact_resistance for layer in layers) or inp.options.contact_layers
        ):
            out.append(f"the {self.name} engine has no contact resistance")
        if not cap.massless_layers and any(layer.is_massless for layer in layers):
            out.append(f"the {self.name} engine has no no-mass layer")
        return out

    def check(self, inp: SimulationInput) -> None:
        """Raise :class:`~wallcal.errors.EngineError` listing :meth:`problems`, if any."""
        probs = self.problems(inp)
        if probs:
            raise EngineError("; ".join(probs))

    def prepare(self, inp: SimulationInput):  # pragma: no cover - interface
        """The work that depends only on ``inp``; the result has ``inp`` as attribute ``inp``."""
        raise NotImplementedError

    def run_wall(self, prepared, wall: Wall) -> EngineOutput:  # pragma: no cover - interface
        """Run one wall (the input's or another with the same layer structure and probes): what an engine
        that runs walls one at a time implements; :meth:`run` calls it."""
        raise NotImplementedError

    def run(self, prepared, walls: Wall | Sequence[Wall] | WallBatch | None = None, *, initial_state=None):
        """Run the prepared wall (``walls`` None) or another wall (a :class:`Wall`): -> :class:`EngineOutput`;
        a batch (a list of walls or a :class:`WallBatch`): -> :class:`BatchOutput`.

        ``prepared`` may be a :class:`SimulationInput` (prepared on the fly). ``initial_state``: node
        temperatures [degC] on the engine's grid to start from, as a ``final_state`` returned earlier
        (engines with the ``initial_state`` capability; default: the steady state of the first inputs).
        This default runs the walls one after the other through :meth:`run_wall`; engines with
        ``batches`` override it.
        """
        if initial_state is not None and not self.capabilities.initial_state:
            raise EngineError(f"the {self.name} engine cannot start from a given state")
        if isinstance(prepared, SimulationInput):
            prepared = self.prepare(prepared)
        inp = prepared.inp
        if not is_batch(walls):
            return self.run_wall(prepared, inp.wall if walls is None else walls)
        if isinstance(walls, WallBatch):
            walls = walls.walls(inp.wall, inp.probes)
        return stack_outputs(self.name, inp.probes, [self.run_wall(prepared, w) for w in walls])

    def run_as_inputs(self, inp: SimulationInput, walls=None):
        """:meth:`run` for an engine whose runs go through :meth:`run_inputs` (EnergyPlus): the input's wall,
        another wall or a batch, each wall an input of its own (so a batch runs in parallel on the executor)."""
        if not is_batch(walls):
            wall = inp.wall if walls is None else walls
            return self.run_inputs([inp if wall is inp.wall else inp.replace(wall=wall)])[0]
        if isinstance(walls, WallBatch):
            walls = walls.walls(inp.wall, inp.probes)
        return stack_outputs(self.name, inp.probes, self.run_inputs([inp.replace(wall=w) for w in walls]))

    def run_inputs(self, inputs: Sequence[SimulationInput]) -> list[EngineOutput]:
        """One run of each input's wall (inputs that may differ in anything: time step, grid, wall). This default
        runs them one after the other; an engine whose runs take seconds (EnergyPlus) sends them to the executor
        of :mod:`wallcal.cluster`. Each output's ``info["seconds"]`` is its run time [s] (preparing included)."""
        outs = []
        for inp in inputs:
            t = time.perf_counter()
            out = self.run(self.prepare(inp))
            out.info.setdefault("seconds", time.perf_counter() - t)
            outs.append(out)
        return outs

    def simulate(self, inp: SimulationInput) -> EngineOutput:
        """``run(prepare(inp))``: one run of the input's wall."""
        return self.run(self.prepare(inp))


def stack_outputs(engine: str, probes: Sequence[str], outs: Sequence[EngineOutput]) -> BatchOutput:
    """The :class:`BatchOutput` of one :class:`EngineOutput` per wall (candidate axis first)."""
    return BatchOutput(
        temperatures={k: np.stack([o.temperatures[k] for o in outs]) for k in probes},
        fluxes={k: np.stack([o.fluxes[k] for o in outs]) for k in outs[0].fluxes} if outs else {},
        info={"engine": engine, "runs": [o.info for o in outs]},
        relative_humidity={k: np.stack([o.relative_humidity[k] for o in outs]) for k in outs[0].relative_humidity}
        if outs
        else {},
        water_content={k: np.stack([o.water_content[k] for o in outs]) for k in outs[0].water_content} if outs else {},
    )


def is_batch(walls) -> bool:
    """Whether ``walls`` asks :meth:`Engine.run` for a batch (a list of walls or a :class:`WallBatch`)."""
    return isinstance(walls, WallBatch) or (walls is not None and not isinstance(walls, Wall))
