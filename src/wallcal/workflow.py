"""The whole study in one command: ``wallcal run``.

Stages, in the order of the reference study:

1. ``data`` - measured signals over the period (Table III, Fig. 3)
2. ``engines`` - base case in every available engine (Table IV)
3. ``grid`` - sensitivity to the numerical grid (Fig. 4)
4. ``sensitivity`` - one-at-a-time sensitivity over the calibration space
5. ``calibration`` - automatic calibration (Tables V-VII, Fig. 5)
6. ``diagnose`` - which extensions of the model structure the data support (``wallcal diagnose``)
7. ``crosscheck`` - base and calibrated walls in every engine (Table VIII)
8. ``standards`` - ISO 6946 U-value and ISO 13786 dynamic figures before and after, ISO 9869-1 verdict
9. ``identifiability`` - which calibrated properties the data identify
10. ``retrofit`` - the study's ``[retrofit]`` variants from the calibrated wall over a weather year
11. ``building`` - with a ``[building]`` table: the study's and the calibrated wall (and the study's posterior
    draws) in the whole building through EnergyPlus (``wallcal building``)

Each stage writes its machine-readable results in its own sub-directory of the
output and returns a :class:`StageOutput` for the report. A failing *optional*
stage is recorded (with its error) and the run goes on; the data, base-case and
calibration stages are required. The whole output directory appears only when
complete (:func:`wallcal.outputs.output_dir`).
"""

from __future__ import annotations

import json
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from .errors import OptionalDependencyError, WallcalError
from .study import Study


@dataclass
class StageOutput:
    """What a stage hands to the report."""

    name: str
    title: str
    status: str = "ok"  # ok | failed | skipped
    message: str = ""
    text: list[str] = field(default_factory=list)  # paragraphs (plain text)
    tables: list[tuple[str, pd.DataFrame, tuple[str, ...]]] = field(default_factory=list)  # title, df, % columns
    figures: list[tuple[str, Path]] = field(default_factory=list)
    files: list[str] = field(default_factory=list)
    seconds: float = 0.0


@dataclass
class RunContext:
    study: Study
    out: Path
    quick: bool = False
    progress: bool = True
    engines: list[str] = field(default_factory=list)
    measurements: object = None
    prepared: object = None
    results: dict = field(default_factory=dict)

    def say(self, msg: str):
        if self.progress:
            print(msg, file=sys.stderr, flush=True)


@dataclass
class Stage:
    name: str
    title: str
    func: Callable[[RunContext, Path, StageOutput], None]
    required: bool = False


# ============================================================================ stages
def _stage_data(ctx: RunContext, d: Path, so: StageOutput):
    from .data import load_measurements, summarize
    from .plots import plot_measurements
    from .simulation import BATCH_NEEDS, boundary_named, prepare

    study = ctx.study
    ctx.measurements = load_measurements(study)
    ctx.prepared = prepare(
        study, needs=BATCH_NEEDS, purpose="calibration and the analyses", measurements=ctx.measurements
    )
    frame = boundary_named(ctx.measurements.frame, study)
    summ = summarize(frame, study.period.start, study.period.end)
    summ.to_csv(d / "summary.csv", float_format="%.6g")
    plot_measurements(study, ctx.measurements.frame, d / "measurements.png")
    so.tables.append(("Measured signals over the comparison period (Table III)", summ, ()))
    so.figures.append(("Measured probe temperatures and heat flux densities (Fig. 3)", d / "measurements.png"))
    m = ctx.measurements
    so.text.append(
        f"{len(ctx.prepared.times)} measured timestamps from {study.period.start} to {study.period.end}"
        f" (warm-up from {ctx.prepared.inp.t0}); data file {Path(study.data.file).name}, "
        f"sha256 {m.sha256[:12]}."
    )
    if len(m.spikes):
        m.spikes.to_csv(d / "spikes.csv", index=False)
        kept = "left out of the metrics." if study.data.remove_spikes else "kept (data.remove_spikes = false)."
        so.text.append(f"{len(m.spikes)} single-sample spike(s) found and {kept}")
    if len(m.bridged_gaps):
        m.bridged_gaps.to_csv(d / "bridged_gaps.csv", index=False)
        so.text.append(f"{len(m.bridged_gaps)} gap(s) in boundary series bridged by linear interpolation.")
    ctx.results["summary"] = summ


