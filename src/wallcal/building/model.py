"""The building a wall is tested in: the bundled reference building, a user's model, the wall put on its surfaces.

Models are epJSON dicts (``{object type: {name: {field: value}}}``), EnergyPlus 25.2. The wall's objects come
from :func:`wallcal.idf.wall_to_idf_objects` (the one place that writes EnergyPlus materials), converted to
epJSON by :func:`wallcal.idf.idf_to_epjson`; a user's IDF model is converted by EnergyPlus itself
(``energyplus --convert-only``).

The reference building (:func:`reference_building`, documented in docs/building.md)
----------------------------------------------------------------------------------
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
import subprocess
import tempfile
from pathlib import Path

from ..errors import DataError, StudyError, closest
from ..idf import idf_to_epjson, wall_to_idf_objects
from ..wall import Wall

#: The construction name the wall gets in a model.
WALL_CONSTRUCTION = "WALLCAL_WALL"
#: Reference building geometry [m].
LENGTH_X, LENGTH_Y, HEIGHT = 10.0, 8.0, 3.0
WINDOW_TO_WALL = 0.2
SILL, WINDOW_HEIGHT = 0.9, 1.5
INTERNAL_GAINS_W_M2 = 5.0
INFILTRATION_ACH = 0.3
GROUND_TEMPERATURE = 10.0
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
def _material(thickness, conductivity, density, specific_heat):
    return {
        "roughness": "MediumRough",
        "thickness": thickness,
        "conductivity": conductivity,
        "density": density,
        "specific_heat": specific_heat,
        "thermal_absorptance": 0.9,
        "solar_absorptance": 0.7,
        "visible_absorptance": 0.7,
    }


def _surface(kind, construction, boundary, vertices):
    return {
        "surface_type": kind,
        "construction_name": construction,
        "zone_name": ZONE,
        "outside_boundary_condition": boundary,
        "sun_exposure": "SunExposed" if boundary == "Outdoors" else "NoSun",
        "wind_exposure": "WindExposed" if boundary == "Outdoors" else "NoWind",
        "number_of_vertices": len(vertices),
        "vertices": [
            {"vertex_x_coordinate": x, "vertex_y_coordinate": y, "vertex_z_coordinate": z} for x, y, z in vertices
        ],
    }


def reference_building(
    *, heating_setpoint: float = HEATING_SETPOINT, cooling_setpoint: float = COOLING_SETPOINT
) -> dict:
    """The bundled reference building as an epJSON dict, without its wall construction (see the module text).

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
    X, Y, H = LENGTH_X, LENGTH_Y, HEIGHT
    # counter-clockwise seen from outside, upper-left corner first
    walls = {
        "WALL_SOUTH": [(0, 0, H), (0, 0, 0), (X, 0, 0), (X, 0, H)],
        "WALL_EAST": [(X, 0, H), (X, 0, 0), (X, Y, 0), (X, Y, H)],
        "WALL_NORTH": [(X, Y, H), (X, Y, 0), (0, Y, 0), (0, Y, H)],
        "WALL_WEST": [(0, Y, H), (0, Y, 0), (0, 0, 0), (0, 0, H)],
    }
    surfaces = {name: _surface("Wall", WALL_CONSTRUCTION, "Outdoors", v) for name, v in walls.items()}
    surfaces["ROOF"] = _surface("Roof", "WALLCAL_ROOF", "Outdoors", [(0, Y, H), (0, 0, H), (X, 0, H), (X, Y, H)])
    surfaces["FLOOR"] = _surface("Floor", "WALLCAL_FLOOR", "Ground", [(0, 0, 0), (0, Y, 0), (X, Y, 0), (X, 0, 0)])
    windows = {}
    for name, v in walls.items():
        (x0, y0, _), (x1, y1, _) = v[1], v[2]
        length = ((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5
        width = WINDOW_TO_WALL * length * H / WINDOW_HEIGHT
        a = (length - width) / 2 / length
        b = 1 - a
        p0 = (x0 + a * (x1 - x0), y0 + a * (y1 - y0))
        p1 = (x0 + b * (x1 - x0), y0 + b * (y1 - y0))
        top, sill = SILL + WINDOW_HEIGHT, SILL
        corners = [(p0[0], p0[1], top), (p0[0], p0[1], sill), (p1[0], p1[1], sill), (p1[0], p1[1], top)]
        win = {
            "surface_type": "Window",
            "construction_name": "WALLCAL_WINDOW",
            "building_surface_name": name,
            "number_of_vertices": 4,
        }
        for k, (x, y, z) in enumerate(corners, 1):
            win[f"vertex_{k}_x_coordinate"] = x
            win[f"vertex_{k}_y_coordinate"] = y
            win[f"vertex_{k}_z_coordinate"] = z
        windows[name.replace("WALL", "WINDOW")] = win
    return {
        "Version": {"Version 1": {"version_identifier": "25.2"}},
        "Building": {
            "wallcal reference building": {
                "north_axis": 0.0,
                "terrain": "Suburbs",
                "loads_convergence_tolerance_value": 0.04,
                "temperature_convergence_tolerance_value": 0.4,
                "solar_distribution": "FullExterior",
                "maximum_number_of_warmup_days": 25,
                "minimum_number_of_warmup_days": 6,
            }
        },
        "GlobalGeometryRules": {
            "GlobalGeometryRules 1": {
                "starting_vertex_position": "UpperLeftCorner",
                "vertex_entry_direction": "Counterclockwise",
                "coordinate_system": "Relative",
            }
        },
        "Zone": {ZONE: {"x_origin": 0.0, "y_origin": 0.0, "z_origin": 0.0, "multiplier": 1}},
        "Material": {
            "WALLCAL_ROOF_INSULATION": _material(0.24, 0.035, 30.0, 1030.0),
            "WALLCAL_ROOF_CONCRETE": _material(0.20, 2.0, 2400.0, 1000.0),
            "WALLCAL_FLOOR_XPS": _material(0.15, 0.035, 30.0, 1450.0),
            "WALLCAL_FLOOR_CONCRETE": _material(0.15, 2.0, 2400.0, 1000.0),
        },
        "WindowMaterial:SimpleGlazingSystem": {
            "WALLCAL_GLAZING": {"u_factor": 1.1, "solar_heat_gain_coefficient": 0.5, "visible_transmittance": 0.7}
        },
        "Construction": {
            "WALLCAL_ROOF": {"outside_layer": "WALLCAL_ROOF_INSULATION", "layer_2": "WALLCAL_ROOF_CONCRETE"},
            "WALLCAL_FLOOR": {"outside_layer": "WALLCAL_FLOOR_XPS", "layer_2": "WALLCAL_FLOOR_CONCRETE"},
            "WALLCAL_WINDOW": {"outside_layer": "WALLCAL_GLAZING"},
        },
        "BuildingSurface:Detailed": surfaces,
        "FenestrationSurface:Detailed": windows,
        "Site:GroundTemperature:BuildingSurface": {
            "Site:GroundTemperature:BuildingSurface 1": {
                f"{m}_ground_temperature": GROUND_TEMPERATURE
                for m in (
                    "january february march april may june july august september october november december".split()
                )
            }
        },
        "ScheduleTypeLimits": {"WALLCAL_ANY": {}},
        "Schedule:Constant": {
            "WALLCAL_ON": {"schedule_type_limits_name": "WALLCAL_ANY", "hourly_value": 1.0},
            "WALLCAL_CONTROL": {"schedule_type_limits_name": "WALLCAL_ANY", "hourly_value": 4.0},
            "WALLCAL_HEATING_SETPOINT": {"schedule_type_limits_name": "WALLCAL_ANY", "hourly_value": heating_setpoint},
            "WALLCAL_COOLING_SETPOINT": {"schedule_type_limits_name": "WALLCAL_ANY", "hourly_value": cooling_setpoint},
        },
        "ElectricEquipment": {
            "WALLCAL_GAINS": {
                "zone_or_zonelist_or_space_or_spacelist_name": ZONE,
                "schedule_name": "WALLCAL_ON",
                "design_level_calculation_method": "Watts/Area",
                "watts_per_floor_area": INTERNAL_GAINS_W_M2,
                "fraction_latent": 0.0,
                "fraction_radiant": 0.3,
                "fraction_lost": 0.0,
            }
        },
        "ZoneInfiltration:DesignFlowRate": {
            "WALLCAL_INFILTRATION": {
                "zone_or_zonelist_or_space_or_spacelist_name": ZONE,
                "schedule_name": "WALLCAL_ON",
                "design_flow_rate_calculation_method": "AirChanges/Hour",
                "air_changes_per_hour": INFILTRATION_ACH,
                "constant_term_coefficient": 1.0,
                "temperature_term_coefficient": 0.0,
                "velocity_term_coefficient": 0.0,
                "velocity_squared_term_coefficient": 0.0,
            }
        },
        "ZoneControl:Thermostat": {
            "WALLCAL_THERMOSTAT": {
                "zone_or_zonelist_name": ZONE,
                "control_type_schedule_name": "WALLCAL_CONTROL",
                "control_1_object_type": "ThermostatSetpoint:DualSetpoint",
                "control_1_name": "WALLCAL_SETPOINTS",
            }
        },
        "ThermostatSetpoint:DualSetpoint": {
            "WALLCAL_SETPOINTS": {
                "heating_setpoint_temperature_schedule_name": "WALLCAL_HEATING_SETPOINT",
                "cooling_setpoint_temperature_schedule_name": "WALLCAL_COOLING_SETPOINT",
            }
        },
        "ZoneHVAC:EquipmentConnections": {
            "ZoneHVAC:EquipmentConnections 1": {
                "zone_name": ZONE,
                "zone_conditioning_equipment_list_name": "ZONE Equipment",
                "zone_air_inlet_node_or_nodelist_name": "ZONE Inlets",
                "zone_air_node_name": "ZONE Air Node",
                "zone_return_air_node_or_nodelist_name": "ZONE Return Node",
            }
        },
        "NodeList": {"ZONE Inlets": {"nodes": [{"node_name": "ZONE Ideal Supply"}]}},
        "ZoneHVAC:EquipmentList": {
            "ZONE Equipment": {
                "load_distribution_scheme": "SequentialLoad",
                "equipment": [
                    {
                        "zone_equipment_object_type": "ZoneHVAC:IdealLoadsAirSystem",
                        "zone_equipment_name": "ZONE Ideal",
                        "zone_equipment_cooling_sequence": 1,
                        "zone_equipment_heating_or_no_load_sequence": 1,
                    }
                ],
            }
        },
        "ZoneHVAC:IdealLoadsAirSystem": {
            "ZONE Ideal": {
                "zone_supply_air_node_name": "ZONE Ideal Supply",
                "maximum_heating_supply_air_temperature": 50.0,
                "minimum_cooling_supply_air_temperature": 13.0,
                "maximum_heating_supply_air_humidity_ratio": 0.0156,
                "minimum_cooling_supply_air_humidity_ratio": 0.0077,
                "heating_limit": "NoLimit",
                "cooling_limit": "NoLimit",
                "dehumidification_control_type": "None",
                "humidification_control_type": "None",
            }
        },
    }


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
        from ..engines.energyplus.runner import energyplus_binary, error_lines

        with tempfile.TemporaryDirectory(prefix="wallcal_convert_") as tmp:
            proc = subprocess.run(
                [str(energyplus_binary()), "--convert-only", "-d", tmp, str(path.resolve())],
                capture_output=True,
                text=True,
                timeout=300,
            )
            out = Path(tmp) / (path.stem + ".epJSON")
            err = Path(tmp) / "eplusout.err"
            lines = error_lines(err.read_text(errors="replace")) if err.exists() else []
            if proc.returncode != 0 or not out.exists() or lines:
                why = lines[0] if lines else (proc.stderr or proc.stdout or "").strip().splitlines()[-1:]
                raise DataError(f"{path}: EnergyPlus could not convert the IDF file to epJSON: {why}")
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
