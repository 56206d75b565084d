"""The building a wall is tested in: the bundled reference building, a user's model, the wall put on its surfaces.

Models are epJSON dicts (``{object type: {name: {field: value}}}``), EnergyPlus 25.2. The wall's objects come
from :func:`wallcal.idf.wall_to_idf_objects` (the one place that writes EnergyPlus materials), converted to
epJSON by :func:`wallcal.idf.idf_to_epjson`; a user's IDF model is converted by EnergyPlus itself
(``energyplus --convert-only``).

The reference building (:func:`reference_building`, documented in docs/building.md)
----------------------------------------------------------------------------------
Data, not code: the epJSON file ``reference_building.epJSON`` beside this module.
One conditioned zone, 10 m (east-west) x 8 m (north-south) x 3 m high (floor area 80 m2, volume 240 m3),
its long faces facing north and south:

- the four exterior walls: the study's wall (net 24.0 m2 south and north, 19.2 m2 east and west);
- a window centred in each wall, window-to-wall ratio 0.2 (sill 0.9 m, 1.5 m high): simple glazing
  U 1.1 W/(m2K), solar heat gain coefficient 0.5, visible transmittance 0.7;
- a flat roof (outside first: 0.24 m mineral wool 0.035 W/(mK), 0.20 m concrete 2.0 W/(mK); U about
  0.14 W/(m2K));
- a ground floor on a ground held at 10 degC all year (outside first: 0.15 m XPS 0.035 W/(mK), 0.15 m
  concrete; U about 0.22 W/(m2K) with the surface resistances);
- internal gains 5 W/m2 of floor, all year, 30 % radiant;
- infiltration 0.3 air changes per hour, constant;
- ideal loads (``ZoneHVAC:IdealLoadsAirSystem``, no outdoor air) holding the zone air between a heating
  set-point (20 degC) and a cooling set-point (26 degC).
"""

from __future__ import annotations

import copy
import json
import tempfile
from pathlib import Path

from ..errors import DataError, EngineError, StudyError, closest
from ..idf import idf_to_epjson, wall_to_idf_objects
from ..wall import Wall

#: The construction name the wall gets in a model.
WALL_CONSTRUCTION = "WALLCAL_WALL"
#: Default zone air set-points of the reference building's ideal loads [degC].
HEATING_SETPOINT, COOLING_SETPOINT = 20.0, 26.0
#: Zone of the reference building.
ZONE = "ZONE"
#: The object types that may hold an outdoor wall.
WALL_TYPES = ("BuildingSurface:Detailed", "Wall:Detailed", "Wall:Exterior")
#: Object types dropped from a user's model (wallcal asks for its own outputs).
DROPPED_OUTPUTS = (
    "Output:Variable",
    "Output:Meter",
    "Output:Meter:MeterFileOnly",
    "Output:Meter:Cumulative",
    "Output:Meter:Cumulative:MeterFileOnly",
    "Output:Table:SummaryReports",
    "Output:Table:Monthly",
    "Output:Table:Annual",
    "Output:Table:TimeBins",
    "OutputControl:Table:Style",
    "Output:SQLite",
    "Output:JSON",
    "Output:VariableDictionary",
    "Output:Surfaces:Drawing",
    "Output:Surfaces:List",
    "Output:Constructions",
    "OutputControl:Files",
    "Output:Diagnostics",
)


# ============================================================================ the reference building
#: The reference building's epJSON file, shipped with the package (package data).
REFERENCE_BUILDING_FILE = Path(__file__).with_name("reference_building.epJSON")


def reference_building(
    *, heating_setpoint: float = HEATING_SETPOINT, cooling_setpoint: float = COOLING_SETPOINT
) -> dict:
    """The bundled reference building as an epJSON dict, without its wall construction (see the module text).

    Read from :data:`REFERENCE_BUILDING_FILE`; the two set-point schedules get the given values.

    Parameters
    ----------
    heating_setpoint, cooling_setpoint : float
        Zone air set-points of the ideal loads [degC].

    Returns
    -------
    dict
        epJSON objects; the four walls use the construction :data:`WALL_CONSTRUCTION`, which
        :func:`with_wall` adds.
    """
    model = json.loads(REFERENCE_BUILDING_FILE.read_text(encoding="utf-8"))
    schedules = model["Schedule:Constant"]
    schedules["WALLCAL_HEATING_SETPOINT"]["hourly_value"] = heating_setpoint
    schedules["WALLCAL_COOLING_SETPOINT"]["hourly_value"] = cooling_setpoint
    return model


