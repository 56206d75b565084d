"""From a study to simulated-versus-measured series and metrics.

Pipeline: :func:`wallcal.study.load_study` -> :func:`wallcal.data.load_measurements`
-> :func:`prepare` (boundary series on the engine grid, comparison times) ->
engine -> :class:`SimulationResult` (series, metrics, summary).
Data preparation happens once here; calibration and sensitivity reuse the
:class:`Prepared` object and call the engine's batch interface directly.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from . import metrics as _metrics
from .data import Measurements, load_measurements, summarize
from .engines import get_engine, scheme_of
from .engines.base import BoundaryInput, EngineOutput, SimulationInput
from .errors import StudyError
from .study import Study
from .wall import Probe

#: Most time steps one simulation may take (a 10-year record at 10 s is about 31 million).
MAX_STEPS = 50_000_000


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
    """

    study: Study
    measurements: Measurements
    inp: SimulationInput
    times: pd.DatetimeIndex
    measured: pd.DataFrame
    engine_name: str

    @property
    def sensor_outputs(self) -> list[tuple[str, str, str]]:
        """(sensor name, kind, key): kind 'probe' (key: probe name), 'flux' (key: face) or 'flux_depth'
        (key: the sensor name; see :func:`flux_at_depth`)."""
        out = []
        for s in self.study.sensors:
            if s.quantity == "heat_flux":
                out.append((s.name, "flux_depth", s.name) if s.depth is not None else (s.name, "flux", s.face))
            else:
                out.append((s.name, "probe", s.name))
        return out

    def with_wall(self, wall) -> Prepared:
        """The same data with another wall (same layer structure); hidden flux probes are kept."""
        names = {p.name for p in wall.probes}
        hidden = tuple(p for p in self.inp.wall.probes if p.name.startswith("__") and p.name not in names)
        return dataclasses.replace(
            self, inp=dataclasses.replace(self.inp, wall=wall.replace(probes=wall.probes + hidden))
        )


def prepare(
    study: Study,
    engine: str | None = None,
    *,
    time_step: float | None = None,
    grid_constant: float | None = None,
    node_rule: str | None = None,
    measurements: Measurements | None = None,
) -> Prepared:
    """Put a study's data onto the engine grid.

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
    """
    sim = study.simulation
    engine = engine or sim.engine
    dt = float(time_step or sim.time_step)
    C = float(grid_constant or sim.grid_constant)
    if dt <= 0 or not math.isfinite(dt):
        raise StudyError([f"simulation.time_step: must be > 0, got {dt}"])
    if C <= 0 or not math.isfinite(C):
        raise StudyError([f"simulation.grid_constant: must be > 0, got {C}"])
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
    grid_s = np.arange(n_steps + 1) * dt
    t_s = (frame.index - t0).total_seconds().to_numpy()

    def on_grid(col):
        v = frame[col].to_numpy()
        ok = np.isfinite(v)
        return np.interp(grid_s, t_s[ok], v[ok])

    ext = BoundaryInput(study.exterior.type, on_grid("exterior"), study.exterior.surface_coefficient)
    intr = BoundaryInput(study.interior.type, on_grid("interior"), study.interior.surface_coefficient)
    in_period = (frame.index >= start) & (frame.index <= end)
    times = frame.index[in_period]
    measured = frame.loc[in_period, [s.name for s in study.sensors]]
    positions = (times - t0).total_seconds().to_numpy() / dt
    probes = tuple(s.name for s in study.sensors if s.quantity == "temperature")
    faces = tuple(dict.fromkeys(s.face for s in study.sensors if s.quantity == "heat_flux" and s.depth is None))
    wall = study.wall
    for s in study.sensors:  # a heat flux inside the wall is read from three hidden probes around its depth
        if s.quantity == "heat_flux" and s.depth is not None:
            extra = tuple(
                Probe(n, d) for n, d in zip(flux_probe_names(s.name), flux_probe_depths(wall, s.depth), strict=True)
            )
            wall = wall.replace(probes=wall.probes + extra)
            probes += tuple(p.name for p in extra)
    inp = SimulationInput(
        wall=wall,
        t0=t0,
        time_step=dt,
        exterior=ext,
        interior=intr,
        output_positions=positions,
        probes=probes,
        flux_faces=faces,
        grid_constant=C,
        node_rule=node_rule or sim.node_rule,
        scheme=scheme_of(engine),
        options={"stiff_limit": sim.stiff_limit},
    )
    return Prepared(study=study, measurements=meas, inp=inp, times=times, measured=measured, engine_name=engine)


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
    sim = {}
    for name, kind, key in prep.sensor_outputs:
        if kind == "probe":
            sim[name] = out.temperatures[key]
        elif kind == "flux":
            sim[name] = out.fluxes[key]
        else:
            t_m, t_0, t_p = (out.temperatures[n] for n in flux_probe_names(key))
            sim[name] = flux_at_depth(prep.inp.wall, study.sensor(key).depth, t_m, t_0, t_p)
    simulated = pd.DataFrame(sim, index=prep.times)
    acc = {s.name: (s.accuracy, s.accuracy_relative) for s in study.sensors}
    met = _metrics.table(prep.measured, simulated, acc)
    excluded = {s.name: int(prep.measured[s.name].isna().sum()) for s in study.sensors}
    summ = summarize(_boundary_named(prep.measurements.frame, study), study.period.start, study.period.end)
    info = dict(out.info)
    info.update(
        {
            "engine": engine,
            "time_step_s": prep.inp.time_step,
            "grid_constant": prep.inp.grid_constant,
            "comparison_samples": len(prep.times),
            "skipped_samples": excluded,
            "spikes_found": int(len(prep.measurements.spikes)),
            "spikes_removed": bool(study.data.remove_spikes),
            "bridged_gaps": int(len(prep.measurements.bridged_gaps)),
        }
    )
    return SimulationResult(
        study=study,
        engine=engine,
        measured=prep.measured.copy(),
        simulated=simulated,
        metrics=met,
        summary=summ,
        info=info,
        spikes=prep.measurements.spikes,
        bridged_gaps=prep.measurements.bridged_gaps,
    )


