"""From a study to simulated-versus-measured series and metrics.

Pipeline: :func:`wallcal.study.load_study` -> :func:`wallcal.data.load_measurements`
-> :func:`prepare` (boundary series on the engine grid, comparison times) ->
engine (through the contract of :mod:`wallcal.engines.base`) -> :class:`SimulationResult`
(series, metrics, summary).

Data preparation happens once: :func:`prepare` keeps its last few results (per study object, data
files' modification stamps, engine, time step, C and node rule), and a :class:`Prepared` keeps the
engine's prepared state, the measured values as an array and the summary table, so that a repeated
``simulate(study)`` costs little more than the engine run. Calibration and the analyses reuse the
:class:`Prepared` object and run batches through the engine contract.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from . import metrics as _metrics
from .data import Measurements, humidity_name, load_measurements, summarize
from .engines import engine_class, engine_for, get_engine, scheme_of
from .engines.base import BoundaryInput, Engine, EngineOptions, EngineOutput, MoistureInput, SimulationInput
from .errors import StudyError, check_finite
from .grid import intervals_for_layer
from .study import Study

#: What calibration, the analyses and the live page need of an engine: batches of candidate walls.
BATCH_NEEDS = ("batches",)

#: Most time steps one simulation may take (a 10-year record at 10 s is about 31 million).
MAX_STEPS = 50_000_000

#: Most nodes of a wall's grid (a 24-layer wall at dt = 10 s and C = 2 has a few hundred; 2,000 nodes cost
#: about 0.5 GB and a second per week of 15-s steps, and the cost grows as nodes^2 x steps).
MAX_NODES = 2000

#: Most sensors one simulation compares (each is an output series as long as the comparison period).
MAX_SENSORS = 400


@dataclass
class Prepared:
    """A study's data on an engine grid, ready for one or many runs.

    Attributes
    ----------
    study : Study
    measurements : Measurements
    inp : SimulationInput
        Engine input for the study's wall.
    times : DatetimeIndex
        Measured timestamps in the comparison period (outputs are formed there).
    measured : DataFrame
        Measured value of every sensor at ``times`` (NaN = missing or excluded).
    engine_name : str
        The engine these data are prepared for.
    note : str
        Why ``engine_name`` is not the engine asked for (empty when it is; see
        :func:`wallcal.engines.engine_for`).
    """

    study: Study
    measurements: Measurements
    inp: SimulationInput
    times: pd.DatetimeIndex
    measured: pd.DataFrame
    engine_name: str
    note: str = ""
    _engine: Engine | None = field(default=None, init=False, repr=False, compare=False)
    _engine_prepared: object = field(default=None, init=False, repr=False, compare=False)
    _shared: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def engine(self) -> Engine:
        """The engine object (built once)."""
        if self._engine is None:
            self._engine = get_engine(self.engine_name)
        return self._engine

    def engine_prepared(self):
        """``engine.prepare(inp)``, built once."""
        if self._engine_prepared is None:
            self._engine_prepared = self.engine.prepare(self.inp)
        return self._engine_prepared

    def run(self, walls=None):
        """``engine.run(engine_prepared(), walls)``: see :meth:`wallcal.engines.base.Engine.run`."""
        return self.engine.run(self.engine_prepared(), walls)

    def summary(self) -> pd.DataFrame:
        """The measured signals over the comparison period (Table III), computed once per data."""
        if "summary" not in self._shared:
            self._shared["summary"] = summarize(
                boundary_named(self.measurements.frame, self.study), self.study.period.start, self.study.period.end
            )
        return self._shared["summary"]

    def measured_array(self) -> np.ndarray:
        """``measured`` as a float array, one row per sensor: shape (n_sensors, n_times), computed once."""
        if "measured" not in self._shared:
            self._shared["measured"] = np.ascontiguousarray(self.measured.to_numpy(dtype=float).T)
        return self._shared["measured"]

    def measured_stats(self) -> dict:
        """:func:`wallcal.metrics.measured_stats` of :meth:`measured_array`, computed once."""
        if "stats" not in self._shared:
            self._shared["stats"] = _metrics.measured_stats(self.measured_array())
        return self._shared["stats"]

    def sensor_index(self) -> pd.Index:
        """The sensor names as a pandas Index (the simulated table's columns), built once."""
        if "index" not in self._shared:
            self._shared["index"] = pd.Index([s.name for s in self.study.sensors])
        return self._shared["index"]

    def signal_names(self):
        """The sensor names as a pandas string array (the metrics table's first column), built once."""
        if "names" not in self._shared:
            self._shared["names"] = pd.array([s.name for s in self.study.sensors], dtype="str")
        return self._shared["names"]

    def accuracies(self) -> list[tuple]:
        """(accuracy, accuracy_relative) of every sensor."""
        return [(s.accuracy, s.accuracy_relative) for s in self.study.sensors]

    def with_wall(self, wall) -> Prepared:
        """The same data with another wall (same layer structure and probes)."""
        new = dataclasses.replace(self, inp=self.inp.replace(wall=wall))
        new._shared = self._shared
        return new


#: pandas >= 3 copies on write: a shallow copy handed to the user leaves the prepared data alone
_COPY_ON_WRITE = int(pd.__version__.split(".")[0]) >= 3

#: Prepared data kept by :func:`prepare`: the two most recent (each holds its boundary series on the
#: engine grid, 0.5 GB for ten years at 10 s: a few, not many).
_CACHE_SIZE = 2
_cache: OrderedDict = OrderedDict()


def _data_stamp(study: Study) -> tuple:
    """Modification stamps of the study's data files (a changed file re-prepares)."""
    out = []
    for path in study.data.paths:
        try:
            st = os.stat(path)
            out.append((str(path), st.st_mtime_ns, st.st_size))
        except OSError:
            out.append((str(path), None, None))
    return tuple(out)


def prepare(
    study: Study,
    engine: str | None = None,
    *,
    time_step: float | None = None,
    grid_constant: float | None = None,
    node_rule: str | None = None,
    measurements: Measurements | None = None,
    needs: tuple[str, ...] = (),
    purpose: str = "",
) -> Prepared:
    """Put a study's data onto the engine grid (reused while the study and its data files are unchanged).

    Parameters
    ----------
    study : Study
    engine : str, optional
        Engine name; default the study's ``simulation.engine``.
    time_step : float, optional
        [s]; default the study's.
    grid_constant : float, optional
        C [-]; default the study's.
    node_rule : str, optional
        ``"wallcal"`` or ``"energyplus"``.
    measurements : Measurements, optional
        Already loaded data (avoid reading the file again).
    needs : tuple of str
        Engine capabilities the caller needs (e.g. ``("batches",)``): an engine without them is
        replaced by its declared substitute, and :attr:`Prepared.note` says so
        (:func:`wallcal.engines.engine_for`).
    purpose : str
        What the data are prepared for, in words (for that note).
    """
    sim = study.simulation
    requested = engine or sim.engine
    dt = float(sim.time_step if time_step is None else time_step)  # an explicit 0 is checked, not replaced
    C = float(sim.grid_constant if grid_constant is None else grid_constant)
    if dt <= 0 or not math.isfinite(dt):
        raise StudyError([f"simulation.time_step: must be > 0, got {dt}"])
    if C <= 0 or not math.isfinite(C):
        raise StudyError([f"simulation.grid_constant: must be > 0, got {C}"])
    if study.has_moisture and not engine_class(requested).capabilities.moisture:
        raise StudyError(
            [
                f"simulation.engine: the {requested} engine computes heat only, and this study has moisture "
                '(relative_humidity / water_content sensors or humidity boundaries): use engine = "ham"'
            ],
            source=str(study.path) if study.path else None,
        )
    choice = engine_for(requested, needs, purpose=purpose or "this task")
    rule = node_rule or sim.node_rule
    key = (
        id(study),
        id(measurements) if measurements is not None else _data_stamp(study),
        choice.name,
        choice.note,
        dt,
        C,
        rule,
    )
    hit = _cache.get(key)
    if hit is not None and hit.study is study and (measurements is None or hit.measurements is measurements):
        _cache.move_to_end(key)
        return hit
    prep = _prepare(study, choice.name, dt, C, rule, measurements)
    prep.note = choice.note
    _cache[key] = prep
    while len(_cache) > _CACHE_SIZE:
        _cache.popitem(last=False)
    return prep


def _prepare(study: Study, engine: str, dt: float, C: float, node_rule: str, measurements) -> Prepared:
    sim = study.simulation
    meas = measurements if measurements is not None else load_measurements(study)
    frame = meas.frame
    p = study.period
    t0 = pd.Timestamp(p.warmup_start) if p.warmup_start else frame.index[0]
    start, end = pd.Timestamp(p.start), pd.Timestamp(p.end)
    n_steps = int(math.ceil((end - t0).total_seconds() / dt - 1e-9))
    if n_steps > MAX_STEPS:
        raise StudyError(
            [
                f"simulation.time_step: {dt:g} s gives {n_steps:,} steps from {t0} to {end}, more than "
                f"{MAX_STEPS:,}; use a larger time step or a shorter period"
            ]
        )
    _check_nodes(study, dt, C, node_rule)
    _check_conductivity(study, frame, t0, end)
    grid_s = np.arange(n_steps + 1) * dt
    t_s = (frame.index - t0).total_seconds().to_numpy()

    def on_grid(col):
        v = frame[col].to_numpy()
        ok = np.isfinite(v)
        return np.interp(grid_s, t_s[ok], v[ok])

    def boundary(face, b):
        rh = on_grid(humidity_name(face)) if b.humidity_column else None
        return BoundaryInput(b.type, on_grid(face), b.surface_coefficient, rh, b.vapour_coefficient)

    ext = boundary("exterior", study.exterior)
    intr = boundary("interior", study.interior)
    in_period = (frame.index >= start) & (frame.index <= end)
    times = frame.index[in_period]
    measured = frame.loc[in_period, [s.name for s in study.sensors]]
    if p.validation is not None:  # the held-out window: no fitting (nor the period's metrics) sees it
        held = (times >= pd.Timestamp(p.validation_start)) & (times <= pd.Timestamp(p.validation_end))
        if held.any():
            measured = measured.copy()
            measured.loc[held] = np.nan
    positions = (times - t0).total_seconds().to_numpy() / dt
    probes = tuple(s.name for s in study.sensors if s.quantity == "temperature")
    moisture = _moisture_input(study, frame, t0, ext, intr) if study.has_moisture else None
    faces = tuple(dict.fromkeys(s.face for s in study.sensors if s.quantity == "heat_flux" and s.depth is None))
    depths = tuple((s.name, s.depth) for s in study.sensors if s.quantity == "heat_flux" and s.depth is not None)
    inp = SimulationInput(
        wall=study.wall,
        t0=t0,
        time_step=dt,
        exterior=ext,
        interior=intr,
        output_positions=positions,
        probes=probes,
        flux_faces=faces,
        flux_depths=depths,
        grid_constant=C,
        node_rule=node_rule,
        scheme=scheme_of(engine),
        options=EngineOptions(stiff_limit=sim.stiff_limit),
        moisture=moisture,
    )
    return Prepared(study=study, measurements=meas, inp=inp, times=times, measured=measured, engine_name=engine)


def _moisture_input(study: Study, frame: pd.DataFrame, t0, ext: BoundaryInput, intr: BoundaryInput) -> MoistureInput:
    """The moisture outputs and initial state of a moisture study (``[simulation] initial_state``)."""
    sim = study.simulation
    rh_probes = tuple(s.name for s in study.sensors if s.quantity == "relative_humidity")
    w_probes = tuple(s.name for s in study.sensors if s.quantity == "water_content")
    if sim.initial_state == "constant":
        return MoistureInput(
            rh_probes,
            w_probes,
            "constant",
            temperature=(float(sim.initial_temperature),),
            relative_humidity=None if sim.initial_relative_humidity is None else (sim.initial_relative_humidity,),
            water_content=sim.initial_water_content,
            profiles=sim.profiles,
        )
    # the first data row: boundary values at the faces, the probes' first values in between (a periodic run
    # starts its first pass from it, then from its own end state)
    wall = study.wall
    first = frame.loc[frame.index >= t0]
    t_pts = {0.0: float(ext.values[0]), wall.thickness: float(intr.values[0])}
    rh_pts = {}
    for b, x in ((ext, 0.0), (intr, wall.thickness)):
        if b.relative_humidity is not None:
            rh_pts[x] = float(b.relative_humidity[0])
    for s in study.sensors:
        if s.quantity not in ("temperature", "relative_humidity"):
            continue
        col = first[s.name].to_numpy(dtype=float)
        ok = np.flatnonzero(np.isfinite(col))
        if not ok.size:
            continue
        depth = wall.probe(s.name).depth
        if s.quantity == "temperature":
            t_pts[depth] = float(col[ok[0]])
        else:
            rh_pts[depth] = float(np.clip(col[ok[0]], 1e-4, 1.0))
    if not rh_pts:
        rh_pts = {0.0: 0.5}
    depths = np.union1d(list(t_pts), list(rh_pts))
    tx, tv = zip(*sorted(t_pts.items()), strict=True)
    rx, rv = zip(*sorted(rh_pts.items()), strict=True)
    return MoistureInput(
        rh_probes,
        w_probes,
        "periodic" if sim.initial_state == "periodic" else "profile",
        depths=tuple(float(d) for d in depths),
        temperature=tuple(float(v) for v in np.interp(depths, tx, tv)),
        relative_humidity=tuple(float(v) for v in np.interp(depths, rx, rv)),
        profiles=sim.profiles,
    )


def node_count(wall, dt: float, C: float, node_rule: str) -> int:
    """Nodes of ``wall``'s grid at time step ``dt`` [s] and grid constant ``C`` (as :func:`wallcal.grid.build_grid`
    lays them out, counting a contact node at every contact resistance), without building it."""
    n = 1
    for layer in wall.layers:
        if layer.is_massless:
            n += 1
        else:
            n += intervals_for_layer(layer.thickness, layer.diffusivity, dt, C, node_rule)
        n += 1 if layer.contact_resistance else 0
    return n


def _check_nodes(study: Study, dt: float, C: float, node_rule: str) -> None:
    """Refuse more than :data:`MAX_SENSORS` sensors, and a grid of more than :data:`MAX_NODES` nodes, naming the
    layer that needs most."""
    if len(study.sensors) > MAX_SENSORS:
        raise StudyError(
            [f"sensors: {len(study.sensors):,} sensors, more than wallcal compares ({MAX_SENSORS})"],
            source=str(study.path) if study.path else None,
        )
    n = node_count(study.wall, dt, C, node_rule)
    if n <= MAX_NODES:
        return
    per = [
        0 if layer.is_massless else intervals_for_layer(layer.thickness, layer.diffusivity, dt, C, node_rule)
        for layer in study.wall.layers
    ]
    i = int(np.argmax(per))

    def count(k: int) -> str:
        return f"{k:,}" if k < 10**9 else f"{k:.3g}"

    raise StudyError(
        [
            f"wall.layers[{i}]: needs {count(per[i])} nodes at dt = {dt:g} s and C = {C:g} (the wall {count(n)}), "
            f"more than {MAX_NODES:,}; check its properties, or raise simulation.time_step or grid_constant"
        ],
        source=str(study.path) if study.path else None,
    )


def _check_conductivity(study: Study, frame: pd.DataFrame, t0, end) -> None:
    """Refuse a lambda(T) law that leaves its range over the data's temperatures (``Wall.conductivity_problems``)."""
    if study.wall.is_linear:
        return
    cols = [face for face, b in (("exterior", study.exterior), ("interior", study.interior)) if b.type != "heat_flux"]
    cols += [s.name for s in study.sensors if s.quantity == "temperature"]
    window = frame.loc[(frame.index >= t0) & (frame.index <= end), cols].to_numpy(dtype=float)
    window = window[np.isfinite(window)]
    if not len(window):
        return
    problems = study.wall.conductivity_problems(float(window.min()), float(window.max()))
    if problems:
        raise StudyError(problems, source=str(study.path) if study.path else None)


@dataclass
class SimulationResult:
    """Simulated and measured series with their metrics.

    Attributes
    ----------
    measured, simulated : DataFrame
        Index: measured timestamps of the comparison period; one column per sensor.
        Temperatures [degC], heat fluxes [W/m2] positive towards the interior.
    metrics : DataFrame
        One row per sensor (see :mod:`wallcal.metrics`).
    summary : DataFrame
        Measured signals over the period (Table III).
    info : dict
        Engine facts (path, nodes, energy balance, run time), spikes, gaps.
    """

    study: Study
    engine: str
    measured: pd.DataFrame
    simulated: pd.DataFrame
    metrics: pd.DataFrame
    summary: pd.DataFrame
    info: dict = field(default_factory=dict)
    spikes: pd.DataFrame | None = None
    bridged_gaps: pd.DataFrame | None = None
    profiles: pd.DataFrame | None = None
    #: the held-out window's ``validation.csv`` table (:func:`wallcal.validation.score_wall`), when scored
    validation: pd.DataFrame | None = None

    def write(self, out_dir: str | Path) -> Path:
        """Write ``simulated.csv``, ``metrics.csv``, ``summary.csv``, ``measured.csv`` and
        ``info.json`` into ``out_dir`` atomically."""
        from .outputs import output_dir

        with output_dir(out_dir, manifest=manifest_of(self.study, "simulate")) as tmp:
            self.write_into(Path(tmp))
        return Path(out_dir)

    def write_into(self, d: Path) -> None:
        sim = self.simulated.copy()
        sim.index = sim.index.strftime("%Y-%m-%dT%H:%M:%S")
        sim.to_csv(d / "simulated.csv", float_format="%.6g")
        meas = self.measured.copy()
        meas.index = meas.index.strftime("%Y-%m-%dT%H:%M:%S")
        meas.to_csv(d / "measured.csv", float_format="%.6g")
        self.metrics.to_csv(d / "metrics.csv", index=False, float_format="%.6g")
        self.summary.to_csv(d / "summary.csv", float_format="%.6g")
        if self.spikes is not None and len(self.spikes):
            self.spikes.to_csv(d / "spikes.csv", index=False)
        if self.profiles is not None:
            self.profiles.to_csv(d / "profiles.csv", index=False, float_format="%.6g")
        _metrics.write_validation(self.validation, d)
        (d / "info.json").write_text(json.dumps(self.info, indent=2, default=str))


def manifest_of(study: Study, command: str) -> dict:
    """Traceability entries for an output directory: wallcal version (added by the writer), the study
    file's hash and the input data's hash (all data files for multi-file data)."""
    from .data import data_sha256

    try:
        data_hash = data_sha256(study)
    except OSError:
        data_hash = None
    return {
        "command": command,
        "study_file": str(study.path) if study.path else None,
        "study_sha256": study.sha256,
        "data_files": [str(p) for p in study.data.paths],
        "data_sha256": data_hash,
    }


def result_from_output(prep: Prepared, out: EngineOutput, engine: str) -> SimulationResult:
    """Assemble a :class:`SimulationResult` from an engine's output."""
    study = prep.study
    names = [s.name for s in study.sensors]
    cols = []
    for s in study.sensors:
        if s.quantity == "heat_flux":
            cols.append(out.fluxes[s.name if s.depth is not None else s.face])
        elif s.quantity == "relative_humidity":
            cols.append(out.relative_humidity[s.name])
        elif s.quantity == "water_content":
            cols.append(out.water_content[s.name])
        else:
            cols.append(out.temperatures[s.name])
    sim = np.empty((len(names), len(prep.times)))  # one row per sensor: the layout of a DataFrame's block
    for k, c in enumerate(cols):
        sim[k] = c
    check_finite(dict(zip(names, sim, strict=True)), engine, study.wall.nonfinite_cause())
    simulated = pd.DataFrame(sim.T, index=prep.times, columns=prep.sensor_index(), copy=False)
    met = _metrics.table_arrays(
        prep.signal_names(), prep.measured_array(), sim, prep.accuracies(), prep.measured_stats()
    )
    skipped = np.isnan(prep.measured_array()).sum(axis=1)
    info = dict(out.info)
    info.update(
        {
            "engine": engine,
            "time_step_s": prep.inp.time_step,
            "grid_constant": prep.inp.grid_constant,
            "comparison_samples": len(prep.times),
            "skipped_samples": {name: int(v) for name, v in zip(names, skipped, strict=True)},
            "spikes_found": int(len(prep.measurements.spikes)),
            "spikes_removed": bool(study.data.remove_spikes),
            "bridged_gaps": int(len(prep.measurements.bridged_gaps)),
        }
    )
    if prep.note:
        info["engine_note"] = prep.note
    return SimulationResult(
        study=study,
        engine=engine,
        measured=prep.measured.copy(deep=not _COPY_ON_WRITE),
        simulated=simulated,
        metrics=met,
        summary=prep.summary().copy(deep=not _COPY_ON_WRITE),
        info=info,
        spikes=prep.measurements.spikes,
        bridged_gaps=prep.measurements.bridged_gaps,
        profiles=out.profiles,
    )


def boundary_named(frame: pd.DataFrame, study: Study) -> pd.DataFrame:
    """The frame with its boundary columns named after their data columns (TSe, TSi...)."""
    names = {}
    for face, b in (("exterior", study.exterior), ("interior", study.interior)):
        name = b.column if b.column not in frame.columns else f"{b.column} ({face} boundary)"
        names[face] = name
    return frame.rename(columns=names)


def simulate(
    study: Study,
    engine: str | None = None,
    *,
    time_step: float | None = None,
    grid_constant: float | None = None,
    node_rule: str | None = None,
    wall=None,
    prepared: Prepared | None = None,
) -> SimulationResult:
    """Simulate a study and compare with the measurements.

    Parameters
    ----------
    study : Study
        From :func:`wallcal.load_study`.
    engine : str, optional
        A registered engine name (:func:`wallcal.engines.engine_names`); default the study's.
    time_step : float, optional
        [s]
    grid_constant : float, optional
        C = dx^2 / (alpha dt) [-]
    node_rule : str, optional
        ``"wallcal"`` or ``"energyplus"``.
    wall : Wall, optional
        Run this wall instead of the study's (same probes).
    prepared : Prepared, optional
        Reuse prepared data (e.g. from :func:`prepare`); its engine runs (``engine``, if given, must be it).

    Returns
    -------
    SimulationResult

    Notes
    -----
    A repeated call with the same study object reuses the prepared data (and the engine's prepared
    state) while the data files are unchanged (see :func:`prepare`): it costs the engine run and
    forming the tables.
    """
    if prepared is not None:
        if engine is not None and engine != prepared.engine_name:
            raise StudyError([f"engine: {engine!r} asked for, but the prepared data are for {prepared.engine_name!r}"])
        prep = prepared
    else:
        prep = prepare(study, engine, time_step=time_step, grid_constant=grid_constant, node_rule=node_rule)
    if wall is not None:
        prep = prep.with_wall(wall)
    t = time.perf_counter()
    out = prep.run()
    out.info.setdefault("seconds", time.perf_counter() - t)
    return result_from_output(prep, out, prep.engine_name)