def _available_engines(prepared) -> tuple[list[str], str]:
    """The registry's base-case engines that can run the study, and why the others cannot (empty when every
    one runs): each engine's own :meth:`~wallcal.engines.base.Engine.problems` with the study's input, or
    that it is not installed."""
    from .engines import available, engine_names

    # the study's own engine too (ham, for a moisture study, is no base case of heat-only studies)
    engines, why = available(tuple(dict.fromkeys((*engine_names(base_case=True), prepared.engine_name))), prepared.inp)
    return engines, "; ".join(f"{name}: {reason}" for name, reason in why.items())


def _stage_engines(ctx: RunContext, d: Path, so: StageOutput):
    from .comparison import compare_engines

    why = ""
    if not ctx.engines:
        ctx.engines, why = _available_engines(ctx.prepared)
    comp = compare_engines(ctx.study, ctx.engines)
    so.files += comp.write_into(d)
    so.tables.append(("Base case vs measurements per engine (Table IV)", comp.table_iv(), ()))
    so.tables.append(("RMS difference between engines", comp.difference_matrix(), ()))
    so.figures.append(("Measured vs each engine", d / "comparison.png"))
    if why:
        so.text.append(f"The base case ran in {', '.join(ctx.engines)} only: {why}.")
    ctx.results["comparison"] = comp
    from .engines import engine_class
    from .report import moisture_figures
    from .study import QUANTITY_UNITS

    moist = next((n for n in comp.results if engine_class(n).capabilities.moisture), None)
    if ctx.study.has_moisture and moist is not None:
        so.figures += moisture_figures(ctx.study, d, comp.results[moist], engine=moist)
    base = comp.results[ctx.engines[0]].metrics
    units = {s.name: QUANTITY_UNITS[s.quantity] for s in ctx.study.sensors}
    so.text.insert(
        0,
        f"RMSE of the base case ({ctx.engines[0]}): "
        + ", ".join(
            f"{r.signal} {r.rmse:.3f} {units[r.signal]}" + (" (within accuracy)" if r.within_accuracy else "")
            for r in base.itertuples()
        )
        + f"; engines run: {', '.join(comp.results)}.",
    )
    base.to_csv(d / "metrics_base.csv", index=False, float_format="%.6g")
    ctx.results["base_metrics"] = base


def _stage_grid(ctx: RunContext, d: Path, so: StageOutput):
    from .analysis.gridstudy import grid_study

    kw = {"time_steps": (60, 300, 900), "grid_constants": (1, 2, 3)} if ctx.quick else {}
    targets = list(ctx.study.calibration.targets) if ctx.study.calibration else None
    res = grid_study(ctx.study, targets=targets, progress=ctx.progress, **kw)
    res.write_into(d)
    so.files += ["grid_study.csv", "rmse_vs_time_step.csv", "convergence.csv", "grid_study.json", "grid_study.png"]
    so.text += res.summary().splitlines()
    so.tables.append(("RMSE against the time step for each grid constant C (Fig. 4 as numbers)", res.rmse_table(), ()))
    so.figures.append(("RMSE against the time step for C = 1, 2, 3 (Fig. 4)", d / "grid_study.png"))
    ctx.results["grid"] = res


def _stage_sensitivity(ctx: RunContext, d: Path, so: StageOutput):
    from .analysis.sensitivity import sensitivity

    if not ctx.study.calibration:
        so.status, so.message = "skipped", "the study has no [calibration] table"
        return
    res = sensitivity(ctx.study, method="oat", prepared=ctx.prepared, progress=False)
    res.write_into(d)
    so.files += [
        "sensitivity_oat.csv",
        "sensitivity_oat_per_target.csv",
        "sensitivity_oat_by_layer.csv",
        "sensitivity.json",
        "sensitivity_oat.png",
    ]
    so.text += res.summary().splitlines()
    so.tables.append(("Ranking of the calibration parameters (one at a time, each to its bounds)", res.ranking, ()))
    so.tables.append(("Influence summed per layer", res.by_layer, ()))
    so.figures.append(("One-at-a-time sensitivity", d / "sensitivity_oat.png"))
    ctx.results["sensitivity"] = res


