"""The lambda(T) law, in one place.

A layer's conductivity at temperature T [degC] is ``lambda(T) = conductivity * exp(f (T - T_ref))``
(ISO 10456 clause 7's temperature factor F_T, :mod:`wallcal.standards.iso10456`), with ``f`` the layer's
``conductivity_temperature_coefficient`` [1/K] and ``T_ref`` its ``reference_temperature`` [degC]; or a
table of (T, lambda) points, piecewise linear and constant beyond its ends, scaled so that a calibrated
``conductivity`` holds at ``T_ref``.

:func:`exponential_factor` is the law's factor ``exp(f dT)``; ``exponential_factor_inner`` is the same
function compiled for the numba kernels (:func:`wallcal.jit.inner`, made when the kernels import it), so
Python code and the kernels evaluate one formula. :func:`conductivity` is the whole law (exponential or
table) on numpy arrays.
"""

from __future__ import annotations

import numpy as np


def exponential_factor(coefficient, delta_T):
    """``exp(f dT)`` [-]: lambda(T) / lambda(T_ref) of the exponential law, ``coefficient`` f [1/K] and
    ``delta_T`` = T - T_ref [K] (floats or arrays)."""
    return np.exp(coefficient * delta_T)


def __getattr__(name: str):
    # exponential_factor_inner: exponential_factor compiled for the kernels, made on first use so that
    # importing this module (the wall, the study) does not import numba
    if name == "exponential_factor_inner":
        from .jit import inner

        globals()[name] = compiled = inner()(exponential_factor)
        return compiled
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def conductivity(conductivity_ref, coefficient, reference_temperature, temperature, table=None):
    """lambda(T) [W/(m K)] (arrays broadcast).

    Parameters
    ----------
    conductivity_ref : float or array
        Conductivity at the reference temperature [W/(m K)] (None with a table: the table's own values).
    coefficient : float or array
        Exponential coefficient f [1/K] (ignored with a table).
    reference_temperature : float or array
        T_ref [degC].
    temperature : float or array
        T [degC].
    table : array, shape (n, 2), optional
        (T [degC], lambda [W/(m K)]) points, increasing in T.
    """
    temperature = np.asarray(temperature, dtype=float)
    if table is not None:
        tab = np.asarray(table, dtype=float)
        lam = np.interp(temperature, tab[:, 0], tab[:, 1])
        if conductivity_ref is None:
            return lam
        return lam * conductivity_ref / np.interp(reference_temperature, tab[:, 0], tab[:, 1])
    return conductivity_ref * exponential_factor(
        np.asarray(coefficient, dtype=float), temperature - reference_temperature
    )
