"""The study file: one TOML file describing a wall and a monitoring campaign.

Validated in one place (here). Every problem is reported at once with its key
path, e.g. ``wall.layers[2].conductivity: must be > 0, got -0.035``; unknown
keys are rejected with the closest valid name. ``docs/study-file.md``
documents every key.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import StudyError, closest
from .wall import Layer, Probe, Wall

ENGINES = ("fd-cn", "fd-implicit", "energyplus")
BOUNDARY_TYPES = ("surface_temperature", "air_temperature", "heat_flux")
QUANTITIES = ("temperature", "heat_flux")
FACES = ("exterior", "interior")
TEMPERATURE_UNITS = ("degC", "K")
FLUX_DIRECTIONS = ("towards_interior", "towards_exterior")
TIME_FORMATS = ("iso", "elapsed_seconds")

_MISSING = object()


# ============================================================================ spec objects
@dataclass(frozen=True)
class BoundarySpec:
    """A face's boundary condition as the study states it.

    ``type``: surface_temperature | air_temperature | heat_flux; ``column``: data
    column; ``surface_coefficient`` [W/(m2K)] for air_temperature; ``unit``:
    degC | K for temperatures; ``positive``: direction of a heat-flux column;
    ``offset``: added to the column after the unit and sign conversion (a declared
    sensor correction, degC or W/m2).
    """

    face: str
    type: str
    column: str
    surface_coefficient: float | None = None
    unit: str = "degC"
    positive: str = "towards_interior"
    offset: float = 0.0


@dataclass(frozen=True)
class SensorSpec:
    """A measured signal compared with the model.

    ``quantity``: temperature (``name`` is a probe of the wall) or heat_flux (at
    ``face``, or at ``depth`` [m from the exterior face] inside the wall). ``accuracy`` [degC or
    W/m2] or ``accuracy_relative`` [-].
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
    """Comparison period (both ends included) and the start of the warm-up."""

    warmup_start: _dt.datetime | None
    start: _dt.datetime
    end: _dt.datetime


@dataclass(frozen=True)
class SimulationSpec:
    """Engine and grid settings."""

    engine: str = "fd-cn"
    time_step: float = 60.0
    grid_constant: float = 2.0
    node_rule: str = "wallcal"
    stiff_limit: float = 10.0


@dataclass(frozen=True)
class Study:
    """A validated study. Build it with :func:`load_study`."""

    name: str
    wall: Wall
    data: DataSpec
    exterior: BoundarySpec
    interior: BoundarySpec
    sensors: tuple[SensorSpec, ...]
    period: PeriodSpec
    simulation: SimulationSpec
    description: str = ""
    calibration: dict = field(default_factory=dict)
    retrofit: Any = None  # wallcal.retrofitting.config.RetrofitSpec, from the [retrofit] table
    path: Path | None = None
    raw: dict = field(default_factory=dict, compare=False, repr=False)
    sha256: str = ""

    def sensor(self, name: str) -> SensorSpec:
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(name)

    def replace(self, **changes) -> Study:
        import dataclasses

        return dataclasses.replace(self, **changes)


# ============================================================================ validation helpers
class _Problems(list):
    def add(self, path: str, msg: str) -> None:
        self.append(f"{path}: {msg}")


def _describe(value: Any) -> str:
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "a list"
    return repr(value)


