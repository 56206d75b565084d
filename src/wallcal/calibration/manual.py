"""Manual calibration helpers (the study's second route).

:func:`convert_conductivities` moves declared conductivities from their declared
temperature (usually 10 degC) to the temperature the wall actually had during the
campaign, with the ISO 10456 exponential factor (:mod:`wallcal.standards.iso10456`,
the same law as the engine's lambda(T)). :func:`layer_mean_temperatures` gives that
temperature per layer from the measurements: the time-mean measured profile
(surface temperatures and probes, linear in depth between them) at each layer's
mid-depth over the comparison period.
"""

from __future__ import annotations

import numpy as np

from ..errors import StudyError
from ..standards.iso10456 import convert_conductivity
from ..wall import Wall


def layer_mean_temperatures(study, measurements=None) -> dict[str, float]:
    """Mean temperature [degC] of every layer over the comparison period, from the measurements.

    Needs surface-temperature boundaries (both faces) or probes that bracket the layers; layers
    outside the measured span take the nearest measured value.
    """
    from ..data import load_measurements

    meas = measurements or load_measurements(study)
    f = meas.frame.loc[str(study.period.start) : str(study.period.end)]
    depths, temps = [], []
    if study.exterior.type == "surface_temperature":
        depths.append(0.0)
        temps.append(float(np.nanmean(f["exterior"])))
    if study.interior.type == "surface_temperature":
        depths.append(study.wall.thickness)
        temps.append(float(np.nanmean(f["interior"])))
    for s in study.sensors:
        if s.quantity == "temperature":
            depths.append(study.wall.probe(s.name).depth)
            temps.append(float(np.nanmean(f[s.name])))
    if not depths:
        raise StudyError(["no measured temperature in the wall: give --temperature"])
    order = np.argsort(depths)
    d, t = np.asarray(depths)[order], np.asarray(temps)[order]
    x = study.wall.interfaces
    return {layer.id: float(np.interp(0.5 * (x[i] + x[i + 1]), d, t)) for i, layer in enumerate(study.wall.layers)}


def convert_conductivities(
    wall: Wall,
    temperatures: dict[str, float] | float,
    *,
    coefficients: dict[str, float] | float | None = None,
    layers: list[str] | None = None,
) -> Wall:
    """Conductivities converted from each layer's ``reference_temperature`` to ``temperatures``.

    Parameters
    ----------
    wall : Wall
    temperatures : float or dict
        Target temperature [degC], one for all layers or per layer id.
    coefficients : float or dict, optional
        Temperature conversion coefficient f_T [1/K] (ISO 10456; e.g. 0.0046 for mineral wool),
        one for all or per layer id; default each layer's ``conductivity_temperature_coefficient``.
    layers : list of str, optional
        Layer ids to convert; default every layer with a non-zero coefficient.

    Returns
    -------
    Wall
        The converted conductivities now hold at the new ``reference_temperature`` of each layer.
    """
    ids = [layer.id for layer in wall.layers]
    for lid in layers or []:
        if lid not in ids:
            from ..errors import closest

            raise StudyError([f"layers: {lid!r} is not a layer id; {closest(lid, ids)}"])
    out = wall
    for layer in wall.layers:
        if layer.is_massless or (layers is not None and layer.id not in layers):
            continue
        if isinstance(coefficients, dict):
            f = coefficients.get(layer.id, layer.conductivity_temperature_coefficient)
        elif coefficients is not None:
            f = float(coefficients)
        else:
            f = layer.conductivity_temperature_coefficient
        if f == 0.0 and layers is None:
            continue
        t_new = temperatures[layer.id] if isinstance(temperatures, dict) else float(temperatures)
        lam = convert_conductivity(
            layer.conductivity_at(layer.reference_temperature), layer.reference_temperature, t_new, f
        )
        out = out.replace_layer(
            layer.id,
            conductivity=float(lam),
            reference_temperature=float(t_new),
            conductivity_temperature_coefficient=layer.conductivity_temperature_coefficient,
            conductivity_table=None if layer.conductivity_table is None else layer.conductivity_table,
        )
    return out
