"""Grid convergence of the retrofit moisture runs (``wallcal.retrofitting.moisture_risk.GRID``).

Runs the point walls of ``wallcal retrofit`` (no posterior draws) for the classic case (examples/retrofit_classic,
as bench/retrofit_classic.py; also with ``driving_rain_factor`` 2.0, and 8.0: about the station's real rain) and
the bundled example's five variants, on several grids (first cell at every face and interface [m], growth, widest
cell [m]; a capillary layer's face cells are ``moisture_risk.CAPILLARY_CELL``, or the grid's first cell if
smaller), and on the retrofit grid with steps of at most 5 minutes (the time-step check). For each variant it
prints the highest hourly RH and mould index over every interface of the periodic year, their difference from the
finest grid, and the solver's time. The table in docs/retrofit.md ("Grid") comes from this script.

Usage: python bench/retrofit_grid.py [--quick]   (--quick: the classic cases only; about 2 min, else about 4)
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parent
sys.path.insert(0, str(BENCH))

from retrofit_classic import EXAMPLE, write_classic  # noqa: E402

FINE = (1e-4, 1.3, 0.02)
GRIDS = [
    (5e-3, 1.3, 0.02),
    (1e-3, 2.0, 0.04),
    (5e-4, 2.0, 0.04),
    (5e-4, 4.0, 0.04),
    (2e-4, 4.0, 0.04),
    (5e-4, 8.0, 0.08),
    (1e-4, 2.0, 0.04),
    FINE,
]
#: the time-step check: GRID with the solver's steps at most STEP_DT [s] (moisture_risk.DT_MAX is 3600 s)
STEP, STEP_DT = "step", 300.0


def run_case(study_path: Path, wall_path: Path | None, grid, dt_max: float | None = None):
    """{variant: (highest interface RH, highest mould index, seconds)} of the point walls on ``grid`` (and with the
    solver's steps at most ``dt_max`` [s] instead of ``moisture_risk.DT_MAX``)."""
    import wallcal
    from wallcal.retrofitting import moisture_risk as mr
    from wallcal.study import load_study, load_wall

    orig, orig_dt = mr.periodic_run, mr.DT_MAX

    def on_grid(*a, **k):
        return orig(*a, **{**k, "grid": grid})

    mr.periodic_run = on_grid
    if dt_max is not None:
        mr.DT_MAX = dt_max
    try:
        wall = load_wall(wall_path) if wall_path is not None else None
        res = wallcal.retrofit(load_study(study_path), wall=wall, samples=1)
    finally:
        mr.periodic_run, mr.DT_MAX = orig, orig_dt
    return {v.spec.name: (float(v.hygro.rh.max()), float(v.hygro.mould.max()), v.hygro.seconds) for v in res.variants}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the classic case only")
    args = ap.parse_args()
    from wallcal.retrofitting.moisture_risk import GRID

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "rain").mkdir()
        (tmp / "rain8").mkdir()
        cases = {
            "classic": write_classic(tmp),
            "classic, R_1 = 2.0": write_classic(tmp / "rain", lines=("driving_rain_factor = 2.0",)),
            "classic, R_1 = 8.0": write_classic(tmp / "rain8", lines=("driving_rain_factor = 8.0",)),
        }
        if not args.quick:
            cases["bundled example"] = (EXAMPLE, None)
        for name, (study, wall) in cases.items():
            t = time.perf_counter()
            results = {g: run_case(study, wall, g) for g in GRIDS}
            results[STEP] = run_case(study, wall, GRID, dt_max=STEP_DT)
            print(
                f"\n{name} ({time.perf_counter() - t:.0f} s): highest interface RH / mould index, "
                f"difference from the finest grid {FINE}, solver seconds"
            )
            for variant, ref in results[FINE].items():
                print(f"  {variant}")
                for g in [*GRIDS, STEP]:
                    rh, m, s = results[g][variant]
                    mark = "  <- GRID" if tuple(g) == tuple(GRID) else ""
                    g = f"GRID, dt_max {STEP_DT:.0f} s" if g == STEP else g
                    print(
                        f"    {str(g):24s} RH {rh:.3f} ({rh - ref[0]:+.3f})  M {m:.2f} ({m - ref[1]:+.2f})  "
                        f"{s:5.1f} s{mark}"
                    )


if __name__ == "__main__":
    main()