class _Table:
    """Reads one TOML table, recording problems and unknown keys."""

    def __init__(self, data: Any, path: str, problems: _Problems, allowed: tuple[str, ...]):
        self.path = path
        self.problems = problems
        self.allowed = allowed
        self.ok = isinstance(data, dict)
        if not self.ok:
            problems.add(path, f"must be a table, got {_describe(data)}")
            data = {}
        self.data = data
        for key in data:
            if key not in allowed:
                problems.add(self._p(key), f"unknown key; {closest(key, allowed)}")

    def _p(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default=None):
        return self.data.get(key, default)

    def str(self, key: str, default=_MISSING, choices: tuple[str, ...] | None = None):
        v = self.data.get(key, _MISSING)
        if v is _MISSING:
            if default is _MISSING:
                self.problems.add(self._p(key), "required, missing")
                return None
            return default
        if not isinstance(v, str):
            self.problems.add(self._p(key), f"must be a string, got {_describe(v)}")
            return None if default is _MISSING else default
        if choices is not None and v not in choices:
            self.problems.add(self._p(key), f"must be one of {', '.join(choices)}; got {v!r}; {closest(v, choices)}")
            return None if default is _MISSING else default
        return v

    def num(self, key: str, default=_MISSING, *, gt=None, ge=None, le=None, lt=None, integer=False):
        v = self.data.get(key, _MISSING)
        if v is _MISSING:
            if default is _MISSING:
                self.problems.add(self._p(key), "required, missing")
            return None if default is _MISSING else default
        return _check_number(v, self._p(key), self.problems, gt=gt, ge=ge, le=le, lt=lt, integer=integer)

    def bool(self, key: str, default: bool) -> bool:
        v = self.data.get(key, _MISSING)
        if v is _MISSING:
            return default
        if not isinstance(v, bool):
            self.problems.add(self._p(key), f"must be true or false, got {_describe(v)}")
            return default
        return v

    def datetime(self, key: str, default=_MISSING):
        v = self.data.get(key, _MISSING)
        if v is _MISSING:
            if default is _MISSING:
                self.problems.add(self._p(key), "required, missing")
                return None
            return default
        return _to_datetime(v, self._p(key), self.problems)

    def table(self, key: str, allowed: tuple[str, ...], required=True) -> _Table | None:
        v = self.data.get(key, _MISSING)
        if v is _MISSING:
            if required:
                self.problems.add(self._p(key), "required table, missing")
            return None
        return _Table(v, self._p(key), self.problems, allowed)

    def tables(self, key: str, allowed: tuple[str, ...], required=True) -> list[_Table]:
        v = self.data.get(key, _MISSING)
        if v is _MISSING:
            if required:
                self.problems.add(self._p(key), "required, missing (an array of tables [[...]])")
            return []
        if not isinstance(v, list):
            self.problems.add(self._p(key), f"must be an array of tables [[{self._p(key)}]], got {_describe(v)}")
            return []
        return [_Table(item, f"{self._p(key)}[{i}]", self.problems, allowed) for i, item in enumerate(v)]


def _check_number(v, path, problems, *, gt=None, ge=None, le=None, lt=None, integer=False):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        problems.add(path, f"must be a number, got {_describe(v)}")
        return None
    if isinstance(v, float) and not math.isfinite(v):
        problems.add(path, f"must be a finite number, got {v}")
        return None
    if isinstance(v, int) and abs(v) > 10**15:  # float(v) would overflow for TOML's unbounded integers
        problems.add(path, "is out of any physical range, got an integer beyond 1e15")
        return None
    if integer and not float(v).is_integer():
        problems.add(path, f"must be a whole number, got {v}")
        return None
    v = float(v)
    if abs(v) > 1e15:
        problems.add(path, f"is out of any physical range, got {v:g}")
        return None
    if gt is not None and not v > gt:
        problems.add(path, f"must be > {gt:g}, got {v:g}")
        return None
    if ge is not None and not v >= ge:
        problems.add(path, f"must be >= {ge:g}, got {v:g}")
        return None
    if lt is not None and not v < lt:
        problems.add(path, f"must be < {lt:g}, got {v:g}")
        return None
    if le is not None and not v <= le:
        problems.add(path, f"must be <= {le:g}, got {v:g}")
        return None
    return v


def _to_datetime(v, path, problems):
    if isinstance(v, _dt.datetime):
        if v.tzinfo is not None:
            problems.add(path, "give a local date-time without a time-zone offset (local standard time)")
            return None
        return v
    if isinstance(v, _dt.date):
        return _dt.datetime(v.year, v.month, v.day)
    if isinstance(v, str):
        try:
            out = _dt.datetime.fromisoformat(v)
        except ValueError:
            problems.add(path, f"must be a date-time like 2025-05-30T00:00:00, got {v!r}")
            return None
        if out.tzinfo is not None:
            problems.add(path, "give a local date-time without a time-zone offset (local standard time)")
            return None
        return out
    problems.add(path, f"must be a date-time like 2025-05-30T00:00:00, got {_describe(v)}")
    return None


