"""The EnergyPlus model of the fictitious zone: the IDF text, the boundary schedules, the warm-up length.

See :mod:`wallcal.engines.energyplus` for the strategy and the quirks it handles.
"""

from __future__ import annotations

import math

import numpy as np

from ...idf import cfd_settings_object, idf_object, wall_to_idf_objects
from ...wall import Wall

#: Timesteps per hour EnergyPlus accepts with CondFD (divisors of 60, at least 20).
ALLOWED_STEPS_PER_HOUR = (20, 30, 60)
#: Name of the reported surface.
WALL_SURFACE = "WALL"
#: Seconds per day.
DAY = 86400.0
#: Days of the (non-leap) year the schedules cover.
YEAR_DAYS = 365


#: the fictitious zone's surfaces: a 2 m cube whose first face is the studied wall (WALL_SURFACE)
BOX_SIZE_M = 2.0
BOX_SURFACES = (WALL_SURFACE, "EAST", "NORTH", "WEST", "ROOF", "FLOOR")


def box_surfaces(construction: str, outside: str, outside_object: str | None, *, other_surfaces_ctf: bool) -> list[str]:
    """The fictitious zone's six ``BuildingSurface:Detailed`` objects, all of ``construction`` with the outside
    boundary ``outside`` (and its object), no sun and no wind; with ``other_surfaces_ctf`` every surface but the
    studied wall is solved by conduction transfer functions (cheaper, and it does not change the wall)."""
    s = BOX_SIZE_M
    boxes = {
        WALL_SURFACE: ("Wall", [(0, 0, s), (0, 0, 0), (s, 0, 0), (s, 0, s)]),
        "EAST": ("Wall", [(s, 0, s), (s, 0, 0), (s, s, 0), (s, s, s)]),
        "NORTH": ("Wall", [(s, s, s), (s, s, 0), (0, s, 0), (0, s, s)]),
        "WEST": ("Wall", [(0, s, s), (0, s, 0), (0, 0, 0), (0, 0, s)]),
        "ROOF": ("Roof", [(0, s, s), (0, 0, s), (s, 0, s), (s, s, s)]),
        "FLOOR": ("Floor", [(s, s, 0), (s, 0, 0), (0, 0, 0), (0, s, 0)]),
    }
    o = []
    for name, (kind, verts) in boxes.items():
        fields = [(name, "Name"), (kind, "Surface Type"), (construction, "Construction Name"), ("ZONE", "Zone Name"),
                  (None, "Space Name"), (outside, "Outside Boundary Condition"),
                  (outside_object, "Outside Boundary Condition Object"), ("NoSun", "Sun Exposure"),
                  ("NoWind", "Wind Exposure"), (0.0, "View Factor to Ground"), (4, "Number of Vertices")]  # fmt: skip
        for j, (vx, vy, vz) in enumerate(verts, start=1):
            fields += [(float(vx), f"Vertex {j} X"), (float(vy), f"Vertex {j} Y"), (float(vz), f"Vertex {j} Z")]
        o.append(idf_object("BuildingSurface:Detailed", fields))
        if name != WALL_SURFACE and other_surfaces_ctf:
            o.append(
                idf_object(
                    "SurfaceProperty:HeatTransferAlgorithm",
                    [(name, "Surface Name"), ("ConductionTransferFunction", "Algorithm")],
                )
            )
    return o


