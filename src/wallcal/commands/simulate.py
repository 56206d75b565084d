"""``wallcal simulate STUDY``: simulated vs measured series and the error metrics."""

from __future__ import annotations

from pathlib import Path

from ..formatting import table


def register(sub) -> None:
    from ..engines import engine_names

    p = sub.add_parser(
        "simulate",
        help="simulate a study and compare with the measurements",
        description="Simulate the study's wall driven by its boundary data and print the "
        "measured-signal summary (Table III) and the error metrics (Table IV).",
    )
    p.add_argument("study", help="study file (TOML)")
    p.add_argument("--engine", choices=engine_names(in_studies=True), help="default: the study's")
    p.add_argument("--time-step", type=float, metavar="S", help="time step [s]; default: the study's")
    p.add_argument("--grid-constant", type=float, metavar="C", help="C = dx^2/(alpha dt); default: the study's")
    p.add_argument("--node-rule", choices=("wallcal", "energyplus"), help="nodes per layer rule")
    p.add_argument("--out", metavar="DIR", help="write simulated.csv, metrics.csv, summary.csv here")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..simulation import simulate
    from ..study import load_study

    study = load_study(args.study)
    res = simulate(
        study, args.engine, time_step=args.time_step, grid_constant=args.grid_constant, node_rule=args.node_rule
    )
    print(
        f"{study.name or Path(args.study).name}: engine {res.engine}, dt = {res.info['time_step_s']:g} s, "
        f"C = {res.info['grid_constant']:g}, {res.info.get('nodes', '?')} nodes, "
        f"{1e3 * res.info.get('seconds', float('nan')):.1f} ms"
    )
    print()
    print(
        table(
            res.summary[["n", "max", "min", "range", "mean", "effective"]],
            "Measured signals over the period (Table III)",
        )
    )
    print()
    m = res.metrics.set_index("signal")
    print(
        table(
            m,
            "Simulated vs measured (RMSE etc. in the signal's unit; fractions in %)",
            percent=("rn_rmse", "cv_rmse_eff", "nmbe", "cv_rmse_g14"),
        )
    )
    if res.info.get("spikes_found"):
        print(
            f"\n{res.info['spikes_found']} single-sample spike(s) found"
            + (" and left out of the metrics" if res.info["spikes_removed"] else "")
            + "."
        )
    if res.info.get("bridged_gaps"):
        print(f"{res.info['bridged_gaps']} gap(s) in boundary series bridged by linear interpolation.")
    p = study.period
    if p.validation is not None:  # the held-out window: left out of the table above, scored on its own
        from ..validation import score_wall

        settings = {"time_step": args.time_step, "grid_constant": args.grid_constant, "node_rule": args.node_rule}
        res.validation = score_wall(study, engine=res.engine, **settings)
        print()
        print(
            table(
                res.validation.set_index("sensor"),
                f"Held-out window {p.validation_start} .. {p.validation_end} (not in the metrics above)",
            )
        )
    if args.out:
        res.write(args.out)
        extra = ", validation.csv" if res.validation is not None else ""
        print(f"\nwrote {args.out}/simulated.csv, metrics.csv, summary.csv{extra}")
    return 0
