"""Automatic calibration: parameter space, batched objective, algorithms, outputs."""

from .run import CalibrationResult, calibrate, convergence_table
from .space import Parameter, ParameterSpace, parse_space

__all__ = ["CalibrationResult", "Parameter", "ParameterSpace", "calibrate", "convergence_table", "parse_space"]