#: Half-distance [m] of the hidden probes that read a heat flux inside the wall
FLUX_PROBE_SPACING = 1e-3


def flux_probe_names(sensor: str) -> tuple[str, str, str]:
    """Names of the hidden probes behind a heat-flux sensor inside the wall."""
    return (f"__{sensor}__minus", f"__{sensor}__at", f"__{sensor}__plus")


def flux_probe_depths(wall, depth: float) -> tuple[float, float, float]:
    """Depths [m] of the hidden probes: depth - h, depth, depth + h (h = 1 mm, inside the wall)."""
    h = FLUX_PROBE_SPACING
    return (max(depth - h, 0.0), depth, min(depth + h, wall.thickness))


def _layer_at(wall, x: float):
    bounds = wall.interfaces
    return wall.layers[int(np.clip(np.searchsorted(bounds, x, side="right") - 1, 0, len(wall.layers) - 1))]


def _conductivity(layer, temperature):
    if layer.is_massless:
        return layer.thickness / layer.thermal_resistance if layer.thickness > 0 else np.inf
    return layer.conductivity_at(temperature)


def _effusivity(layer) -> float:
    """sqrt(lambda rho c) [J/(m2 K s^0.5)]: on a grid with dx ~ sqrt(C alpha dt), a layer's half cell next to an
    interface holds a heat capacity proportional to it."""
    if layer.is_massless:
        return 0.0
    return float(np.sqrt(layer.conductivity_at(layer.reference_temperature) * layer.volumetric_heat_capacity))


def flux_at_depth(wall, depth: float, t_minus, t_at, t_plus):
    """Heat flux density [W/m2], positive towards the interior, at ``depth`` inside the wall.

    From the temperatures of three probes at depth - h, depth and depth + h (h = 1 mm; probes are linear
    between nodes, so each half gives the flux of the link it lies in): q_l = lambda_l (T(x-h) - T(x)) / h
    and q_r = lambda_r (T(x) - T(x+h)) / h at the half-interval's mean temperature. Inside a layer
    q = (q_l + q_r) / 2 (a central difference at a node). At a layer interface the heat stored in the two
    half cells between the links must be shared out: q = (b_r q_l + b_l q_r) / (b_l + b_r) with b each layer's
    effusivity, to which the half cells' capacities are proportional on a C-rule grid.
    """
    xm, x0, xp = flux_probe_depths(wall, depth)
    t_minus, t_at, t_plus = (np.asarray(v, dtype=float) for v in (t_minus, t_at, t_plus))
    halves = []
    if x0 > xm:
        layer = _layer_at(wall, 0.5 * (xm + x0))
        halves.append((layer, _conductivity(layer, 0.5 * (t_minus + t_at)) * (t_minus - t_at) / (x0 - xm)))
    if xp > x0:
        layer = _layer_at(wall, 0.5 * (x0 + xp))
        halves.append((layer, _conductivity(layer, 0.5 * (t_at + t_plus)) * (t_at - t_plus) / (xp - x0)))
    if len(halves) == 1:
        return halves[0][1]
    (ll, ql), (lr, qr) = halves
    if ll is lr:
        return 0.5 * (ql + qr)
    bl, br = _effusivity(ll), _effusivity(lr)
    if bl + br == 0:
        return 0.5 * (ql + qr)
    return (br * ql + bl * qr) / (bl + br)


def _boundary_named(frame: pd.DataFrame, study: Study) -> pd.DataFrame:
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
        ``"fd-cn"``, ``"fd-implicit"`` or ``"energyplus"``; default the study's.
    time_step : float, optional
        [s]
    grid_constant : float, optional
        C = dx^2 / (alpha dt) [-]
    node_rule : str, optional
        ``"wallcal"`` or ``"energyplus"``.
    wall : Wall, optional
        Run this wall instead of the study's (same probes).
    prepared : Prepared, optional
        Reuse prepared data (e.g. from :func:`prepare`).

    Returns
    -------
    SimulationResult
    """
    engine = engine or study.simulation.engine
    prep = prepared or prepare(study, engine, time_step=time_step, grid_constant=grid_constant, node_rule=node_rule)
    if wall is not None:
        prep = prep.with_wall(wall)
    eng = get_engine(engine)
    t = time.perf_counter()
    out = eng.run(prep.inp)
    out.info.setdefault("seconds", time.perf_counter() - t)
    return result_from_output(prep, out, engine)
