"""``wallcal verify``: the heat-and-moisture engine against EN 15026 Annex A and the HAMSTAD benchmarks."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..formatting import table

#: the failed checks printed one by one at most
SHOW_FAILED = 30


def register(sub) -> None:
    from ..moisture.cases import CASES, HAMSTAD1_DATA

    p = sub.add_parser(
        "verify",
        help="verify the heat-and-moisture engine (EN 15026 Annex A, HAMSTAD 1, 2 and 5)",
        description="Run the heat-and-moisture engine's verification cases, compare with the bundled reference "
        "limits and write OUT/verification.csv (case, quantity, day, x_m, value, lower, upper, passed) and "
        "OUT/<case>/profiles.csv (time_s, x_m, temperature, relative_humidity, water_content at the engine's "
        "cells; x from the exterior face). Exit status 0 when every check passes, 1 otherwise. HAMSTAD 1 needs "
        "its hourly climate and the participants' bands (the HAMSTAD archive's files, not shipped): see --data.",
    )
    names = ", ".join(CASES)
    p.add_argument(
        "cases",
        nargs="*",
        metavar="CASE",
        help=f"cases to run ({names}; default: all, hamstad1 only when its data are found)",
    )
    p.add_argument(
        "--data",
        metavar="DIR",
        help="folder of HAMSTAD 1's files: ClimateBench1.txt and Bench1Year{1,5}_M{A,B}.csv "
        f"(default: {HAMSTAD1_DATA.as_posix()} beside the repository)",
    )
    p.add_argument("--out", metavar="OUT", required=True, help="output directory (written atomically)")
    p.add_argument("--plot", action="store_true", help="also write OUT/<case>/profiles.png")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=run_verify)


def run_verify(args) -> int:
    from ..moisture.cases import CASES, hamstad1_missing, run_case
    from ..outputs import output_dir

    names = list(dict.fromkeys(args.cases)) or [n for n in CASES if n != "hamstad1" or not hamstad1_missing(args.data)]
    runs = [
        run_case(n, args.data) for n in names
    ]  # every name is checked (unknown ones raise) before anything is written
    checks = pd.concat([r.checks for r in runs], ignore_index=True)
    with output_dir(args.out, {"command": "verify", "cases": names}) as tmp:
        checks.to_csv(Path(tmp) / "verification.csv", index=False)
        for r in runs:
            d = Path(tmp) / r.name
            d.mkdir()
            r.profiles.to_csv(d / "profiles.csv", index=False)
            if args.plot:
                from ..moisture.plots import plot_case

                plot_case(r, d / "profiles.png")
    summary = pd.DataFrame(
        [
            {
                "case": r.name,
                "checks": len(r.checks),
                "passed": int(r.checks["passed"].sum()),
                "mass balance": float(r.result.mass_balance_error.max()),
                "energy balance": float(r.result.energy_balance_error.max()),
                "steps": r.result.stats["steps"],
                "seconds": r.seconds,
            }
            for r in runs
        ]
    ).set_index("case")
    if not args.quiet:
        print(table(summary, "Heat-and-moisture verification (balance: max relative error of the run)"))
        failed = checks[~checks["passed"]]
        if len(failed) > SHOW_FAILED:  # HAMSTAD 1 checks every hour: count, then the first ones
            counts = checks.groupby(["case", "quantity"], sort=False)["passed"].agg(checks="size", passed="sum")
            print()
            print(table(counts[counts["passed"] < counts["checks"]], "Checks outside their limits, by quantity"))
        if len(failed):
            print()
            title = "Checks outside their limits" + (f" (the first {SHOW_FAILED})" if len(failed) > SHOW_FAILED else "")
            print(table(failed.drop(columns="passed").head(SHOW_FAILED), title, index=False))
        print(f"\nwrote {args.out}/verification.csv and {len(runs)} profiles.csv")
    return 0 if bool(checks["passed"].all()) else 1
