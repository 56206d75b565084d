"""The ham engine's grid (:data:`wallcal.engines.ham.GRID`): the rain taken up through a face cell as on a
grid with the same 0.1 mm face cells and ten times finer inside, with fewer cells than the previous grid
(bench/ham.py --grid-study; docs/moisture.md, Speed)."""

from __future__ import annotations

import numpy as np

from wallcal.engines.ham import GRID
from wallcal.moisture.cases import HOUR, hamstad5_materials
from wallcal.moisture.solver import Boundary, Layer, make_grid, solve

FINE = (1e-4, 1.1, 2e-3)
OLD_GRID = (5e-4, 1.2, 5e-3)


def _layers():
    brick, mortar, insulation = hamstad5_materials()
    return [Layer(brick, 0.2), Layer(mortar, 0.015), Layer(insulation, 0.04)]


def _rain_days(grid_spec, days=6):
    """A brick wall wetted by showers for ``days`` days: the grid, the result, total water [kg/m2] daily."""
    layers = _layers()
    grid = make_grid(layers, *grid_spec)
    t = np.arange(days * 24 + 1) * HOUR
    rain = np.where(np.arange(t.size) % 12 < 3, 1.0 / 3600.0, 0.0)  # 1 mm/h, 3 h in every 12
    ext = Boundary("air", 5.0 + 3.0 * np.sin(2 * np.pi * t / 86400.0), 0.85, times=t, h=25.0, beta=2e-7, rain=rain)
    inn = Boundary("air", 20.0, 0.5, h=8.0, beta=5.9e-8)
    res = solve(grid, ext, inn, 10.0, 0.7, t[24::24], dt_max=HOUR)
    return grid, res, res.water_content @ grid.dx


def test_engine_grid_takes_up_the_rain_of_a_fine_grid_with_fewer_cells():
    # the previous grid's 0.5 mm face cell took up 10 % more water than the fine grid here
    _, _, water_ref = _rain_days(FINE)
    grid, res, water = _rain_days(GRID)
    assert np.abs(water - water_ref).max() < 0.01 * water_ref.max()
    assert grid.dx.size < make_grid(_layers(), *OLD_GRID).dx.size
    assert res.mass_balance_error.max() < 1e-9
