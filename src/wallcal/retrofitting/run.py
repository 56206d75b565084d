"""Retrofit runs: every variant over a weather year from a periodic state, with ISO 13788 and uncertainty.

For each variant: its wall (:func:`.config.apply_variant` on the base wall), U (ISO 6946 with Rsi = 1/h_i,
Rse = 1/h_e), an engine run over the weather file driven by :func:`.boundary.year_boundaries` (sol-air
exterior, constant interior air), and ISO 13788 (:mod:`.glaser`) on the weather file's monthly means.

The year: the weather period is treated as periodic. A warm-up over its last 30 days (from the steady
state of its first boundary values) gives the state at its start; then the period runs again and again,
each pass from the end state of the last, until the end state equals the start state within
``PERIODIC_TOLERANCE`` at every node. The annual figures are those of the last pass, so they do not
depend on the initial temperatures; ``passes`` says how many full periods ran.

Annual loss: with q_i the heat flux density at the interior surface, positive towards the interior (into
the room; wallcal's convention), the loss is -q_i, the heat leaving the room into the wall, and
``annual_loss_kWh_m2`` = integral of -q_i dt over the period / 3.6e6 (trapezoids at the engine's steps): a
net figure (hours in which the wall gives heat to the room count negative). ``peak_loss_W_m2`` = max of -q_i.

Uncertainty: with posterior samples every variant runs for every sample (the sampled properties applied
to the base wall, then the variant's changes) in one batch call of the engine; p05 and p95 are the 5 % and
95 % quantiles of the samples' annual losses, and the Spearman rank correlation of each sampled property
with the annual loss says which properties make the spread.

Checkpoint: with posterior draws and an output directory, the draws' results so far (each variant's thermal
losses, its moisture draws in chunks of ``DRAW_CHUNK_PER_WORKER`` per executor worker) are saved atomically after
each chunk to ``.<out>.retrofit-checkpoint.npz`` beside the output directory (:class:`DrawCheckpoint`), with the
inputs that determine them; ``resume=True`` takes them from there instead of running them again, and the
checkpoint is removed once the outputs are written.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..errors import StudyError
from ..wall import Probe, Wall
from ..weather import Weather, monthly_climate, read_weather, resolve_weather
from .boundary import YearBoundaries, year_boundaries
from .config import RetrofitSpec, VariantSpec, apply_variant

if TYPE_CHECKING:
    from ..analysis.posterior import Samples

#: Periodic state: largest change of any node temperature over one pass [K]
PERIODIC_TOLERANCE = 1e-3
MAX_PASSES = 20
WARMUP_DAYS = 30
#: Grid: the engine's C-rule grid built for this step and C (dx = sqrt(C alpha dt_grid)), run at the
#: retrofit time step; see docs/retrofit.md for the convergence check behind the choice.
GRID_TIME_STEP = 600.0
#: The time scheme of the year runs: ``exact`` (fd-exact) is exact in time for walls with constant properties, so
#: the result does not depend on the retrofit time step; its grid is built for ``EXACT_GRID_TIME_STEP`` whatever
#: the step (the spatial error of the 24-h wave: -0.19 % on the example wall's interior flux amplitude, against
#: -0.66 % on the 600-s grid; bench/exact_time_step.py); lambda(T) walls run Crank-Nicolson at that grid step.
#: The theta schemes (``cn``, ``implicit``) keep the grid for ``min(GRID_TIME_STEP, time_step)``.
SCHEME = "exact"
EXACT_GRID_TIME_STEP = 120.0
GRID_CONSTANT = 2.0

VARIANT_COLUMNS = (
    "variant",
    "U",
    "annual_loss_kWh_m2",
    "annual_loss_p05",
    "annual_loss_p95",
    "saving_vs_first_kWh_m2",
    "peak_loss_W_m2",
    "min_interior_surface_temperature",
    "frsi",
    "condensation_max_kg_m2",
    "condensation_verdict",
    # the hygrothermal year (EN 15026) and the mould index (moisture_risk.py); empty without hygric data
    "moisture_years",
    "water_content_trend_kg_m2_per_year",
    "water_content_trend_p05",
    "water_content_trend_p95",
    "max_relative_humidity_critical",
    "critical_interface",
    "mould_index_max",
    "mould_index_max_p05",
    "mould_index_max_p95",
    "moisture_verdict",
)


# ============================================================================ the engine over a year
@dataclass
class YearRun:
    """Outputs of a periodic year run for a batch of walls (same layer structure).

    ``t_si``, ``t_se`` [degC], ``q_i``, ``q_e`` [W/m2, positive towards the interior], shape (n_walls,
    n_steps + 1) (NaN for rows not asked for); ``passes``: full periods run; ``residual``: the last pass's
    largest node change [K]; ``path``: engine path.
    """

    t_si: np.ndarray
    t_se: np.ndarray
    q_i: np.ndarray
    q_e: np.ndarray
    time_step: float
    passes: int
    residual: float
    path: str
    nodes: int

    @property
    def annual_loss_kWh_m2(self) -> np.ndarray:
        """Net heat leaving the room through the interior surface over the period [kWh/m2] (trapezoids)."""
        loss = -self.q_i
        return (loss[:, 1:] + loss[:, :-1]).sum(axis=1) * 0.5 * self.time_step / 3.6e6

    @property
    def peak_loss_W_m2(self) -> np.ndarray:
        return (-self.q_i).max(axis=1)


def _with_face_probes(wall: Wall) -> Wall:
    return wall.replace(probes=(Probe("__se", 0.0), Probe("__si", wall.thickness)))


def _grid_time_step(scheme: str, grid_time_step: float | None, dt: float) -> float:
    """The step the year run's grid is built for [s] (see ``SCHEME``)."""
    if scheme == "exact":
        return EXACT_GRID_TIME_STEP if grid_time_step is None else grid_time_step
    return min(GRID_TIME_STEP if grid_time_step is None else grid_time_step, dt)


