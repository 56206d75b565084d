"""Does a year run depend on its time step? The retrofit year runs of the bundled example at 60, 600 and 3600 s.

Two checks, each for the exact scheme (fd-exact, the retrofit default) and Crank-Nicolson (fd-cn, the scheme
before it), each with the retrofit's grid for it (fd-exact: built for 120 s whatever the step; fd-cn: for
min(600 s, step); C = 2):

- ISO 13786: the study's wall (src/wallcal/examples/campaign_a/study.toml) under an exterior air temperature
  5 + 10 cos(2 pi t / 24 h) (h_e = 25, h_i = 7.69 W/(m2K), interior air 20 degC), run as a periodic period of
  four days by :func:`wallcal.retrofitting.run.periodic_year`; the 24-h fundamental of the interior flux
  (Fourier projection over the last day) against ISO 13786's Y12 with Rse = 1/h_e, Rsi = 1/h_i: amplitude
  error [%] and lag error [min];
- Chicago: ``wallcal retrofit``'s base wall over the shipped Chicago TMY3 year: peak loss [W/m2] and annual
  loss [kWh/m2], and their change from 60 s [%].

Usage: python bench/exact_time_step.py [--steps 3600 600 60] [--schemes exact cn] [--no-chicago]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

EXAMPLE = Path(__file__).resolve().parents[1] / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"
AMPLITUDE = 10.0
H_E, H_I = 25.0, 7.69
DAY = 86400.0


def iso_case(wall, dt: float, scheme: str, days: int = 4) -> tuple[float, float]:
    """(amplitude error [%], lag error [min]) of the interior flux's 24-h fundamental against ISO 13786."""
    from wallcal.engines.base import BoundaryInput
    from wallcal.retrofitting.boundary import YearBoundaries
    from wallcal.retrofitting.run import periodic_year
    from wallcal.standards import iso13786

    n = int(round(days * DAY / dt))
    t = np.arange(n + 1) * dt
    w = 2 * np.pi / DAY
    yb = YearBoundaries(
        exterior=BoundaryInput("air_temperature", 5.0 + AMPLITUDE * np.cos(w * t), H_E),
        interior=BoundaryInput("air_temperature", np.full(n + 1, 20.0), H_I),
        time_step=dt,
        hours=days * 24,
        hourly={},
    )
    run = periodic_year([wall], yb, scheme=scheme, tolerance=1e-6)
    m = int(round(DAY / dt))
    sl = slice(n - m, n)
    q = 2.0 / m * np.sum(run.q_i[0, sl] * np.exp(-1j * w * t[sl]))
    dc = iso13786.dynamic_characteristics(wall, DAY, rsi=1.0 / H_I, rse=1.0 / H_E)
    y12 = q / AMPLITUDE
    amp_err = (abs(y12) / abs(dc.Y12) - 1.0) * 100.0
    lag_h = (-np.angle(y12) * DAY / (2 * np.pi) / 3600.0) % 24.0
    d = (lag_h - dc.time_shift_h + 12.0) % 24.0 - 12.0
    return amp_err, d * 60.0


def chicago(dt: float, scheme: str) -> tuple[float, float]:
    """(peak loss [W/m2], annual loss [kWh/m2]) of the example's base wall over the Chicago year."""
    import wallcal
    from wallcal.retrofitting.boundary import year_boundaries
    from wallcal.retrofitting.run import periodic_year
    from wallcal.weather import read_weather, resolve_weather

    study = wallcal.load_study(EXAMPLE)
    spec = study.retrofit
    yb = year_boundaries(read_weather(resolve_weather(spec.weather, EXAMPLE.parent)), spec, time_step=dt)
    run = periodic_year([study.wall], yb, scheme=scheme)
    return float(run.peak_loss_W_m2[0]), float(run.annual_loss_kWh_m2[0])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=float, nargs="+", default=[3600.0, 600.0, 60.0])
    ap.add_argument("--schemes", nargs="+", default=["exact", "cn"])
    ap.add_argument("--no-chicago", action="store_true")
    args = ap.parse_args()
    from wallcal.study import load_wall

    wall = load_wall(EXAMPLE)
    print("ISO 13786, study wall, 24 h, +-10 K exterior air: interior flux amplitude error [%], lag error [min]")
    for scheme in args.schemes:
        for dt in args.steps:
            a, p = iso_case(wall, dt, scheme)
            print(f"  fd-{scheme:8s} dt = {dt:6.0f} s: amplitude {a:+7.3f} %, lag {p:+6.1f} min")
    if args.no_chicago:
        return
    print("Chicago TMY3, example base wall: peak loss [W/m2], annual loss [kWh/m2] (change from the first step)")
    for scheme in args.schemes:
        ref = None
        for dt in sorted(args.steps):
            t = time.perf_counter()
            peak, annual = chicago(dt, scheme)
            if ref is None:
                ref = (peak, annual)
            dp, da = (peak / ref[0] - 1) * 100, (annual / ref[1] - 1) * 100
            print(
                f"  fd-{scheme:8s} dt = {dt:6.0f} s: peak {peak:8.4f} ({dp:+.3f} %), annual {annual:8.4f} "
                f"({da:+.3f} %)  [{time.perf_counter() - t:.1f} s]"
            )


if __name__ == "__main__":
    main()
