"""``wallcal diagnose``: which extensions of the calibration's structure the data support."""

from __future__ import annotations

from ..formatting import table


def register(sub) -> None:
    d = sub.add_parser(
        "diagnose",
        help="let the data choose the model structure (probe depth, contact resistance, lambda(T), sensor offset)",
        description="Look at the residuals of the calibrated model (bias, lag, daily pattern of each target), "
        "propose extensions of the [calibration] space (a probe's depth, a contact resistance at each "
        "interface next to a probe, lambda(T) of each insulation layer or group or all sharing one coefficient, a "
        "sensor offset), score each and each useful combination by a warm-started recalibration with BIC on the "
        "AR(1) likelihood of the residuals (each sensor's bias within its accuracy integrated out), and adopt "
        "the set the data support (with a [period] validation window: only plausible extensions that lower the "
        "held-out RMSE of every temperature target). Writes OUT/candidates.csv, OUT/study.toml (the study "
        "with the adopted extensions), OUT/residuals.csv and OUT/diagnose.json.",
    )
    d.add_argument("study")
    d.add_argument(
        "--from",
        dest="from_dir",
        metavar="DIR",
        help="start at the optimum of this `wallcal calibrate` output (or a wall file); default: calibrate first",
    )
    d.add_argument("--out", metavar="OUT", required=True, help="output directory (written atomically)")
    d.add_argument("--quiet", action="store_true")
    d.set_defaults(func=run_diagnose)


def run_diagnose(args) -> int:
    from ..analysis.diagnose import CRITERION, diagnose
    from ..errors import WallcalError
    from ..study import load_study

    study = load_study(args.study)
    if args.from_dir is not None:
        from pathlib import Path

        p = Path(args.from_dir)
        if not p.exists():
            raise WallcalError(f"--from {args.from_dir}: no such calibration output directory or wall file")
    d = diagnose(study, start=args.from_dir, progress=not args.quiet)
    c = d.candidates.set_index("extension")
    print(table(c, f"Candidate extensions ({CRITERION}: BIC change against the study's structure; < 0 better)"))
    print()
    print(d.summary())
    out = d.write(args.out)
    extra = ", validation.csv (the held-out window)" if d.validation is not None else ""
    print(f"\nwrote {out}/candidates.csv, study.toml, residuals.csv, diagnose.json{extra}")
    return 0
