"""Boundary types by name: the one list (what a study's ``[boundary.<face>]`` ``type`` and a
:class:`~wallcal.engines.base.BoundaryInput` may say).

Each type is one :class:`BoundaryType` line: its name, how the engines' schemes treat the face (``kind``:
``"dirichlet"`` a known face temperature, ``"robin"`` an exchange ``h (u - T_s)`` with a temperature ``u``
through a surface coefficient, ``"neumann"`` a given heat flux density; :mod:`wallcal.engines.boundary` has
the kernels' code of each kind), the quantity of its values (``"temperature"`` [degC] or ``"heat_flux"``
[W/m2], positive towards the interior), whether a study may name it, and whether it also imposes a relative
humidity (``moisture``: the ``ham`` engine's surface and air types). A new boundary type that is one of
these kinds with another input (as the sol-air temperature is a Robin face with an equivalent temperature)
is one module calling :func:`register_boundary_type`; the study loader, the contract's checks and the fd
engines' kernel codes follow.
"""

from __future__ import annotations

from dataclasses import dataclass

KINDS = ("dirichlet", "robin", "neumann")
QUANTITIES = ("temperature", "heat_flux")


@dataclass(frozen=True)
class BoundaryType:
    """One boundary type (see the module docstring)."""

    name: str
    kind: str
    quantity: str
    in_studies: bool = True
    description: str = ""
    moisture: bool = False

    @property
    def needs_surface_coefficient(self) -> bool:
        """The face exchanges with its input through a surface coefficient [W/(m2K)]."""
        return self.kind == "robin"

    @property
    def needs_vapour_coefficient(self) -> bool:
        """The face exchanges vapour with the air through a vapour transfer coefficient [s/m]."""
        return self.moisture and self.kind == "robin"

    @property
    def fixes_temperature_level(self) -> bool:
        """The face ties the wall's temperature level (two faces that do not leave it undetermined)."""
        return self.kind != "neumann"


_TYPES: dict[str, BoundaryType] = {}


def register_boundary_type(
    name: str, kind: str, quantity: str, *, in_studies: bool = True, description: str = "", moisture: bool = False
) -> BoundaryType:
    """Register a boundary type (a name not yet taken); ``moisture``: it also imposes a relative humidity
    (engines with the ``moisture`` capability only)."""
    if name in _TYPES:
        raise ValueError(f"boundary type {name!r} is already registered")
    if kind not in KINDS:
        raise ValueError(f"boundary type {name!r}: kind must be one of {KINDS}, got {kind!r}")
    if quantity not in QUANTITIES:
        raise ValueError(f"boundary type {name!r}: quantity must be one of {QUANTITIES}, got {quantity!r}")
    bt = BoundaryType(name, kind, quantity, in_studies, description, moisture)
    _TYPES[name] = bt
    return bt


def unregister_boundary_type(name: str) -> None:
    """Forget boundary type ``name`` (tests; the built-in ones stay)."""
    if name in BUILT_IN:
        raise ValueError(f"boundary type {name!r} is built in")
    _TYPES.pop(name, None)


def boundary_type(name: str) -> BoundaryType:
    """The registered type ``name`` (KeyError when it is not)."""
    return _TYPES[name]


def boundary_type_names(*, in_studies: bool | None = None) -> tuple[str, ...]:
    """Registered boundary type names, in registration order (``in_studies=True``: those a study may name)."""
    return tuple(n for n, t in _TYPES.items() if in_studies is None or t.in_studies == in_studies)


register_boundary_type("surface_temperature", "dirichlet", "temperature", description="imposed surface temperature")
register_boundary_type(
    "air_temperature", "robin", "temperature", description="air temperature through a surface coefficient"
)
register_boundary_type(
    "sol_air_temperature",
    "robin",
    "temperature",
    in_studies=False,
    description="an exterior face in the weather: the sol-air temperature through the combined exterior "
    "coefficient (built from a weather file by wallcal.retrofitting.boundary.year_boundaries)",
)
register_boundary_type("heat_flux", "neumann", "heat_flux", description="imposed heat flux density")
register_boundary_type(
    "surface_temperature_humidity",
    "dirichlet",
    "temperature",
    moisture=True,
    description="imposed surface temperature and relative humidity (a PASSYS cell's faces; ham engine)",
)
register_boundary_type(
    "air_temperature_humidity",
    "robin",
    "temperature",
    moisture=True,
    description="air temperature and relative humidity through a surface coefficient and a vapour transfer "
    "coefficient (ham engine)",
)

#: The built-in types (registered above).
BUILT_IN = boundary_type_names()
