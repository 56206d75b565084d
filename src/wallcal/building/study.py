"""``wallcal building``: the study's walls in a whole building, through EnergyPlus.

:func:`building` prepares one EnergyPlus model per wall (the wall on the chosen surfaces of the reference
building or a user's model, :mod:`.model`), runs them as independent tasks of :func:`.run.run_building`
and gathers the contract table (``building.csv``), the spread over posterior draws and, with measured zone
air temperatures, the whole-envelope check. Everything is checked before the first run; outputs are
written atomically (:func:`wallcal.outputs.output_dir`).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import StudyError
from .config import BuildingSpec
from .model import check_model, load_model, needs_condfd, reference_building, select_surfaces, with_wall
from .run import compare_zone, read_zone_measurements, run_building
from .sources import WallEntry

#: ``building.csv``: the contract columns, one row per wall.
COLUMNS = (
    "wall",
    "heating_kWh",
    "cooling_kWh",
    "heating_kWh_m2",
    "cooling_kWh_m2",
    "peak_heating_W",
    "peak_cooling_W",
    "difference_vs_first_heating_kWh",
)
#: Figures whose spread over posterior draws is reported.
FIGURES = COLUMNS[1:7]


@dataclass
class BuildingResult:
    """Every wall's figures in the building; see :func:`building`."""

    walls: list[WallEntry]
    figures: list[dict]
    spec: BuildingSpec
    weather: Path
    model_source: str
    surfaces: list[str]
    zones: list[str]
    check: pd.DataFrame | None = None
    zone_series: dict = field(default_factory=dict)
    measured: pd.Series | None = None
    seconds: float = 0.0

    def table(self) -> pd.DataFrame:
        """``building.csv``: the contract columns, one row per wall."""
        first = self.figures[0]["heating_kWh"]
        rows = []
        for e, f in zip(self.walls, self.figures, strict=True):
            a = f["floor_area_m2"]
            rows.append(
                {
                    "wall": e.name,
                    "heating_kWh": f["heating_kWh"],
                    "cooling_kWh": f["cooling_kWh"],
                    "heating_kWh_m2": f["heating_kWh"] / a,
                    "cooling_kWh_m2": f["cooling_kWh"] / a,
                    "peak_heating_W": f["peak_heating_W"],
                    "peak_cooling_W": f["peak_cooling_W"],
                    "difference_vs_first_heating_kWh": f["heating_kWh"] - first,
                }
            )
        return pd.DataFrame(rows, columns=list(COLUMNS))

    @property
    def floor_area(self) -> float:
        return float(self.figures[0]["floor_area_m2"])

    def spread(self) -> pd.DataFrame:
        """p05, median and p95 of each figure over the posterior draws (empty without draws)."""
        tab = self.table()
        draws = tab[[e.kind == "draw" for e in self.walls]]
        if draws.empty:
            return pd.DataFrame()
        q = draws[list(FIGURES)].quantile([0.05, 0.5, 0.95]).T
        q.columns = ["p05", "median", "p95"]
        q.index.name = "figure"
        return q

    def notes(self) -> list[str]:
        """Plain sentences for the terminal and the report."""
        s = self.spec
        (bm, bd), (em, ed) = s.start, s.end
        out = [
            f"{self.model_source}; the wall on {len(self.surfaces)} surface(s) ({', '.join(self.surfaces[:6])}"
            + (", ..." if len(self.surfaces) > 6 else "")
            + f"); conditioned floor area {self.floor_area:.1f} m2 ({', '.join(self.zones)}); weather "
            f"{self.weather.name}; run period {bm:02d}-{bd:02d} to {em:02d}-{ed:02d}; heating and cooling are "
            "what the ideal loads deliver to hold the set-points.",
        ]
        tab = self.table()
        kinds = [e.kind for e in self.walls]
        sp = self.spread()
        others = tab[[k != "draw" for k in kinds]]
        if not sp.empty:
            n = kinds.count("draw")
            lo, hi = sp.loc["heating_kWh", "p05"], sp.loc["heating_kWh", "p95"]
            width = hi - lo
            out.append(
                f"{n} posterior draws: heating {lo:.1f} to {hi:.1f} kWh (5-95 %, {width:.1f} kWh wide, "
                f"{100 * width / max(abs(sp.loc['heating_kWh', 'median']), 1e-12):.1f} % of the median); cooling "
                f"{sp.loc['cooling_kWh', 'p05']:.1f} to {sp.loc['cooling_kWh', 'p95']:.1f} kWh."
            )
            if len(others) >= 2:
                diff = float(others["heating_kWh"].max() - others["heating_kWh"].min())
                verdict = "more" if diff > width else "less"
                out.append(
                    f"The {len(others)} other walls differ in heating by {diff:.1f} kWh, {verdict} than the "
                    f"posterior spread ({width:.1f} kWh): "
                    + (
                        "walls that fit the data equally well do lead to different heating demands in this building."
                        if verdict == "more"
                        else "in this building the choice among them matters less than what the data leave open."
                    )
                )
            else:
                out.append(
                    "The draws all fit the data (they are the posterior); so walls that fit the data equally well "
                    f"differ in this building's heating by up to {width:.1f} kWh (5-95 %)"
                    + (
                        " - more than 5 % of the demand."
                        if width > 0.05 * abs(sp.loc["heating_kWh", "median"])
                        else " - less than 5 % of the demand."
                    )
                )
        elif len(tab) >= 2:
            diff = float(tab["heating_kWh"].max() - tab["heating_kWh"].min())
            med = float(tab["heating_kWh"].median())
            out.append(
                f"The {len(tab)} walls differ in heating by {diff:.1f} kWh ({100 * diff / max(abs(med), 1e-12):.1f} % "
                "of the median); no posterior draws were given to say whether that is more than what the data leave "
                "open (add --from <posterior output>)."
            )
        if self.check is not None:
            best = self.check.sort_values("rmse_K").iloc[0]
            out.append(
                f"Whole-envelope check against {self.measured.name!r} ({int(best['hours'])} h, free-floating zone "
                f"air): RMSE {self.check['rmse_K'].min():.2f} to {self.check['rmse_K'].max():.2f} K over the walls, "
                f"best {best['wall']!r} (RMSE {best['rmse_K']:.2f} K, MBE {best['mbe_K']:+.2f} K)."
            )
        return out

    def write(self, out_dir, manifest: dict | None = None) -> Path:
        from ..outputs import output_dir

        with output_dir(out_dir, manifest=manifest) as tmp:
            self.write_into(Path(tmp))
        return Path(out_dir)

    def write_into(self, d: Path) -> list[str]:
        """Write ``building.csv``, ``building.json`` and, when there are any, ``spread.csv``,
        ``envelope_check.csv`` and ``zone_temperatures.csv`` into ``d``; returns the file names."""
        d = Path(d)
        self.table().to_csv(d / "building.csv", index=False, float_format="%.6g")
        files = ["building.csv"]
        sp = self.spread()
        if not sp.empty:
            sp.to_csv(d / "spread.csv", float_format="%.6g")
            files.append("spread.csv")
        if self.check is not None:
            self.check.to_csv(d / "envelope_check.csv", index=False, float_format="%.6g")
            series = pd.DataFrame(self.zone_series)
            series.insert(
                0,
                "measured",
                np.interp(
                    series.index.asi8.astype(float), self.measured.index.asi8.astype(float), self.measured.to_numpy()
                ),
            )
            series.index = series.index.strftime("%Y-%m-%dT%H:%M")
            series.to_csv(d / "zone_temperatures.csv", index_label="time", float_format="%.4g")
            files += ["envelope_check.csv", "zone_temperatures.csv"]
        s = self.spec
        info = {
            "model": self.model_source,
            "surfaces": self.surfaces,
            "conditioned_zones": self.zones,
            "conditioned_floor_area_m2": self.floor_area,
            "weather": str(self.weather),
            "run_period": [f"{s.start[0]:02d}-{s.start[1]:02d}", f"{s.end[0]:02d}-{s.end[1]:02d}"],
            "walls": [
                {"name": e.name, "kind": e.kind, "source": e.source, "energyplus_warnings": f.get("warnings", 0)}
                for e, f in zip(self.walls, self.figures, strict=True)
            ],
            "seconds": self.seconds,
            "notes": self.notes(),
        }
        (d / "building.json").write_text(json.dumps(info, indent=2, default=float))
        files.append("building.json")
        return files


