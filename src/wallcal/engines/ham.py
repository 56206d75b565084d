"""The ``ham`` engine: coupled heat and moisture (EN 15026, :mod:`wallcal.moisture`) behind the engine contract.

It maps a :class:`~wallcal.engines.base.SimulationInput` onto :func:`wallcal.moisture.solver.solve`:

- each layer's :class:`~wallcal.moisture.materials.HygricMaterial` from its thermal and hygric keys
  (:meth:`wallcal.wall.Layer.hygric_material`); cells of 0.1 mm at every face and interface doubling
  to at most 40 mm (:data:`GRID`; bench/ham.py --grid-study); the solver's adaptive step, at most the input's time step;
- boundaries on the input's time grid: ``surface_temperature_humidity`` -> a surface face (T and RH imposed),
  ``air_temperature_humidity`` -> an air face (``h`` the surface coefficient, ``beta`` the vapour
  coefficient), ``surface_temperature`` / ``air_temperature`` -> the same, sealed to vapour (RH 0.5 on a
  surface face, beta = 0 on an air face: the face lets no vapour through), ``heat_flux`` -> an air face
  with ``h = 0`` and the flux into the face;
- outputs at the measured times: probe temperature, relative humidity and water content linear between cell
  centres (at an interface, between the two cells beside it: w jumps there, so a water-content probe belongs
  inside a layer), face heat fluxes (the mean over the solver's step that ends at each time) positive
  towards the interior;
- the initial state of :class:`~wallcal.engines.base.MoistureInput` (constant, the first data row's profile,
  or periodic: the run repeated from its own end state, at most :data:`PERIODIC_PASSES` times, until no cell
  ends more than 0.001 (K or RH) away from where it started).

A batch runs its walls on numba's threads (``NUMBA_NUM_THREADS``; the kernel releases the GIL); inside a
command's executor (:mod:`wallcal.cluster`) the walls go to it as the EnergyPlus runs do
(:func:`wallcal.eplus.map_runs`) when a wall runs for at least :data:`DISPATCH_S`.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
import pandas as pd

from ..errors import EngineError
from ..moisture.solver import Boundary, HamResult, Layer, make_grid, solve
from ..wall import Wall
from .base import Capabilities, Engine, EngineOutput, SimulationInput, WallBatch, is_batch, stack_outputs

#: cells at every face and interface [m], growth, widest cell [m]
GRID = (1e-4, 2.0, 0.04)
#: most layers' tabulated materials kept by one prepared input (about 100 kB each)
MATERIAL_CACHE = 64
#: most passes of a periodic run
PERIODIC_PASSES = 6
#: inside a command's executor, a batch's walls go to it only when one of them runs for at least this long [s]:
#: a task's dispatch costs about 10 ms and a local cluster about 3 s to start, which two-week records of
#: 25 ms a wall never repay (docs/moisture.md, "Speed": batches inside a command)
DISPATCH_S = 0.1
#: a sealed surface face's relative humidity (it sets the potential at the face; beta = 0 air faces carry none)
SEALED_RH = 0.5


class HamEngine(Engine):
    """Coupled heat and moisture (see the module docstring)."""

    name = "ham"
    capabilities = Capabilities(
        batches=True,
        conductivity_laws=False,
        flux_at_depth=False,
        contact_resistance=False,
        massless_layers=False,
        moisture=True,
    )

    def problems(self, inp: SimulationInput) -> list[str]:
        out = super().problems(inp)
        for face in ("exterior", "interior"):
            b = getattr(inp, face)
            if b.type == "air_temperature_humidity" and b.vapour_coefficient is None:
                out.append(f"the {face} face's air_temperature_humidity needs a vapour_coefficient [s/m]")
            if b.type in ("surface_temperature_humidity", "air_temperature_humidity") and b.relative_humidity is None:
                out.append(f"the {face} face's {b.type} needs a relative humidity series")
        return out

    def prepare(self, inp: SimulationInput):
        self.check(inp)
        return _Prepared(inp)

    def run_wall(self, prepared, wall: Wall) -> EngineOutput:
        return prepared.run(wall)

    def run(self, prepared, walls=None, *, initial_state=None):
        if initial_state is not None:
            raise EngineError("the ham engine cannot start from a given state")
        if isinstance(prepared, SimulationInput):
            prepared = self.prepare(prepared)
        inp = prepared.inp
        if not is_batch(walls):
            return prepared.run(inp.wall if walls is None else walls)
        if isinstance(walls, WallBatch):
            walls = walls.walls(inp.wall, inp.probes)
        from ..cluster import current_executor

        outs, rest = [], list(walls)
        if current_executor() is not None and len(walls) > 1:
            # the first wall runs here; the others go to the executor only when it took longer than a task's
            # dispatch is worth (DISPATCH_S), else they run here too
            start = time.perf_counter()
            outs.append(prepared.run(rest.pop(0)))
            if time.perf_counter() - start >= DISPATCH_S:
                from ..eplus import map_runs

                outs += map_runs(_run_task, [(inp, w) for w in rest], label="ham", inline=True)
                rest = []
        outs += prepared.run_many(rest)
        return stack_outputs(self.name, inp.probes, outs)


def _run_task(task) -> EngineOutput:
    """One wall of a batch on an executor (a top-level function of a picklable task: the input and the wall)."""
    inp, wall = task
    return _Prepared(inp).run(wall)


def _boundary(b, times: np.ndarray, face: str) -> Boundary:
    """A contract face as the solver's :class:`Boundary` (see the module docstring)."""
    v = np.asarray(b.values, dtype=float)
    rh = np.asarray(b.relative_humidity, dtype=float) if b.relative_humidity is not None else None
    if b.type in ("surface_temperature", "surface_temperature_humidity"):
        return Boundary("surface", v, SEALED_RH if rh is None else rh, times=times)
    if b.type in ("air_temperature", "air_temperature_humidity", "sol_air_temperature"):
        beta = float(b.vapour_coefficient or 0.0) if rh is not None else 0.0
        return Boundary(
            "air", v, SEALED_RH if rh is None else rh, times=times, h=float(b.surface_coefficient), beta=beta
        )
    if b.type == "heat_flux":  # positive towards the interior: into the wall at the exterior face
        q = v if face == "exterior" else -v
        return Boundary("air", 20.0, SEALED_RH, times=times, h=0.0, heat_flux=q)
    raise EngineError(f"the ham engine has no {b.type!r} boundary")