# ============================================================================ a user's model
def load_model(path: str | Path) -> dict:
    """A user's EnergyPlus 25.2 model as an epJSON dict: ``.epJSON``/``.json`` read as is, ``.idf`` converted
    by EnergyPlus (``energyplus --convert-only``).

    Raises
    ------
    DataError
        The file cannot be read or converted.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"--building {path}: no such file")
    suffix = path.suffix.lower()
    if suffix in (".epjson", ".json"):
        try:
            model = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise DataError(f"{path}: not a readable epJSON file ({exc})") from exc
    elif suffix == ".idf":
        from ..eplus import convert_to_epjson

        with tempfile.TemporaryDirectory(prefix="wallcal_convert_") as tmp:
            try:
                out = convert_to_epjson(path, Path(tmp))
            except EngineError as exc:
                raise DataError(f"{path}: EnergyPlus could not convert the IDF file to epJSON: {exc}") from exc
            model = json.loads(out.read_text(encoding="utf-8"))
    else:
        raise DataError(f"--building {path}: expected an .epJSON or .idf file (EnergyPlus 25.2)")
    if not isinstance(model, dict) or not isinstance(model.get("Zone"), dict) or not model["Zone"]:
        raise DataError(f"{path}: the model has no Zone object")
    return model


def outdoor_walls(model: dict) -> list[str]:
    """Names of the model's outdoor walls (walls with an ``Outdoors`` boundary), in the model's order."""
    out = []
    for kind in WALL_TYPES:
        for name, obj in (model.get(kind) or {}).items():
            if kind == "BuildingSurface:Detailed" and str(obj.get("surface_type", "")).lower() != "wall":
                continue
            if kind != "Wall:Exterior" and str(obj.get("outside_boundary_condition", "")).lower() != "outdoors":
                continue
            out.append(name)
    return out


def select_surfaces(
    model: dict, names: list[str] | None, source: str = "the building model", key: str = "--surfaces"
) -> list[str]:
    """The surfaces that get the wall: ``names`` checked against the model, or every outdoor wall.

    Raises
    ------
    StudyError
        A model without outdoor walls, an unknown name (with the closest names) or a surface that is not
        an outdoor wall.
    """
    walls = outdoor_walls(model)
    if not walls:
        raise StudyError([f"{source} has no outdoor wall (a wall surface with an Outdoors boundary)"])
    if not names:
        return walls
    all_surfaces = {n for kind in (*WALL_TYPES, "Roof:Detailed", "Floor:Detailed") for n in (model.get(kind) or {})}
    lower = {w.lower(): w for w in walls}
    problems, out = [], []
    for name in names:
        if name.lower() in lower:
            out.append(lower[name.lower()])
        elif name in all_surfaces:
            problems.append(f"{key}: {name!r} is not an outdoor wall of {source}")
        else:
            problems.append(f"{key}: {name!r} is not a surface of {source}; {closest(name, walls)}")
    if problems:
        raise StudyError(problems)
    return out


def conditioned_zones(model: dict) -> list[str]:
    """Zones served by a ``ZoneHVAC:IdealLoadsAirSystem`` (the loads wallcal reports)."""
    lists = {}
    for name, eq in (model.get("ZoneHVAC:EquipmentList") or {}).items():
        kinds = [str(e.get("zone_equipment_object_type", "")).lower() for e in eq.get("equipment", [])]
        lists[name.lower()] = "zonehvac:idealloadsairsystem" in kinds
    out = []
    for conn in (model.get("ZoneHVAC:EquipmentConnections") or {}).values():
        if lists.get(str(conn.get("zone_conditioning_equipment_list_name", "")).lower()):
            out.append(str(conn.get("zone_name")))
    return out


def wall_objects(wall: Wall) -> dict:
    """The wall's EnergyPlus objects (materials, lambda(T) properties, construction) as epJSON."""
    objs = idf_to_epjson(wall_to_idf_objects(wall, name=WALL_CONSTRUCTION, settings=False))
    return objs


def needs_condfd(wall: Wall) -> bool:
    """True when the wall needs EnergyPlus' finite-difference algorithm (a temperature-dependent conductivity)."""
    return any(layer.is_temperature_dependent for layer in wall.layers)