# ============================================================================ the wall
LAYER_KEYS = (
    "id",
    "material",
    "thickness",
    "conductivity",
    "density",
    "specific_heat",
    "conductivity_temperature_coefficient",
    "reference_temperature",
    "conductivity_table",
    "contact_resistance",
    "thermal_resistance",
    "vapour_resistance_factor",
)
PROBE_KEYS = ("name", "depth", "depth_from", "side")
WALL_KEYS = ("name", "description", "layers", "probes", "file")


def _parse_wall(t: _Table, problems: _Problems, base_dir: Path | None) -> Wall | None:
    if t.has("file"):
        others = [k for k in t.data if k not in ("file",)]
        fname = t.str("file")
        if others:
            problems.add(t.path, f"with 'file', give no other wall keys (found {', '.join(others)})")
        if fname is None:
            return None
        path = (base_dir / fname) if base_dir else Path(fname)
        try:
            return load_wall(path)
        except StudyError as exc:
            for p in exc.problems:
                problems.append(f"{t.path}.file ({path}): {p}")
            return None
    layers: list[Layer] = []
    ids: set[str] = set()
    geometry_thickness = 0.0
    for lt in t.tables("layers", LAYER_KEYS):
        lid = lt.data.get("id")
        if isinstance(lid, int) and not isinstance(lid, bool):
            lid = str(lid)
        elif not isinstance(lid, str):
            problems.add(
                lt._p("id"),
                'required, a string such as "3"' if lid is None else f"must be a string, got {_describe(lid)}",
            )
            lid = None
        if lid is not None:
            if lid in ids:
                problems.add(lt._p("id"), f"layer id {lid!r} is used twice")
            ids.add(lid)
        massless = lt.has("thermal_resistance")
        thickness = lt.num(
            "thickness", 0.0 if massless else _MISSING, ge=0.0 if massless else None, gt=None if massless else 0.0
        )
        if thickness is not None:
            geometry_thickness += thickness  # probes are checked against every valid thickness
        kw: dict[str, Any] = {}
        if massless:
            kw["thermal_resistance"] = lt.num("thermal_resistance", gt=0.0)
            for k in (
                "conductivity",
                "density",
                "specific_heat",
                "conductivity_table",
                "conductivity_temperature_coefficient",
            ):
                if lt.has(k):
                    problems.add(lt._p(k), "a no-mass layer (thermal_resistance) takes no " + k)
        else:
            table = None
            if lt.has("conductivity_table"):
                table = _parse_table(lt.raw("conductivity_table"), lt._p("conductivity_table"), problems)
            kw["conductivity"] = lt.num("conductivity", None if table is not None else _MISSING, gt=0.0)
            kw["density"] = lt.num("density", gt=0.0)
            kw["specific_heat"] = lt.num("specific_heat", gt=0.0)
            kw["conductivity_temperature_coefficient"] = lt.num(
                "conductivity_temperature_coefficient", 0.0, ge=-0.2, le=0.2
            )
            kw["conductivity_table"] = table
            if table is not None and kw["conductivity_temperature_coefficient"]:
                problems.add(
                    lt._p("conductivity_table"),
                    "give either conductivity_table or conductivity_temperature_coefficient, not both",
                )
        kw["reference_temperature"] = lt.num("reference_temperature", 10.0, ge=-100.0, le=200.0)
        kw["contact_resistance"] = lt.num("contact_resistance", 0.0, ge=0.0)
        kw["vapour_resistance_factor"] = lt.num("vapour_resistance_factor", None, gt=0.0)
        material = lt.str("material", "")
        if (
            None in (lid, thickness)
            or any(kw.get(k) is None for k in ("density", "specific_heat", "thermal_resistance") if k in kw)
            or ("conductivity" in kw and kw["conductivity"] is None and kw.get("conductivity_table") is None)
        ):
            continue
        if kw.get("conductivity_table") is not None and kw.get("conductivity") is None:
            kw["conductivity"] = None
        layers.append(
            Layer(
                id=lid,
                thickness=thickness,
                material=material or "",
                **{k: v for k, v in kw.items() if v is not None or k == "conductivity_table"},
            )
        )
    if t.has("layers") and isinstance(t.raw("layers"), list) and not t.raw("layers"):
        problems.add(t._p("layers"), "the wall needs at least one layer")
    total = geometry_thickness  # also counts layers dropped for another bad value: no follow-up problems
    probes: list[Probe] = []
    names: set[str] = set()
    for pt in t.tables("probes", PROBE_KEYS, required=False):
        name = pt.str("name")
        depth = pt.num("depth", ge=0.0)
        depth_from = pt.str("depth_from", "exterior", choices=FACES)
        side = pt.str("side", None, choices=FACES)
        if name is not None:
            if name in names:
                problems.add(pt._p("name"), f"probe {name!r} is defined twice")
            names.add(name)
        if name is None or depth is None:
            continue
        if layers and depth > total * (1 + 1e-12):
            problems.add(pt._p("depth"), f"{depth:g} m is beyond the wall's thickness {total:g} m")
            continue
        if depth_from == "interior":
            depth = max(total - depth, 0.0)
        probes.append(Probe(name=name, depth=depth, side=side))
    name = t.str("name", "")
    desc = t.str("description", "")
    if not layers:
        return None
    return Wall(layers=tuple(layers), probes=tuple(probes), name=name or "", description=desc or "")


