"""Coupled heat and moisture transport in a wall (EN 15026): material functions, the numba solver and
its verification cases (EN 15026 Annex A, HAMSTAD). See ``docs/moisture.md``."""

from .materials import HygricMaterial
from .solver import Boundary, HamResult, Layer, make_grid, solve

__all__ = ["Boundary", "HamResult", "HygricMaterial", "Layer", "make_grid", "solve"]
