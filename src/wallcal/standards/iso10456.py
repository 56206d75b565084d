"""ISO 10456 conversion of a thermal conductivity between temperatures.

ISO 10456:2007, clause 7 (eq. 3 and 4): a declared value lambda_1 at mean
temperature T_1 converts to lambda_2 at T_2 with the temperature factor

    F_T = exp(f_T * (T_2 - T_1))

where f_T [1/K] is the material's temperature conversion coefficient (its
Table 4 gives e.g. 0.0046 1/K for mineral wool). wallcal's lambda(T) model in the
engine is this same function: lambda(T) = conductivity * F_T(T - reference_temperature).
"""

from __future__ import annotations

import numpy as np

from ..conductivity import exponential_factor


def temperature_factor(coefficient_per_K, delta_T_K):
    """Temperature conversion factor F_T = exp(f_T * dT).

    Parameters
    ----------
    coefficient_per_K : float or array
        Temperature conversion coefficient f_T [1/K].
    delta_T_K : float or array
        Temperature difference T_2 - T_1 [K].

    Returns
    -------
    float or array
        F_T [-].
    """
    return exponential_factor(np.asarray(coefficient_per_K), np.asarray(delta_T_K))


def convert_conductivity(conductivity, from_temperature_C, to_temperature_C, coefficient_per_K):
    """Convert a conductivity between mean temperatures (ISO 10456 eq. 3-4).

    Parameters
    ----------
    conductivity : float or array
        Conductivity at ``from_temperature_C`` [W/(m K)].
    from_temperature_C, to_temperature_C : float
        Mean temperatures [degC].
    coefficient_per_K : float
        Temperature conversion coefficient f_T [1/K].

    Returns
    -------
    float or array
        Conductivity at ``to_temperature_C`` [W/(m K)].
    """
    out = np.asarray(conductivity, dtype=float) * temperature_factor(
        coefficient_per_K, np.asarray(to_temperature_C) - np.asarray(from_temperature_C)
    )
    return float(out) if np.ndim(out) == 0 else out