def write_stage_manifest(ctx: RunContext, d: Path, command: str) -> None:
    """A stage folder that is another command's output gets that command's manifest (its format version)."""
    from .outputs import write_manifest
    from .simulation import manifest_of

    write_manifest(d, {**manifest_of(ctx.study, command), "written_by": "wallcal run"})


def _stage_calibration(ctx: RunContext, d: Path, so: StageOutput):
    from .calibration import calibrate

    if not ctx.study.calibration:
        so.status = "skipped"
        so.message = "the study has no [calibration] table"
        return
    quick = ctx.quick and ctx.study.calibration.algorithm == "pso-hj"
    res = calibrate(
        ctx.study, prepared=ctx.prepared, progress=ctx.progress, settings={"generations": 8} if quick else None
    )
    res.write_into(d)
    write_stage_manifest(ctx, d, "calibrate")  # a calibrate output: 'wallcal building/retrofit --from' read it
    so.files += [
        "calibrated_wall.toml",
        "calibration.json",
        "metrics.csv",
        "parameters.csv",
        "convergence.png",
        "fit.png",
    ]
    so.text.append(
        f"{res.algorithm}: objective ({res.space.objective}) {res.f_base:.6g} -> {res.f_opt:.6g} in "
        f"{res.evaluations} simulations, {res.seconds:.1f} s; {res.space.n} parameters, targets "
        f"{', '.join(res.space.targets)}."
    )
    so.tables.append(
        (
            "Calibrated properties (optimal wall, as in Tables V-VII)",
            res.parameter_table()[["base", "lower", "upper", "optimum", "change", "at_bound"]],
            ("change",),
        )
    )
    m = res.metrics.pivot(index="signal", columns="case", values="rmse")[["base", "calibrated"]]
    if res.floors:
        m["noise floor (reference wall)"] = pd.Series(res.floors)
    so.tables.append(("RMSE per sensor before and after calibration", m, ()))
    from .report import HELD_OUT_TITLE, held_out_table
    from .validation import read as read_validation

    held = read_validation(d)  # the held-out window ([period] validation_start/end), when the study has one
    if held is not None:
        so.files.append("validation.csv")
        so.tables.append((HELD_OUT_TITLE, held_out_table(m["calibrated"], held), ()))
    so.figures.append(("Measured vs base case vs calibrated (Fig. 5)", d / "fit.png"))
    so.figures.append(("Convergence of the calibration", d / "convergence.png"))
    so.text += [f"Note: {n}" for n in res.notes]
    ctx.results["calibration"] = res


def _stage_diagnose(ctx: RunContext, d: Path, so: StageOutput):
    from .analysis.diagnose import CRITERION, diagnose

    cal = ctx.results.get("calibration")
    if cal is None:
        so.status, so.message = "skipped", "no calibrated wall"
        return
    kw = {"max_jacobians": 3, "max_adopted": 1} if ctx.quick else {}
    res = diagnose(ctx.study, start=cal, prepared=ctx.prepared, **kw)
    so.files += res.write_into(d)
    so.text += res.summary().splitlines()
    if ctx.quick:
        so.text.append("Quick run: at most 3 Jacobians per candidate; one extension adopted at most.")
    rule = (
        "with the held-out window, an extension is adopted when its values are plausible and it lowers the held-out "
        "RMSE of every temperature target (columns 'validation RMSE')"
        if ctx.study.period.validation is not None
        else "an extension is adopted when it lowers BIC by 10 or more and its values are plausible"
    )
    so.text.append(
        f"{CRITERION}: the change of BIC on the AR(1) likelihood of the residuals against the study's structure "
        f"(negative is better; {rule}; docs/identifiability.md). "
        "study.toml is the study with the adopted extensions in its [calibration] table: calibrate it to use them."
    )
    so.tables.append(
        ("Candidate extensions of the model structure, each recalibrated", res.candidates.set_index("extension"), ())
    )
    so.tables.append(("Residuals of the calibrated model per target", res.residuals, ("daily_share",)))
    ctx.results["diagnose"] = res