def periodic_year(
    walls: list[Wall],
    yb: YearBoundaries,
    *,
    all_rows: bool = True,
    tolerance: float = PERIODIC_TOLERANCE,
    grid_time_step: float | None = None,
    grid_constant: float = GRID_CONSTANT,
    scheme: str = SCHEME,
) -> YearRun:
    """Run walls (same layer structure) over the period of ``yb`` until the state repeats.

    ``all_rows=False`` forms only the interior surface temperature and flux (what the batch needs);
    ``scheme``: the engine's time scheme (``"exact"``, ``"cn"`` or ``"implicit"``); ``grid_time_step``: the step
    the grid is built for (default ``EXACT_GRID_TIME_STEP`` for ``exact``, else ``min(GRID_TIME_STEP, step)``).
    """
    from ..engines import get_engine
    from ..engines.base import BoundaryInput, EngineOptions, SimulationInput, WallBatch
    from ..errors import EngineError

    walls = [_with_face_probes(w) for w in walls]
    n = yb.n_steps
    dt = yb.time_step
    inp = SimulationInput(
        wall=walls[0],
        t0=pd.Timestamp("2021-01-01"),
        time_step=dt,
        exterior=yb.exterior,
        interior=yb.interior,
        output_positions=np.arange(n + 1, dtype=float),
        probes=("__se", "__si") if all_rows else ("__si",),
        flux_faces=("exterior", "interior") if all_rows else ("interior",),
        grid_constant=grid_constant,
        scheme=scheme,
        options=EngineOptions(grid_time_step=_grid_time_step(scheme, grid_time_step, dt)),
    )
    engine = get_engine(f"fd-{scheme}")
    prep = engine.prepare(inp)
    batch = WallBatch.from_walls(walls, inp.probes)
    # warm-up: the last WARMUP_DAYS of the period from the steady state of their first values (same grid)
    m = min(int(round(WARMUP_DAYS * 86400 / dt)), n)
    inp_w = inp.replace(
        exterior=BoundaryInput(yb.exterior.type, yb.exterior.values[n - m :], yb.exterior.surface_coefficient),
        interior=BoundaryInput(yb.interior.type, yb.interior.values[n - m :], yb.interior.surface_coefficient),
        output_positions=np.array([float(m)]),
        probes=("__si",),
        flux_faces=(),
    )
    state = engine.run(engine.prepare(inp_w), WallBatch.from_walls(walls, inp_w.probes)).final_state
    passes, residual = 0, math.inf
    while passes < MAX_PASSES:
        res = engine.run(prep, batch, initial_state=state)
        passes += 1
        residual = float(np.max(np.abs(res.final_state - state)))
        state = res.final_state
        if residual < tolerance:
            break
    else:
        raise EngineError(
            f"the year did not become periodic in {MAX_PASSES} passes (last change {residual:.3g} K); "
            "the wall's time constant is longer than the weather period allows"
        )
    nan = np.full((len(walls), n + 1), np.nan)
    return YearRun(
        t_se=res.temperatures.get("__se", nan),
        t_si=res.temperatures["__si"],
        q_e=res.fluxes.get("exterior", nan),
        q_i=res.fluxes["interior"],
        time_step=dt,
        passes=passes,
        residual=residual,
        path=res.info["path"],
        nodes=res.info["nodes"],
    )


# ============================================================================ a retrofit output, read back
#: The command whose output :meth:`RetrofitResult.write_into` writes (its format version: :mod:`wallcal.outputs`).
COMMAND = "retrofit"


def read_variant_walls(directory: str | Path) -> dict[str, Wall]:
    """The variants' walls of a retrofit output (``retrofit.json`` names them, ``variant_<k>.toml`` holds
    them): ``{variant name: wall}`` in the variants' order.

    Raises
    ------
    OutputFormatError
        A folder of another format version, or without one (:func:`wallcal.outputs.check_format`).
    StudyError
        An unreadable ``retrofit.json``, a missing or unparsable variant file.
    """
    from ..outputs import check_format
    from ..wallfile import load_wall

    d = Path(directory)
    check_format(d, COMMAND)
    try:
        info = json.loads((d / "retrofit.json").read_text())
        variants = [(int(v["index"]), str(v["name"])) for v in info["variants"]]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise StudyError([f"{d}: retrofit.json is not readable ({exc})"]) from exc
    out = {}
    for k, name in variants:
        f = d / f"variant_{k}.toml"
        if not f.exists():
            raise StudyError([f"{d}: {f.name} is missing; run 'wallcal retrofit' again"])
        out[name] = load_wall(f)
    return out


# ============================================================================ uncertainty inputs
def base_wall_from(study, wall: Wall | None, from_dir: Path | None) -> tuple[Wall, str, Path | None]:
    """The wall the variants start from and where it comes from; a posterior folder is returned too."""

    if wall is not None and from_dir is not None:
        raise StudyError(["give --wall or --from, not both"])
    if wall is not None:
        return _fill_mu(wall, study.wall), "the given wall", None
    if from_dir is None:
        return study.wall, "the study's wall", None
    from ..calibration.output import WALL_FILE, read_calibrated_walls

    from_dir = Path(from_dir)
    if (from_dir / "chain.npz").exists():  # read by load_samples
        return study.wall, f"the posterior in {from_dir}", from_dir
    if (from_dir / WALL_FILE).exists():
        (cal,) = read_calibrated_walls(from_dir).values()
        return _fill_mu(cal, study.wall), f"the calibrated wall of {from_dir}", None
    raise StudyError(
        [f"--from {from_dir}: neither a calibrate output (calibrated_wall.toml) nor a posterior output (chain.npz)"]
    )


def find_posterior(study) -> tuple[Path | None, str]:
    """The ``wallcal posterior`` output in its default place (``posterior/`` next to the study) when it was
    written for this very study file (same sha256 in its manifest) in the format this wallcal reads; else None
    and why (for ``wallcal run``)."""
    if study.path is None:
        return None, "the study has no file"
    d = Path(study.path).resolve().parent / "posterior"
    if not (d / "chain.npz").exists():
        return None, f"no posterior output at {d}"
    try:
        sha = json.loads((d / "manifest.json").read_text()).get("study_sha256")
    except (OSError, ValueError):
        sha = None
    if not sha or sha != study.sha256:
        return None, f"the posterior output at {d} was written for another version of the study file"
    from ..outputs import OutputFormatError, check_format

    try:
        check_format(d, "posterior")
    except OutputFormatError as exc:
        return None, str(exc)
    return d, ""