def slowest_time_constant(wall: Wall, n_cells: int = 400) -> float:
    """Time constant [s] of the wall's slowest mode with both faces held at fixed temperatures.

    Parameters
    ----------
    wall : Wall
    n_cells : int
        About this many intervals, shared among the massive layers by thickness (at least 2 each).

    Returns
    -------
    float
        1 / (smallest eigenvalue of Cap^-1 K) [s] on the fd engine's grid and operator
        (:func:`wallcal.engines.operator.assemble_operator`); 0 for a wall without mass.
    """
    from scipy.linalg import eigh_tridiagonal

    from ...grid import PropertyArrays, assemble, build_grid
    from .. import boundary
    from ..operator import assemble_operator, unknown_range

    total = sum(layer.thickness for layer in wall.layers if not layer.is_massless)
    if total <= 0.0:
        return 0.0
    intervals = [0 if L.is_massless else max(2, round(n_cells * L.thickness / total)) for L in wall.layers]
    grid = build_grid(wall, 1.0, 1.0, intervals=intervals)
    cap, g = (a[0] for a in assemble(grid, PropertyArrays.from_walls([wall])))
    # nodes without capacity (between two no-mass layers) are eliminated: their links act in series
    keep_c, keep_g = [cap[0]], []
    r = 0.0
    for lnk in range(len(g)):
        r += 1.0 / g[lnk]
        j = lnk + 1
        if cap[j] > 0.0 or j == len(cap) - 1:
            keep_g.append(1.0 / r)
            keep_c.append(cap[j])
            r = 0.0
    cap, g = np.array(keep_c), np.array(keep_g)
    faces = np.full(2, boundary.SURFACE_TEMPERATURE, dtype=np.int64)
    j0, m = unknown_range(len(cap), faces)
    if m < 1:
        return 0.0
    diag, off = np.zeros(m), np.zeros(m)
    assemble_operator(g, np.ones(len(g)), faces, np.zeros(2), np.ones(2), j0, m, diag, off)
    s = 1.0 / np.sqrt(cap[j0 : j0 + m])  # Cap^-1/2 K Cap^-1/2: symmetric tridiagonal
    lam_min = eigh_tridiagonal(
        diag * s * s, off[: m - 1] * s[:-1] * s[1:], eigvals_only=True, select="i", select_range=(0, 0)
    )[0]
    return 1.0 / float(lam_min)


def warmup_days_needed(wall: Wall, t_ext: float, t_int: float, tol: float = 1e-4) -> int:
    """Warm-up days for the slowest mode to decay to ``tol`` [K] from a 23 degC uniform start.

    Parameters
    ----------
    wall : Wall
    t_ext, t_int : float
        First boundary values [degC].
    tol : float
        Target residual [K].

    Returns
    -------
    int
        Between 1 and 60.
    """
    tau = slowest_time_constant(wall)
    amplitude = max(abs(t_ext - 23.0), abs(t_int - 23.0), 1.0)
    days = tau * math.log(amplitude / tol) / DAY
    return int(min(60, max(1, math.ceil(days))))


def boundary_schedules(te, ti, flux_e, flux_i, pad_flux, *, h_max: float, theta: float, advance: bool):
    """Schedule values for EnergyPlus steps 1..N (step k ends at grid point k).

    Parameters
    ----------
    te, ti : ndarray, shape (N + 1,)
        Imposed exterior and interior surface temperatures on the grid [degC].
    flux_e, flux_i : ndarray, shape (N,)
        Mean face heat flux densities over each step [W/m2], positive towards the interior.
    pad_flux : (float, float)
        Face fluxes of the initial steady state [W/m2].
    h_max : float
        Film coefficient between the schedules and the face nodes [W/(m2K)].
    theta : float
        Weight of the new time level in the boundary value: 0.5 (mid-step, Crank-Nicolson) or 1.
    advance : bool
        Shift the zone-air setpoint one step earlier (the inside face sees the previous step's air).

    Returns
    -------
    steps_e, steps_i : ndarray, shape (N,)
        Other-side temperature and zone setpoint for steps 1..N [degC].
    pads : (float, float, float)
        Constant other-side temperature and setpoint of the pad/warm-up day, and the setpoint of
        its last step (which leads into grid point 0).
    """
    te = np.asarray(te, dtype=float)
    ti = np.asarray(ti, dtype=float)
    steps_e = theta * te[1:] + (1 - theta) * te[:-1] + np.asarray(flux_e) / h_max
    need_i = theta * ti[1:] + (1 - theta) * ti[:-1] - np.asarray(flux_i) / h_max
    pad_e = te[0] + pad_flux[0] / h_max
    pad_i = ti[0] - pad_flux[1] / h_max
    if advance:
        steps_i = np.concatenate([need_i[1:], need_i[-1:]])
        last_pad_i = need_i[0]
    else:
        steps_i = need_i
        last_pad_i = pad_i
    return steps_e, steps_i, (pad_e, pad_i, last_pad_i)


def guess_node_count(wall: Wall, c: float, dt: float) -> int:
    """Upper estimate of CondFD's node count (EnergyPlus: int(L / sqrt(C alpha dt)) per layer)."""
    count = 1
    for layer in wall.layers:
        if layer.is_massless:
            count += 2
        else:
            alpha = float(layer.conductivity_at(layer.reference_temperature)) / layer.volumetric_heat_capacity
            count += max(1, int(layer.thickness / math.sqrt(c * alpha * dt))) + 1
        if layer.contact_resistance:
            count += 2
    return count