def _stage_crosscheck(ctx: RunContext, d: Path, so: StageOutput):
    from .crosscheck import crosscheck
    from .engines import DEFAULT_ENGINE

    cal = ctx.results.get("calibration")
    if cal is None:
        so.status = "skipped"
        so.message = "no calibrated wall"
        return
    comp = ctx.results.get("comparison")  # the base case already ran
    res = crosscheck(
        ctx.study,
        {"base case": ctx.study.wall, "calibrated": cal.wall_opt},
        ctx.engines or [DEFAULT_ENGINE],
        targets=cal.space.targets,
        known={"base case": comp} if comp is not None else None,
    )
    so.files += res.write_into(d)
    write_stage_manifest(ctx, d, "crosscheck")  # a crosscheck output: 'wallcal building --from' reads it
    so.tables.append(("Walls x engines: RMSE per target (Table VIII)", res.table.set_index(["wall", "engine"]), ()))


def _stage_standards(ctx: RunContext, d: Path, so: StageOutput):
    from .standards import iso6946, iso13786

    walls = [("base case", ctx.study.wall)]
    cal = ctx.results.get("calibration")
    if cal is not None:
        walls.append(("calibrated", cal.wall_opt))
    rows = {}
    for label, wall in walls:
        dyn = iso13786.dynamic_characteristics(wall)
        res6946 = iso6946.thermal_resistance(wall)
        rows[label] = {
            "R surface to surface [m2K/W]": res6946.resistance,
            "U (ISO 6946, Rsi 0.13, Rse 0.04) [W/(m2K)]": res6946.u_value,
            "areal heat capacity [kJ/(m2K)]": wall.areal_heat_capacity / 1000,
            "|Y12| periodic transmittance [W/(m2K)]": abs(dyn.Y12),
            "decrement factor [-]": dyn.decrement_factor,
            "time shift [h]": dyn.time_shift_h,
            "|Y11| interior admittance [W/(m2K)]": abs(dyn.Y11),
            "kappa1 interior [kJ/(m2K)]": dyn.kappa1 / 1000,
            "kappa2 exterior [kJ/(m2K)]": dyn.kappa2 / 1000,
        }
    df = pd.DataFrame(rows)
    df.index.name = "figure"
    df.to_csv(d / "wall_figures.csv", float_format="%.6g")
    so.files.append("wall_figures.csv")
    so.tables.append(
        (
            "U-value (ISO 6946) and dynamic thermal characteristics (ISO 13786, 24 h), before and after calibration",
            df,
            (),
        )
    )
    # ISO 9869-1 on the measured data, when the study has a heat-flux sensor and surface temperatures
    from .standards.insitu import iso9869_for_study

    faces = [s.face for s in ctx.study.sensors if s.quantity == "heat_flux"]
    if not faces:
        so.text.append("ISO 9869-1 average method not evaluated: the study has no heat-flux sensor.")
        return
    face = "interior" if "interior" in faces else faces[0]
    try:
        ins = iso9869_for_study(ctx.study, face=face, measurements=ctx.measurements)
    except WallcalError as exc:
        so.text.append(f"ISO 9869-1 average method not evaluated: {exc}")
        return
    so.files += ins.write_into(d)
    so.text.append(
        f"ISO 9869-1 average method on {ins.sensor} ({face} face): R = {ins.res.r_value:.3f} m2K/W "
        f"over {ins.res.duration_h:g} h; verdict: {ins.verdict}."
    )
    so.tables.append(("ISO 9869-1 acceptance criteria", ins.criteria_table()[["result", "value", "limit"]], ()))
    so.figures.append(("ISO 9869-1: running R estimate", d / "iso9869.png"))