def _fill_mu(wall: Wall, study_wall: Wall) -> Wall:
    """Layers without mu take the study wall's mu of the same id (mu is not calibrated)."""
    mu = {layer.id: layer.vapour_resistance_factor for layer in study_wall.layers}
    return wall.replace(
        layers=tuple(
            layer.replace(vapour_resistance_factor=mu.get(layer.id))
            if layer.vapour_resistance_factor is None and mu.get(layer.id) is not None
            else layer
            for layer in wall.layers
        )
    )


# ============================================================================ the result
@dataclass
class VariantResult:
    """One variant: its wall, the contract figures, the hourly series, ISO 13788 and the sample losses."""

    spec: VariantSpec
    wall: Wall
    u_value: float
    annual_loss: float
    peak_loss: float
    min_surface_temperature: float
    passes: int
    residual: float
    hourly: pd.DataFrame
    glaser: object = None
    sample_losses: np.ndarray | None = None
    hygro: object = None  # moisture_risk.HygroResult
    sample_moisture: np.ndarray | None = None  # (draws, 4): mould index, trend, years, CPU seconds

    def moisture_quantile(self, column: int, q: float) -> float:
        """A quantile of the draws' mould index (column 0) or water trend (column 1); NaN without draws."""
        if self.sample_moisture is None or not len(self.sample_moisture):
            return math.nan
        return float(np.nanpercentile(self.sample_moisture[:, column], q))

    @property
    def p05(self) -> float:
        return float(np.percentile(self.sample_losses, 5)) if self.sample_losses is not None else math.nan

    @property
    def p95(self) -> float:
        return float(np.percentile(self.sample_losses, 95)) if self.sample_losses is not None else math.nan


