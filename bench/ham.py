"""Speed of the heat-and-moisture engine: one year, hourly boundary data, 7-layer walls; and HAMSTAD 5.

Run: ``NUMBA_NUM_THREADS=1 PYTHONPATH=src python bench/ham.py [--grid-study] [--plots DOCS_DIR]``. Prints
the CPU time of the warm runs (kernels compiled beforehand; median of five; on a shared machine the CPU
time is the steadier figure), the steps, Newton iterations and balance errors, for the study's wall
(``examples/campaign_a/study.toml``, layers #3..#9, with the catalogue's hygric properties) on the engine's
grid, and for a masonry wall with rain. The issue's target is 0.25 s on one core for the study's wall.
``--grid-study`` compares both walls' grids with a fine reference (relative humidity at interfaces,
total water, interior heat flux).
``--plots DIR`` also writes the verification cases' figures (``moisture_<case>.png``) into DIR (the ones
in docs/ come from ``--plots docs``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from wallcal.engines.ham import GRID
from wallcal.materials import find
from wallcal.moisture.cases import (
    HOUR,
    _hamstad5_run,
    en15026_material,
    hamstad2_material,
    hamstad5_materials,
    run_case,
)
from wallcal.moisture.materials import hygric_material
from wallcal.moisture.solver import Boundary, Layer, make_grid, solve
from wallcal.study import load_study

STUDY = Path(__file__).resolve().parents[1] / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"
#: catalogue materials whose hygric keys stand in for the study's layers (the study file has none; LVL has no
#: catalogue entry with hygric data, wood fibre board is the nearest wood-based one)
STUDY_HYGRIC = {"mineral wool": "mineral wool", "LVL": "wood fibre board", "plasterboard": "gypsum plasterboard"}

YEAR = 8760


def seven_layer_wall():
    brick, mortar, insulation = hamstad5_materials()
    render = en15026_material()
    return [
        Layer(render, 0.02),
        Layer(brick, 0.10),
        Layer(mortar, 0.015),
        Layer(brick, 0.10),
        Layer(mortar, 0.015),
        Layer(insulation, 0.06),
        Layer(hamstad2_material(), 0.0125),
    ]


def study_wall():
    """The study's layers #3..#9 with its thermal data and vapour resistance factors, the catalogue's storage
    and liquid transport (:data:`STUDY_HYGRIC`)."""
    layers = []
    for layer in load_study(STUDY).wall.layers:
        name = next(v for k, v in STUDY_HYGRIC.items() if k in layer.material)
        keys = {k: v for k, v in find(name).hygric.items() if k != "source"}
        keys["vapour_resistance_factor"] = layer.vapour_resistance_factor
        m = hygric_material(
            layer.material,
            keys,
            conductivity=float(layer.conductivity_at(layer.reference_temperature)),
            density=layer.density,
            specific_heat=layer.specific_heat,
        )
        layers.append(Layer(m, layer.thickness))
    return layers


def weather(hours: int = YEAR, seed: int = 1):
    """A synthetic hourly year: annual and daily temperature waves, humid air, rain showers, solar gain."""
    rng = np.random.default_rng(seed)
    t = np.arange(hours + 1) * HOUR
    day = 2 * np.pi * t / 86400.0
    year = 2 * np.pi * t / (365 * 86400.0)
    t_air = 8.0 - 8.0 * np.cos(year) + 4.0 * np.sin(day) + rng.normal(0, 1.0, t.size)
    rh = np.clip(0.8 + 0.1 * np.cos(year) - 0.1 * np.sin(day) + rng.normal(0, 0.03, t.size), 0.3, 0.99)
    rain = np.where(rng.random(t.size) < 0.08, rng.exponential(1.0, t.size) / 3600.0, 0.0)  # kg/(m2 s)
    solar = np.maximum(0.0, 300.0 * np.sin(day - np.pi / 2)) * 0.6
    ext = Boundary("air", t_air, rh, times=t, h=25.0, beta=2e-7, rain=rain, heat_flux=solar)
    inn = Boundary("air", 20.0, 0.5, h=8.0, beta=5.9e-8)
    return ext, inn, t


def timed(grid, ext, inn, out, repeats=5, **kw):
    """Median CPU time [s] of ``repeats`` warm runs and the last result."""
    solve(grid, ext, inn, 15.0, 0.7, out[:2], dt_max=HOUR, **kw)  # compile / load the kernels
    cpu = []
    for _ in range(repeats):
        start = time.process_time()
        res = solve(grid, ext, inn, 15.0, 0.7, out, dt_max=HOUR, **kw)
        cpu.append(time.process_time() - start)
    return float(np.median(cpu)), res


def report(label, grid, cpu, res, repeats):
    it = res.stats["newton_iterations"]
    print(
        f"{label}: {cpu:.3f} s CPU (median of {repeats}; target 0.25 s), {grid.dx.size} cells, "
        f"{res.stats['steps']} steps, {it} Newton iterations ({it / res.stats['steps']:.2f} a step), "
        f"{res.stats['rejected_steps']} rejected, {1e9 * cpu / (it * grid.dx.size):.0f} ns per cell and iteration; "
        f"runoff {res.runoff[-1, 0]:.2f} kg/m2; "
        f"balance errors: mass {res.mass_balance_error.max():.1e}, energy {res.energy_balance_error.max():.1e}"
    )


def bench_year(repeats: int = 5):
    ext, inn, t = weather()
    out = t[24::24]  # daily states
    grid = make_grid(study_wall(), *GRID)
    cpu, res = timed(grid, ext, inn, out, repeats)
    report("study wall (campaign A, layers #3..#9), 1 year hourly, engine grid", grid, cpu, res, repeats)
    grid = make_grid(seven_layer_wall(), *GRID)
    cpu, res = timed(grid, ext, inn, out, repeats)
    report("masonry wall with rain, 1 year hourly, engine grid", grid, cpu, res, repeats)


#: the engine's grid before this study (cells of 0.5 mm at faces and interfaces, growth 1.2, at most 5 mm)
OLD_GRID = (5e-4, 1.2, 5e-3)


def grid_study(repeats: int = 3):
    """Each wall's quantities on coarser grids against a fine reference (cells of 0.1 mm growing by 10 % to
    2 mm): relative humidity at fixed depths (linear between cell centres; for the study wall on both sides
    of the two LVL panels, where condensation would start), total water [kg/m2], interior face heat flux
    [W/m2]; largest difference over the year's daily states."""
    ext, inn, t = weather()
    out = t[24::24]
    for label, layers, depths in (
        ("study wall", study_wall(), (0.05, 0.0995, 0.1005, 0.1130, 0.1530, 0.1660, 0.30)),
        ("masonry wall with rain", seven_layer_wall(), (0.01, 0.05, 0.12, 0.20, 0.25, 0.30, 0.31)),
    ):
        ref_grid = make_grid(layers, 1e-4, 1.1, 2e-3)
        _, ref = timed(ref_grid, ext, inn, out, 1)
        rh_ref = np.array([np.interp(depths, ref_grid.x, r) for r in ref.relative_humidity])
        water_ref = ref.water_content @ ref_grid.dx
        for g in (OLD_GRID, GRID, (2e-4, 2.0, 0.04), (5e-4, 2.0, 0.04)):
            grid = make_grid(layers, *g)
            cpu, res = timed(grid, ext, inn, out, repeats)
            rh = np.array([np.interp(depths, grid.x, r) for r in res.relative_humidity])
            water = res.water_content @ grid.dx
            d_q = np.abs(res.face_flux[1:, 1, 1] - ref.face_flux[1:, 1, 1]).max()
            print(
                f"{label}, grid first={g[0]:g} m ratio={g[1]:g} max={g[2]:g} m: {grid.dx.size} cells, "
                f"{cpu:.3f} s CPU; against {ref_grid.dx.size} cells: RH {100 * np.abs(rh - rh_ref).max():.2f} % RH, "
                f"total water {100 * np.abs(water - water_ref).max() / water_ref.max():.2f} %, interior heat flux "
                f"{d_q:.3f} W/m2, runoff {res.runoff[-1, 0]:.1f} (reference {ref.runoff[-1, 0]:.1f}) kg/m2"
            )


def bench_hamstad5(repeats: int = 5):
    """HAMSTAD 5 as ``wallcal verify hamstad5`` runs it (without the refinement self-check)."""
    _hamstad5_run()
    cpu = []
    for _ in range(repeats):
        start = time.process_time()
        res, grid, _ = _hamstad5_run()
        cpu.append(time.process_time() - start)
    print(
        f"HAMSTAD 5, 60 days: {np.median(cpu):.3f} s CPU (median of {repeats}), {grid.dx.size} cells, "
        f"{res.stats['steps']} steps; balance errors: mass {res.mass_balance_error.max():.1e}, "
        f"energy {res.energy_balance_error.max():.1e}"
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plots", metavar="DIR", help="write the verification figures into DIR")
    ap.add_argument("--grid-study", action="store_true", help="the study wall's grid convergence")
    args = ap.parse_args()
    bench_year()
    if args.grid_study:
        grid_study()
    bench_hamstad5()
    if args.plots:
        from wallcal.moisture.plots import plot_case

        for name in ("en15026", "hamstad2", "hamstad5"):
            path = plot_case(run_case(name), Path(args.plots) / f"moisture_{name}.png")
            print(f"wrote {path}")


if __name__ == "__main__":
    main()