def _stage_identifiability(ctx: RunContext, d: Path, so: StageOutput):
    from .analysis.identifiability import identifiability

    if not ctx.study.calibration:
        so.status, so.message = "skipped", "the study has no [calibration] table"
        return
    cal = ctx.results.get("calibration")
    res = identifiability(
        ctx.study,
        x0=None if cal is None else cal.x_opt,
        at="base case" if cal is None else "calibrated optimum",
        prepared=ctx.prepared,
    )
    res.write_into(d)
    so.files += ["identifiability.json", "targets_comparison.csv", "singular_values.png"]
    a = res.main
    flat = []
    if len(a.flat):
        rho_c = [str(k)[len("rho_c") + 1 : -1] for k in a.flat.index if str(k).startswith("rho_c[")]
        if rho_c:
            flat.append(
                f"rho*c of layers {', '.join(rho_c)} (density and specific heat act only through their product)"
            )
        flat += [f"{k}: {r['in words']}" for k, r in a.flat.iterrows() if not str(k).startswith("rho_c[")]
    so.text.append(
        f"{a.rank} of {a.n} parameter directions are identifiable from {'+'.join(a.targets)} at the "
        f"{res.at}" + (f"; flat directions: {'; '.join(flat)}" if flat else "; no flat direction") + "."
    )
    so.text += list(res.notes)
    so.tables.append(("Rank and the effect of adding heat-flux sensors", res.comparison(), ()))
    so.tables.append(("Per parameter (local analysis)", a.parameters, ()))
    if len(a.combos):
        so.tables.append(("Physical combinations", a.combos, ()))
    so.figures.append(("Singular values of the scaled Jacobian", d / "singular_values.png"))
    ctx.results["identifiability"] = res


def _stage_retrofit(ctx: RunContext, d: Path, so: StageOutput):
    from .retrofitting.run import find_posterior, retrofit

    if ctx.study.retrofit is None:
        so.status, so.message = "skipped", "the study has no [retrofit] table"
        return
    post, why = find_posterior(ctx.study)
    cal = ctx.results.get("calibration")
    if post is not None:  # intervals from the study's own posterior output
        res = retrofit(ctx.study, from_dir=post)
    else:
        res = retrofit(
            ctx.study,
            wall=None if cal is None else cal.wall_opt,
            wall_source="the study's wall" if cal is None else "the calibrated wall",
        )
    so.files += res.write_into(d)
    so.text += res.notes()
    if post is None:
        so.text.append(
            f"No intervals: {why}. Run 'wallcal posterior STUDY' (its default output, posterior/ next to the "
            "study, is used here when it belongs to this study file), or 'wallcal retrofit STUDY --from "
            "<posterior output>'."
        )
    so.tables.append(("Variants over the weather year (variants.csv)", res.table().set_index("variant"), ()))
    if res.samples is not None:
        so.tables.append(("Rank correlation of each sampled property with the annual loss", res.spread(), ()))
    so.figures.append(("Annual heat loss per variant", d / "annual_loss.png"))
    if (d / "glaser_worst_month.png").exists():
        so.figures.append(("ISO 13788: Glaser diagram of each variant's worst month", d / "glaser_worst_month.png"))
        so.figures.append(("ISO 13788: accumulated condensate month by month", d / "accumulation.png"))
    tables, figures = res.report_items(d)  # the moisture run (EN 15026) and the mould index
    so.tables += tables
    so.figures += figures
    ctx.results["retrofit"] = res


def _stage_building(ctx: RunContext, d: Path, so: StageOutput):
    import dataclasses

    from .building import WallEntry, building, collect_walls
    from .retrofitting.run import find_posterior

    spec = ctx.study.building
    if spec is None:
        so.status, so.message = "skipped", "the study has no [building] table"
        return
    if ctx.quick:  # a preview: two weeks of January
        spec = dataclasses.replace(spec, start=(1, 1), end=(1, 14))
    walls = [WallEntry("study wall", ctx.study.wall, "study", "the study's wall")]
    cal = ctx.results.get("calibration")
    if cal is not None:
        walls.append(WallEntry("calibrated wall", cal.wall_opt, "optimal", "the calibration stage"))
    post, why = find_posterior(ctx.study)
    if post is not None:
        walls += collect_walls(ctx.study, (), [post], spec.samples)
    res = building(ctx.study, walls, spec=spec, progress=ctx.progress)
    so.files += res.write_into(d)
    so.text += res.notes()
    if post is None:
        so.text.append(f"No posterior draws: {why}. Run 'wallcal posterior STUDY' for the spread over the draws.")
    so.tables.append(("The walls in the building (building.csv)", res.table().set_index("wall"), ()))
    if not res.spread().empty:
        so.tables.append(("Spread over the posterior draws (spread.csv)", res.spread(), ()))
    ctx.results["building"] = res


