"""HAMSTAD 1 over its five years: wallcal's M_A and M_B with the participants' 99.9 % bands of years 1 and 5.

Run: ``NUMBA_NUM_THREADS=1 PYTHONPATH=src python bench/hamstad1_plot.py --data DIR [--out PNG]``. ``DIR`` holds
the HAMSTAD archive's ``ClimateBench1.txt`` and ``Bench1Year{1,5}_M{A,B}.csv`` (not shipped with wallcal;
public in LBNL-ETA/HygroThermFEM ``tst/units/validation/hamstad``); without ``--data`` the folder
``../shared/data/ham/hamstad`` beside the repository. Runs the case as ``wallcal verify hamstad1`` does,
prints the hours inside the band per year and quantity, the run's balance errors, steps and run time, and
writes the figure (default ``docs/moisture_hamstad1.png``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from wallcal.errors import StudyError  # noqa: E402
from wallcal.moisture.cases import DAY, HOUR, hamstad1, load_hamstad1  # noqa: E402

DOCS = Path(__file__).resolve().parents[1] / "docs"
LABEL = {"M_A": "M_A, load-bearing layer [kg/m2]", "M_B": "M_B, insulation [kg/m2]"}


def pass_counts(run, period_days: float):
    """Hours inside the band by (year, quantity): ``{(year, q): (passed, checked)}``."""
    c = run.checks[run.checks["quantity"].isin(["M_A", "M_B"])]
    year = np.where(c["day"] <= 2.5 * period_days, 1, 5)  # year 1 ends at 1 period, year 5 starts at 4
    out = {}
    for (y, q), g in c.groupby([year, c["quantity"]]):
        out[(int(y), q)] = (int(g["passed"].sum()), len(g))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", metavar="DIR", help="folder of the HAMSTAD 1 files")
    ap.add_argument("--out", metavar="PNG", default=str(DOCS / "moisture_hamstad1.png"))
    args = ap.parse_args(argv)
    try:
        data = load_hamstad1(args.data)
        run = hamstad1(args.data)
    except StudyError as e:
        print(f"hamstad1_plot: {e}", file=sys.stderr)
        return 2
    period = float(data.climate["time_s"].iloc[-1])
    res = run.result
    counts = pass_counts(run, period / DAY)
    for (y, q), (ok, n) in sorted(counts.items()):
        print(f"year {y} {q}: {ok} of {n} hours inside the 99.9 % band ({100.0 * ok / n:.1f} %)")
    mass, energy = float(res.mass_balance_error.max()), float(res.energy_balance_error.max())
    print(f"balance errors (largest, relative): mass {mass:.1e}, energy {energy:.1e}")
    print(f"{res.stats['steps']} steps, {res.dx.size} cells, {run.seconds:.1f} s")

    s = run.series
    years = s["time_s"] / period
    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True, layout="constrained")
    for ax, q in zip(axes, ("M_A", "M_B"), strict=True):
        for y in (1, 5):
            band = data.bands[(y, q)]
            t = ((y - 1) * period + band["hour"] * HOUR) / period
            ax.fill_between(t, band["lower"], band["upper"], color="tab:orange", alpha=0.35, lw=0)
            ax.plot(t, band["average"], color="tab:orange", lw=0.8)
            ok, n = counts[(y, q)]
            ax.text(
                y - 0.5,
                1.0,
                f"year {y}: {ok}/{n} h in band",
                transform=ax.get_xaxis_transform(),
                ha="center",
                va="bottom",
                fontsize=8,
            )
        ax.plot(years, s[q], color="tab:blue", lw=0.9, label="wallcal (ham engine)")
        ax.fill_between([], [], [], color="tab:orange", alpha=0.35, label="participants' 99.9 % band (mean: line)")
        ax.set_ylabel(LABEL[q])
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper right")
    axes[1].set_xlabel("time [years of the climate file]")
    fig.suptitle(
        f"HAMSTAD 1, insulated roof: max relative balance error mass {mass:.1e}, energy {energy:.1e}; "
        f"{res.stats['steps']} steps, {run.seconds:.1f} s",
        fontsize=10,
    )
    fig.savefig(args.out, dpi=90)
    plt.close(fig)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
