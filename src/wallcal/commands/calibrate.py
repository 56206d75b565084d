"""``wallcal calibrate``, ``wallcal crosscheck`` and ``wallcal convert-conductivity``."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..formatting import table
from .clusteropts import add_cluster_options, add_scheduler, executor_for


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="automatic calibration of the wall's properties",
        description="Calibrate the study's wall over its [calibration] parameter space. Writes "
        "calibrated_wall.toml, calibration.json, metrics.csv (base and calibrated, "
        "Table VIII), parameters.csv, convergence.png and fit.png. Ctrl-C keeps the best "
        "wall so far; --resume continues from the last checkpoint.",
    )
    p.add_argument("studies", nargs="+", metavar="STUDY", help="study file; several: each calibrated as its own task")
    p.add_argument(
        "--out",
        metavar="DIR",
        help="output directory (default: calibration/ next to the study); with several studies OUT/<study file "
        "stem>/ for each (required)",
    )
    p.add_argument(
        "--algorithm",
        choices=("pso-hj", "least-squares", "differential-evolution", "nelder-mead", "cma-es"),
        help="default: the study's calibration.algorithm",
    )
    p.add_argument("--seed", type=int)
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue from the checkpoint of --out (several studies: reuse the studies already calibrated)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress line")
    add_scheduler(p)
    p.set_defaults(func=run_calibrate)

    c = sub.add_parser(
        "crosscheck",
        help="every wall in every engine: RMSE per target (Table VIII)",
        description="Run each wall file in each engine against the study's measurements.",
    )
    c.add_argument("study")
    c.add_argument("walls", nargs="+", metavar="WALL.toml")
    c.add_argument("--engines", default="fd-cn", help="comma-separated engines (default fd-cn)")
    c.add_argument("--out", metavar="DIR")
    add_cluster_options(c)
    c.set_defaults(func=run_crosscheck)

    v = sub.add_parser(
        "convert-conductivity",
        help="convert declared conductivities to the wall's temperature (ISO 10456)",
        description="Move conductivities from their declared temperature to the "
        "mean temperature each layer had in the campaign (from the study's data) or to a given "
        "temperature, with the exponential temperature factor of ISO 10456; writes a new wall file.",
    )
    v.add_argument("study", help="study file (its wall and data)")
    v.add_argument(
        "--temperature",
        type=float,
        metavar="DEGC",
        help="one target temperature for all layers (default: each layer's mean measured temperature over the period)",
    )
    v.add_argument(
        "--coefficient",
        action="append",
        default=[],
        metavar="[ID=]F",
        help="temperature conversion coefficient f_T [1/K], for all layers or ID=F per layer "
        "(repeatable); default each layer's conductivity_temperature_coefficient",
    )
    v.add_argument("--layers", help="comma-separated layer ids to convert (default: layers with a coefficient)")
    v.add_argument("--out", metavar="FILE", required=True, help="the new wall file (TOML)")
    v.set_defaults(func=run_convert)


def run_calibrate(args) -> int:
    if len(args.studies) > 1:
        return calibrate_studies(args)
    import sys

    from ..calibration import calibrate
    from ..calibration.checkpoint import checkpoint_path, present
    from ..calibration.run import complete_output
    from ..outputs import clean_stale
    from ..study import load_study

    study = load_study(args.studies[0])
    out = Path(args.out) if args.out else Path(args.studies[0]).resolve().parent / "calibration"
    clean_stale(out)  # what a killed run left next to --out (temporary directories)
    resume = args.resume
    if resume and not present(checkpoint_path(out)):
        if complete_output(out, study):
            print(f"nothing to resume: {out} holds the complete calibration; run without --resume to calibrate again")
            return 0
        print(f"no checkpoint of {out} (the run stopped before its first): calibrating from the start", file=sys.stderr)
        resume = False
    with executor_for(args, out, progress=not args.quiet):
        res = calibrate(
            study, algorithm=args.algorithm, seed=args.seed, out_dir=out, resume=resume, progress=not args.quiet
        )
        res.write(out)
    print(
        f"{study.name}: {res.algorithm}, objective {res.space.objective} {res.f_base:.6g} -> {res.f_opt:.6g} "
        f"in {res.evaluations} simulations, {res.seconds:.1f} s ({res.status})"
    )
    print()
    print(
        table(
            res.parameter_table()[["base", "lower", "upper", "optimum", "change"]],
            "Parameters (SI units)",
            percent=("change",),
        )
    )
    print()
    m = res.metrics.pivot(index="signal", columns="case", values="rmse")[["base", "calibrated"]]
    if res.floors:
        m["noise floor"] = pd.Series(res.floors)
    print(table(m.loc[[s.name for s in study.sensors]], "RMSE per sensor (Table VIII)"))
    from ..validation import read as read_validation

    held = read_validation(out)
    if held is not None:
        p = study.period
        print()
        title = f"Held-out window {p.validation_start} .. {p.validation_end}, never fitted (validation.csv)"
        print(table(held.set_index("sensor"), title))
    if res.refinement is not None:
        ref = res.refinement
        print()
        print(
            table(
                ref.table().rename(
                    columns={"rmse_energyplus_fast_optimum": "fast optimum", "rmse_energyplus_refined": "refined"}
                ),
                f"EnergyPlus RMSE per target before and after the refinement ({ref.runs} EnergyPlus runs)",
            )
        )
    for note in res.notes:
        print(f"note: {note}")
    extra = ", energyplus_wall.toml, energyplus_refinement.csv" if res.refinement is not None else ""
    print(f"\nwrote {out}/calibrated_wall.toml, calibration.json, metrics.csv, convergence.png, fit.png{extra}")
    if res.status != "complete":
        print("the run was interrupted: these are the best values so far; continue with --resume")
        return 130
    return 0


def calibrate_studies(args) -> int:
    """``wallcal calibrate S1.toml S2.toml ... --out OUT``: each study one task, into OUT/<study file stem>/."""
    import json

    from .. import __version__
    from ..calibration.many import calibrate_many, study_stems
    from ..errors import StudyError
    from ..outputs import output_dir
    from ..simulation import manifest_of

    if not args.out:
        raise StudyError(["--out: give the output directory for several studies (OUT/<study file stem>/ each)"])
    stems = study_stems(args.studies)
    with executor_for(args, args.out, label="studies calibrated", progress=not args.quiet) as ex:
        results = calibrate_many(args.studies, algorithm=args.algorithm, seed=args.seed, executor=ex)
        manifest = {"command": "calibrate", "studies": [str(Path(p).resolve()) for p in args.studies]}
        with output_dir(args.out, manifest=manifest) as tmp:
            for stem, res in zip(stems, results, strict=True):
                d = Path(tmp) / stem
                d.mkdir()
                res.write_into(d)
                man = {"wallcal_version": __version__, **manifest_of(res.study, "calibrate")}
                (d / "manifest.json").write_text(json.dumps(man, indent=2, default=str))
    rows = [
        {
            "study": stem,
            "algorithm": r.algorithm,
            "objective base": r.f_base,
            "objective optimum": r.f_opt,
            "simulations": r.evaluations,
            "seconds": r.seconds,
            "status": r.status,
        }
        for stem, r in zip(stems, results, strict=True)
    ]
    print(table(pd.DataFrame(rows).set_index("study"), f"{len(rows)} studies calibrated"))
    print(f"\nwrote {args.out}/<study>/calibrated_wall.toml, calibration.json, metrics.csv, ... for each study")
    return 0


def run_crosscheck(args) -> int:
    with executor_for(args, args.out):
        return crosscheck_command(args)


def crosscheck_command(args) -> int:
    from ..crosscheck import CSV, WALLS, crosscheck, with_study_probes
    from ..outputs import output_dir
    from ..simulation import manifest_of
    from ..study import load_study, load_wall

    study = load_study(args.study)
    engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    walls = {}  # by file name; the same name again gets -2, -3, ...
    for w in args.walls:
        name, k = Path(w).stem, 2
        while name in walls:
            name, k = f"{Path(w).stem}-{k}", k + 1
        walls[name] = with_study_probes(study, load_wall(w), str(w))
    res = crosscheck(study, walls, engines)
    print(table(res.table.set_index(["wall"]), "Optimal cases and cross-check: RMSE per target (Table VIII)"))
    if args.out:
        with output_dir(args.out, manifest=manifest_of(study, "crosscheck")) as tmp:
            res.write_into(Path(tmp))
        print(f"\nwrote {args.out}/{CSV} and the walls checked in {args.out}/{WALLS}/")
    return 0


def run_convert(args) -> int:
    from ..calibration.manual import convert_conductivities, layer_mean_temperatures
    from ..errors import StudyError
    from ..study import dump_wall, load_study

    study = load_study(args.study)
    coeffs: dict[str, float] | float | None = None
    for item in args.coefficient:
        if "=" in item:
            lid, val = item.split("=", 1)
            coeffs = coeffs if isinstance(coeffs, dict) else {}
            try:
                coeffs[lid.strip()] = float(val)
            except ValueError:
                raise StudyError([f"--coefficient: {item!r} is not ID=number"]) from None
        else:
            try:
                coeffs = float(item)
            except ValueError:
                raise StudyError([f"--coefficient: {item!r} is not a number"]) from None
    temps = args.temperature if args.temperature is not None else layer_mean_temperatures(study)
    layers = [x.strip() for x in args.layers.split(",")] if args.layers else None
    new = convert_conductivities(study.wall, temps, coefficients=coeffs, layers=layers)
    rows = []
    for a, b in zip(study.wall.layers, new.layers, strict=True):
        if a.is_massless:
            continue
        rows.append(
            {
                "layer": a.id,
                "from degC": a.reference_temperature,
                "to degC": b.reference_temperature,
                "lambda before": a.conductivity,
                "lambda after": b.conductivity,
            }
        )
    print(table(pd.DataFrame(rows).set_index("layer"), "Conductivities (ISO 10456 temperature conversion)"))
    from ..outputs import write_text_atomic

    write_text_atomic(args.out, dump_wall(new, f"converted from {args.study} by wallcal convert-conductivity"))
    print(f"\nwrote {args.out}")
    return 0
