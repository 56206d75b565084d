"""Convergence of the retrofit year run in time step and grid: the table of docs/retrofit.md.

The bundled example's variants "as built", "ETICS, EPS 100 mm" and "interior wool 60 mm + vapour control",
and a brick + EPS wall (0.24 m brick 0.8 W/(mK), 1800 kg/m3, 840 J/(kgK), 0.10 m EPS from the catalogue),
over the example's weather year (Chicago TMY3, shipped with the energyplus extra), each run as
``wallcal retrofit`` runs it (:func:`wallcal.retrofitting.run.periodic_year`) at four (time step, time step
the grid is built for) pairs, with the exact scheme (the default) and with Crank-Nicolson. Prints a Markdown table
per scheme: annual loss [kWh/m2] / peak loss [W/m2], and the
largest spread of the minimum interior surface temperature over the cases [K].

Usage: python bench/retrofit_convergence.py   (about two minutes)
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"
VARIANTS = ("as built", "ETICS, EPS 100 mm", "interior wool 60 mm + vapour control")
#: (time step, time step the grid is built for) per scheme
CASES = {
    "exact": ((3600.0, 600.0), (3600.0, 120.0), (3600.0, 60.0), (600.0, 60.0)),
    "cn": ((3600.0, 3600.0), (3600.0, 600.0), (3600.0, 60.0), (600.0, 60.0)),
}


def main() -> None:
    import wallcal
    from wallcal.retrofitting import materials
    from wallcal.retrofitting.boundary import year_boundaries
    from wallcal.retrofitting.config import apply_variant
    from wallcal.retrofitting.run import SCHEME, _grid_time_step, periodic_year
    from wallcal.wall import Layer, Wall
    from wallcal.weather import read_weather, resolve_weather

    study = wallcal.load_study(EXAMPLE)
    spec = study.retrofit
    by_name = {v.name: v for v in spec.variants}
    walls = {name: apply_variant(study.wall, by_name[name]) for name in VARIANTS}
    eps = materials.find("EPS")
    walls["brick + EPS"] = Wall(
        (
            Layer("eps", 0.10, eps.conductivity, eps.density, eps.specific_heat),
            Layer("brick", 0.24, conductivity=0.8, density=1800.0, specific_heat=840.0),
        ),
        name="brick + EPS",
    )
    weather = read_weather(resolve_weather(spec.weather, EXAMPLE.parent))
    labels = {"as built": "as built", "ETICS, EPS 100 mm": "+ EPS 100 mm"}
    labels["interior wool 60 mm + vapour control"] = "+ interior wool"
    for scheme, cases in CASES.items():
        default_grid = _grid_time_step(scheme, None, spec.time_step)
        print(
            f"\nscheme {scheme}{' (the default)' if scheme == SCHEME else ''}; (default): the grid it uses by default\n"
        )
        print("| time step / grid built for | " + " | ".join(labels.get(n, n) for n in walls) + " |")
        print("|---|" + "---|" * len(walls))
        t_si_min: dict[str, list[float]] = {name: [] for name in walls}
        for dt, grid_dt in cases:
            yb = year_boundaries(weather, dataclasses.replace(spec, time_step=dt))
            cells = []
            for name, w in walls.items():
                yr = periodic_year([w], yb, all_rows=False, grid_time_step=grid_dt, scheme=scheme)
                t_si_min[name].append(float(yr.t_si[0].min()))
                cells.append(f"{yr.annual_loss_kWh_m2[0]:.4f} / {yr.peak_loss_W_m2[0]:.3f}")
            default = " (default)" if (dt, grid_dt) == (spec.time_step, default_grid) else ""
            print(f"| {dt:g} s / {grid_dt:g} s{default} | " + " | ".join(cells) + " |")
        spread = max(max(v) - min(v) for v in t_si_min.values())
        print(f"\nlargest spread of the minimum interior surface temperature over the cases: {spread:.4f} K")


if __name__ == "__main__":
    main()