def _parse_table(v, path, problems):
    if not isinstance(v, list) or len(v) < 2:
        problems.add(path, "must be a list of at least two [temperature_degC, conductivity] pairs")
        return None
    out = []
    for i, pair in enumerate(v):
        if not isinstance(pair, list) or len(pair) != 2:
            problems.add(f"{path}[{i}]", "must be a pair [temperature_degC, conductivity]")
            return None
        tc = _check_number(pair[0], f"{path}[{i}][0]", problems)
        lam = _check_number(pair[1], f"{path}[{i}][1]", problems, gt=0.0)
        if tc is None or lam is None:
            return None
        out.append((tc, lam))
    if any(b[0] <= a[0] for a, b in zip(out, out[1:], strict=False)):
        problems.add(path, "temperatures must increase")
        return None
    return tuple(out)


def load_wall(path: str | Path) -> Wall:
    """Read a wall file (a TOML file with a ``[wall]`` table, or a study file).

    Raises
    ------
    StudyError
        With every problem found.
    """
    path = Path(path)
    raw = _read_toml(path)
    problems = _Problems()
    if "wall" not in raw:
        raise StudyError(["wall: required table, missing"], source=str(path))
    wt = _Table(raw["wall"], "wall", problems, WALL_KEYS)
    wall = _parse_wall(wt, problems, path.parent)
    if problems:
        raise StudyError(problems, source=str(path))
    if wall is None:
        raise StudyError(["wall: no valid layer"], source=str(path))
    return wall


def _read_toml(path: Path) -> dict:
    if not path.exists():
        raise StudyError([f"file not found: {path}"], source=str(path))
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise StudyError([f"cannot read the file: {exc.strerror}"], source=str(path)) from exc
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise StudyError(
            [f"not valid UTF-8 text (byte {exc.start}): save the file as UTF-8"], source=str(path)
        ) from exc
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError([f"not valid TOML: {exc}"], source=str(path)) from exc


# ============================================================================ the study
TOP_KEYS = ("study", "wall", "data", "boundary", "sensors", "period", "simulation", "calibration", "retrofit")
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
BOUNDARY_KEYS = ("type", "column", "surface_coefficient", "unit", "positive", "offset")
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
PERIOD_KEYS = ("warmup_start", "start", "end")
SIMULATION_KEYS = ("engine", "time_step", "grid_constant", "node_rule", "stiff_limit")


