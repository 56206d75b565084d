"""The study file: one TOML file describing a wall and a monitoring campaign.

Validated in one place (:func:`load_study`, with the helpers of :mod:`wallcal.schema`; the
``[wall]`` table is read by :mod:`wallcal.wallfile`). Every problem is reported at once with its
key path, e.g. ``wall.layers[2].conductivity: must be > 0, got -0.035``; unknown keys are rejected
with the closest valid name. ``docs/study-file.md`` documents every key.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .engines import DEFAULT_ENGINE, engine_names
from .engines.boundary_types import boundary_type, boundary_type_names
from .errors import StudyError, closest
from .features import StudyContext, feature_keys, parse_features
from .schema import Problems, Table, describe, read_toml
from .wall import Wall
from .wallfile import FACES, WALL_KEYS, dump_wall, load_wall, parse_wall, wall_to_dict

__all__ = [
    "BoundarySpec",
    "DataFileSpec",
    "DataSpec",
    "PeriodSpec",
    "SensorSpec",
    "SimulationSpec",
    "Study",
    "dump_wall",
    "load_study",
    "load_wall",
    "parse_study",
    "wall_to_dict",
]

QUANTITIES = ("temperature", "heat_flux", "relative_humidity", "water_content")
#: quantities only the engines with the ``moisture`` capability compute (``ham``)
MOISTURE_QUANTITIES = ("relative_humidity", "water_content")
#: the unit of each quantity inside wallcal (after a column's unit and sign conversion)
QUANTITY_UNITS = {"temperature": "degC", "heat_flux": "W/m2", "relative_humidity": "fraction", "water_content": "kg/m3"}
HUMIDITY_UNITS = ("fraction", "percent")
INITIAL_STATES = ("first_row", "constant", "periodic")
TEMPERATURE_UNITS = ("degC", "K")
FLUX_DIRECTIONS = ("towards_interior", "towards_exterior")
TIME_FORMATS = ("iso", "elapsed_seconds")


# ============================================================================ spec objects
@dataclass(frozen=True)
class BoundarySpec:
    """A face's boundary condition as the study states it.

    ``type``: a boundary type a study may name (:mod:`wallcal.engines.boundary_types`: surface_temperature |
    air_temperature | heat_flux); ``column``: data
    column; ``surface_coefficient`` [W/(m2K)] for air_temperature; ``unit``:
    degC | K for temperatures; ``positive``: direction of a heat-flux column;
    ``offset``: added to the column after the unit and sign conversion (a declared
    sensor correction, degC or W/m2). The humidity types (``surface_temperature_humidity``,
    ``air_temperature_humidity``; the ``ham`` engine) add ``humidity_column`` (relative humidity, read as a
    fraction), its ``humidity_unit`` (fraction | percent) and, for air, ``vapour_coefficient`` beta [s/m].
    """

    face: str
    type: str
    column: str
    surface_coefficient: float | None = None
    unit: str = "degC"
    positive: str = "towards_interior"
    offset: float = 0.0
    humidity_column: str | None = None
    humidity_unit: str = "fraction"
    vapour_coefficient: float | None = None


@dataclass(frozen=True)
class SensorSpec:
    """A measured signal compared with the model.

    ``quantity``: temperature (``name`` is a probe of the wall), heat_flux (at
    ``face``, or at ``depth`` [m from the exterior face] inside the wall), relative_humidity (a probe; read
    as a fraction, ``unit`` fraction | percent) or water_content [kg/m3] (a probe): the last two need the
    ``ham`` engine. ``accuracy`` [degC, W/m2, fraction or kg/m3: the quantity's unit in wallcal, a percent
    sensor's accuracy is given in percent and converted] or ``accuracy_relative`` [-].
    ``weight`` [-] enters weighted objectives. ``offset`` is added to the column after
    the unit and sign conversion.
    """

    name: str
    column: str
    quantity: str = "temperature"
    face: str | None = None
    depth: float | None = None
    accuracy: float | None = None
    accuracy_relative: float | None = None
    unit: str = "degC"
    positive: str = "towards_interior"
    weight: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class DataFileSpec:
    """One file of a multi-file data set (``[[data.files]]``).

    ``columns``: ``(name_in_study, column_in_file)`` pairs (only these columns are
    taken), or ``None`` to take every column but the time column, each named
    ``prefix + column_in_file``.
    """

    file: Path
    time_column: str = "timestamp"
    columns: tuple[tuple[str, str], ...] | None = None
    prefix: str = ""
    separator: str | None = None


@dataclass(frozen=True)
class DataSpec:
    """Where and how the monitoring data are read.

    One file (``file``) or several (``files``, joined on their timestamps; ``file`` is
    then the folder of the first one, for messages).
    """

    file: Path
    time_column: str = "timestamp"
    time_format: str = "iso"
    start: _dt.datetime | None = None
    utc_offset: str | None = None
    max_gap: float = 7200.0
    separator: str | None = None
    remove_spikes: bool = True
    spike_sigma: float = 8.0
    files: tuple[DataFileSpec, ...] = ()

    @property
    def paths(self) -> tuple[Path, ...]:
        """Every data file read (one, or each of ``files``)."""
        return tuple(f.file for f in self.files) if self.files else (self.file,)


@dataclass(frozen=True)
class PeriodSpec:
    """Comparison period (both ends included), the start of the warm-up and the held-out validation window.

    ``validation_start`` .. ``validation_end`` (both included, or both None) is a window no fitting sees: inside
    ``[start, end]`` the fitting uses the rest of the period, after ``end`` it is simulated on from the period
    (:mod:`wallcal.validation`).
    """

    warmup_start: _dt.datetime | None
    start: _dt.datetime
    end: _dt.datetime
    validation_start: _dt.datetime | None = None
    validation_end: _dt.datetime | None = None

    @property
    def validation(self) -> tuple[_dt.datetime, _dt.datetime] | None:
        """(validation_start, validation_end), or None without a validation window."""
        if self.validation_start is None or self.validation_end is None:
            return None
        return self.validation_start, self.validation_end


@dataclass(frozen=True)
class SimulationSpec:
    """Engine and grid settings."""

    engine: str = DEFAULT_ENGINE
    time_step: float = 60.0
    grid_constant: float = 2.0
    node_rule: str = "wallcal"
    stiff_limit: float | None = None  # None: the engine's derived limit 1 / (1 - theta)
    # the ham engine's initial state (docs/moisture.md): first_row | constant | periodic
    initial_state: str = "first_row"
    initial_temperature: float | None = None  # degC
    initial_relative_humidity: float | None = None  # fraction
    initial_water_content: float | None = None  # kg/m3
    profiles: bool = False  # write the cell states (profiles.csv)


@dataclass(frozen=True)
class Study:
    """A validated study. Build it with :func:`load_study`.

    The feature tables (:mod:`wallcal.features`) are in :attr:`features` (top-level key -> the feature's
    spec), the three built in also as attributes: ``calibration`` is the ``[calibration]`` table, validated at
    load against the study's wall and sensors (a frozen :class:`~wallcal.calibration.ParameterSpace`: base
    values and absolute bounds from this wall), ``retrofit`` the ``[retrofit]`` table
    (:class:`~wallcal.retrofitting.config.RetrofitSpec`), ``building`` the ``[building]`` table
    (:class:`~wallcal.building.config.BuildingSpec`); each None when the study has no such table.
    """

    name: str
    wall: Wall
    data: DataSpec
    exterior: BoundarySpec
    interior: BoundarySpec
    sensors: tuple[SensorSpec, ...]
    period: PeriodSpec
    simulation: SimulationSpec
    description: str = ""
    calibration: Any = None  # wallcal.calibration.ParameterSpace, from the [calibration] table
    retrofit: Any = None  # wallcal.retrofitting.config.RetrofitSpec, from the [retrofit] table
    building: Any = None  # wallcal.building.config.BuildingSpec, from the [building] table
    features: dict = field(default_factory=dict, compare=False, repr=False)
    path: Path | None = None
    raw: dict = field(default_factory=dict, compare=False, repr=False)
    sha256: str = ""

    @property
    def has_moisture(self) -> bool:
        """The study needs an engine with the ``moisture`` capability (humidity sensors or boundaries)."""
        return any(s.quantity in MOISTURE_QUANTITIES for s in self.sensors) or any(
            boundary_type(b.type).moisture for b in (self.exterior, self.interior)
        )

    def sensor(self, name: str) -> SensorSpec:
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(name)

    def replace(self, **changes) -> Study:
        import dataclasses

        return dataclasses.replace(self, **changes)


# ============================================================================ the study
#: The core's top-level keys; the feature tables' keys come from :mod:`wallcal.features`.
CORE_KEYS = ("study", "wall", "data", "boundary", "sensors", "period", "simulation")
STUDY_KEYS = ("name", "description")
DATA_KEYS = (
    "file",
    "time_column",
    "time_format",
    "start",
    "utc_offset",
    "max_gap",
    "separator",
    "remove_spikes",
    "spike_sigma",
    "files",
)
DATA_FILE_KEYS = ("file", "time_column", "columns", "prefix", "separator")
BOUNDARY_KEYS = (
    "type",
    "column",
    "surface_coefficient",
    "unit",
    "positive",
    "offset",
    "humidity_column",
    "humidity_unit",
    "vapour_coefficient",
)
SENSOR_KEYS = (
    "name",
    "column",
    "quantity",
    "face",
    "depth",
    "depth_from",
    "accuracy",
    "accuracy_relative",
    "unit",
    "positive",
    "weight",
    "offset",
)
PERIOD_KEYS = ("warmup_start", "start", "end", "validation_start", "validation_end")
SIMULATION_KEYS = (
    "engine",
    "time_step",
    "grid_constant",
    "node_rule",
    "stiff_limit",
    "initial_state",
    "initial_temperature",
    "initial_relative_humidity",
    "initial_water_content",
    "profiles",
)


def _parse_data_files(dt_: Table, problems: Problems, base_dir: Path | None) -> tuple[DataFileSpec, ...]:
    """``[[data.files]]``: several files joined on their timestamps."""
    default_time = dt_.raw("time_column", "timestamp")
    default_time = default_time if isinstance(default_time, str) else "timestamp"
    out: list[DataFileSpec] = []
    names: dict[str, str] = {}
    tables = dt_.tables("files", DATA_FILE_KEYS)
    if isinstance(dt_.raw("files"), list) and not dt_.raw("files"):
        problems.add(dt_.at("files"), "list at least one file")
    for ft in tables:
        fname = ft.str("file")
        time_col = ft.str("time_column", default_time)
        prefix = ft.str("prefix", "")
        sep = ft.str("separator", None)
        columns = None
        if ft.has("columns"):
            cols = ft.raw("columns")
            if ft.has("prefix"):
                problems.add(ft.path, "give columns (a mapping) or prefix, not both")
            if not isinstance(cols, dict) or not cols:
                problems.add(
                    ft.at("columns"),
                    f'must be a non-empty table {{ name_in_study = "column_in_file" }}, got {describe(cols)}',
                )
            else:
                pairs = []
                for k, v in cols.items():
                    if not isinstance(v, str) or not v:
                        problems.add(f"{ft.at('columns')}.{k}", f"must be a column name (a string), got {describe(v)}")
                        continue
                    if time_col is not None and v == time_col:
                        problems.add(f"{ft.at('columns')}.{k}", f"{v!r} is the file's time column")
                        continue
                    if k in names:
                        problems.add(f"{ft.at('columns')}.{k}", f"the name {k!r} is already taken by {names[k]}")
                        continue
                    names[k] = f"{ft.path} ({fname})"
                    pairs.append((k, v))
                columns = tuple(pairs)
        if fname is None or time_col is None:
            continue
        out.append(
            DataFileSpec(
                file=(base_dir / fname) if base_dir else Path(fname),
                time_column=time_col,
                columns=columns,
                prefix=prefix or "",
                separator=sep,
            )
        )
    return tuple(out)


def load_study(path: str | Path) -> Study:
    """Read and validate a study file.

    Parameters
    ----------
    path : str or Path
        The study TOML file. Relative data and wall files are relative to it.

    Returns
    -------
    Study

    Raises
    ------
    StudyError
        Listing every problem found, each with its key path.
    """
    path = Path(path)
    raw = read_toml(path)
    study = parse_study(raw, base_dir=path.parent, source=str(path))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return study.replace(path=path, sha256=digest)


def parse_study(raw: dict, base_dir: Path | None = None, source: str | None = None) -> Study:
    """Validate a study given as a dict (the parsed TOML)."""
    problems = Problems()
    top = Table(raw, "", problems, CORE_KEYS + feature_keys())
    st = top.table("study", STUDY_KEYS, required=False)
    name = (st.str("name", "") if st else "") or ""
    desc = (st.str("description", "") if st else "") or ""

    wt = top.table("wall", WALL_KEYS)
    n_problems = len(problems)
    wall = parse_wall(wt, problems, base_dir) if wt else None
    wall_clean = wall is not None and len(problems) == n_problems  # calibration parameters are checked against it

    dt_ = top.table("data", DATA_KEYS)
    data = None
    if dt_:
        files: tuple[DataFileSpec, ...] = ()
        if dt_.has("files"):
            fname = None
            if dt_.has("file"):
                problems.add(dt_.at("file"), "give either data.file (one file) or [[data.files]] (several), not both")
            files = _parse_data_files(dt_, problems, base_dir)
        else:
            fname = dt_.str("file")
        time_format = dt_.str("time_format", "iso", choices=TIME_FORMATS)
        start = dt_.datetime("start", None)
        if time_format == "elapsed_seconds" and start is None and dt_.ok:
            problems.add(dt_.at("start"), 'required with time_format = "elapsed_seconds" (the date-time of t = 0)')
        sep = dt_.str("separator", None)
        utc_offset = dt_.str("utc_offset", None)
        if utc_offset is not None:
            try:
                _dt.datetime.strptime(utc_offset.replace("Z", "+00:00"), "%z")
            except ValueError:
                problems.add(dt_.at("utc_offset"), f'must look like "+01:00", got {utc_offset!r}')
        if files:
            data_file = files[0].file.parent
        else:
            data_file = (base_dir / fname) if (fname and base_dir) else Path(fname or "")
        data = DataSpec(
            file=data_file,
            files=files,
            time_column=dt_.str("time_column", "timestamp") or "timestamp",
            time_format=time_format or "iso",
            start=start,
            utc_offset=utc_offset,
            max_gap=dt_.num("max_gap", 7200.0, gt=0.0) or 7200.0,
            separator=sep,
            remove_spikes=dt_.bool("remove_spikes", True),
            spike_sigma=dt_.num("spike_sigma", 8.0, gt=2.0) or 8.0,
        )

    bt = top.table("boundary", FACES)
    bounds: dict[str, BoundarySpec | None] = {"exterior": None, "interior": None}
    if bt:
        for face in FACES:
            ft = bt.table(face, BOUNDARY_KEYS)
            if not ft:
                continue
            btype = ft.str("type", choices=boundary_type_names(in_studies=True))
            bkind = boundary_type(btype) if btype else None
            col = ft.str("column")
            h = None
            robin, flux = (
                " or ".join(f'"{n}"' for n in boundary_type_names(in_studies=True) if test(boundary_type(n)))
                for test in (lambda t: t.needs_surface_coefficient, lambda t: t.quantity == "heat_flux")
            )
            if bkind is not None and bkind.needs_surface_coefficient:
                h = ft.num("surface_coefficient", gt=0.0)
            elif ft.has("surface_coefficient"):
                problems.add(ft.at("surface_coefficient"), f"only for type = {robin}, not {btype!r}")
            is_flux = bkind is not None and bkind.quantity == "heat_flux"
            if is_flux:
                unit = ft.str("unit", "W/m2", choices=("W/m2",))
                if ft.has("unit") and unit is None:
                    unit = "W/m2"
            else:
                unit = ft.str("unit", "degC", choices=TEMPERATURE_UNITS)
            positive = ft.str("positive", "towards_interior", choices=FLUX_DIRECTIONS)
            if ft.has("positive") and not is_flux:
                problems.add(ft.at("positive"), f"only for type = {flux}")
            offset = ft.num("offset", 0.0, ge=-1e6, le=1e6)
            hcol, hunit, beta = None, "fraction", None
            if bkind is not None and bkind.moisture:
                hcol = ft.str("humidity_column")
                hunit = ft.str("humidity_unit", choices=HUMIDITY_UNITS)
                if bkind.needs_vapour_coefficient:
                    beta = ft.num("vapour_coefficient", ge=0.0, le=1e-5)
                elif ft.has("vapour_coefficient"):
                    problems.add(ft.at("vapour_coefficient"), 'only for type = "air_temperature_humidity"')
            else:
                for k in ("humidity_column", "humidity_unit", "vapour_coefficient"):
                    if ft.has(k):
                        problems.add(
                            ft.at(k),
                            'only for type = "surface_temperature_humidity" or "air_temperature_humidity"',
                        )
            if btype and col:
                bounds[face] = BoundarySpec(
                    face=face,
                    type=btype,
                    column=col,
                    surface_coefficient=h,
                    unit=unit or "degC",
                    positive=positive or "towards_interior",
                    offset=offset or 0.0,
                    humidity_column=hcol,
                    humidity_unit=hunit or "fraction",
                    vapour_coefficient=beta,
                )
        if all(b is not None and not boundary_type(b.type).fixes_temperature_level for b in bounds.values()):
            problems.add(
                "boundary",
                "heat-flux boundaries on both faces leave the temperature level undetermined: "
                "impose a temperature on at least one face",
            )

    sensors: list[SensorSpec] = []
    sensor_names: set[str] = set()
    probe_names = {p.name for p in wall.probes} if wall else set()
    for sn in top.tables("sensors", SENSOR_KEYS):
        sname = sn.str("name")
        col = sn.str("column")
        quantity = sn.str("quantity", "temperature", choices=QUANTITIES)
        face = sn.str("face", None, choices=FACES)
        acc = sn.num("accuracy", None, gt=0.0)
        accr = sn.num("accuracy_relative", None, gt=0.0, lt=1.0)
        weight = sn.num("weight", 1.0, ge=0.0)
        offset = sn.num("offset", 0.0, ge=-1e6, le=1e6)
        positive = sn.str("positive", "towards_interior", choices=FLUX_DIRECTIONS)
        depth = None
        if quantity == "heat_flux":
            unit = sn.str("unit", "W/m2", choices=("W/m2",))
            if sn.has("depth"):
                depth = sn.num("depth", ge=0.0)
                depth_from = sn.str("depth_from", "exterior", choices=FACES)
                if sn.has("face"):
                    problems.add(sn.path, "give face (a heat flux at a face) or depth (inside the wall), not both")
                elif depth is not None and wall is not None:
                    if not 0.0 < depth < wall.thickness:
                        problems.add(
                            sn.at("depth"),
                            f"must be inside the wall (0 < depth < {wall.thickness:g} m); "
                            'for a face, give face = "exterior" or "interior"',
                        )
                        depth = None
                    elif depth_from == "interior":
                        depth = wall.thickness - depth
            elif face is None and sn.ok and not sn.has("face"):
                problems.add(
                    sn.at("face"),
                    'required for a heat_flux sensor: "exterior" or "interior" (or a depth inside the wall)',
                )
        else:
            if sn.has("depth") or sn.has("depth_from"):
                problems.add(sn.at("depth"), "only for heat_flux sensors; a temperature sensor's depth is its probe's")
            if quantity == "relative_humidity":
                unit = sn.str("unit", choices=HUMIDITY_UNITS)  # required: a percent column read as a fraction
                if unit == "percent" and acc is not None:
                    acc = acc / 100.0
            elif quantity == "water_content":
                unit = sn.str("unit", "kg/m3", choices=("kg/m3",))
            else:
                unit = sn.str("unit", "degC", choices=TEMPERATURE_UNITS)
            if sn.has("face"):
                problems.add(sn.at("face"), "only for heat_flux sensors; a temperature sensor is a probe of the wall")
            if sn.has("positive"):
                problems.add(sn.at("positive"), "only for heat_flux sensors")
            if sname is not None and wall is not None and sname not in probe_names:
                problems.add(
                    sn.at("name"),
                    f"{sname!r} is not a probe of the wall; "
                    f"{closest(sname, sorted(probe_names)) if probe_names else 'the wall has no probes'}",
                )
        if acc is not None and accr is not None:
            problems.add(sn.path, "give accuracy or accuracy_relative, not both")
        if sname is not None:
            if sname in sensor_names:
                problems.add(sn.at("name"), f"sensor {sname!r} is defined twice")
            sensor_names.add(sname)
        if sname and col and quantity:
            sensors.append(
                SensorSpec(
                    name=sname,
                    column=col,
                    quantity=quantity,
                    face=face,
                    depth=depth,
                    accuracy=acc,
                    accuracy_relative=accr,
                    unit=unit or "degC",
                    positive=positive or "towards_interior",
                    weight=weight,
                    offset=offset or 0.0,
                )
            )
    if top.has("sensors") and isinstance(top.raw("sensors"), list) and not top.raw("sensors"):
        problems.add("sensors", "list at least one sensor to compare with")

    pt = top.table("period", PERIOD_KEYS)
    period = None
    if pt:
        warm = pt.datetime("warmup_start", None)
        start = pt.datetime("start")
        end = pt.datetime("end")
        if start and end and not end > start:
            problems.add("period.end", f"must be after period.start ({start.isoformat()}), got {end.isoformat()}")
        if warm and start and warm > start:
            problems.add(
                "period.warmup_start", f"must not be after period.start ({start.isoformat()}), got {warm.isoformat()}"
            )
        vs, ve = pt.datetime("validation_start", None), pt.datetime("validation_end", None)
        if (vs is None) != (ve is None):
            problems.add(
                "period.validation_end" if ve is None else "period.validation_start",
                "give both validation_start and validation_end (the held-out window), or neither",
            )
        elif vs and ve and start and end:
            if not ve > vs:
                problems.add(
                    "period.validation_end", f"must be after validation_start ({vs.isoformat()}), got {ve.isoformat()}"
                )
            elif vs <= start:
                problems.add(
                    "period.validation_start",
                    f"must be after period.start ({start.isoformat()}): the fitting needs the start of the period, "
                    f"got {vs.isoformat()}",
                )
        if start and end:
            period = PeriodSpec(warmup_start=warm, start=start, end=end, validation_start=vs, validation_end=ve)

    smt = top.table("simulation", SIMULATION_KEYS, required=False)
    sim = SimulationSpec()
    if smt:
        sim = SimulationSpec(
            engine=smt.str("engine", DEFAULT_ENGINE, choices=engine_names(in_studies=True)) or DEFAULT_ENGINE,
            time_step=smt.num("time_step", 60.0, gt=0.0, le=86400.0) or 60.0,
            grid_constant=smt.num("grid_constant", 2.0, gt=0.0, le=1000.0) or 2.0,
            node_rule=smt.str("node_rule", "wallcal", choices=("wallcal", "energyplus")) or "wallcal",
            stiff_limit=smt.num("stiff_limit", None, gt=0.0),
            initial_state=smt.str("initial_state", "first_row", choices=INITIAL_STATES) or "first_row",
            initial_temperature=smt.num("initial_temperature", None, ge=-100.0, le=200.0),
            initial_relative_humidity=smt.num("initial_relative_humidity", None, gt=0.0, le=1.0),
            initial_water_content=smt.num("initial_water_content", None, ge=0.0),
            profiles=smt.bool("profiles", False),
        )
        if sim.initial_state == "constant":
            if sim.initial_temperature is None:
                problems.add(smt.at("initial_temperature"), 'required with initial_state = "constant" (degC)')
            if (sim.initial_relative_humidity is None) == (sim.initial_water_content is None):
                problems.add(
                    smt.path,
                    'initial_state = "constant" needs initial_relative_humidity (a fraction) or '
                    "initial_water_content (kg/m3), one of them",
                )
        else:
            for k in ("initial_temperature", "initial_relative_humidity", "initial_water_content"):
                if smt.has(k):
                    problems.add(smt.at(k), 'only with initial_state = "constant"')
    ctx = StudyContext(wall, wall_clean, tuple(sensors), frozenset(sensor_names), base_dir)
    features = parse_features(raw if isinstance(raw, dict) else {}, problems, ctx)

    if problems:
        raise StudyError(problems, source=source)
    if wall is None or data is None or period is None or None in bounds.values():
        raise StudyError(["the study is incomplete (wall, data, boundary or period missing)"], source=source)
    study = Study(
        name=name,
        description=desc,
        wall=wall,
        data=data,
        exterior=bounds["exterior"],
        interior=bounds["interior"],
        sensors=tuple(sensors),
        period=period,
        simulation=sim,
        calibration=features.get("calibration"),
        retrofit=features.get("retrofit"),
        building=features.get("building"),
        features=features,
        raw=raw,
    )
    if study.has_moisture:
        _check_moisture(study, source)
    return study


def _check_moisture(study: Study, source: str | None) -> None:
    """A moisture study's layers must carry every hygric key the ham engine needs, and a constant initial
    water content must not exceed any layer's capillary saturation."""
    problems: list[str] = []
    sim = study.simulation
    for i, layer in enumerate(study.wall.layers):
        where = f"wall.layers[{i}] (id {layer.id!r})"
        try:
            mat = layer.hygric_material(where)
        except StudyError as exc:
            problems.extend(exc.problems)
            continue
        if sim.initial_state == "constant" and sim.initial_water_content is not None:
            w_sat = float(mat.w[0])
            if sim.initial_water_content > w_sat * (1 + 1e-9):
                problems.append(
                    f"simulation.initial_water_content: {sim.initial_water_content:g} kg/m3 is above the capillary "
                    f"saturation {w_sat:.4g} kg/m3 of {where}"
                )
    if problems:
        raise StudyError(problems, source=source)
