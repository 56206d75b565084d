"""Automatic calibration: parameter space, batched objective, algorithms, outputs.

:mod:`.space` (the ``[calibration]`` table, parsed by :func:`wallcal.load_study`) is imported here;
the runner (:mod:`.run`, which needs the engines and the study) on first use of its names, so that
the study parser can use :mod:`.space` without an import cycle.
"""

from .space import Parameter, ParameterSpace, parse_space, space_of

__all__ = [
    "CalibrationResult",
    "Parameter",
    "ParameterSpace",
    "calibrate",
    "convergence_table",
    "parse_space",
    "space_of",
]
_RUN = ("CalibrationResult", "calibrate", "convergence_table")


def __getattr__(name):
    if name in _RUN:
        from . import run

        return getattr(run, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