@dataclass
class RetrofitResult:
    """Every variant's figures over the weather year (see the module docstring)."""

    study: object
    spec: RetrofitSpec
    weather: Weather
    wall_source: str
    variants: list[VariantResult]
    samples: Samples | None = None
    seconds: float = 0.0
    info: dict = field(default_factory=dict)

    def table(self) -> pd.DataFrame:
        """``variants.csv``: the contract columns, one row per variant."""
        first = self.variants[0].annual_loss
        rows = []
        for v in self.variants:
            g = v.glaser
            rows.append(
                {
                    "variant": v.spec.name,
                    "U": v.u_value,
                    "annual_loss_kWh_m2": v.annual_loss,
                    "annual_loss_p05": v.p05,
                    "annual_loss_p95": v.p95,
                    "saving_vs_first_kWh_m2": first - v.annual_loss,
                    "peak_loss_W_m2": v.peak_loss,
                    "min_interior_surface_temperature": v.min_surface_temperature,
                    "frsi": g.frsi if g is not None else _frsi(v.wall, self.spec),
                    "condensation_max_kg_m2": g.max_accumulated if g is not None else math.nan,
                    "condensation_verdict": g.verdict if g is not None else "",
                    **self._moisture_row(v),
                }
            )
        return pd.DataFrame(rows, columns=list(VARIANT_COLUMNS))

    @staticmethod
    def _moisture_row(v: VariantResult) -> dict:
        h = v.hygro
        if h is None:
            return {
                "moisture_years": math.nan,
                "water_content_trend_kg_m2_per_year": math.nan,
                "water_content_trend_p05": math.nan,
                "water_content_trend_p95": math.nan,
                "max_relative_humidity_critical": math.nan,
                "critical_interface": "",
                "mould_index_max": math.nan,
                "mould_index_max_p05": math.nan,
                "mould_index_max_p95": math.nan,
                "moisture_verdict": "",
            }
        return {
            "moisture_years": h.years,
            "water_content_trend_kg_m2_per_year": h.trend,
            "water_content_trend_p05": v.moisture_quantile(1, 5),
            "water_content_trend_p95": v.moisture_quantile(1, 95),
            "max_relative_humidity_critical": h.rh_max,
            "critical_interface": h.critical_name,
            "mould_index_max": h.mould_max,
            "mould_index_max_p05": v.moisture_quantile(0, 5),
            "mould_index_max_p95": v.moisture_quantile(0, 95),
            "moisture_verdict": h.verdict,
        }

    def spread(self) -> pd.DataFrame:
        """Spearman rank correlation of each sampled property with each variant's annual loss, plus the
        correlation with the sampled wall's total resistance (the common-scale direction)."""
        if self.samples is None:
            return pd.DataFrame()
        if getattr(self, "_spread", None) is not None:
            return self._spread
        S = self.samples
        cols = {}
        r_tot = np.array([w.resistance for w in S.walls])
        for v in self.variants:
            y = v.sample_losses[: len(S.walls)]
            col = {name: _spearman(S.values[:, j], y) for j, name in enumerate(S.names)}
            col["R total of the sampled wall"] = _spearman(r_tot, y)
            cols[v.spec.name] = col
        df = pd.DataFrame(cols)
        df.index.name = "sampled property"
        self._spread = df
        return df

    def notes(self) -> list[str]:
        """Plain sentences for the terminal and the report."""
        s = self.spec
        first = self.variants[0]
        out = [
            f"weather {self.weather.name} ({self.weather.hours} h, lat {self.weather.latitude:.2f}, "
            f"lon {self.weather.longitude:.2f}); wall facing {s.azimuth:g} deg from north; solar absorptance "
            f"{s.solar_absorptance:g}; sky radiation {'on' if s.sky_radiation else 'off'}; h_e "
            f"{s.exterior_surface_coefficient:g}, h_i {s.interior_surface_coefficient:g} W/(m2K); interior "
            f"{s.interior_temperature:g} degC, "
            + (
                f"humidity class {s.interior_humidity_class}"
                if s.interior_humidity_class
                else f"RH {s.interior_relative_humidity:g}"
            )
            + f"; variants start from {self.wall_source}.",
            f"periodic year: {first.passes} pass(es) after a {WARMUP_DAYS}-day warm-up for the first variant "
            f"(max over variants {max(v.passes for v in self.variants)}), last change "
            f"{max(v.residual for v in self.variants):.1e} K < {PERIODIC_TOLERANCE:g} K; time step "
            f"{s.time_step:g} s; annual loss = net heat leaving the room through the wall (hours of gain count "
            "negative).",
        ]
        out += self.moisture_notes()
        for v in self.variants:
            g = v.glaser
            if g is not None and not g.mould_ok:
                out.append(
                    f"{v.spec.name}: f_Rsi {g.frsi:.3f} <= f_Rsi,min {g.frsi_min:.3f} (month {g.critical_month}): "
                    "mould risk at the interior surface (ISO 13788, surface RH 0.8)"
                )
        if self.samples is not None:
            sp = self.spread()
            dominant = sp.drop(index="R total of the sampled wall").abs().mean(axis=1).sort_values(ascending=False)
            top = [f"{k} ({sp.loc[k].mean():+.2f})" for k in dominant.index[:3] if np.isfinite(dominant[k])]
            rt = float(sp.loc["R total of the sampled wall"].mean())
            width = {v.spec.name: v.p95 - v.p05 for v in self.variants}
            narrowest = min(width, key=width.get)
            out.append(
                f"{len(self.samples.walls)} posterior draws per variant from {self.samples.source}; the spread of "
                f"the annual loss comes mostly from {', '.join(top)} (Spearman rank correlation with the annual "
                f"loss, mean over the variants); its rank correlation with the sampled wall's total thermal "
                f"resistance is {rt:+.2f}. The 5-95 % interval is {width[first.spec.name]:.2f} kWh/m2 wide for "
                f"{first.spec.name!r} and {width[narrowest]:.2f} kWh/m2 for {narrowest!r}."
            )
            out.append(
                "The temperatures inside a wall fix the ratios of its layers' resistances much better than their "
                "common scale: scaling every conductivity together barely moves the temperature profiles but moves "
                "U and the heat loss in proportion. That direction shows up here"
                + (" (the spread follows the total resistance almost one to one)" if abs(rt) > 0.9 else "")
                + "; a heat-flux sensor in the monitoring campaign measures the heat flow that fixes the scale and "
                "would narrow these intervals. Layers a variant adds come from the catalogue, not from the data, so "
                "the more of the total resistance they carry, the narrower the interval."
            )
        return out

    def moisture_notes(self) -> list[str]:
        """The hygrothermal run's sentences: what ran (or why not), the rain, where Glaser and it disagree."""
        from . import moisture_risk as mr

        info = self.info.get("moisture", {})
        if info.get("skipped"):
            return [f"moisture run (EN 15026): not run: {info['skipped']}"]
        if not any(v.hygro is not None for v in self.variants):
            return []
        ran = [v for v in self.variants if v.hygro is not None]
        out = [
            f"moisture run (EN 15026): each variant year after year from RH {mr.INITIAL_RH:g} until every layer's "
            f"water changes by less than max({mr.PERIODIC_RELATIVE:.0%}, {mr.PERIODIC_ABSOLUTE:g} kg/m2) per year "
            f"(at most {self.spec.moisture_max_years} years): "
            + ", ".join(
                f"{v.spec.name!r} {v.hygro.years}" + ("" if v.hygro.periodic else " (not periodic)") for v in ran
            )
            + f" years; interior: {_interior_words(self.spec)}; mould index (VTT, C_mat "
            f"{self.spec.mould_decline_coefficient:g}) at every layer interface, each side with its material's class; "
            f"verdicts: mould index >= {mr.MOULD_LIMIT:g} mould_risk, RH >= {mr.DRY_RH:g} acceptable, below dry, "
            "not periodic with rising water accumulating.",
        ]
        if info.get("rain"):
            out.append(info["rain"] + ".")
        for v in ran:
            d = moisture_disagreement(v)
            if d:
                out.append(f"{v.spec.name}: {d}")
        return out

    def verdict_table(self) -> pd.DataFrame:
        """One line per variant: the ISO 13788 (Glaser) result beside the transient run's, and which to trust."""
        rows = []
        for v in self.variants:
            if v.hygro is None:
                continue
            h, g = v.hygro, v.glaser
            rows.append(
                {
                    "variant": v.spec.name,
                    "Glaser (ISO 13788)": g.verdict if g is not None else "not checked",
                    "transient (EN 15026)": h.verdict,
                    "critical interface": h.critical_name,
                    "max RH": round(h.rh_max, 3),
                    "mould index": round(h.mould_max, 2),
                    "water trend [kg/(m2 a)]": round(h.trend, 4),
                    "note": moisture_disagreement(v) or "the two agree",
                }
            )
        return pd.DataFrame(rows).set_index("variant") if rows else pd.DataFrame()

    def report_items(self, d: Path) -> tuple[list, list]:
        """The moisture tables and figures for the report (``d``: where :meth:`write_into` wrote)."""
        tables, figures = [], []
        vt = self.verdict_table()
        if len(vt):
            tables.append(("Moisture verdicts: ISO 13788 (Glaser) beside the transient run (EN 15026)", vt, ()))
        if (Path(d) / "moisture_critical.png").exists():
            figures.append(
                (
                    "RH and mould index at each variant's critical interface over the year",
                    Path(d) / "moisture_critical.png",
                )
            )
        if (Path(d) / "water_by_year.png").exists():
            figures.append(("Water per layer by year until periodic", Path(d) / "water_by_year.png"))
        return tables, figures

    # ------------------------------------------------------------------ writing
    def write(self, out_dir) -> Path:
        from ..outputs import output_dir

        manifest = {
            "command": "retrofit",
            "study_file": str(self.study.path) if self.study.path else None,
            "study_sha256": self.study.sha256,
            "weather": str(self.weather.path),
        }
        with output_dir(out_dir, manifest=manifest) as tmp:
            self.write_into(Path(tmp))
        return Path(out_dir)

    def write_into(self, d: Path) -> list[str]:
        """Write ``variants.csv``, per-variant ``hourly_<k>.csv`` / ``glaser_<k>.csv``, ``spread.csv`` (with
        samples), ``retrofit.json`` and the figures into ``d``; returns the file names."""
        from ..wallfile import dump_wall
        from . import plots

        d = Path(d)
        files = ["variants.csv"]
        self.table().to_csv(d / "variants.csv", index=False, float_format="%.6g")
        for k, v in enumerate(self.variants, 1):
            h = v.hourly.copy()
            h.index = h.index.strftime("%Y-%m-%dT%H:%M")
            h.to_csv(d / f"hourly_{k}.csv", float_format="%.5g")
            files.append(f"hourly_{k}.csv")
            (d / f"variant_{k}.toml").write_text(dump_wall(v.wall, f"retrofit variant {v.spec.name!r}"))
            files.append(f"variant_{k}.toml")
            if v.glaser is not None:
                v.glaser.table.to_csv(d / f"glaser_{k}.csv", float_format="%.6g")
                files.append(f"glaser_{k}.csv")
            if v.hygro is not None:
                hourly_m, water = moisture_frames(v, hour_index=v.hourly.index)
                hourly_m.to_csv(d / f"moisture_{k}.csv", float_format="%.5g")
                water.to_csv(d / f"water_{k}.csv", float_format="%.6g")
                files += [f"moisture_{k}.csv", f"water_{k}.csv"]
        if self.samples is not None:
            self.spread().to_csv(d / "spread.csv", float_format="%.4f")
            files.append("spread.csv")
            pd.DataFrame({v.spec.name: v.sample_losses for v in self.variants}).to_csv(
                d / "sample_losses.csv", index_label="sample", float_format="%.6g"
            )
            files.append("sample_losses.csv")
        info = {
            "variants": [
                {
                    "index": k,
                    "name": v.spec.name,
                    "passes": v.passes,
                    "periodic_residual_K": v.residual,
                    "layers": [layer.id for layer in v.wall.layers],
                    **(
                        {
                            "moisture_years": v.hygro.years,
                            "moisture_periodic": v.hygro.periodic,
                            "mould_years": v.hygro.mould_years,
                            "moisture_seconds": v.hygro.seconds,
                            "moisture_cells": v.hygro.stats.get("cells"),
                            "runoff_kg_m2": v.hygro.runoff_kg_m2,
                        }
                        if v.hygro is not None
                        else {}
                    ),
                }
                for k, v in enumerate(self.variants, 1)
            ],
            "weather": self.weather.name,
            "wall_source": self.wall_source,
            "seconds": self.seconds,
            "notes": self.notes(),
            **self.info,
        }
        (d / "retrofit.json").write_text(json.dumps(info, indent=2, default=float))
        files.append("retrofit.json")
        files += plots.write_figures(self, d)
        return files


