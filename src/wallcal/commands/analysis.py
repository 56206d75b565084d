"""``wallcal grid-study``, ``sensitivity``, ``identifiability`` and ``posterior``."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..formatting import table
from .clusteropts import add_cluster_options, executor_for


def _floats(text: str, what: str) -> list[float]:
    from ..errors import StudyError

    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise StudyError([f"{what}: {text!r} is not a comma-separated list of numbers"]) from None


def _targets(text):
    return [t.strip() for t in text.split(",") if t.strip()] if text else None


def _out(args, default: str) -> Path:
    return Path(args.out) if args.out else Path(args.study).resolve().parent / default


def _study_space_optimum(args):
    """The study, its calibration space and the optimum saved under ``--from`` (None without it)."""
    from ..analysis import load_optimum
    from ..calibration.space import parse_space
    from ..study import load_study

    study = load_study(args.study)
    space = parse_space(study)
    x0 = load_optimum(space, args.from_dir) if args.from_dir else None
    return study, space, x0


def register(sub) -> None:
    g = sub.add_parser(
        "grid-study",
        help="RMSE against the time step for each grid constant C (Fig. 4)",
        description="Simulate the study for every time step and grid constant C = dx^2/(alpha dt); "
        "tabulate each target's RMSE, plot it against the time step per C, and name the "
        "cheapest setting whose RMSEs stay within --tolerance of the finest setting's.",
    )
    g.add_argument("study")
    g.add_argument("--time-steps", default="60,120,300,600,900,1800", metavar="S,S,...", help="[s]")
    g.add_argument("--grid-constants", default="1,2,3", metavar="C,C,...")
    g.add_argument("--targets", metavar="A,B", help="sensors to report (default: all)")
    g.add_argument(
        "--tolerance", type=float, default=0.01, help="allowed |RMSE - finest RMSE| in the target's unit (default 0.01)"
    )
    g.add_argument("--out", metavar="DIR", help="default: grid_study/ next to the study")
    g.add_argument("--quiet", action="store_true")
    add_cluster_options(g)
    g.set_defaults(func=run_grid_study)

    s = sub.add_parser(
        "sensitivity",
        help="sensitivity of the objective to the calibration parameters",
        description="One-at-a-time (each parameter to its bounds), Morris (mu*, sigma) or Sobol "
        "(S1, ST with confidence intervals; SALib) over the [calibration] space, "
        "through the batched engine. Writes a ranking table and a bar figure.",
    )
    s.add_argument("study")
    s.add_argument("--method", choices=("oat", "morris", "sobol"), default="oat")
    s.add_argument(
        "--samples",
        type=int,
        metavar="N",
        help="morris: trajectories (32); sobol: base sample N (256, a power of 2; N (n + 2) simulations)",
    )
    s.add_argument(
        "--from",
        dest="from_dir",
        metavar="CALIBRATION_DIR",
        help="oat: vary around the calibrated optimum instead of the base case",
    )
    s.add_argument("--seed", type=int, default=1)
    s.add_argument("--out", metavar="DIR", help="default: sensitivity/ next to the study")
    s.add_argument("--quiet", action="store_true")
    s.set_defaults(func=run_sensitivity)

    i = sub.add_parser(
        "identifiability",
        help="structural and practical identifiability of the parameters",
        description="Jacobian of the scaled residuals w.r.t. the log-parameters (one batch of 2n "
        "simulations), its singular values, the flat directions named in words, the "
        "identifiable combinations, and the effect of adding the heat-flux sensors.",
    )
    i.add_argument("study")
    i.add_argument(
        "--from",
        dest="from_dir",
        metavar="CALIBRATION_DIR",
        help="linearise at the calibrated optimum (default: the base case)",
    )
    i.add_argument("--targets", metavar="A,B", help="default: the study's calibration.targets")
    i.add_argument(
        "--sigma",
        choices=("accuracy", "residual"),
        default="accuracy",
        help="error sd per target: sensor accuracy (default) or residual RMSE",
    )
    i.add_argument("--out", metavar="DIR", help="default: identifiability/ next to the study")
    i.set_defaults(func=run_identifiability)

    p = sub.add_parser(
        "posterior",
        help="Bayesian posterior of the calibration parameters (emcee)",
        description="Uniform priors on the bounds, Gaussian AR(1) errors per target, emcee "
        "ensemble (each step one engine batch). Reports mean, sd, 95 %% interval, a "
        "verdict per parameter, correlations, identified combinations and distinct "
        "parameter sets that fit equally well. Ctrl-C keeps the chain; --resume "
        "continues.",
    )
    p.add_argument("study")
    p.add_argument(
        "--from",
        dest="from_dir",
        metavar="CALIBRATION_DIR",
        help="start at this calibration's optimum (default: run calibrate first)",
    )
    p.add_argument("--targets", metavar="A,B")
    p.add_argument(
        "--sigma",
        choices=("estimated", "accuracy"),
        default="estimated",
        help="error sd: residual RMSE at the optimum (default) or the sensor accuracy",
    )
    p.add_argument(
        "--tempering",
        choices=("sandwich", "none"),
        default="sandwich",
        help="temper the likelihood when the residuals vary more than the AR(1) model expects (default), or not",
    )
    p.add_argument(
        "--diagnosis",
        metavar="DIAGNOSE_DIR",
        help="a `wallcal diagnose` output: its adopted extensions that this study lacks make the self-check say "
        "that the data reject the structure",
    )
    p.add_argument(
        "--walkers",
        type=int,
        help="default 4 x the sampled coordinates (a layer's density and specific heat count as one)",
    )
    p.add_argument(
        "--steps",
        type=int,
        help="chain length (default: until the chain is adequate: --effective-samples, its autocorrelation time "
        "no longer growing, at most --max-steps)",
    )
    p.add_argument("--effective-samples", type=float, metavar="N", help="default 500")
    p.add_argument("--max-steps", type=int, metavar="N", help="longest default chain (default 5000)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--resume", action="store_true")
    p.add_argument(
        "--predict",
        nargs=2,
        metavar=("START", "END"),
        help="predict this period of the study's data from the draws plus their out-of-sample errors over the "
        "fitted period (predictive.csv, predictive_summary.csv); default the study's validation window "
        "(predictive.csv, validation.csv)",
    )
    p.add_argument("--out", metavar="DIR", help="default: posterior/ next to the study")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=run_posterior)


def _write(res, study, out, command):
    from ..outputs import output_dir
    from ..simulation import manifest_of

    with output_dir(out, manifest=manifest_of(study, command)) as tmp:
        res.write_into(Path(tmp))


# ============================================================================ commands
def run_grid_study(args) -> int:
    from ..analysis.gridstudy import grid_study
    from ..study import load_study

    study = load_study(args.study)
    out = _out(args, "grid_study")
    with executor_for(args, out, progress=not args.quiet):
        return grid_study_command(args, study, out, grid_study)


def grid_study_command(args, study, out, grid_study) -> int:
    res = grid_study(
        study,
        _floats(args.time_steps, "--time-steps"),
        _floats(args.grid_constants, "--grid-constants"),
        targets=_targets(args.targets),
        tolerance=args.tolerance,
        progress=not args.quiet,
    )
    print(table(res.rmse_table(), "RMSE per target against the time step [s] for each grid constant C (Fig. 4)"))
    print()
    conv = res.convergence().reset_index()
    conv.index = [f"dt {r.time_step:g} C {r.grid_constant:g}" for r in conv.itertuples()]
    print(table(conv.drop(columns=["time_step", "grid_constant"]), "Convergence against the finest setting"))
    print()
    print(res.summary())
    _write(res, study, out, "grid-study")
    print(f"\nwrote {out}/grid_study.csv, rmse_vs_time_step.csv, convergence.csv, grid_study.png")
    return 0


def run_sensitivity(args) -> int:
    from ..analysis.sensitivity import sensitivity

    study, space, x0 = _study_space_optimum(args)
    res = sensitivity(study, args.method, space=space, x0=x0, n=args.samples, seed=args.seed, progress=not args.quiet)
    out = _out(args, "sensitivity")
    cols = {
        "oat": ["layer", "d_objective_lower", "d_objective_upper", "|d objective|", "relative"],
        "morris": ["layer", "mu_star", "mu_star_conf", "sigma", "mu"],
        "sobol": ["layer", "ST", "ST_conf", "S1", "S1_conf"],
    }[args.method]
    print(table(res.ranking[cols], f"Sensitivity ranking ({args.method}) of the objective", percent=("relative",)))
    print()
    print(table(res.per_target, f"{res.measure} of each target's RMSE"))
    print()
    print(table(res.by_layer, f"{res.measure} summed per layer", percent=("share",)))
    print()
    print(res.summary())
    _write(res, study, out, "sensitivity")
    print(f"\nwrote {out}/sensitivity_{args.method}.csv, sensitivity_{args.method}.png")
    return 0


def run_identifiability(args) -> int:
    from ..analysis.identifiability import identifiability

    study, _, x0 = _study_space_optimum(args)
    at = f"calibrated optimum ({args.from_dir})" if args.from_dir else "base case"
    res = identifiability(study, x0=x0, at=at, targets=_targets(args.targets), sigma=args.sigma)
    out = _out(args, "identifiability")
    a = res.main
    print(
        f"Identifiability at the {at}, targets {'+'.join(a.targets)}: {a.rank} of {a.n} parameter directions "
        f"identifiable (numerical rank of the residual Jacobian; threshold s/s_max < 1e-6)"
    )
    print(
        f"error sd per target ({args.sigma}): "
        + ", ".join(f"{k} {v:.3g}" for k, v in a.sigma.items())
        + "; lag-1 autocorrelation: "
        + ", ".join(f"{k} {v:.3f}" for k, v in a.phi.items())
    )
    for note in res.notes:
        print(f"note: {note}")
    print()
    print("Flat directions (the data cannot move along these):")
    for key, r in a.flat.iterrows():
        print(f"  - {key}: {r['in words']}")
    if not len(a.flat):
        print("  none")
    print()
    _print_combinations(a)
    print()
    print(
        table(
            a.singular[["s", "relative", "sd_log", "prior_sd", "verdict", "direction"]],
            "Singular values (sd_log: predicted posterior sd along the direction, log units)",
        )
    )
    print()
    print(table(a.parameters[["value", "null share", "sd_log", "prior_sd", "verdict"]], "Per parameter"))
    print()
    comp = res.comparison()
    print(
        table(
            comp,
            "Effect of adding the heat-flux sensors (common scale gain: |J d| along the common scale of "
            "all lambda and rho*c; sd: 1/gain)",
        )
    )
    if any(b.scale_gain for b in res.analyses):
        print(
            "note: a heat-flux meter's own gain error (e.g. +-3 %) maps one-to-one onto the common scale, so a flux "
            "fixes the absolute conductivities only to about that accuracy, whatever the sd above says"
        )
    if res.demo is not None:
        print()
        print(table(res.demo, "Moving along the common-scale direction (every lambda and rho*c times k)"))
    for b in res.analyses[1:]:
        gained = [
            c
            for c in a.combos.index
            if a.combos.loc[c, "verdict"].startswith("not identifiable")
            and not b.combos.loc[c, "verdict"].startswith("not identifiable")
        ]
        if gained:
            print(
                f"\nwith {'+'.join(b.targets)}: structurally identifiable now: "
                + ", ".join(f"{c} (sd {b.combos.loc[c, 'sd %']:.1f} %)" for c in gained)
            )
    _write(res, study, out, "identifiability")
    print(
        f"\nwrote {out}/identifiability.json, singular_values_*.csv, parameters_*.csv, combinations_*.csv, "
        "singular_values.png"
    )
    return 0


def _print_combinations(a):
    ok = a.combos[~a.combos["verdict"].str.startswith("not identifiable")]
    no = a.combos[a.combos["verdict"].str.startswith("not identifiable")]
    if len(no):
        print("Not identifiable from these targets: " + ", ".join(no.index))
    if len(ok):
        print(table(ok[["sd %", "prior sd %", "verdict"]], "Identifiable combinations (linearised sd, %)"))


def _window(pair):
    """``--predict START END`` as two timestamps (a clear error for a bad one), or None."""
    if not pair:
        return None
    import pandas as pd

    from ..errors import WallcalError

    try:
        start, end = (pd.Timestamp(v) for v in pair)
    except ValueError as exc:
        raise WallcalError(f"--predict {pair[0]} {pair[1]}: not two timestamps ({exc})") from None
    if not end > start:
        raise WallcalError(f"--predict {pair[0]} {pair[1]}: END must be after START")
    return start, end


def run_posterior(args) -> int:
    from ..analysis.identifiability import identifiability
    from ..analysis.posterior import check_positive, missing_from_diagnosis, posterior

    check_positive(
        {"--steps": args.steps, "--effective-samples": args.effective_samples, "--max-steps": args.max_steps}
    )
    study, _, x0 = _study_space_optimum(args)
    missing = missing_from_diagnosis(study, args.diagnosis) if args.diagnosis else []
    out = _out(args, "posterior")
    if x0 is None:
        from ..calibration import calibrate

        print("no --from: calibrating first to find the starting point")
        cal = calibrate(study, progress=not args.quiet)
        x0 = cal.x_opt
    ident = identifiability(study, x0=x0, targets=_targets(args.targets), add_fluxes=False)
    a = ident.main
    flat = ":" if len(a.flat) else ": none"
    print(f"Before sampling: {a.rank} of {a.n} directions identifiable from {'+'.join(a.targets)}; flat{flat}")
    for key, r in a.flat.iterrows():
        print(f"  - {key}: {r['in words']}")
    print()
    res = posterior(
        study,
        x_start=x0,
        targets=_targets(args.targets),
        sigma=args.sigma,
        walkers=args.walkers,
        steps=args.steps,
        effective_samples=args.effective_samples,
        max_steps=args.max_steps,
        seed=args.seed,
        out_dir=out,
        resume=args.resume,
        progress=not args.quiet,
        tempering=args.tempering,
        missing_extensions=missing,
        predict=_window(args.predict),
    )
    print(res.report())
    print()
    print(table(res.checks, "Posterior predictive residuals against the sensors' stated accuracy"))
    print()
    cols = ["mean", "sd", "q2.5", "q97.5", "sd/prior sd", "verdict"]
    if res.truth is not None:
        cols += ["truth", "inside 50%", "inside 95%"]
    print(table(res.summary[cols], "Posterior per parameter (SI units)"))
    print()
    print(table(res.combinations[cols], "Derived combinations, best identified first"))
    print()
    c = res.correlation
    pairs = [(i, j, c.loc[i, j]) for a, i in enumerate(c.index) for j in c.columns[a + 1 :] if abs(c.loc[i, j]) >= 0.7]
    if pairs:
        print("Strong posterior correlations (|r| >= 0.7): " + "; ".join(f"{i} ~ {j} {v:+.2f}" for i, j, v in pairs))
        print()
    if len(res.nonunique):
        print(
            table(
                res.nonunique.T,
                "Distinct parameter sets whose RMSEs all sit within the sensor accuracy (non-uniqueness)",
            )
        )
    else:
        print("no posterior sample kept every RMSE within the sensor accuracy")
    _write(res, study, out, "posterior")
    print(
        f"\nwrote {out}/posterior_summary.csv, posterior_correlation.csv, posterior_combinations.csv, "
        "posterior_checks.csv, non_uniqueness.csv, posterior.json, chain.npz, corner.png, trace.png"
        + (
            ""
            if res.predictive is None
            else ", predictive.csv, " + ("validation.csv" if res.predicted_validation else "predictive_summary.csv")
        )
    )
    if res.predictive is not None:
        w = res.predictive.window
        print()
        print(
            table(
                res.predictive.table.set_index("sensor"),
                f"Posterior predictive {w[0]} .. {w[1]}"
                + (" (held out)" if res.predicted_validation else "")
                + ": the band's median against the measured values; coverage_95: share of measured points inside "
                "the 95 % band (85-99 % is right: wider is as wrong as narrower)",
            )
        )
    if res.structure["rejected"]:
        print(f"\nSTRUCTURE REJECTED: {res.structure['statement']}")
    if res.status != "complete":
        print("the run was interrupted: the chain so far is summarised; continue with --resume")
        return 130
    return 0


_ = pd  # pandas is used through the result objects
