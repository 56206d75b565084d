"""wallcal: calibrate the thermal model of a real building wall against in-situ monitoring data."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("wallcal")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

from .analysis.diagnose import diagnose  # noqa: E402  (cheap: the engine loads when it runs)
from .errors import DataError, EngineError, StudyError, WallcalError  # noqa: E402
from .retrofitting import retrofit  # noqa: E402  (cheap: pvlib and the engine load when it runs)
from .simulation import SimulationResult, prepare, simulate  # noqa: E402
from .study import Study, dump_wall, load_study, load_wall  # noqa: E402
from .wall import Layer, Probe, Wall  # noqa: E402

__all__ = [
    "DataError",
    "EngineError",
    "Layer",
    "Probe",
    "SimulationResult",
    "Study",
    "StudyError",
    "Wall",
    "WallcalError",
    "__version__",
    "diagnose",
    "dump_wall",
    "load_study",
    "load_wall",
    "prepare",
    "retrofit",
    "simulate",
]
