"""The bundled material catalogue for retrofit variants (``materials.toml``, beside this module).

Each entry gives density [kg/m3], conductivity [W/(m K)], specific heat [J/(kg K)] and the water vapour
resistance factor mu [-], and names where every value comes from (ISO 10456:2007 Tables 3 and 4, product
standards' typical declared values, EnergyPlus's ASHRAE 2005 dataset). ``docs/retrofit.md`` lists them.
"""

from __future__ import annotations

import functools
import tomllib
from dataclasses import dataclass
from importlib import resources

from ..errors import closest

PROPERTY_KEYS = ("density", "conductivity", "specific_heat", "vapour_resistance_factor")


@dataclass(frozen=True)
class Material:
    """One catalogue entry (SI units, see the module docstring)."""

    name: str
    description: str
    density: float
    conductivity: float
    specific_heat: float
    vapour_resistance_factor: float
    source: str

    def layer_keys(self) -> dict:
        """The ``[[wall.layers]]`` keys this material supplies."""
        return {k: getattr(self, k) for k in PROPERTY_KEYS}


@functools.cache
def catalogue() -> dict[str, Material]:
    """Every catalogue material by name."""
    text = resources.files(__package__).joinpath("materials.toml").read_text(encoding="utf-8")
    raw = tomllib.loads(text)
    return {name: Material(name=name, **{k: v for k, v in entry.items() if k != "name"}) for name, entry in raw.items()}


def find(name: str) -> Material | None:
    """The material called ``name`` (case-insensitive), or None."""
    cat = catalogue()
    if name in cat:
        return cat[name]
    low = {k.lower(): v for k, v in cat.items()}
    return low.get(name.strip().lower())


def unknown_message(name: str) -> str:
    """'unknown material ...; did you mean ...?' for a name that is not in the catalogue."""
    return f"unknown material {name!r} (not in the catalogue); {closest(name, list(catalogue()))}"