def build_idf(
    wall: Wall | None,
    *,
    schedule_file: str,
    minutes_per_item: int,
    steps_per_hour: int,
    run_days: int,
    warmup_days: int,
    grid_constant: float,
    scheme: str,
    h_max: float,
    inside_convergence: float,
    t_range=(-20.0, 70.0),
    n_node_outputs: int = 100,
    year: int = 2025,
    other_surfaces_ctf: bool = False,
    wall_objects: str | None = None,
    construction: str = "WALLCAL",
) -> str:
    """The complete single-wall EnergyPlus model.

    Parameters
    ----------
    wall : Wall
    schedule_file : str
        CSV with a header row and two columns (other-side temperature, zone setpoint) [degC],
        one row per ``minutes_per_item`` for a whole (non-leap) year.
    minutes_per_item : int
        Minutes per schedule row.
    steps_per_hour : int
        EnergyPlus timesteps per hour.
    run_days : int
        Length of the run period from January 1 [d].
    warmup_days : int
        Minimum number of warm-up days.
    grid_constant : float
        CondFD space discretisation constant [-].
    scheme : str
        ``"cn"`` or ``"implicit"``.
    h_max : float
        Maximum (and imposed inside) convection coefficient [W/(m2K)].
    inside_convergence : float
        CondFD inside-face convergence criterion [K].
    t_range : (float, float)
        Range [degC] over which lambda(T) laws are tabulated.
    n_node_outputs : int
        Number of "CondFD Surface Temperature Node N" outputs requested.
    year : int
        Calendar year of the run period (not a leap year).
    other_surfaces_ctf : bool
        Compute the five other zone surfaces with CTF.
    wall_objects : str, optional
        IDF text of the wall's materials, construction and CondFD settings (e.g. the output of
        ``wallcal export-idf``) used verbatim instead of writing them here; ``grid_constant``,
        ``scheme``, ``inside_convergence`` and ``t_range`` are then ignored.
    construction : str
        Name of the construction the surfaces use.

    Returns
    -------
    str
        IDF text.
    """
    cons = construction
    end = np.datetime64(f"{year}-01-01") + np.timedelta64(run_days - 1, "D")
    end_month, end_day = int(str(end)[5:7]), int(str(end)[8:10])
    o = []
    o.append(idf_object("Version", [("25.2", "Version Identifier")]))
    o.append(
        idf_object(
            "SimulationControl",
            [
                ("No", "Do Zone Sizing Calculation"),
                ("No", "Do System Sizing Calculation"),
                ("No", "Do Plant Sizing Calculation"),
                ("No", "Run Simulation for Sizing Periods"),
                ("Yes", "Run Simulation for Weather File Run Periods"),
                ("No", "Do HVAC Sizing Simulation for Sizing Periods"),
                (1, "Maximum Number of HVAC Sizing Simulation Passes"),
            ],
        )
    )
    o.append(
        idf_object(
            "Building",
            [
                ("wallcal single wall", "Name"),
                (0.0, "North Axis {deg}"),
                ("Suburbs", "Terrain"),
                (0.04, "Loads Convergence Tolerance Value {W}"),
                (0.4, "Temperature Convergence Tolerance Value {deltaC}"),
                ("MinimalShadowing", "Solar Distribution"),
                (max(25, warmup_days), "Maximum Number of Warmup Days"),
                (warmup_days, "Minimum Number of Warmup Days"),
            ],
        )
    )
    o.append(idf_object("Timestep", [(steps_per_hour, "Number of Timesteps per Hour")]))
    o.append(
        idf_object(
            "HeatBalanceAlgorithm",
            [
                ("ConductionFiniteDifference", "Algorithm"),
                (200, "Surface Temperature Upper Limit {C}"),
                (0.1, "Minimum Surface Convection Heat Transfer Coefficient Value {W/m2-K}"),
                (float(h_max), "Maximum Surface Convection Heat Transfer Coefficient Value {W/m2-K}"),
            ],
        )
    )
    o.append(idf_object("SurfaceConvectionAlgorithm:Inside", [("TARP", "Algorithm")]))
    o.append(idf_object("SurfaceConvectionAlgorithm:Outside", [("DOE-2", "Algorithm")]))
    o.append(idf_object("ZoneAirHeatBalanceAlgorithm", [("AnalyticalSolution", "Algorithm")]))
    o.append(
        idf_object(
            "RunPeriod",
            [
                ("wallcal", "Name"),
                (1, "Begin Month"),
                (1, "Begin Day of Month"),
                (year, "Begin Year"),
                (end_month, "End Month"),
                (end_day, "End Day of Month"),
                (year, "End Year"),
                (None, "Day of Week for Start Day"),
                ("No", "Use Weather File Holidays and Special Days"),
                ("No", "Use Weather File Daylight Saving Period"),
                ("No", "Apply Weekend Holiday Rule"),
                ("No", "Use Weather File Rain Indicators"),
                ("No", "Use Weather File Snow Indicators"),
            ],
        )
    )
    o.append(
        idf_object(
            "GlobalGeometryRules",
            [
                ("UpperLeftCorner", "Starting Vertex Position"),
                ("Counterclockwise", "Vertex Entry Direction"),
                ("Relative", "Coordinate System"),
            ],
        )
    )
    o.append(idf_object("ScheduleTypeLimits", [("Any Number", "Name")]))
    for name, column in (("T_other_side", 1), ("T_zone_setpoint", 2)):  # the two columns of one schedule file
        o.append(
            idf_object(
                "Schedule:File",
                [
                    (name, "Name"),
                    ("Any Number", "Schedule Type Limits Name"),
                    (schedule_file, "File Name"),
                    (column, "Column Number"),
                    (1, "Rows to Skip at Top"),
                    (8760, "Number of Hours of Data"),
                    ("Comma", "Column Separator"),
                    ("No", "Interpolate to Timestep"),
                    (minutes_per_item, "Minutes per Item"),
                    ("No", "Adjust Schedule for Daylight Savings"),
                ],
            )
        )
    o.append(
        idf_object(
            "Schedule:Constant",
            [("ControlType", "Name"), ("Any Number", "Schedule Type Limits Name"), (3, "Hourly Value")],
        )
    )
    if wall_objects is None:
        o.append(
            wall_to_idf_objects(
                wall,
                grid_constant=grid_constant,
                scheme=scheme,
                name=cons,
                temperature_range=t_range,
                settings=False,
            )
        )
        o.append(cfd_settings_object(grid_constant=grid_constant, scheme=scheme, inside_convergence=inside_convergence))
    else:
        o.append(wall_objects)
    o.append(idf_object("Zone", [("ZONE", "Name")]))
    o.append(
        idf_object(
            "SurfaceProperty:OtherSideCoefficients",
            [
                ("OSC", "Name"),
                (0.0, "Combined Convective/Radiative Film Coefficient {W/m2-K}"),
                (0.0, "Constant Temperature {C}"),
                (1.0, "Constant Temperature Coefficient"),
                (0.0, "External Dry-Bulb Temperature Coefficient"),
                (0.0, "Ground Temperature Coefficient"),
                (0.0, "Wind Speed Coefficient"),
                (0.0, "Zone Air Temperature Coefficient"),
                ("T_other_side", "Constant Temperature Schedule Name"),
            ],
        )
    )
    o += box_surfaces(cons, "OtherSideCoefficients", "OSC", other_surfaces_ctf=other_surfaces_ctf)
    for name in BOX_SURFACES:
        o.append(
            idf_object(
                "SurfaceProperty:ConvectionCoefficients",
                [
                    (name, "Surface Name"),
                    ("Inside", "Convection Coefficient 1 Location"),
                    ("Value", "Convection Coefficient 1 Type"),
                    (float(h_max), "Convection Coefficient 1 {W/m2-K}"),
                ],
            )
        )
    # zone air held at the setpoint by an unlimited ideal-loads system
    o.append(
        idf_object(
            "ZoneControl:Thermostat",
            [
                ("ZONE Thermostat", "Name"),
                ("ZONE", "Zone or ZoneList Name"),
                ("ControlType", "Control Type Schedule Name"),
                ("ThermostatSetpoint:SingleHeatingOrCooling", "Control 1 Object Type"),
                ("SP", "Control 1 Name"),
            ],
        )
    )
    o.append(
        idf_object(
            "ThermostatSetpoint:SingleHeatingOrCooling",
            [("SP", "Name"), ("T_zone_setpoint", "Setpoint Temperature Schedule Name")],
        )
    )
    o.append(
        idf_object(
            "ZoneHVAC:EquipmentConnections",
            [
                ("ZONE", "Zone Name"),
                ("ZONE Equipment", "Zone Conditioning Equipment List Name"),
                ("ZONE Inlets", "Zone Air Inlet Node or NodeList Name"),
                (None, "Zone Air Exhaust Node or NodeList Name"),
                ("ZONE Air Node", "Zone Air Node Name"),
                ("ZONE Return Node", "Zone Return Air Node or NodeList Name"),
            ],
        )
    )
    o.append(idf_object("NodeList", [("ZONE Inlets", "Name"), ("ZONE Ideal Supply", "Node 1 Name")]))
    o.append(
        idf_object(
            "ZoneHVAC:EquipmentList",
            [
                ("ZONE Equipment", "Name"),
                ("SequentialLoad", "Load Distribution Scheme"),
                ("ZoneHVAC:IdealLoadsAirSystem", "Zone Equipment 1 Object Type"),
                ("ZONE Ideal", "Zone Equipment 1 Name"),
                (1, "Zone Equipment 1 Cooling Sequence"),
                (1, "Zone Equipment 1 Heating or No-Load Sequence"),
            ],
        )
    )
    o.append(
        idf_object(
            "ZoneHVAC:IdealLoadsAirSystem",
            [
                ("ZONE Ideal", "Name"),
                (None, "Availability Schedule Name"),
                ("ZONE Ideal Supply", "Zone Supply Air Node Name"),
                (None, "Zone Exhaust Air Node Name"),
                (None, "System Inlet Air Node Name"),
                (99.0, "Maximum Heating Supply Air Temperature {C}"),
                (-99.0, "Minimum Cooling Supply Air Temperature {C}"),
                (0.0156, "Maximum Heating Supply Air Humidity Ratio"),
                (0.0077, "Minimum Cooling Supply Air Humidity Ratio"),
                ("NoLimit", "Heating Limit"),
                (None, "Maximum Heating Air Flow Rate"),
                (None, "Maximum Sensible Heating Capacity"),
                ("NoLimit", "Cooling Limit"),
                (None, "Maximum Cooling Air Flow Rate"),
                (None, "Maximum Total Cooling Capacity"),
                (None, "Heating Availability Schedule Name"),
                (None, "Cooling Availability Schedule Name"),
                ("None", "Dehumidification Control Type"),
                (0.7, "Cooling Sensible Heat Ratio"),
                ("None", "Humidification Control Type"),
            ],
        )
    )
    o.append(
        idf_object(
            "OutputControl:Files",
            [
                ("Yes", "Output CSV"),
                ("No", "Output MTR"),
                ("Yes", "Output ESO"),
                ("Yes", "Output EIO"),
                ("No", "Output Tabular"),
                ("No", "Output SQLite"),
                ("No", "Output JSON"),
                ("No", "Output AUDIT"),
                ("No", "Output Space Sizing"),
                ("No", "Output Zone Sizing"),
                ("No", "Output System Sizing"),
                ("No", "Output DXF"),
                ("No", "Output BND"),
                ("No", "Output RDD"),
                ("No", "Output MDD"),
                ("No", "Output MTD"),
                ("Yes", "Output END"),
                ("No", "Output SHD"),
            ],
        )
    )
    o.append(idf_object("Output:Diagnostics", [("DisplayAdvancedReportVariables", "Key 1")]))
    o.append(idf_object("Output:Constructions", [("Constructions", "Details Type 1")]))
    for j in range(1, n_node_outputs + 1):
        o.append(
            idf_object(
                "Output:Variable",
                [
                    (WALL_SURFACE, "Key Value"),
                    (f"CondFD Surface Temperature Node {j}", "Variable Name"),
                    ("Timestep", "Reporting Frequency"),
                ],
            )
        )
    o.append(
        idf_object(
            "Output:Variable",
            [
                ("ZONE", "Key Value"),
                ("Zone Mean Air Temperature", "Variable Name"),
                ("Timestep", "Reporting Frequency"),
            ],
        )
    )
    return "\n".join(o)