def _parse_data_files(dt_: _Table, problems: _Problems, base_dir: Path | None) -> tuple[DataFileSpec, ...]:
    """``[[data.files]]``: several files joined on their timestamps."""
    default_time = dt_.raw("time_column", "timestamp")
    default_time = default_time if isinstance(default_time, str) else "timestamp"
    out: list[DataFileSpec] = []
    names: dict[str, str] = {}
    tables = dt_.tables("files", DATA_FILE_KEYS)
    if isinstance(dt_.raw("files"), list) and not dt_.raw("files"):
        problems.add(dt_._p("files"), "list at least one file")
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
                    ft._p("columns"),
                    f'must be a non-empty table {{ name_in_study = "column_in_file" }}, got {_describe(cols)}',
                )
            else:
                pairs = []
                for k, v in cols.items():
                    if not isinstance(v, str) or not v:
                        problems.add(f"{ft._p('columns')}.{k}", f"must be a column name (a string), got {_describe(v)}")
                        continue
                    if time_col is not None and v == time_col:
                        problems.add(f"{ft._p('columns')}.{k}", f"{v!r} is the file's time column")
                        continue
                    if k in names:
                        problems.add(f"{ft._p('columns')}.{k}", f"the name {k!r} is already taken by {names[k]}")
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
    raw = _read_toml(path)
    study = parse_study(raw, base_dir=path.parent, source=str(path))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return study.replace(path=path, sha256=digest)


def parse_study(raw: dict, base_dir: Path | None = None, source: str | None = None) -> Study:
    """Validate a study given as a dict (the parsed TOML)."""
    problems = _Problems()
    top = _Table(raw, "", problems, TOP_KEYS)
    st = top.table("study", STUDY_KEYS, required=False)
    name = (st.str("name", "") if st else "") or ""
    desc = (st.str("description", "") if st else "") or ""

    wt = top.table("wall", WALL_KEYS)
    wall = _parse_wall(wt, problems, base_dir) if wt else None

    dt_ = top.table("data", DATA_KEYS)
    data = None
    if dt_:
        files: tuple[DataFileSpec, ...] = ()
        if dt_.has("files"):
            fname = None
            if dt_.has("file"):
                problems.add(dt_._p("file"), "give either data.file (one file) or [[data.files]] (several), not both")
            files = _parse_data_files(dt_, problems, base_dir)
        else:
            fname = dt_.str("file")
        time_format = dt_.str("time_format", "iso", choices=TIME_FORMATS)
        start = dt_.datetime("start", None)
        if time_format == "elapsed_seconds" and start is None and dt_.ok:
            problems.add(dt_._p("start"), 'required with time_format = "elapsed_seconds" (the date-time of t = 0)')
        sep = dt_.str("separator", None)
        utc_offset = dt_.str("utc_offset", None)
        if utc_offset is not None:
            try:
                _dt.datetime.strptime(utc_offset.replace("Z", "+00:00"), "%z")
            except ValueError:
                problems.add(dt_._p("utc_offset"), f'must look like "+01:00", got {utc_offset!r}')
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
            btype = ft.str("type", choices=BOUNDARY_TYPES)
            col = ft.str("column")
            h = None
            if btype == "air_temperature":
                h = ft.num("surface_coefficient", gt=0.0)
            elif ft.has("surface_coefficient"):
                problems.add(ft._p("surface_coefficient"), f'only for type = "air_temperature", not {btype!r}')
            if btype == "heat_flux":
                unit = ft.str("unit", "W/m2", choices=("W/m2",))
                if ft.has("unit") and unit is None:
                    unit = "W/m2"
            else:
                unit = ft.str("unit", "degC", choices=TEMPERATURE_UNITS)
            positive = ft.str("positive", "towards_interior", choices=FLUX_DIRECTIONS)
            if ft.has("positive") and btype != "heat_flux":
                problems.add(ft._p("positive"), 'only for type = "heat_flux"')
            offset = ft.num("offset", 0.0, ge=-1e6, le=1e6)
            if btype and col:
                bounds[face] = BoundarySpec(
                    face=face,
                    type=btype,
                    column=col,
                    surface_coefficient=h,
                    unit=unit or "degC",
                    positive=positive or "towards_interior",
                    offset=offset or 0.0,
                )
        if all(b is not None and b.type == "heat_flux" for b in bounds.values()):
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
                            sn._p("depth"),
                            f"must be inside the wall (0 < depth < {wall.thickness:g} m); "
                            'for a face, give face = "exterior" or "interior"',
                        )
                        depth = None
                    elif depth_from == "interior":
                        depth = wall.thickness - depth
            elif face is None and sn.ok and not sn.has("face"):
                problems.add(
                    sn._p("face"),
                    'required for a heat_flux sensor: "exterior" or "interior" (or a depth inside the wall)',
                )
        else:
            if sn.has("depth") or sn.has("depth_from"):
                problems.add(sn._p("depth"), "only for heat_flux sensors; a temperature sensor's depth is its probe's")
            unit = sn.str("unit", "degC", choices=TEMPERATURE_UNITS)
            if sn.has("face"):
                problems.add(sn._p("face"), "only for heat_flux sensors; a temperature sensor is a probe of the wall")
            if sn.has("positive"):
                problems.add(sn._p("positive"), "only for heat_flux sensors")
            if sname is not None and wall is not None and sname not in probe_names:
                problems.add(
                    sn._p("name"),
                    f"{sname!r} is not a probe of the wall; "
                    f"{closest(sname, sorted(probe_names)) if probe_names else 'the wall has no probes'}",
                )
        if acc is not None and accr is not None:
            problems.add(sn.path, "give accuracy or accuracy_relative, not both")
        if sname is not None:
            if sname in sensor_names:
                problems.add(sn._p("name"), f"sensor {sname!r} is defined twice")
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
        if start and end:
            period = PeriodSpec(warmup_start=warm, start=start, end=end)

    smt = top.table("simulation", SIMULATION_KEYS, required=False)
    sim = SimulationSpec()
    if smt:
        sim = SimulationSpec(
            engine=smt.str("engine", "fd-cn", choices=ENGINES) or "fd-cn",
            time_step=smt.num("time_step", 60.0, gt=0.0, le=86400.0) or 60.0,
            grid_constant=smt.num("grid_constant", 2.0, gt=0.0, le=1000.0) or 2.0,
            node_rule=smt.str("node_rule", "wallcal", choices=("wallcal", "energyplus")) or "wallcal",
            stiff_limit=smt.num("stiff_limit", 10.0, gt=0.0) or 10.0,
        )
    calib = top.raw("calibration", {}) or {}
    if top.has("calibration") and not isinstance(calib, dict):
        problems.add("calibration", "must be a table")
        calib = {}
    retrofit = None
    if top.has("retrofit"):
        from .retrofitting.config import parse_retrofit

        retrofit = parse_retrofit(top.raw("retrofit"), problems, base_dir, wall)

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
        calibration=calib,
        retrofit=retrofit,
        raw=raw,
    )
    return study


