"""ISO 6946:2017 thermal resistance and thermal transmittance of a layered wall.

Only thermally homogeneous layers (clauses 6.7 to 6.9 of the standard) are
covered: the layer resistances d / lambda, the conventional surface
resistances, and air layers (unventilated, slightly ventilated, well
ventilated). Inhomogeneous layers (upper/lower limit method), corrections for
air voids, fasteners and inverted roofs are not implemented.

Conventions
-----------
- Layers are read from a :class:`wallcal.wall.Wall`, **exterior first**.
- Resistances in [m2K/W], thicknesses in [m], U in [W/(m2K)].
- Heat-flow direction is one of ``"upward"``, ``"horizontal"``, ``"downward"``
  (the standard's "horizontal" column applies to heat flow within +-30 deg of the
  horizontal plane, i.e. walls).

Air layers
----------
A layer is treated as an ISO 6946 air layer when

- its id is a key of the ``air_layers`` argument, e.g.
  ``air_layers={"2": "slightly_ventilated"}``; or
- ``air_layers`` is None (the default) and the layer's ``material`` text
  contains the word "air" (e.g. ``"Air gap, slightly ventilated"``). Its
  ventilation is then read from the same text ("unventilated",
  "slightly ventilated", "well ventilated"); if the text does not say, a
  :class:`~wallcal.errors.StudyError` asks for ``air_layers``.

Pass ``air_layers={}`` to switch the detection off (layers then count with
their own ``thermal_resistance`` or ``thickness / conductivity``). An air
layer's own conductivity / thermal_resistance is ignored: its resistance comes
from the standard's table and its thickness.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..errors import StudyError, closest

#: Heat-flow directions accepted by the functions of this module.
DIRECTIONS = ("upward", "horizontal", "downward")

#: Conventional interior surface resistances Rsi [m2K/W], ISO 6946:2017 Table 7.
SURFACE_RESISTANCE_INTERIOR = {"upward": 0.10, "horizontal": 0.13, "downward": 0.17}

#: Conventional exterior surface resistance Rse [m2K/W], ISO 6946:2017 Table 7 (all directions).
SURFACE_RESISTANCE_EXTERIOR = 0.04

#: Thicknesses [mm] of ISO 6946:2017 Table 8 (unventilated air layers, high-emissivity surfaces).
AIR_LAYER_THICKNESS_MM = (0.0, 5.0, 7.0, 10.0, 15.0, 25.0, 50.0, 100.0, 300.0)

#: Thermal resistance [m2K/W] of unventilated air layers, ISO 6946:2017 Table 8, by heat-flow
#: direction. Valid for surfaces of emissivity >= 0.8; intermediate values by linear interpolation.
AIR_LAYER_RESISTANCE = {
    "upward": (0.00, 0.11, 0.13, 0.15, 0.16, 0.16, 0.16, 0.16, 0.16),
    "horizontal": (0.00, 0.11, 0.13, 0.15, 0.17, 0.18, 0.18, 0.18, 0.18),
    "downward": (0.00, 0.11, 0.13, 0.15, 0.17, 0.19, 0.21, 0.22, 0.23),
}

#: Ventilation states, with accepted aliases.
VENTILATION = {
    "unventilated": "unventilated",
    "un": "unventilated",
    "none": "unventilated",
    "slightly": "slightly_ventilated",
    "slightly_ventilated": "slightly_ventilated",
    "slightly ventilated": "slightly_ventilated",
    "well": "well_ventilated",
    "well_ventilated": "well_ventilated",
    "well ventilated": "well_ventilated",
}

#: ISO 6946:1996 5.3.3 cap on the resistance between a slightly ventilated air layer
#: and the external environment [m2K/W] (used with the "half" rule).
SLIGHTLY_VENTILATED_EXTERIOR_CAP = 0.15

_AIR_WORD = re.compile(r"\bair\b", re.IGNORECASE)


def _check_direction(direction: str) -> str:
    if direction not in DIRECTIONS:
        raise StudyError([f"direction: unknown heat-flow direction {direction!r}; {closest(direction, DIRECTIONS)}"])
    return direction


def normalize_ventilation(ventilation: str, where: str = "ventilation") -> str:
    """Canonical ventilation name: 'unventilated', 'slightly_ventilated' or 'well_ventilated'.

    Parameters
    ----------
    ventilation : str
        One of the keys of :data:`VENTILATION` (e.g. ``"slightly"``).
    where : str
        Argument path used in the error message.
    """
    key = str(ventilation).strip().lower().replace("-", "_")
    if key in VENTILATION:
        return VENTILATION[key]
    key = key.replace("_", " ")
    if key in VENTILATION:
        return VENTILATION[key]
    raise StudyError([f"{where}: unknown ventilation {ventilation!r}; {closest(str(ventilation), VENTILATION)}"])


def surface_resistances(direction: str = "horizontal") -> tuple[float, float]:
    """Conventional surface resistances (ISO 6946:2017 Table 7).

    Parameters
    ----------
    direction : {"upward", "horizontal", "downward"}
        Direction of heat flow.

    Returns
    -------
    (rsi, rse) : tuple of float
        Interior and exterior surface resistances [m2K/W]: Rsi 0.10 / 0.13 / 0.17,
        Rse 0.04.
    """
    _check_direction(direction)
    return SURFACE_RESISTANCE_INTERIOR[direction], SURFACE_RESISTANCE_EXTERIOR


def unventilated_air_layer_resistance(thickness_m, direction: str = "horizontal"):
    """Thermal resistance of an unventilated air layer (ISO 6946:2017 Table 8).

    Linear interpolation in the table (the standard allows it for intermediate
    thicknesses). The table holds for high-emissivity surfaces (epsilon >= 0.8) and
    thicknesses up to 300 mm.

    Parameters
    ----------
    thickness_m : float or array
        Air layer thickness [m], 0 <= d <= 0.3.
    direction : {"upward", "horizontal", "downward"}
        Direction of heat flow.

    Returns
    -------
    float or array
        Thermal resistance [m2K/W].
    """
    _check_direction(direction)
    d_mm = np.asarray(thickness_m, dtype=float) * 1000.0
    if np.any(~np.isfinite(d_mm)) or np.any(d_mm < 0) or np.any(d_mm > AIR_LAYER_THICKNESS_MM[-1] + 1e-9):
        raise StudyError([f"thickness_m: an ISO 6946 air layer must be 0 to 0.3 m thick, got {thickness_m!r}"])
    r = np.interp(d_mm, AIR_LAYER_THICKNESS_MM, AIR_LAYER_RESISTANCE[direction])
    return float(r) if np.ndim(r) == 0 else r


def air_layer_resistance(thickness_m: float, ventilation: str = "unventilated", direction: str = "horizontal"):
    """Thermal resistance of the air layer alone [m2K/W].

    Parameters
    ----------
    thickness_m : float
        Thickness [m].
    ventilation : str
        ``"unventilated"`` (Table 8), ``"slightly_ventilated"`` (half the Table 8
        value: the ISO 6946:1996 5.3.3 rule; see :func:`thermal_resistance` for the
        opening-area interpolation of ISO 6946:2007/2017, which needs the whole wall),
        or ``"well_ventilated"`` (returns 0.0: the layer and everything outside it
        are ignored, which only :func:`thermal_resistance` can do).
    direction : {"upward", "horizontal", "downward"}

    Returns
    -------
    float
    """
    v = normalize_ventilation(ventilation)
    r_u = unventilated_air_layer_resistance(thickness_m, direction)
    if v == "unventilated":
        return r_u
    if v == "slightly_ventilated":
        return 0.5 * r_u
    return 0.0


@dataclass(frozen=True)
class LayerResistance:
    """One line of a resistance breakdown.

    Attributes
    ----------
    id : str
        Layer id (``"<id>/contact"`` for a contact resistance).
    resistance : float
        Resistance counted in the total [m2K/W].
    kind : str
        ``"material"``, ``"no-mass"``, ``"contact"``, ``"air:<ventilation>"`` or
        ``"ignored"`` (outside a well-ventilated air layer).
    """

    id: str
    resistance: float
    kind: str


@dataclass(frozen=True)
class ResistanceResult:
    """ISO 6946 result for a wall.

    Attributes
    ----------
    rsi, rse : float
        Surface resistances used [m2K/W] (``rse`` equals ``rsi`` outside a
        well-ventilated air layer).
    layers : tuple of LayerResistance
        Breakdown, exterior first.
    resistance : float
        Surface-to-surface resistance R, sum of the counted layers [m2K/W].
    total_resistance : float
        R_T = Rsi + R + Rse [m2K/W].
    u_value : float
        U = 1 / R_T [W/(m2K)].
    notes : tuple of str
        Which rules were applied.
    """

    rsi: float
    rse: float
    layers: tuple[LayerResistance, ...]
    resistance: float
    total_resistance: float
    u_value: float
    notes: tuple[str, ...] = ()


def _ventilation_from_text(text: str) -> str | None:
    t = text.lower().replace("-", " ").replace("_", " ")
    if "well ventilated" in t:
        return "well_ventilated"
    if "slightly ventilated" in t:
        return "slightly_ventilated"
    if "unventilated" in t or "not ventilated" in t or "still air" in t:
        return "unventilated"
    return None


def find_air_layers(wall, air_layers: Mapping[str, str] | None = None) -> dict[str, str]:
    """Which layers of ``wall`` are ISO 6946 air layers, and their ventilation.

    Parameters
    ----------
    wall : Wall
    air_layers : mapping of layer id to ventilation, or None
        Explicit choice (e.g. ``{"2": "slightly_ventilated"}``). None: detect layers
        whose ``material`` contains the word "air" and read their ventilation from
        that text. ``{}``: no air layers.

    Returns
    -------
    dict
        Layer id -> canonical ventilation.
    """
    ids = [layer.id for layer in wall.layers]
    problems: list[str] = []
    out: dict[str, str] = {}
    if air_layers is not None:
        for key, vent in air_layers.items():
            if key not in ids:
                problems.append(f"air_layers[{key!r}]: no layer with this id; {closest(str(key), ids)}")
                continue
            try:
                out[key] = normalize_ventilation(vent, where=f"air_layers[{key!r}]")
            except StudyError as exc:
                problems.extend(exc.problems)
    else:
        for layer in wall.layers:
            if _AIR_WORD.search(layer.material or ""):
                vent = _ventilation_from_text(layer.material)
                if vent is None:
                    problems.append(
                        f"wall.layers[{layer.id!r}]: material {layer.material!r} looks like an air layer but "
                        "does not say its ventilation; pass air_layers={"
                        f"{layer.id!r}: 'unventilated' | 'slightly_ventilated' | 'well_ventilated'}} "
                        "(or air_layers={} to treat it as an ordinary layer)"
                    )
                else:
                    out[layer.id] = vent
    for key in out:
        layer = wall.layers[wall.layer_index(key)]
        if not (0.0 < layer.thickness <= 0.3):
            problems.append(
                f"air_layers[{key!r}]: an ISO 6946 air layer must be > 0 and <= 0.3 m thick, "
                f"got thickness {layer.thickness!r} m"
            )
    if problems:
        raise StudyError(problems)
    return out


def _material_resistance(layer, mean_temperature_C):
    if layer.is_massless:
        return float(layer.thermal_resistance), "no-mass"
    if mean_temperature_C is None:
        return layer.resistance, "material"
    return layer.thickness / float(layer.conductivity_at(mean_temperature_C)), "material"


def thermal_resistance(
    wall,
    *,
    air_layers: Mapping[str, str] | None = None,
    direction: str = "horizontal",
    rsi: float | None = None,
    rse: float | None = None,
    opening_area_mm2_per_m: float | None = None,
    mean_temperature_C: float | None = None,
) -> ResistanceResult:
    """Total thermal resistance and U-value of a wall of homogeneous layers (ISO 6946:2017).

    R_T = Rsi + sum_j R_j + Rse (ISO 6946:2017 eq. 7), R_j = d_j / lambda_j for a
    material layer (eq. 6), contact resistances of the wall included, air layers
    from Table 8, and U = 1 / R_T (eq. 8).

    Air layers:

    - unventilated: Table 8, interpolated in thickness;
    - slightly ventilated: without ``opening_area_mm2_per_m``, half the Table 8
      value, and the resistance of everything between the air layer and the
      exterior (layers + Rse) capped at 0.15 m2K/W (ISO 6946:1996 5.3.3). With
      ``opening_area_mm2_per_m`` = A_v (500 < A_v <= 1500 mm2 per m of length for
      vertical layers), the ISO 6946:2007/2017 interpolation
      R_T = (1500 - A_v)/1000 R_T,u + (A_v - 500)/1000 R_T,v between the
      unventilated (R_T,u) and well-ventilated (R_T,v) totals;
    - well ventilated: the air layer and all layers between it and the exterior
      are ignored and Rse is replaced by Rsi (the value for ``direction``).

    Parameters
    ----------
    wall : Wall
        Layers exterior first.
    air_layers : mapping of str to str, optional
        Layer id -> ventilation; see :func:`find_air_layers`.
    direction : {"upward", "horizontal", "downward"}
        Heat-flow direction (walls: horizontal).
    rsi, rse : float, optional
        Override the conventional surface resistances [m2K/W].
    opening_area_mm2_per_m : float, optional
        A_v of the slightly ventilated air layer [mm2 per m length (vertical) or per m2].
    mean_temperature_C : float, optional
        Evaluate each conductivity at this temperature [degC] (``Layer.conductivity_at``);
        default: each layer's declared value.

    Returns
    -------
    ResistanceResult
    """
    _check_direction(direction)
    rsi_d, rse_d = surface_resistances(direction)
    rsi = rsi_d if rsi is None else float(rsi)
    rse = rse_d if rse is None else float(rse)
    if rsi < 0 or rse < 0:
        raise StudyError([f"rsi, rse: surface resistances must be >= 0, got rsi={rsi!r}, rse={rse!r}"])
    air = find_air_layers(wall, air_layers)
    well = [i for i, layer in enumerate(wall.layers) if air.get(layer.id) == "well_ventilated"]
    slight = [i for i, layer in enumerate(wall.layers) if air.get(layer.id) == "slightly_ventilated"]
    if opening_area_mm2_per_m is not None:
        av = float(opening_area_mm2_per_m)
        if len(slight) != 1:
            raise StudyError(
                [f"opening_area_mm2_per_m: needs exactly one slightly ventilated air layer, found {len(slight)}"]
            )
        if av <= 500.0:
            air[wall.layers[slight[0]].id] = "unventilated"
        elif av > 1500.0:
            air[wall.layers[slight[0]].id] = "well_ventilated"
        else:
            r_u = thermal_resistance(
                wall,
                air_layers={**air, wall.layers[slight[0]].id: "unventilated"},
                direction=direction,
                rsi=rsi,
                rse=rse,
                mean_temperature_C=mean_temperature_C,
            )
            r_v = thermal_resistance(
                wall,
                air_layers={**air, wall.layers[slight[0]].id: "well_ventilated"},
                direction=direction,
                rsi=rsi,
                rse=rse,
                mean_temperature_C=mean_temperature_C,
            )
            r_t = (1500.0 - av) / 1000.0 * r_u.total_resistance + (av - 500.0) / 1000.0 * r_v.total_resistance
            return ResistanceResult(
                rsi=rsi,
                rse=rse,
                layers=r_u.layers,
                resistance=r_t - rsi - rse,
                total_resistance=r_t,
                u_value=1.0 / r_t,
                notes=(
                    f"slightly ventilated air layer {wall.layers[slight[0]].id!r}: ISO 6946:2017 "
                    f"interpolation with A_v = {av:g} mm2/m between R_T,u = {r_u.total_resistance:.4f} and "
                    f"R_T,v = {r_v.total_resistance:.4f} m2K/W",
                ),
            )
        return thermal_resistance(
            wall, air_layers=air, direction=direction, rsi=rsi, rse=rse, mean_temperature_C=mean_temperature_C
        )

    notes: list[str] = []
    start = 0
    if well:
        start = max(well) + 1
        rse = rsi
        notes.append(
            f"well ventilated air layer {wall.layers[max(well)].id!r}: it and the layers outside it ignored, "
            f"Rse = Rsi = {rsi:g} m2K/W"
        )
    breakdown: list[LayerResistance] = []
    for i, layer in enumerate(wall.layers):
        if i < start:
            breakdown.append(LayerResistance(layer.id, 0.0, "ignored"))
            continue
        vent = air.get(layer.id)
        if vent is not None:
            r = air_layer_resistance(layer.thickness, vent, direction)
            breakdown.append(LayerResistance(layer.id, r, f"air:{vent}"))
        else:
            r, kind = _material_resistance(layer, mean_temperature_C)
            breakdown.append(LayerResistance(layer.id, r, kind))
        if layer.contact_resistance and i < len(wall.layers) - 1:
            breakdown.append(LayerResistance(f"{layer.id}/contact", float(layer.contact_resistance), "contact"))

    if slight:
        if len(slight) > 1:
            raise StudyError([f"air_layers: {len(slight)} slightly ventilated air layers; ISO 6946 treats one"])
        k = slight[0]
        lid = wall.layers[k].id
        notes.append(f"slightly ventilated air layer {lid!r}: half the Table 8 value (ISO 6946:1996 5.3.3 rule)")
        # resistance between the air layer and the external environment (exterior layers + Rse)
        ids_outside = {layer.id for layer in wall.layers[:k]}
        outside = [b for b in breakdown if b.id.split("/")[0] in ids_outside]
        r_out = sum(b.resistance for b in outside) + rse
        if r_out > SLIGHTLY_VENTILATED_EXTERIOR_CAP:
            if SLIGHTLY_VENTILATED_EXTERIOR_CAP < rse:
                raise StudyError([f"rse: {rse!r} m2K/W exceeds the 0.15 m2K/W cap of a slightly ventilated layer"])
            # here rse <= cap < r_out, so the layers outside have a resistance > 0 to scale down
            scale = (SLIGHTLY_VENTILATED_EXTERIOR_CAP - rse) / (r_out - rse)
            breakdown = [
                LayerResistance(b.id, b.resistance * scale, b.kind + "(capped)") if b in outside else b
                for b in breakdown
            ]
            notes.append(
                f"resistance between air layer {lid!r} and the exterior {r_out:.4f} m2K/W capped at "
                f"{SLIGHTLY_VENTILATED_EXTERIOR_CAP} m2K/W (ISO 6946:1996 5.3.3)"
            )
    resistance = float(sum(b.resistance for b in breakdown))
    r_t = rsi + resistance + rse
    return ResistanceResult(
        rsi=rsi,
        rse=rse,
        layers=tuple(breakdown),
        resistance=resistance,
        total_resistance=r_t,
        u_value=1.0 / r_t,
        notes=tuple(notes),
    )


def u_value(wall, **kwargs) -> float:
    """Thermal transmittance U = 1 / R_T [W/(m2K)] (ISO 6946:2017 eq. 8).

    Keyword arguments are those of :func:`thermal_resistance`.
    """
    return thermal_resistance(wall, **kwargs).u_value


def resolve_layers(wall, *, air_layers: Mapping[str, str] | None = None, direction: str = "horizontal"):
    """The wall as ISO 13786 sees it: air layers replaced by their ISO 6946 resistance.

    Parameters
    ----------
    wall : Wall
    air_layers : mapping, optional
        See :func:`find_air_layers`.
    direction : str
        Heat-flow direction for the air-layer table.

    Returns
    -------
    layers : list of Layer
        The layers kept (exterior first); air layers turned into no-mass layers
        with their ISO 6946 resistance (slightly ventilated: half Table 8).
    exterior_is_ventilated : bool
        True when a well-ventilated air layer cut the wall (then Rse = Rsi).
    """
    air = find_air_layers(wall, air_layers)
    layers = list(wall.layers)
    cut = False
    well = [i for i, layer in enumerate(layers) if air.get(layer.id) == "well_ventilated"]
    if well:
        layers = layers[max(well) + 1 :]
        cut = True
    out = []
    for layer in layers:
        vent = air.get(layer.id)
        if vent is None:
            out.append(layer)
        else:
            r = air_layer_resistance(layer.thickness, vent, direction)
            out.append(layer.replace(thermal_resistance=r, conductivity=None, density=None, specific_heat=None))
    return out, cut