STAGES = [
    Stage("data", "Measurements", _stage_data, required=True),
    Stage("engines", "Base case in every engine", _stage_engines, required=True),
    Stage("grid", "Sensitivity to the numerical grid", _stage_grid),
    Stage("sensitivity", "One-at-a-time sensitivity", _stage_sensitivity),
    Stage("calibration", "Automatic calibration", _stage_calibration, required=True),
    Stage("diagnose", "Which model structure the data support", _stage_diagnose),
    Stage("crosscheck", "Cross-check of the walls in every engine", _stage_crosscheck),
    Stage("standards", "Standards: U-value, dynamic characteristics, ISO 9869-1", _stage_standards),
    Stage("identifiability", "How well the data identify each property", _stage_identifiability),
    Stage("retrofit", "Retrofit variants over a weather year", _stage_retrofit),
    Stage("building", "The walls in a whole building (EnergyPlus)", _stage_building),
]


# ============================================================================ runner
def run_study(
    study: Study,
    out_dir: str | Path,
    *,
    skip: tuple[str, ...] = (),
    quick: bool = False,
    engines: list[str] | None = None,
    progress: bool = True,
) -> list[StageOutput]:
    """Run every stage and write the results and ``index.html`` into ``out_dir`` (atomically).

    Parameters
    ----------
    study : Study
    out_dir : path
    skip : tuple of str
        Stage names to leave out.
    quick : bool
        Smaller grid study and swarm (for tests and previews).
    engines : list of str, optional
        Engines for the base case and the cross-check; default every available one.
    progress : bool
        Print each stage's progress on stderr.

    Returns
    -------
    list of StageOutput
    """
    from .outputs import output_dir
    from .report import write_report
    from .simulation import manifest_of

    names = [s.name for s in STAGES]
    bad = [s for s in skip if s not in names]
    if bad:
        from .errors import StudyError, closest

        raise StudyError([f"--skip: unknown stage {b!r}; {closest(b, names)}" for b in bad])
    outputs: list[StageOutput] = []
    with output_dir(out_dir, manifest=manifest_of(study, "run")) as tmp:
        ctx = RunContext(study=study, out=Path(tmp), quick=quick, progress=progress, engines=list(engines or []))
        t_all = time.perf_counter()
        for i, st in enumerate(STAGES, 1):
            so = StageOutput(st.name, st.title)
            if st.name in skip:
                so.status, so.message = "skipped", "left out with --skip"
                outputs.append(so)
                continue
            d = Path(tmp) / st.name
            d.mkdir()
            ctx.say(f"[{i}/{len(STAGES)}] {st.title} ...")
            t = time.perf_counter()
            try:
                st.func(ctx, d, so)
            except KeyboardInterrupt:
                raise
            except Exception as exc:  # an optional stage may fail; the report says how
                if st.required:
                    raise
                so.status = "failed"
                so.message = (
                    f"{type(exc).__name__}: {exc}"
                    if isinstance(exc, (WallcalError, ImportError, OptionalDependencyError))
                    else f"{type(exc).__name__}: {exc}"
                )
                (d / "error.txt").write_text(traceback.format_exc())
                ctx.say(f"      {st.name} failed: {so.message}")
            so.seconds = time.perf_counter() - t
            if so.status == "ok":
                ctx.say(f"      done in {so.seconds:.1f} s")
            outputs.append(so)
        (Path(tmp) / "stages.json").write_text(
            json.dumps(
                [
                    {"stage": o.name, "status": o.status, "message": o.message, "seconds": o.seconds, "files": o.files}
                    for o in outputs
                ],
                indent=2,
            )
        )
        write_report(study, outputs, Path(tmp) / "index.html", seconds=time.perf_counter() - t_all)
    return outputs
