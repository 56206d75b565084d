"""``wallcal verify``: the heat-and-moisture engine against EN 15026 Annex A and the HAMSTAD benchmarks."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..formatting import table


def register(sub) -> None:
    from ..moisture.cases import CASES, UNAVAILABLE

    p = sub.add_parser(
        "verify",
        help="verify the heat-and-moisture engine (EN 15026 Annex A, HAMSTAD 2 and 5)",
        description="Run the heat-and-moisture engine's verification cases, compare with the bundled reference "
        "limits and write OUT/verification.csv (case, quantity, day, x_m, value, lower, upper, passed) and "
        "OUT/<case>/profiles.csv (time_s, x_m, temperature, relative_humidity, water_content at the engine's "
        "cells; x from the exterior face). Exit status 0 when every check passes, 1 otherwise.",
    )
    names = ", ".join([*CASES, *UNAVAILABLE])
    p.add_argument("cases", nargs="*", metavar="CASE", help=f"cases to run (default: all available; {names})")
    p.add_argument("--out", metavar="OUT", required=True, help="output directory (written atomically)")
    p.add_argument("--plot", action="store_true", help="also write OUT/<case>/profiles.png")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=run_verify)


def run_verify(args) -> int:
    from ..moisture.cases import CASES, run_case
    from ..outputs import output_dir

    names = list(dict.fromkeys(args.cases)) or list(CASES)
    runs = [run_case(n) for n in names]  # every name is checked (unknown ones raise) before anything is written
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
        if len(failed):
            print()
            print(table(failed.drop(columns="passed"), "Checks outside their limits", index=False))
        print(f"\nwrote {args.out}/verification.csv and {len(runs)} profiles.csv")
    return 0 if bool(checks["passed"].all()) else 1