def moisture_frames(v: VariantResult, hour_index=None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A variant's moisture outputs: the last year's hourly RH, temperature and mould index at each interface
    (``rh <a|b>``, ``T <a|b>``, ``M <a|b>``; M after each hour, 0 at the first mark) and the water per layer at
    the start of each year [kg/m2]."""
    h = v.hygro
    cols = {}
    for k, itf in enumerate(h.interfaces):
        cols[f"rh {itf.name}"] = h.rh[k]
        cols[f"T {itf.name}"] = h.temperature[k]
        cols[f"M {itf.name}"] = np.concatenate([[h.mould[k][-1]], h.mould[k]])
    hourly = pd.DataFrame(cols, index=hour_index)
    if hour_index is not None:
        hourly.index = (
            pd.Index(hour_index).strftime("%Y-%m-%dT%H:%M") if hasattr(hour_index, "strftime") else hour_index
        )
        hourly.index.name = "time"
    water = pd.DataFrame(h.layer_water, columns=[f"layer {i}" for i in h.layer_ids])
    water.insert(0, "year", np.arange(len(water)))
    water["total"] = h.layer_water.sum(axis=1)
    return hourly, water.set_index("year")


def _interior_words(spec: RetrofitSpec) -> str:
    """The moisture run's interior, in words (for the notes)."""
    if spec.moisture_interior_climate != "constant":
        return f"{spec.moisture_interior_climate} occupancy (Annex C, from each day's mean outdoor temperature)"
    rh = (
        f"humidity class {spec.interior_humidity_class}"
        if spec.interior_humidity_class is not None
        else f"RH {spec.interior_relative_humidity:g}"
    )
    return f"{spec.interior_temperature:g} degC and {rh} all year"


def moisture_disagreement(v: VariantResult) -> str:
    """A sentence when ISO 13788 (Glaser) and the transient run disagree, saying which to trust and why.

    Glaser passes with ``none`` or ``evaporates``; the transient run with ``dry`` or ``acceptable``."""
    g, h = v.glaser, v.hygro
    if g is None or h is None:
        return ""
    glaser_ok = g.verdict in ("none", "evaporates")
    transient_ok = h.verdict in ("dry", "acceptable")
    if not glaser_ok and transient_ok:
        return (
            f"Glaser says {g.verdict} but the transient run says {h.verdict}: trust the transient run (EN 15026), "
            "which has the moisture storage, capillary redistribution and hourly weather that the monthly Glaser "
            "method leaves out (ISO 13788 clause 1); Glaser is a conservative screen"
        )
    if glaser_ok and not transient_ok:
        return (
            f"Glaser says {g.verdict} but the transient run says {h.verdict} at {h.critical_name}: trust the "
            "transient run, which sees what Glaser cannot (mould growth at high RH without net condensation, "
            "driving rain, built-in moisture, summer condensation from solar-driven inward vapour, hourly peaks); "
            "Glaser only weighs the heating season's diffusion condensate"
        )
    return ""


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman rank correlation (average ranks for ties); NaN when either is constant."""
    if np.ptp(x) == 0 or np.ptp(y) == 0:
        return math.nan
    rx = pd.Series(x).rank().to_numpy()
    ry = pd.Series(y).rank().to_numpy()
    return float(np.corrcoef(rx, ry)[0, 1])


def _frsi(wall: Wall, spec: RetrofitSpec) -> float:
    from .glaser import temperature_factor

    return temperature_factor(wall, rse=1.0 / spec.exterior_surface_coefficient)


# ============================================================================ the draws' checkpoint
#: moisture draws per executor worker (one worker without an executor) in a chunk; the checkpoint is saved after each
DRAW_CHUNK_PER_WORKER = 4
#: the checkpoint beside the output directory: ``.<out>.retrofit-checkpoint.npz``; its format version
CHECKPOINT_SUFFIX = "retrofit-checkpoint.npz"
CHECKPOINT_FORMAT = 1


def checkpoint_path(out) -> Path | None:
    """The draws' checkpoint of output directory ``out`` (None without one)."""
    from ..calibration.checkpoint import checkpoint_path as beside

    return beside(out, CHECKPOINT_SUFFIX)


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def draw_inputs(study, spec: RetrofitSpec, weather: Weather, base: Wall, vwalls: list[Wall], smp) -> dict:
    """What determines the draws' results, each as a hash (or a count), in the order a refusal names them."""
    from ..wallfile import dump_wall

    wpath = getattr(weather, "path", None)
    if wpath is not None and Path(wpath).is_file():
        weather_sha = _sha(Path(wpath).read_bytes())
    else:
        weather_sha = _sha(pd.util.hash_pandas_object(weather.data).to_numpy().tobytes())
    return {
        "study file": study.sha256 or "",
        "[retrofit] table": _sha(repr(spec).encode()),
        "weather file": weather_sha,
        "wall": _sha("\n".join(dump_wall(w) for w in [base, *vwalls]).encode()),
        "number of draws": len(smp.walls),
        "posterior draws": _sha(
            json.dumps(list(smp.names)).encode() + np.ascontiguousarray(smp.values, float).tobytes()
        ),
    }


@dataclass
class DrawCheckpoint:
    """The posterior draws' results so far, by variant index: ``losses[k]`` the thermal draws' annual losses
    [kWh/m2] (all or none), ``moisture[k]`` the rows of the moisture draws run so far (mould index, trend, years,
    CPU seconds; the first ``len`` draws). Saved atomically to ``path`` with ``inputs`` (:func:`draw_inputs`)."""

    path: Path
    inputs: dict
    variants: list[str]
    losses: dict = field(default_factory=dict)
    moisture: dict = field(default_factory=dict)

    def save(self) -> None:
        from ..calibration.checkpoint import write_bytes

        meta = {"format": CHECKPOINT_FORMAT, "inputs": self.inputs, "variants": self.variants}
        arrays = {f"losses_{k}": a for k, a in self.losses.items()}
        arrays.update({f"moisture_{k}": a for k, a in self.moisture.items()})
        buf = io.BytesIO()
        np.savez(buf, meta=np.array(json.dumps(meta)), **arrays)
        write_bytes(self.path, buf.getvalue())

    @classmethod
    def load(cls, path: Path, inputs: dict, variants: list[str]) -> DrawCheckpoint:
        """Read and check a checkpoint for the run of ``inputs`` and ``variants``; :class:`CheckpointError` (one line
        naming the file, what is wrong and how to start afresh) on anything that does not fit."""
        from ..calibration.checkpoint import CheckpointError, read_bytes

        raw = read_bytes(path)
        try:
            with np.load(io.BytesIO(raw), allow_pickle=False) as z:
                arrays = {key: z[key] for key in z.files}
            meta = json.loads(str(arrays.pop("meta")))
        except Exception as exc:  # a damaged file: whatever numpy or json raise
            raise CheckpointError(path, f"not a retrofit checkpoint (damaged? {type(exc).__name__})") from None
        if not isinstance(meta, dict) or meta.get("format") != CHECKPOINT_FORMAT:
            fmt = meta.get("format") if isinstance(meta, dict) else None
            raise CheckpointError(path, f"format {fmt!r}, this wallcal reads format {CHECKPOINT_FORMAT}")
        old = meta.get("inputs") if isinstance(meta.get("inputs"), dict) else {}
        for what, value in inputs.items():
            if old.get(what) != value:
                raise CheckpointError(path, f"it was made with another {what}")
        if meta.get("variants") != variants:
            raise CheckpointError(path, "it was made for other retrofit variants")
        n = inputs["number of draws"]
        ck = cls(path, inputs, variants)
        for key, a in arrays.items():
            kind, _, k = key.partition("_")
            ok = kind in ("losses", "moisture") and k.isdigit() and int(k) < len(variants)
            shape_ok = a.ndim == 1 and len(a) == n if kind == "losses" else a.ndim == 2 and a.shape[1] == 4
            if not (ok and shape_ok and a.dtype == float and len(a) <= n):
                raise CheckpointError(path, f"unexpected entry {key!r} of shape {a.shape}")
            if kind == "losses" and not np.all(np.isfinite(a)):
                raise CheckpointError(path, f"{key} holds a value that is not a finite number")
            (ck.losses if kind == "losses" else ck.moisture)[int(k)] = a
        return ck


# ============================================================================ the moisture run's set-up
def _layer_path(v: VariantSpec, wall: Wall):
    """``k -> key path`` of layer k of a variant's wall (the variant's added or replaced layer, else the wall's)."""
    added = {id(layer): f"{v.path}.add_exterior[{i}]" for i, layer in enumerate(v.add_exterior)}
    added.update({id(layer): f"{v.path}.add_interior[{i}]" for i, layer in enumerate(v.add_interior)})
    replaced = {lid for lid, _ in v.replace}

    def where(k: int) -> str:
        layer = wall.layers[k]
        if id(layer) in added:
            return added[id(layer)]
        if layer.id in replaced:
            return f"{v.path}.replace.{layer.id}"
        return f"wall layer {layer.id!r}"

    return where


def _moisture_setup(study, spec: RetrofitSpec, weather, yb, base: Wall, source: str, vwalls: list[Wall]):
    """The hygrothermal run's settings (None when it does not run) and what to say about it.

    It runs when ``moisture_check`` is on and every layer of the base wall has hygric properties; then every
    layer a variant adds or changes must have them too (StudyError naming its key path, before any run)."""
    from . import moisture_risk as mr

    if not spec.moisture_check:
        return None, {"skipped": "retrofit.moisture_check = false"}
    missing = mr.missing_hygric(base)
    if missing:
        return None, {
            "skipped": f"layer(s) {', '.join(missing)} of {source} have no hygric properties (moisture_storage and "
            "vapour_resistance_factor, own or from a catalogue material; docs/retrofit.md, 'Moisture risk'); the "
            "moisture columns stay empty"
        }
    problems = []
    for v, w in zip(spec.variants, vwalls, strict=True):
        where = _layer_path(v, w)
        for k, layer in enumerate(w.layers):
            try:
                mr.layer_material(layer, where(k))
            except StudyError as exc:
                problems += [p for p in exc.problems if p not in problems]
    if problems:
        raise StudyError(problems, source=str(study.path) if study.path else None)
    ext, intr, rain = mr.ham_boundaries(weather, spec, yb, spec.driving_rain_factor)
    settings = mr.RunSettings(
        exterior=ext,
        interior=intr,
        hours=weather.hours,
        max_years=spec.moisture_max_years,
        decline=spec.mould_decline_coefficient,
        overrides=spec.mould_sensitivity,
    )
    return settings, {"rain": rain.note(), "driving_rain_mm": rain.driving_rain_mm}


# ============================================================================ the entry point
def retrofit(
    study, *, wall=None, from_dir=None, out=None, samples=None, progress=False, wall_source=None, resume=False
) -> RetrofitResult:
    """Run every ``[retrofit]`` variant of a study over its weather year.

    Parameters
    ----------
    study : Study
        With a ``[retrofit]`` table.
    wall : Wall, optional
        Start from this wall instead of the study's (``--wall``).
    from_dir : path, optional
        A ``wallcal calibrate`` output (its calibrated wall) or a ``wallcal posterior`` output (its samples).
    out : path, optional
        Write the outputs there (atomically).
    samples : int, optional
        At most this many posterior draws; default ``retrofit.samples``.
    progress : bool
        Print a line per variant on stderr, and while the moisture draws run a progress line (draws done of the
        variant's, elapsed, estimated remaining).
    wall_source : str, optional
        How the report names the wall given as ``wall`` (default "the given wall").
    resume : bool
        Take the draws already run from the checkpoint beside ``out`` (module docstring) instead of running them
        again. Without it a checkpoint there is replaced.

    Raises
    ------
    CheckpointError
        ``resume`` and a checkpoint that is damaged or was made with other inputs (one line).

    Returns
    -------
    RetrofitResult
    """
    import sys

    from ..standards import iso6946
    from .glaser import monthly_method

    spec: RetrofitSpec | None = getattr(study, "retrofit", None)
    if spec is None:
        raise StudyError(
            ["retrofit: the study has no [retrofit] table (see docs/retrofit.md)"],
            source=str(study.path) if study.path else None,
        )
    t_start = time.perf_counter()
    base, source, post_dir = base_wall_from(study, wall, from_dir)
    source = wall_source or source
    base_dir = study.path.parent if study.path else None
    weather = read_weather(resolve_weather(spec.weather, base_dir))
    yb = year_boundaries(weather, spec)
    # every variant's wall first: a bad variant fails before any run
    problems = []
    vwalls = []
    for v in spec.variants:
        try:
            vwalls.append(apply_variant(base, v))
        except StudyError as exc:
            problems += exc.problems
    if problems:
        raise StudyError(problems, source=str(study.path) if study.path else None)
    smp = None
    if post_dir is not None:
        from ..analysis.posterior import load_samples

        smp = load_samples(post_dir, base, samples or spec.samples)
        vwalls = [apply_variant(smp.point, v) for v in spec.variants]
    climate = monthly_climate(weather)
    glasers = []
    if spec.condensation_check:
        for v, w in zip(spec.variants, vwalls, strict=True):
            try:
                glasers.append(
                    monthly_method(
                        w,
                        climate,
                        spec.interior_temperature,
                        relative_humidity=spec.interior_relative_humidity,
                        humidity_class=spec.interior_humidity_class,
                        rsi=1.0 / spec.interior_surface_coefficient,
                        rse=1.0 / spec.exterior_surface_coefficient,
                    )
                )
            except StudyError as exc:  # the first variant that fails says it (usually the base wall's layers)
                raise StudyError(
                    [f"{v.path} ({v.name!r}): {exc.problems[0]}"], source=str(study.path) if study.path else None
                ) from None
    else:
        glasers = [None] * len(vwalls)
    settings, moisture_info = _moisture_setup(study, spec, weather, yb, base, source, vwalls)
    ckpt = _open_checkpoint(study, spec, weather, base, vwalls, smp, out, resume, progress)
    results = []
    times = weather.data.index.tz_localize(None)
    hour_index = times.append(pd.DatetimeIndex([times[-1] + pd.Timedelta(hours=1)]))
    per_hour = int(round(3600 / yb.time_step))
    draws_left = _DrawsLeft(len(smp.walls) if smp is not None else 0, len(vwalls), ckpt, t_start, progress)
    for k, (v, w, g) in enumerate(zip(spec.variants, vwalls, glasers, strict=True)):
        t = time.perf_counter()
        point = periodic_year([w], yb, all_rows=True)
        sample_losses = None
        if smp is not None and ckpt is not None and k in ckpt.losses:
            sample_losses = ckpt.losses[k]
        elif smp is not None:  # every posterior draw with the variant's changes, in one batch on the point's grid
            yr = periodic_year([w] + [apply_variant(sw, v) for sw in smp.walls], yb, all_rows=False)
            sample_losses = yr.annual_loss_kWh_m2[1:]
            if ckpt is not None:
                ckpt.losses[k] = sample_losses
                ckpt.save()
        hygro = sample_moisture = None
        if settings is not None:
            from . import moisture_risk as mr

            hygro = mr.run_wall(w, settings, _layer_path(v, w))
            if smp is not None:  # each draw from the point wall's periodic end state, in chunks (saved after each)
                draws = [apply_variant(sw, v) for sw in smp.walls]
                sample_moisture = _moisture_draws(draws, settings, hygro.final_state, k, v.name, ckpt, draws_left)
        u = iso6946.thermal_resistance(
            w, rsi=1.0 / spec.interior_surface_coefficient, rse=1.0 / spec.exterior_surface_coefficient
        ).u_value
        sl = slice(None, None, per_hour)
        hourly = pd.DataFrame(
            {
                "temp_air": yb.hourly["temp_air"],
                "plane_irradiance_W_m2": yb.hourly["plane_irradiance"],
                "temp_sky": yb.hourly["temp_sky"],
                "sol_air_temperature": yb.hourly["sol_air_temperature"],
                "exterior_surface_temperature": point.t_se[0, sl],
                "interior_surface_temperature": point.t_si[0, sl],
                "loss_W_m2": -point.q_i[0, sl],
            },
            index=pd.DatetimeIndex(hour_index, name="time"),
        )
        results.append(
            VariantResult(
                spec=v,
                wall=w,
                u_value=u,
                annual_loss=float(point.annual_loss_kWh_m2[0]),
                peak_loss=float(point.peak_loss_W_m2[0]),
                min_surface_temperature=float(np.nanmin(point.t_si[0])),
                passes=point.passes,
                residual=point.residual,
                hourly=hourly,
                glaser=g,
                sample_losses=sample_losses,
                hygro=hygro,
                sample_moisture=sample_moisture,
            )
        )
        if progress:
            print(f"  {v.name}: {time.perf_counter() - t:.1f} s", file=sys.stderr, flush=True)
    res = RetrofitResult(
        study=study,
        spec=spec,
        weather=weather,
        wall_source=source,
        variants=results,
        samples=smp,
        seconds=time.perf_counter() - t_start,
        info={"engine_path": point.path, "nodes_first_variant": point.nodes, "moisture": moisture_info},
    )
    if out is not None:
        res.write(out)
    if ckpt is not None:  # only now that the outputs are in place (a kill before this line resumes from it)
        from ..calibration.checkpoint import remove

        remove(ckpt.path)
    return res


def _open_checkpoint(study, spec, weather, base, vwalls, smp, out, resume, progress):
    """The run's :class:`DrawCheckpoint` (None without posterior draws or output directory): the one beside ``out``
    with ``resume``, checked, else a new one (a checkpoint there is replaced)."""
    import sys

    from ..calibration.checkpoint import CheckpointError, present, remove
    from ..errors import WallcalError

    path = checkpoint_path(out)
    if resume and path is None:
        raise WallcalError("resume: give the output directory (out); the checkpoint is kept beside it")
    if resume and not present(path):
        raise WallcalError(f"nothing to resume: no checkpoint {path} (run without --resume)")
    if smp is None or path is None:
        if resume:
            raise CheckpointError(path, "this run has no posterior draws to resume (give --from a posterior output)")
        return None
    names = [v.name for v in spec.variants]
    inputs = draw_inputs(study, spec, weather, base, vwalls, smp)
    if resume:
        ck = DrawCheckpoint.load(path, inputs, names)
        ck.save()  # written again: the command sees the run took it up (the file changed)
        return ck
    if present(path):
        if path.is_dir() and not path.is_symlink():
            raise CheckpointError(path, "a directory stands where the checkpoint goes", "remove it to run")
        if progress:
            print(f"replacing the checkpoint {path.name} of an earlier run (--resume continues one)", file=sys.stderr)
        remove(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ck = DrawCheckpoint(path, inputs, names)
    ck.save()
    return ck


@dataclass
class _DrawsLeft:
    """The moisture draws' progress over the variants: how many are left and how fast they go in this run."""

    per_variant: int
    variants: int
    ckpt: DrawCheckpoint | None
    t_start: float
    progress: bool
    ran: int = 0
    seconds: float = 0.0

    def line(self, k: int, name: str, done: int, resumed: int) -> str:
        left = (
            self.per_variant
            - done
            + sum(
                self.per_variant - (len(self.ckpt.moisture.get(j, ())) if self.ckpt is not None else 0)
                for j in range(k + 1, self.variants)
            )
        )
        eta = f", ~{self.seconds / self.ran * left:.0f} s left" if self.ran and left else ""
        was = f", {resumed} from the checkpoint" if resumed else ""
        return (
            f"{name!r} ({k + 1}/{self.variants}): moisture draws {done}/{self.per_variant}{was}, "
            f"{time.perf_counter() - self.t_start:.0f} s{eta}"
        )


def _moisture_draws(draws, settings, initial, k: int, name: str, ckpt, left: _DrawsLeft) -> np.ndarray:
    """A variant's moisture draws in chunks, those of the checkpoint taken from it; the checkpoint saved and the
    progress line updated after each chunk."""
    from ..calibration.algorithms import Progress
    from ..cluster import current_executor
    from . import moisture_risk as mr

    done = ckpt.moisture.get(k) if ckpt is not None else None
    resumed = 0 if done is None else len(done)
    prog = Progress("retrofit", enabled=left.progress)
    ex = current_executor()
    chunk = DRAW_CHUNK_PER_WORKER * (_workers(ex) if ex is not None else 1)
    t = [time.perf_counter(), resumed]

    def on_chunk(rows: np.ndarray) -> None:
        if ckpt is not None:
            ckpt.moisture[k] = rows
            ckpt.save()
        now = time.perf_counter()
        left.ran += len(rows) - t[1]
        left.seconds += now - t[0]
        t[:] = [now, len(rows)]
        if len(rows) < len(draws):  # (the last is shown by close)
            prog.update(left.line(k, name, len(rows), resumed))

    if resumed < len(draws):
        prog.update(left.line(k, name, resumed, resumed), force=True)
    out = mr.run_draws(draws, settings, initial, done=done, chunk=chunk, on_chunk=on_chunk)
    prog.close(left.line(k, name, len(out), resumed))
    return out


def _workers(ex) -> int:
    """The executor's worker processes (a remote cluster: as its scheduler reports them, at least 1)."""
    if ex.address is None:
        return ex.n_local_workers()
    try:
        return max(1, len(ex.client().scheduler_info().get("workers", {})))
    except Exception:  # the count only sizes the chunks
        return 1
