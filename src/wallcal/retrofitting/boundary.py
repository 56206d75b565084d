"""Boundary conditions of a retrofit run: the one place that turns weather and face parameters into the
engine's boundary inputs.

Exterior face: the sol-air (equivalent) temperature of ISO 52016-1 / ISO 13790, imposed through the
engine's ``sol_air_temperature`` boundary type (a Robin face, :mod:`wallcal.engines.boundary`) with the
combined coefficient h_e::

    T_eq = T_e + (alpha_s I_sol - F_sky h_r (T_e - T_sky)) / h_e
    F_sky = (1 + cos(tilt)) / 2          (1/2 for a vertical wall; the other half sees the ground,
                                          taken at air temperature)
    h_r = 4 eps sigma T_m^3,  T_m = (T_e + T_sky) / 2 [K]

so that q_e = h_e (T_eq - T_se) = h_e (T_e - T_se) + alpha_s I_sol - F_sky h_r (T_e - T_sky): convection and
long-wave exchange with air-temperature surroundings are inside h_e (ISO 6946's Rse = 1/h_e), the sky's
deficit below air temperature is the extra term (h_r evaluated at air and sky temperature, not at the
unknown surface temperature: the linearisation of ISO 13790 11.4.6). Interior face: air at a constant
temperature with h_i.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..engines.base import BoundaryInput
from ..errors import StudyError
from ..weather import SIGMA, Weather, plane_irradiance, sky_temperature


def sol_air_temperature(
    temp_air,
    irradiance,
    temp_sky,
    *,
    solar_absorptance: float,
    exterior_surface_coefficient: float,
    sky_radiation: bool = True,
    thermal_emissivity: float = 0.9,
    tilt: float = 90.0,
):
    """Sol-air temperature T_eq [degC] (module docstring).

    Parameters
    ----------
    temp_air : array
        Exterior air temperature T_e [degC].
    irradiance : array
        Global irradiance on the wall's plane I_sol [W/m2].
    temp_sky : array
        Apparent sky temperature [degC] (ignored when ``sky_radiation`` is false).
    solar_absorptance : float
        alpha_s [-].
    exterior_surface_coefficient : float
        h_e [W/(m2K)], convective plus radiative.
    sky_radiation : bool
        Include the long-wave deficit of the sky.
    thermal_emissivity : float
        eps [-].
    tilt : float
        Degrees from horizontal (90 = vertical).
    """
    t_e = np.asarray(temp_air, dtype=float)
    extra = solar_absorptance * np.asarray(irradiance, dtype=float)
    if sky_radiation:
        t_sky = np.asarray(temp_sky, dtype=float)
        f_sky = 0.5 * (1.0 + math.cos(math.radians(tilt)))
        t_m = 0.5 * (t_e + t_sky) + 273.15
        h_r = 4.0 * thermal_emissivity * SIGMA * t_m**3
        extra = extra - f_sky * h_r * (t_e - t_sky)
    return t_e + extra / exterior_surface_coefficient


@dataclass(frozen=True)
class YearBoundaries:
    """Boundary inputs over one weather period on the engine grid, and the hourly series behind them.

    ``exterior`` / ``interior``: :class:`BoundaryInput` with ``n_steps + 1`` values at ``k * time_step``
    from the start of the file's first hour; the last value equals the first (the period closes).
    ``hourly``: series at the hour marks 0..N (N = hours in the file): air temperature, plane irradiance and
    sky temperature (each hour's value spread half onto each of its two marks), sol-air temperature.
    """

    exterior: BoundaryInput
    interior: BoundaryInput
    time_step: float
    hours: int
    hourly: dict

    @property
    def n_steps(self) -> int:
        return len(self.exterior.values) - 1


def _marks_from_means(x: np.ndarray) -> np.ndarray:
    """Hour-mean values (hour k from k to k+1) -> values at the marks 0..N, periodic, whose trapezoid sum
    equals the sum of the means."""
    return 0.5 * (np.concatenate([[x[-1]], x]) + np.concatenate([x, [x[0]]]))


def year_boundaries(weather: Weather, spec, time_step: float | None = None) -> YearBoundaries:
    """The exterior (sol-air) and interior boundary inputs of a retrofit run over the weather period.

    Parameters
    ----------
    weather : Weather
    spec : RetrofitSpec
        Face parameters (absorptance, sky radiation, h_e, emissivity, albedo, azimuth; T_i, h_i).
    time_step : float, optional
        Engine step [s] (a divisor of 3600); default ``spec.time_step``.

    The air temperature of EPW row k is the value at the end of hour k, so at mark k + 1 (mark 0 takes the
    last row: the period closes). The radiative term of each hour (plane irradiance and sky from the hour's
    fields, air temperature at the hour's middle) is spread onto the marks by :func:`_marks_from_means`, so
    that the energy it brings over the year is kept exactly. Between marks the engine grid is linear.
    """
    dt = float(spec.time_step if time_step is None else time_step)
    if not (dt > 0 and math.isfinite(dt)) or abs(3600.0 / dt - round(3600.0 / dt)) > 1e-9:
        raise StudyError([f"retrofit.time_step: must be a positive divisor of 3600 s, got {dt:g}"])
    d = weather.data
    n = len(d)
    t_rows = d["temp_air"].to_numpy(dtype=float)
    t_marks = np.concatenate([[t_rows[-1]], t_rows])
    t_mid = 0.5 * (t_marks[:-1] + t_marks[1:])
    irr = (
        plane_irradiance(weather, spec.azimuth, 90.0, spec.ground_albedo) if spec.solar_absorptance > 0 else np.zeros(n)
    )
    t_sky = sky_temperature(weather) if spec.sky_radiation else np.full(n, np.nan)
    t_eq_mid = sol_air_temperature(
        t_mid,
        irr,
        t_sky,
        solar_absorptance=spec.solar_absorptance,
        exterior_surface_coefficient=spec.exterior_surface_coefficient,
        sky_radiation=spec.sky_radiation,
        thermal_emissivity=spec.thermal_emissivity,
    )
    extra_marks = _marks_from_means(t_eq_mid - t_mid)
    t_eq_marks = t_marks + extra_marks
    per_hour = int(round(3600.0 / dt))
    grid_h = np.arange(n * per_hour + 1) / per_hour
    marks = np.arange(n + 1, dtype=float)
    ext = BoundaryInput("sol_air_temperature", np.interp(grid_h, marks, t_eq_marks), spec.exterior_surface_coefficient)
    intr = BoundaryInput(
        "air_temperature", np.full(len(grid_h), float(spec.interior_temperature)), spec.interior_surface_coefficient
    )
    hourly = {
        "temp_air": t_marks,
        "plane_irradiance": _marks_from_means(irr),
        "temp_sky": _marks_from_means(t_sky) if spec.sky_radiation else np.full(n + 1, np.nan),
        "sol_air_temperature": t_eq_marks,
    }
    return YearBoundaries(exterior=ext, interior=intr, time_step=dt, hours=n, hourly=hourly)