def with_wall(
    model: dict,
    wall: Wall,
    surfaces: list[str],
    *,
    period: tuple[tuple[int, int], tuple[int, int]],
    steps_per_hour: int,
    free_floating: bool = False,
    zone_temperatures: bool = False,
) -> dict:
    """A copy of ``model`` with ``wall`` on ``surfaces``, wallcal's run period, simulation control and outputs.

    Parameters
    ----------
    model : dict
        epJSON objects.
    wall : Wall
    surfaces : list of str
        Surfaces (from :func:`select_surfaces`) whose construction becomes the wall's.
    period : ((month, day), (month, day))
        First and last day of the run period (inclusive).
    steps_per_hour : int
        EnergyPlus timesteps per hour (at least 20 when the wall needs CondFD).
    free_floating : bool
        Switch every ideal-loads system off (zone air free-floating).
    zone_temperatures : bool
        Report the hourly zone mean air temperatures.

    Returns
    -------
    dict
    """
    m = {k: copy.deepcopy(v) for k, v in model.items() if k not in DROPPED_OUTPUTS and k != "RunPeriod"}
    m["Version"] = {"Version 1": {"version_identifier": "25.2"}}
    for kind, objs in wall_objects(wall).items():
        m.setdefault(kind, {}).update(objs)
    names = set(surfaces)
    for kind in WALL_TYPES:
        for name, obj in (m.get(kind) or {}).items():
            if name in names:
                obj["construction_name"] = WALL_CONSTRUCTION
    if needs_condfd(wall):
        m["SurfaceProperty:HeatTransferAlgorithm:Construction"] = {
            **m.get("SurfaceProperty:HeatTransferAlgorithm:Construction", {}),
            "WALLCAL_WALL_CONDFD": {"algorithm": "ConductionFiniteDifference", "construction_name": WALL_CONSTRUCTION},
        }
    m["Timestep"] = {"Timestep 1": {"number_of_timesteps_per_hour": int(steps_per_hour)}}
    m["SimulationControl"] = {
        "SimulationControl 1": {
            "do_zone_sizing_calculation": "No",
            "do_system_sizing_calculation": "No",
            "do_plant_sizing_calculation": "No",
            "run_simulation_for_sizing_periods": "No",
            "run_simulation_for_weather_file_run_periods": "Yes",
        }
    }
    (bm, bd), (em, ed) = period
    m["RunPeriod"] = {
        "wallcal": {
            "begin_month": bm,
            "begin_day_of_month": bd,
            "end_month": em,
            "end_day_of_month": ed,
            "use_weather_file_holidays_and_special_days": "No",
            "use_weather_file_daylight_saving_period": "No",
            "apply_weekend_holiday_rule": "No",
            "use_weather_file_rain_indicators": "Yes",
            "use_weather_file_snow_indicators": "Yes",
        }
    }
    outputs = {}
    if free_floating:
        m.setdefault("ScheduleTypeLimits", {})["WALLCAL_ANY"] = {}
        m.setdefault("Schedule:Constant", {})["WALLCAL_OFF"] = {
            "schedule_type_limits_name": "WALLCAL_ANY",
            "hourly_value": 0.0,
        }
        for obj in (m.get("ZoneHVAC:IdealLoadsAirSystem") or {}).values():
            obj["availability_schedule_name"] = "WALLCAL_OFF"
    else:
        for what in ("Heating", "Cooling"):
            outputs[f"wallcal {what}"] = {
                "key_value": "*",
                "variable_name": f"Zone Ideal Loads Supply Air Total {what} Rate",
                "reporting_frequency": "Timestep",
            }
    if zone_temperatures:
        outputs["wallcal Tzone"] = {
            "key_value": "*",
            "variable_name": "Zone Mean Air Temperature",
            "reporting_frequency": "Hourly",
        }
    m["Output:Variable"] = outputs
    m["OutputControl:Files"] = {
        "OutputControl:Files 1": {
            "output_csv": "Yes",
            "output_mtr": "No",
            "output_eso": "Yes",
            "output_eio": "Yes",
            "output_tabular": "No",
            "output_sqlite": "No",
            "output_json": "No",
        }
    }
    return m


def check_model(model: dict, source: str) -> list[str]:
    """The conditioned zones of ``model``; raises when there is none.

    Raises
    ------
    StudyError
        No zone served by a ``ZoneHVAC:IdealLoadsAirSystem``.
    """
    zones = conditioned_zones(model)
    if not zones:
        raise StudyError(
            [
                f"{source}: no zone is served by a ZoneHVAC:IdealLoadsAirSystem; wallcal building reports the "
                "ideal loads of the conditioned zones (see docs/building.md)"
            ]
        )
    return zones
