"""The calibrated walls in a whole building: EnergyPlus runs of a reference building or a user's model.

See docs/building.md. :func:`building` runs the walls; :func:`collect_walls` gathers them from wall files and
other commands' outputs; :func:`reference_building` is the bundled building as epJSON.
"""

from .config import BuildingSpec, parse_building
from .model import reference_building
from .sources import WallEntry, collect_walls
from .study import COLUMNS, BuildingResult, building

__all__ = [
    "COLUMNS",
    "BuildingResult",
    "BuildingSpec",
    "WallEntry",
    "building",
    "collect_walls",
    "parse_building",
    "reference_building",
]
