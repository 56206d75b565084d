"""The bundled material catalogue (``materials.toml``, beside this module): thermal and hygric data.

Each entry gives density [kg/m3], conductivity [W/(m K)], specific heat [J/(kg K)] and the water vapour
resistance factor mu [-], and names where every value comes from (ISO 10456:2007 Tables 3 and 4, product
standards' typical declared values, EnergyPlus's ASHRAE 2005 dataset). Most entries also carry hygric data
(a ``hygric`` table with the layer keys of :data:`wallcal.moisture.materials.HYGRIC_KEYS` and its own
``source``), which the heat-and-moisture engine ``ham`` needs. A thin membrane may be given by its
equivalent air layer thickness ``sd`` [m] instead: its mu is ``sd / thickness`` of the layer that uses it.

The catalogue serves ``material = "..."`` in ``[[wall.layers]]`` (study and wall files) and in retrofit
variants (``wallcal.retrofitting.materials`` re-exports this module). ``docs/retrofit.md`` and
``docs/moisture.md`` list the entries.
"""

from __future__ import annotations

import functools
import tomllib
from dataclasses import dataclass, field
from importlib import resources

from .errors import closest

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
    sd: float | None = None
    hygric: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def hygric_source(self) -> str:
        """Where the hygric data come from ('' when the entry has none)."""
        return str(self.hygric.get("source", ""))

    @property
    def has_hygric(self) -> bool:
        """True when the entry carries the data the heat-and-moisture engine needs."""
        return "moisture_storage" in self.hygric

    def resistance_factor(self, thickness: float | None = None) -> float:
        """mu [-]; for a membrane given by ``sd``, ``sd / thickness`` (the catalogue's own value without one)."""
        ok = isinstance(thickness, int | float) and not isinstance(thickness, bool) and 1e-9 < thickness < 1e3
        if self.sd is not None and ok:  # anything else is the layer table's own problem, reported there
            return max(1.0, float(self.sd) / float(thickness))
        return float(self.vapour_resistance_factor)

    def layer_keys(self, thickness: float | None = None, hygric: bool = False) -> dict:
        """The ``[[wall.layers]]`` keys this material supplies (with ``hygric``, its hygric keys too)."""
        out = {k: getattr(self, k) for k in PROPERTY_KEYS}
        out["vapour_resistance_factor"] = self.resistance_factor(thickness)
        if hygric:
            out.update({k: v for k, v in self.hygric.items() if k not in ("source", "vapour_resistance_factor")})
        return out

    def hygric_material(self, thickness: float | None = None):
        """The :class:`wallcal.moisture.materials.HygricMaterial` of this entry (StudyError without hygric data)."""
        from .moisture.materials import hygric_material

        return hygric_material(
            self.name,
            self.layer_keys(thickness, hygric=True),
            conductivity=self.conductivity,
            density=self.density,
            specific_heat=self.specific_heat,
            where=f"catalogue material {self.name!r}",
        )


@functools.cache
def catalogue() -> dict[str, Material]:
    """Every catalogue material by name."""
    text = resources.files("wallcal").joinpath("materials.toml").read_text(encoding="utf-8")
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