class _Prepared:
    """What depends only on the input: boundaries, output times, probe depths."""

    def __init__(self, inp: SimulationInput):
        self.inp = inp
        dt = float(inp.time_step)
        times = np.arange(inp.n_steps + 1) * dt
        self.exterior = _boundary(inp.exterior, times, "exterior")
        self.interior = _boundary(inp.interior, times, "interior")
        self.output_times = np.asarray(inp.output_positions, dtype=float) * dt
        self.end = float(times[-1])
        self.moisture = inp.moisture
        self._materials: dict = {}

    def _grid(self, wall: Wall):
        layers = []
        for i, layer in enumerate(wall.layers):
            key = layer
            if key not in self._materials:
                if len(self._materials) >= MATERIAL_CACHE:  # a calibration's candidates: keep the memory bounded
                    self._materials.clear()
                self._materials[key] = layer.hygric_material(f"wall.layers[{i}] (id {layer.id!r})")
            layers.append(Layer(self._materials[key], layer.thickness))
        return make_grid(layers, *GRID)

    def _initial(self, grid) -> dict:
        m = self.moisture
        if m is None:  # a heat-only input: start at the mean of the first boundary temperatures, RH 0.5
            t0 = 0.5 * (self.exterior_t0 + self.interior_t0)
            return {"initial_temperature": t0, "initial_relative_humidity": 0.5}
        if m.initial == "constant":
            out = {"initial_temperature": m.temperature[0]}
            if m.water_content is not None:
                out["initial_water_content"] = m.water_content
            else:
                out["initial_relative_humidity"] = m.relative_humidity[0]
            return out
        d = np.asarray(m.depths, dtype=float)
        return {
            "initial_temperature": np.interp(grid.x, d, np.asarray(m.temperature, dtype=float)),
            "initial_relative_humidity": np.interp(grid.x, d, np.asarray(m.relative_humidity, dtype=float)),
        }

    @property
    def exterior_t0(self) -> float:
        return float(np.atleast_1d(self.exterior.temperature)[0])

    @property
    def interior_t0(self) -> float:
        return float(np.atleast_1d(self.interior.temperature)[0])

    def _solve(self, grid, start: dict) -> HamResult:
        times = np.append(self.output_times, self.end) if self.end > self.output_times[-1] else self.output_times
        return solve(
            grid,
            self.exterior,
            self.interior,
            output_times=times,
            dt_max=max(float(self.inp.time_step), 1.0),
            **start,
        )

    def run_many(self, walls) -> list[EngineOutput]:
        """Each wall's run, on numba's threads (``NUMBA_NUM_THREADS``, as the fd engine's batches; the kernel
        releases the GIL); the grids, and with them the material cache, are built first, in this thread."""
        grids = [self._grid(w) for w in walls]
        n = min(len(walls), max(1, int(numba.config.NUMBA_NUM_THREADS)))
        if n <= 1:
            return [self.run(w, g) for w, g in zip(walls, grids, strict=True)]
        with ThreadPoolExecutor(n) as pool:
            return list(pool.map(self.run, walls, grids))

    def run(self, wall: Wall, grid=None) -> EngineOutput:
        """One wall's run (``grid``: its :meth:`_grid`, when built already)."""
        t = time.perf_counter()
        grid = self._grid(wall) if grid is None else grid
        start = self._initial(grid)
        res = self._solve(grid, start)
        passes = 1
        if self.moisture is not None and self.moisture.initial == "periodic":
            while passes < PERIODIC_PASSES:
                end_t, end_rh = res.temperature[-1], np.clip(res.relative_humidity[-1], 1e-6, 1.0)
                moved = max(
                    float(np.abs(end_t - np.broadcast_to(start["initial_temperature"], end_t.shape)).max()),
                    float(np.abs(end_rh - np.broadcast_to(start["initial_relative_humidity"], end_rh.shape)).max()),
                )
                if moved < 1e-3:
                    break
                start = {"initial_temperature": end_t, "initial_relative_humidity": end_rh}
                res = self._solve(grid, start)
                passes += 1
        n = len(self.output_times)
        inp = self.inp
        temps = {p: _at(res.temperature[:n], res.x, wall.probe(p).depth) for p in inp.probes}
        fluxes = {}
        for face in inp.flux_faces:
            q = res.face_flux[:n, 0 if face == "exterior" else 1, 1]
            q = np.array(q if face == "exterior" else -q)
            if n > 1 and not np.isfinite(q[0]):  # an output at time 0 has no step behind it: the first step's
                q[0] = q[1]
            fluxes[face] = q
        m = self.moisture
        rh_probes = m.probes_relative_humidity if m else ()
        w_probes = m.probes_water_content if m else ()
        rh = {p: _at(res.relative_humidity[:n], res.x, wall.probe(p).depth) for p in rh_probes}
        w = {p: _at(res.water_content[:n], res.x, wall.probe(p).depth) for p in w_probes}
        info = {
            "engine": "ham",
            "cells": int(len(res.x)),
            "steps": int(res.stats.get("steps", 0)),
            "newton_iterations": int(res.stats.get("newton_iterations", 0)),
            "mass_balance_error": float(np.nanmax(res.mass_balance_error)),
            "energy_balance_error": float(np.nanmax(res.energy_balance_error)),
            "passes": passes,
            "seconds": time.perf_counter() - t,
        }
        profiles = None
        if m is not None and m.profiles:
            nx = len(res.x)
            profiles = pd.DataFrame(
                {
                    "time_s": np.repeat(res.times[:n], nx),
                    "x_m": np.tile(res.x, n),
                    "temperature": res.temperature[:n].ravel(),
                    "relative_humidity": res.relative_humidity[:n].ravel(),
                    "water_content": res.water_content[:n].ravel(),
                }
            )
        return EngineOutput(temps, fluxes, info, None, rh, w, profiles)


def _at(values: np.ndarray, x: np.ndarray, depth: float) -> np.ndarray:
    """Each row of ``values`` (per cell) at ``depth`` [m], linear between cell centres."""
    k = int(np.clip(np.searchsorted(x, depth), 1, len(x) - 1))
    x0, x1 = x[k - 1], x[k]
    f = float(np.clip((depth - x0) / (x1 - x0), 0.0, 1.0))
    return values[:, k - 1] * (1 - f) + values[:, k] * f