def resolve_building_weather(study, weather: str | None) -> Path:
    """The EPW file: ``weather`` (``--weather``), else ``[building].weather``, else ``[retrofit].weather``;
    a file (relative to the study for the study's keys) or the name of a shipped weather file.

    Raises
    ------
    StudyError
        None given, or a name that is neither a file nor a shipped weather file (the shipped names listed).
    """
    from ..weather import read_weather, resolve_weather

    base = Path(study.path).resolve().parent if study.path else None
    if weather is not None:
        key, name, base = "--weather", weather, None
    elif study.building is not None and study.building.weather:
        key, name = "building.weather", study.building.weather
    elif study.retrofit is not None:
        key, name = "retrofit.weather", study.retrofit.weather
    else:
        from ..weather import shipped_weather_files

        raise StudyError(
            [
                "no weather: give --weather EPW, or weather = ... in the study's [building] or [retrofit] table "
                f"(shipped: {', '.join(shipped_weather_files()) or 'none without the energyplus extra'})"
            ]
        )
    try:
        path = resolve_weather(name, base)
    except StudyError as exc:
        raise StudyError([p.replace("retrofit.weather", key, 1) for p in exc.problems]) from None
    read_weather(path)  # a file that is not a valid EPW fails here, before any run
    return path


def building(
    study,
    walls: list[WallEntry],
    *,
    spec: BuildingSpec | None = None,
    model: str | Path | None = None,
    surfaces: list[str] | None = None,
    weather: str | None = None,
    measured: str | Path | None = None,
    zone_column: str | None = None,
    zone: str | None = None,
    scheduler: str | None = None,
    cache_dir: str | Path | None = None,
    resume: bool = False,
    progress: bool = False,
    timeout: float = 3600.0,
) -> BuildingResult:
    """Run each wall in the building.

    Parameters
    ----------
    study : Study
    walls : list of WallEntry
        From :func:`.sources.collect_walls`.
    spec : BuildingSpec, optional
        Default: the study's ``[building]`` table, else the defaults (reference building, whole year).
    model : path, optional
        A user's model (``--building``), overriding ``spec.model``.
    surfaces : list of str, optional
        Surfaces that get the wall (``--surfaces``), overriding ``spec.surfaces``; default every outdoor wall.
    weather : str, optional
        ``--weather`` (see :func:`resolve_building_weather`).
    measured, zone_column : optional
        Measured zone air temperatures (CSV, first column the time) and the column to compare with.
    zone : str, optional
        The zone whose air is compared (default: the only conditioned zone).
    scheduler : str, optional
        dask scheduler address (``--scheduler``); default: the active executor of the calling command
        (``wallcal run``), else ``WALLCAL_SCHEDULER``, else a local cluster (:mod:`wallcal.cluster`).
    cache_dir : path, optional
        Where finished runs are stored as they complete (by the hash of their inputs).
    resume : bool
        Reuse the runs stored in ``cache_dir`` (``--resume``).
    progress : bool
        A progress line on stderr.
    timeout : float
        Wall-clock limit of one EnergyPlus run [s].

    Returns
    -------
    BuildingResult

    Raises
    ------
    StudyError, DataError
        Bad input, before any run.
    """
    t0 = time.perf_counter()
    spec = spec or study.building or BuildingSpec()
    if not walls:
        raise StudyError(["no wall to run"])
    model_path = Path(model) if model is not None else spec.model_path
    if model_path is not None:
        base = load_model(model_path)
        source = f"model {model_path.name}"
    else:
        base = reference_building(heating_setpoint=spec.heating_setpoint, cooling_setpoint=spec.cooling_setpoint)
        source = "the reference building (docs/building.md)"
    zones = check_model(base, source)
    key = "--surfaces" if surfaces else "building.surfaces"
    chosen = select_surfaces(base, list(surfaces) if surfaces else list(spec.surfaces), source, key)
    epw = resolve_building_weather(study, weather)
    series = None
    if measured is not None:
        if not zone_column:
            raise StudyError(["--measured needs --zone-column NAME (the measured zone air temperature column)"])
        series = read_zone_measurements(measured, zone_column)
        if zone is None:
            if len(zones) > 1:
                raise StudyError(
                    [f"--zone: the model has {len(zones)} conditioned zones ({', '.join(zones)}); name one"]
                )
            zone = zones[0]
        elif zone.upper() not in {z.upper() for z in base.get("Zone", {})}:
            from ..errors import closest

            raise StudyError([f"--zone {zone!r}: not a zone of {source}; {closest(zone, list(base['Zone']))}"])
    period = (spec.start, spec.end)
    tasks = []
    for e in walls:
        steps = max(spec.timesteps_per_hour, 20) if needs_condfd(e.wall) else spec.timesteps_per_hour
        mdl = with_wall(base, e.wall, chosen, period=period, steps_per_hour=steps)
        tasks.append(
            {
                "label": e.name,
                "model": mdl,
                "weather": str(epw),
                "steps_per_hour": steps,
                "zones": zones,
                "timeout": timeout,
            }
        )
    if series is not None:
        # EnergyPlus' hours end at the marks: a record from 01:00 to 24:00 (the next day's 00:00) is one day
        first, last = series.index[0] - pd.Timedelta(seconds=1), series.index[-1] - pd.Timedelta(seconds=1)
        check_period = ((first.month, first.day), (last.month, last.day))
        for e in walls:
            steps = max(spec.timesteps_per_hour, 20) if needs_condfd(e.wall) else spec.timesteps_per_hour
            mdl = with_wall(
                base,
                e.wall,
                chosen,
                period=check_period,
                steps_per_hour=steps,
                free_floating=True,
                zone_temperatures=True,
            )
            tasks.append(
                {
                    "label": f"{e.name} (free-floating)",
                    "model": mdl,
                    "weather": str(epw),
                    "steps_per_hour": steps,
                    "zones": zones,
                    "temperature_zone": zone,
                    "timeout": timeout,
                }
            )
    from ..eplus import map_runs

    # inside a command's executor (wallcal run): its cluster, its --scheduler and store
    results = map_runs(
        run_building,
        tasks,
        scheduler=scheduler,
        cache_dir=cache_dir,
        resume=resume,
        progress=progress,
        label="EnergyPlus runs (building)",
    )
    figures = results[: len(walls)]
    res = BuildingResult(
        walls=list(walls),
        figures=figures,
        spec=spec,
        weather=Path(epw),
        model_source=source,
        surfaces=chosen,
        zones=zones,
        measured=series,
    )
    if series is not None:
        rows = []
        for e, r in zip(walls, results[len(walls) :], strict=True):
            rmse, mbe, n, s = compare_zone(r["zone_temperature"], series)
            rows.append({"wall": e.name, "rmse_K": rmse, "mbe_K": mbe, "hours": n})
            res.zone_series[e.name] = s
        res.check = pd.DataFrame(rows)
        if int(res.check["hours"].max()) == 0:
            raise StudyError([f"--measured {measured}: no simulated hour falls inside the measured record"])
    res.seconds = time.perf_counter() - t0
    return res


__all__ = ["COLUMNS", "BuildingResult", "building", "resolve_building_weather"]
