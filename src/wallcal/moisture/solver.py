"""The heat-and-moisture solver as a pure function over arrays: layers + boundary time series -> states.

:func:`solve` takes the layers (material and thickness, exterior first), a boundary description per face
and the initial state, runs the kernel (:mod:`wallcal.moisture.kernel`) and returns a :class:`HamResult`
with the cell states at the requested times and the run's mass and energy balances. It reads and writes no
file; the engine contract and the ``wallcal verify`` command wrap it.

Positions ``x`` [m] are measured from the exterior face (side 0).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import EngineError, StudyError
from .kernel import run_ham
from .materials import C_WATER, HygricMaterial, potential_from_rh, rh_from_suction, saturation_pressure, stack_tables


@dataclass(frozen=True)
class Layer:
    """One layer: a :class:`~wallcal.moisture.materials.HygricMaterial` and its thickness [m]."""

    material: HygricMaterial
    thickness: float


@dataclass
class Grid:
    """Cell widths ``dx`` [m], material index per cell ``mat``, cell centres ``x`` [m] from the exterior face."""

    dx: np.ndarray
    mat: np.ndarray
    x: np.ndarray
    materials: list[HygricMaterial]


def make_grid(
    layers: list[Layer], first: float | Sequence[float] = 2e-4, ratio: float = 1.15, max_cell: float = 0.01
) -> Grid:
    """Finite-volume cells refined geometrically towards both faces of every layer.

    ``first`` is the width of the cells at each face [m] (one value, or one per layer), ``ratio`` the growth
    from one cell to the next, ``max_cell`` the widest cell [m]."""
    if not layers:
        raise StudyError(["layers: at least one layer is needed"])
    firsts = [float(first)] * len(layers) if np.isscalar(first) else [float(f) for f in first]
    if len(firsts) != len(layers):
        raise StudyError([f"grid: need one first cell per layer ({len(layers)}), got {len(firsts)}"])
    for f in firsts:
        if not (f > 0 and ratio >= 1 and max_cell >= f):
            raise StudyError([f"grid: need first > 0, ratio >= 1, max_cell >= first; got {f}, {ratio}, {max_cell}"])
    materials: list[HygricMaterial] = []
    dx_all, mat_all = [], []
    for k, layer in enumerate(layers):
        if not (layer.thickness > 0 and np.isfinite(layer.thickness)):
            raise StudyError([f"layers[{k}].thickness: must be > 0 m, got {layer.thickness}"])
        if layer.material not in materials:
            materials.append(layer.material)
        half = 0.5 * layer.thickness
        sizes = []
        s = firsts[k]
        total = 0.0
        while total + s < half:
            sizes.append(s)
            total += s
            s = min(s * ratio, max_cell)
        rest = half - total
        if sizes and rest < 0.5 * sizes[-1]:
            sizes[-1] += rest
        else:
            sizes.append(rest)
        cells = sizes + sizes[::-1]
        dx_all.extend(cells)
        mat_all.extend([materials.index(layer.material)] * len(cells))
    dx = np.array(dx_all, dtype=float)
    x = np.cumsum(dx) - 0.5 * dx
    return Grid(dx=dx, mat=np.array(mat_all, dtype=np.int64), x=x, materials=materials)


@dataclass
class Boundary:
    """One face's conditions over time (values at ``times`` [s], linear in between).

    ``kind="surface"``: the surface temperature [degC] and relative humidity (fraction) are imposed.
    ``kind="air"``: air temperature and relative humidity with a heat transfer coefficient ``h``
    [W/(m2 K)] and a vapour transfer coefficient ``beta`` [s/m] (0: sealed), a liquid water supply ``rain``
    [kg/(m2 s)] of which what the surface cannot take up at saturation runs off, and a further heat flux
    into the face ``heat_flux`` [W/m2] (absorbed solar minus long-wave loss, for weather years).
    Scalars are held constant.
    """

    kind: str
    temperature: np.ndarray | float
    relative_humidity: np.ndarray | float
    times: np.ndarray | float = 0.0
    h: np.ndarray | float = 0.0
    beta: np.ndarray | float = 0.0
    rain: np.ndarray | float = 0.0
    heat_flux: np.ndarray | float = 0.0

    def table(self, where: str) -> tuple[int, np.ndarray, np.ndarray]:
        """``(kind code, times, rows of the kernel's 6 columns)``."""
        times = np.atleast_1d(np.asarray(self.times, dtype=float))
        n = times.size
        if n > 1 and np.any(np.diff(times) <= 0):
            raise StudyError([f"{where}.times: must increase"])

        def col(name):
            v = np.asarray(getattr(self, name), dtype=float)
            v = np.full(n, float(v)) if v.ndim == 0 else v
            if v.shape != (n,) or not np.all(np.isfinite(v)):
                raise StudyError([f"{where}.{name}: need a finite value or one per time ({n}), got shape {v.shape}"])
            return v

        t = col("temperature")
        phi = col("relative_humidity")
        if np.any((phi <= 0) | (phi > 1)):
            raise StudyError([f"{where}.relative_humidity: must be in (0, 1] (a fraction)"])
        rows = np.zeros((n, 6))
        rows[:, 0] = t
        if self.kind == "surface":
            rows[:, 1] = potential_from_rh(phi)
            return 0, times, rows
        if self.kind != "air":
            raise StudyError([f"{where}.kind: must be 'surface' or 'air', got {self.kind!r}"])
        rows[:, 1] = phi * saturation_pressure(t)
        for c, name in ((2, "h"), (3, "beta"), (4, "rain")):
            v = col(name)
            if np.any(v < 0):
                raise StudyError([f"{where}.{name}: must be >= 0"])
            rows[:, c] = v
        rows[:, 5] = col("heat_flux")
        return 1, times, rows


@dataclass
class HamResult:
    """States at the output times and the run's balances.

    ``temperature`` [degC], ``potential`` (``ln pc``), ``relative_humidity`` (fraction) and
    ``water_content`` [kg/m3] have shape ``(len(times), n_cells)``; ``inflow[k, side]`` is the moisture
    [kg/m2] and energy [J/m2] let in through each face (0 exterior, 1 interior) from time 0 to ``times[k]``
    and ``runoff[k, side]`` the rain that ran off [kg/m2]; ``face_flux[k, side]`` the moisture
    [kg/(m2 s)] and energy [W/m2] flux into the wall through each face over the step that ended at
    ``times[k]`` (nan at time 0; into the wall at both faces, so the interior face's heat flux in wallcal's
    convention, positive towards the interior, is ``-face_flux[k, 1, 1]``); ``mass_balance_error`` and
    ``energy_balance_error`` are ``|stored change - inflow|`` relative to the larger of the stored change and
    the face inflows, at each output time."""

    times: np.ndarray
    x: np.ndarray
    dx: np.ndarray
    temperature: np.ndarray
    potential: np.ndarray
    relative_humidity: np.ndarray
    water_content: np.ndarray
    inflow: np.ndarray
    runoff: np.ndarray
    face_flux: np.ndarray
    mass_balance_error: np.ndarray
    energy_balance_error: np.ndarray
    stats: dict = field(default_factory=dict)


def _states(grid: Grid, t: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = np.empty_like(u)
    for k, m in enumerate(grid.materials):
        sel = grid.mat == k
        w[..., sel] = m.water_content(u[..., sel])
    rho_c = np.array([m.rho_c_dry for m in grid.materials])[grid.mat]
    e = (rho_c + C_WATER * w) * t
    return w, e, rh_from_suction(np.exp(u))


def solve(
    grid: Grid,
    exterior: Boundary,
    interior: Boundary,
    initial_temperature: np.ndarray | float,
    initial_relative_humidity: np.ndarray | float | None = None,
    output_times: np.ndarray | list[float] = (),
    *,
    initial_water_content: np.ndarray | float | None = None,
    dt_first: float = 1.0,
    dt_max: float = 3600.0,
    dt_min: float = 1e-6,
    tol_temperature: float = 1e-5,
    tol_potential: float = 1e-6,
    max_iter: int = 12,
) -> HamResult:
    """Run the wall from time 0 to the last of ``output_times`` [s].

    The initial state is the temperature [degC] and either the relative humidity (fraction) or the water
    content [kg/m3], each a scalar or one value per cell of ``grid``."""
    n = grid.dx.size
    t_out = np.asarray(output_times, dtype=float)
    if t_out.ndim != 1 or t_out.size == 0 or np.any(np.diff(t_out) <= 0) or t_out[0] < 0:
        raise StudyError(["output_times: need increasing times >= 0 s"])
    t0 = np.broadcast_to(np.asarray(initial_temperature, dtype=float), (n,)).copy()
    if (initial_relative_humidity is None) == (initial_water_content is None):
        raise StudyError(["initial state: give the relative humidity or the water content (one of them)"])
    if initial_water_content is not None:
        w0 = np.broadcast_to(np.asarray(initial_water_content, dtype=float), (n,))
        u0 = np.empty(n)
        for k, m in enumerate(grid.materials):
            sel = grid.mat == k
            u0[sel] = m.potential_from_water_content(w0[sel])
    else:
        phi0 = np.broadcast_to(np.asarray(initial_relative_humidity, dtype=float), (n,))
        if np.any((phi0 <= 0) | (phi0 > 1)):
            raise StudyError(["initial relative humidity: must be in (0, 1] (a fraction)"])
        u0 = potential_from_rh(phi0)
    kind_e, tb_e, rows_e = exterior.table("exterior")
    kind_i, tb_i, rows_i = interior.table("interior")
    tb = np.union1d(tb_e, tb_i)
    bc = np.empty((2, tb.size, 6))
    for side, (tbs, rows) in enumerate(((tb_e, rows_e), (tb_i, rows_i))):
        for c in range(6):
            bc[side, :, c] = np.interp(tb, tbs, rows[:, c])
    tw, tk, td, thermal = stack_tables(grid.materials)
    t_res, u_res, flux, stats, status = run_ham(
        tw,
        tk,
        td,
        thermal,
        grid.mat,
        grid.dx,
        np.array([kind_e, kind_i], dtype=np.int64),
        tb,
        bc,
        t0,
        u0,
        t_out,
        float(dt_first),
        float(dt_max),
        float(tol_temperature),
        float(tol_potential),
        int(max_iter),
        float(dt_min),
    )
    if status != 0:
        raise EngineError("ham: the time step fell below dt_min without convergence (Newton failed)")
    w, e, phi = _states(grid, t_res, u_res)
    w0s, e0s, _ = _states(grid, t0, u0)
    stored_m = (w - w0s) @ grid.dx
    stored_e = (e - e0s) @ grid.dx
    inflow = flux[:, :, :2]

    def rel(stored, fin):
        scale = np.maximum.reduce([np.abs(stored), np.abs(fin[:, 0]), np.abs(fin[:, 1])])
        return np.abs(stored - fin.sum(axis=1)) / np.maximum(scale, 1e-300)

    return HamResult(
        times=t_out,
        x=grid.x,
        dx=grid.dx,
        temperature=t_res,
        potential=u_res,
        relative_humidity=phi,
        water_content=w,
        inflow=inflow,
        runoff=flux[:, :, 2],
        face_flux=flux[:, :, 3:5],
        mass_balance_error=rel(stored_m, inflow[:, :, 0]),
        energy_balance_error=rel(stored_e, inflow[:, :, 1]),
        stats={
            "steps": int(stats[0]),
            "newton_iterations": int(stats[1]),
            "rejected_steps": int(stats[2]),
            "iterations_per_step": {k: int(v) for k, v in enumerate(stats[3:]) if v},
        },
    )