# ============================================================================ writing walls
def wall_to_dict(wall: Wall) -> dict:
    """The ``[wall]`` table of a wall file (inverse of :func:`load_wall`)."""
    layers = []
    for layer in wall.layers:
        d: dict[str, Any] = {"id": layer.id}
        if layer.material:
            d["material"] = layer.material
        d["thickness"] = layer.thickness
        if layer.is_massless:
            d["thermal_resistance"] = layer.thermal_resistance
        else:
            if layer.conductivity is not None:
                d["conductivity"] = layer.conductivity
            d["density"] = layer.density
            d["specific_heat"] = layer.specific_heat
            if layer.conductivity_temperature_coefficient:
                d["conductivity_temperature_coefficient"] = layer.conductivity_temperature_coefficient
            if layer.conductivity_table is not None:
                d["conductivity_table"] = [list(p) for p in layer.conductivity_table]
        if layer.reference_temperature != 10.0 or layer.is_temperature_dependent:
            d["reference_temperature"] = layer.reference_temperature
        if layer.contact_resistance:
            d["contact_resistance"] = layer.contact_resistance
        if layer.vapour_resistance_factor is not None:
            d["vapour_resistance_factor"] = layer.vapour_resistance_factor
        layers.append(d)
    out: dict[str, Any] = {}
    if wall.name:
        out["name"] = wall.name
    if wall.description:
        out["description"] = wall.description
    out["layers"] = layers
    if wall.probes:
        probes = []
        for p in wall.probes:
            d = {"name": p.name, "depth": p.depth}
            if p.side:
                d["side"] = p.side
            probes.append(d)
        out["probes"] = probes
    return out


def dump_wall(wall: Wall, header: str = "") -> str:
    """A wall file (TOML text) that :func:`load_wall` reads back, and that a study can use with
    ``[wall] file = "..."``."""
    import tomli_w

    text = tomli_w.dumps({"wall": wall_to_dict(wall)})
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    return text
