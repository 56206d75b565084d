"""Write a wall as EnergyPlus (25.2) input objects.

This is the one place in wallcal that writes EnergyPlus materials: the
EnergyPlus engine (:mod:`wallcal.engines.energyplus`) builds its construction
with :func:`wall_to_idf_objects`, and users can paste the exported objects into
their own building models.

Mapping
-------
- a layer with mass -> ``Material`` (thickness [m], conductivity at the
  layer's reference temperature [W/(m K)], density [kg/m3], specific heat
  [J/(kg K)]);
- a no-mass resistive layer (``Layer.thermal_resistance``) -> ``Material:NoMass``;
- a contact resistance between two layers -> a thin ``Material:NoMass`` layer
  (``Material:AirGap`` below EnergyPlus' 0.001 m2K/W minimum for
  ``Material:NoMass``; both are pure resistances in CondFD);
- lambda(T) (exponential ISO 10456 law or a table) ->
  ``MaterialProperty:VariableThermalConductivity`` (at most 10 points, linear
  interpolation between them in EnergyPlus);
- the finite-difference settings -> ``HeatBalanceSettings:ConductionFiniteDifference``.

EnergyPlus builds its CondFD grid from the ``Material`` conductivity, i.e.
lambda at the layer's reference temperature.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import EngineError
from .wall import Layer, Wall

#: EnergyPlus' limit on the points of MaterialProperty:VariableThermalConductivity.
MAX_CONDUCTIVITY_POINTS = 10
#: EnergyPlus' minimum thermal resistance of Material:NoMass [m2K/W].
NOMASS_MIN_RESISTANCE = 0.001
#: Default temperature range [degC] over which an exponential lambda(T) law is tabulated.
DEFAULT_TEMPERATURE_RANGE = (-20.0, 70.0)

_SCHEMES = {"cn": "CrankNicholsonSecondOrder", "implicit": "FullyImplicitFirstOrder"}


def idf_object(kind: str, fields: list[tuple[object, str]]) -> str:
    """Format one IDF object with one commented field per line.

    Parameters
    ----------
    kind : str
        Object class, e.g. ``"Material"``.
    fields : list of (value, comment)
        Field values (numbers are written with 10 significant digits) and
        their IDD field names.

    Returns
    -------
    str
        The object text, ending with a newline.
    """
    lines = [f"{kind},"]
    for i, (value, comment) in enumerate(fields):
        text = _fmt(value)
        end = ";" if i == len(fields) - 1 else ","
        lines.append(f"    {text + end:<28} !- {comment}")
    return "\n".join(lines) + "\n"


def _fmt(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "Yes" if value else "No"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return f"{float(value):.10g}"
    return str(value)


def material_names(wall: Wall, prefix: str) -> list[str]:
    """Names of the EnergyPlus materials of ``wall``, outside first (contact layers included).

    Parameters
    ----------
    wall : Wall
    prefix : str
        Prefix making the names unique in a model.

    Returns
    -------
    list of str
    """
    names = []
    for i, layer in enumerate(wall.layers):
        names.append(f"{prefix}L{layer.id}")
        if layer.contact_resistance and i < len(wall.layers) - 1:
            names.append(f"{prefix}R{layer.id}_{wall.layers[i + 1].id}")
    return names


def conductivity_points(
    layer: Layer, temperature_range: tuple[float, float] = DEFAULT_TEMPERATURE_RANGE
) -> list[tuple[float, float]]:
    """(temperature [degC], conductivity [W/(m K)]) points of a lambda(T) layer for EnergyPlus.

    An exponential law is sampled at :data:`MAX_CONDUCTIVITY_POINTS` evenly spaced
    temperatures over ``temperature_range`` (EnergyPlus interpolates linearly
    between them; for f = 0.005 1/K and a 90 K range the chord error is below
    0.02 %). A table is passed through (it must have at most 10 points).

    Parameters
    ----------
    layer : Layer
        A layer with ``is_temperature_dependent``.
    temperature_range : (float, float)
        Lowest and highest temperature [degC] to tabulate an exponential law over.

    Returns
    -------
    list of (float, float)
    """
    if layer.conductivity_table is not None:
        table = [(float(t), float(k)) for t, k in layer.conductivity_table]
        if len(table) > MAX_CONDUCTIVITY_POINTS:
            raise EngineError(
                f"layer {layer.id!r}: EnergyPlus accepts at most {MAX_CONDUCTIVITY_POINTS} "
                f"(T, lambda) points in MaterialProperty:VariableThermalConductivity, the "
                f"conductivity_table has {len(table)}; resample it"
            )
        if len(table) < 2:
            raise EngineError(f"layer {layer.id!r}: conductivity_table needs at least 2 points")
        return table
    lo, hi = (float(v) for v in temperature_range)
    if not hi > lo:
        raise EngineError(f"temperature_range must be increasing, got {temperature_range}")
    temps = np.linspace(lo, hi, MAX_CONDUCTIVITY_POINTS)
    return [(float(t), float(layer.conductivity_at(t))) for t in temps]


def wall_to_idf_objects(
    wall: Wall,
    *,
    grid_constant: float = 3.0,
    scheme: str = "cn",
    name: str | None = None,
    temperature_range: tuple[float, float] = DEFAULT_TEMPERATURE_RANGE,
    inside_convergence: float | None = None,
    settings: bool = True,
) -> str:
    """EnergyPlus 25.2 objects describing ``wall`` for the CondFD algorithm.

    Parameters
    ----------
    wall : Wall
        The wall, layers from the exterior inwards.
    grid_constant : float
        Space discretisation constant C = dx^2 / (alpha dt) [-].
    scheme : str
        ``"cn"`` (CrankNicholsonSecondOrder) or ``"implicit"`` (FullyImplicitFirstOrder).
    name : str, optional
        Construction name (also the prefix of material names); defaults to the
        wall's name or ``"WALLCAL"``.
    temperature_range : (float, float)
        Range [degC] over which exponential lambda(T) laws are tabulated.
    inside_convergence : float, optional
        CondFD "Inside Face Surface Temperature Convergence Criteria" [K]
        (EnergyPlus' default 0.002 when None; 1e-7 to 0.01).
    settings : bool
        Include the ``HeatBalanceSettings:ConductionFiniteDifference`` object.

    Returns
    -------
    str
        IDF text: materials, optional variable-conductivity properties, the
        construction, and the CondFD settings.

    Raises
    ------
    EngineError
        For settings EnergyPlus cannot represent.
    """
    if scheme not in _SCHEMES:
        raise EngineError(f"scheme must be one of {sorted(_SCHEMES)}, got {scheme!r}")
    if not grid_constant > 0:
        raise EngineError(f"grid_constant must be > 0, got {grid_constant}")
    if not wall.layers:
        raise EngineError("the wall has no layers")
    cname = _safe_name(name or wall.name or "WALLCAL")
    prefix = f"{cname}_"
    names = material_names(wall, prefix)
    parts: list[str] = [f"! ---- wall {cname!r} written by wallcal ({len(wall.layers)} layers)\n"]
    props: list[str] = []
    k = 0
    for i, layer in enumerate(wall.layers):
        mname = names[k]
        k += 1
        if layer.is_massless:
            r = float(layer.thermal_resistance)
            if r < NOMASS_MIN_RESISTANCE:
                raise EngineError(
                    f"layer {layer.id!r}: EnergyPlus Material:NoMass needs a thermal resistance >= "
                    f"{NOMASS_MIN_RESISTANCE} m2K/W, got {r}"
                )
            parts.append(_nomass(mname, r, layer.material))
        else:
            if not layer.thickness > 0:
                raise EngineError(f"layer {layer.id!r}: a layer with mass needs a thickness > 0")
            lam = float(layer.conductivity_at(layer.reference_temperature))
            parts.append(
                idf_object(
                    "Material",
                    [
                        (mname, f"Name ({layer.material or 'layer ' + layer.id})"),
                        ("MediumRough", "Roughness"),
                        (float(layer.thickness), "Thickness {m}"),
                        (lam, "Conductivity {W/m-K}"),
                        (float(layer.density), "Density {kg/m3}"),
                        (float(layer.specific_heat), "Specific Heat {J/kg-K}"),
                        (0.9, "Thermal Absorptance"),
                        (0.7, "Solar Absorptance"),
                        (0.7, "Visible Absorptance"),
                    ],
                )
            )
            if layer.is_temperature_dependent:
                pts = conductivity_points(layer, temperature_range)
                fields: list[tuple[object, str]] = [(mname, "Name")]
                for j, (t, lam_j) in enumerate(pts, start=1):
                    fields.append((t, f"Temperature {j} {{C}}"))
                    fields.append((lam_j, f"Thermal Conductivity {j} {{W/m-K}}"))
                props.append(idf_object("MaterialProperty:VariableThermalConductivity", fields))
        if layer.contact_resistance and i < len(wall.layers) - 1:
            rname = names[k]
            k += 1
            rc = float(layer.contact_resistance)
            if rc < 0:
                raise EngineError(f"layer {layer.id!r}: contact_resistance must be >= 0, got {rc}")
            if rc >= NOMASS_MIN_RESISTANCE:
                parts.append(_nomass(rname, rc, f"contact {layer.id}|{wall.layers[i + 1].id}"))
            else:
                parts.append(
                    idf_object(
                        "Material:AirGap",
                        [
                            (rname, f"Name (contact {layer.id}|{wall.layers[i + 1].id})"),
                            (rc, "Thermal Resistance {m2-K/W}"),
                        ],
                    )
                )
    parts.extend(props)
    parts.append(
        idf_object(
            "Construction",
            [(cname, "Name")] + [(n, "Outside Layer" if j == 0 else f"Layer {j + 1}") for j, n in enumerate(names)],
        )
    )
    if len(names) > 10:
        raise EngineError(
            f"EnergyPlus constructions have at most 10 layers; this wall needs {len(names)} "
            "(contact resistances count as layers)"
        )
    if settings:
        parts.append(
            cfd_settings_object(grid_constant=grid_constant, scheme=scheme, inside_convergence=inside_convergence)
        )
    return "\n".join(parts)


def cfd_settings_object(
    *, grid_constant: float = 3.0, scheme: str = "cn", inside_convergence: float | None = None
) -> str:
    """The ``HeatBalanceSettings:ConductionFiniteDifference`` object.

    Parameters
    ----------
    grid_constant : float
        Space discretisation constant C [-].
    scheme : str
        ``"cn"`` or ``"implicit"``.
    inside_convergence : float, optional
        Inside-face temperature convergence criterion [K]; EnergyPlus default when None.

    Returns
    -------
    str
    """
    if scheme not in _SCHEMES:
        raise EngineError(f"scheme must be one of {sorted(_SCHEMES)}, got {scheme!r}")
    if inside_convergence is not None and not 1e-7 <= inside_convergence <= 0.01:
        raise EngineError(f"inside_convergence must be within [1e-7, 0.01] K, got {inside_convergence}")
    return idf_object(
        "HeatBalanceSettings:ConductionFiniteDifference",
        [
            (_SCHEMES[scheme], "Difference Scheme"),
            (float(grid_constant), "Space Discretization Constant"),
            (1.0, "Relaxation Factor"),
            (inside_convergence, "Inside Face Surface Temperature Convergence Criteria"),
        ],
    )


def export_idf(wall: Wall, path, **kw) -> Path:
    """Write :func:`wall_to_idf_objects` output to a file.

    Parameters
    ----------
    wall : Wall
    path : str or Path
        Output file (``.idf``).
    **kw
        Passed to :func:`wall_to_idf_objects`.

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    path.write_text(wall_to_idf_objects(wall, **kw), encoding="utf-8")
    return path


def _nomass(name: str, resistance: float, what: str) -> str:
    return idf_object(
        "Material:NoMass",
        [
            (name, f"Name ({what})" if what else "Name"),
            ("MediumRough", "Roughness"),
            (float(resistance), "Thermal Resistance {m2-K/W}"),
            (0.9, "Thermal Absorptance"),
            (0.7, "Solar Absorptance"),
            (0.7, "Visible Absorptance"),
        ],
    )


def _safe_name(name: str) -> str:
    out = "".join(c if (c.isalnum() or c in "_-.") else "_" for c in str(name))
    return out[:60] or "WALLCAL"


def epjson_schema() -> dict:
    """EnergyPlus' epJSON schema (``Energy+.schema.epJSON`` of the ``energyplus`` extra), read once."""
    global _SCHEMA
    if _SCHEMA is None:
        import json

        from .eplus import energyplus_binary

        path = energyplus_binary().parent / "Energy+.schema.epJSON"
        _SCHEMA = json.loads(path.read_text(encoding="utf-8"))
    return _SCHEMA


_SCHEMA: dict | None = None


def idf_to_epjson(text: str) -> dict:
    """IDF text -> epJSON objects ``{object type: {name: {field: value}}}``.

    Meant for the objects wallcal writes (:func:`wall_to_idf_objects`): fields are mapped by the
    schema's ``legacy_idd`` field lists (extensible groups included); numeric fields become numbers
    unless they hold a keyword (``Autosize``). A user's whole model is converted by EnergyPlus itself
    (:func:`wallcal.building.model.load_model`).

    Raises
    ------
    EngineError
        An object type the schema does not know.
    """
    props = epjson_schema()["properties"]
    by_lower = {k.lower(): k for k in props}
    out: dict[str, dict] = {}
    body = "\n".join(line.split("!", 1)[0] for line in text.splitlines())
    for chunk in body.split(";"):
        fields = [f.strip() for f in chunk.split(",")]
        if not fields or not fields[0]:
            continue
        kind = by_lower.get(fields[0].lower())
        if kind is None:
            raise EngineError(f"IDF object type {fields[0]!r} is not in the EnergyPlus 25.2 schema")
        legacy = props[kind]["legacy_idd"]
        info = legacy.get("field_info", {})
        names = legacy.get("fields", [])
        values = fields[1:]
        obj: dict = {}
        name = None
        for key, val in zip(names, values, strict=False):
            if val == "":
                continue
            if key == "name":
                name = val
                continue
            obj[key] = _epjson_value(val, info.get(key, {}).get("field_type"))
        ext = legacy.get("extensibles")
        if ext and len(values) > len(names):
            rest = values[len(names) :]
            groups = []
            for j in range(0, len(rest), len(ext)):
                g = {
                    k: _epjson_value(v, info.get(k, {}).get("field_type")) for k, v in zip(ext, rest[j:], strict=False)
                }
                groups.append({k: v for k, v in g.items() if v != ""})
            obj[legacy["extension"]] = groups
        bucket = out.setdefault(kind, {})
        bucket[name if name is not None else f"{kind} {len(bucket) + 1}"] = obj
    return out


def _epjson_value(val: str, field_type: str | None):
    if field_type == "n":
        try:
            return float(val)
        except ValueError:
            return val
    return val
