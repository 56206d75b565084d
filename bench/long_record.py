"""Long records (issue 10): a year of 1-minute boundary data (525,600 steps) through the fd engine.

Prints, for 1, 3 and 12 months of synthetic data, the run time of both engine paths (modal fast path and
general tridiagonal path), the time per step, and the memory: the Python-side peak above the inputs and
outputs (tracemalloc; numba's own allocations are not traced) and the process's peak resident set
(each size runs in a fresh subprocess, so ru_maxrss is that size's own peak). Linear time = constant
microseconds per step; flat memory = the peak beyond inputs + outputs does not grow with the length.

    .venv/bin/python bench/long_record.py              # 1, 3, 12 months
    .venv/bin/python bench/long_record.py --months 1 12 --threads 1

Not a test: it prints figures (see docs/robustness.md for the last ones).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

MIN_PER_MONTH = 43800  # 365 days / 12 in minutes


def child(months: float, path: str) -> dict:
    import resource
    import tracemalloc

    import numpy as np
    import pandas as pd

    from wallcal.engines.base import BoundaryInput, SimulationInput
    from wallcal.engines.fd import FDEngine
    from wallcal.wall import Layer, Probe, Wall

    wall = Wall(
        (
            Layer("brick", 0.10, conductivity=0.8, density=1800.0, specific_heat=840.0),
            Layer("wool", 0.12, conductivity=0.04, density=60.0, specific_heat=1030.0),
            Layer("gypsum", 0.03, conductivity=0.25, density=900.0, specific_heat=1000.0),
        ),
        tuple(Probe(f"P{i}", d) for i, d in enumerate((0.05, 0.12, 0.2, 0.235))),
    )
    n = int(months * MIN_PER_MONTH)
    dt = 60.0
    t = np.arange(n + 1) * dt
    rng = np.random.default_rng(0)
    ue = 5 + 10 * np.sin(2 * np.pi * t / 86400) + 8 * np.sin(2 * np.pi * t / 3.15e7) + rng.normal(0, 0.3, n + 1)
    ui = 20 + np.sin(2 * np.pi * t / 86400)
    inp = SimulationInput(
        wall=wall,
        t0=pd.Timestamp("2025-01-01"),
        time_step=dt,
        exterior=BoundaryInput("surface_temperature", ue),
        interior=BoundaryInput("surface_temperature", ui),
        output_positions=np.arange(n + 1, dtype=float),
        probes=tuple(p.name for p in wall.probes),
        flux_faces=("exterior", "interior"),
        grid_constant=2.0,
        node_rule="wallcal",
        scheme="cn",
    )
    eng = FDEngine("cn")
    # compile (and warm caches) on a short record first, so that the timing is the run's own
    short = SimulationInput(
        **{
            **inp.__dict__,
            "exterior": BoundaryInput("surface_temperature", ue[:200]),
            "interior": BoundaryInput("surface_temperature", ui[:200]),
            "output_positions": np.arange(200, dtype=float),
        }
    )
    eng.run(short, path=path)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    out = eng.run(inp, path=path)
    sec = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    n_out_values = (len(wall.probes) + 2) * (n + 1)
    io_bytes = 8 * (2 * (n + 1) + (n + 1) + 2 * n_out_values)  # inputs + output positions + outputs (+ copies)
    assert np.isfinite(out.temperatures["P0"]).all()
    return {
        "months": months,
        "steps": n,
        "path": out.info["path"],
        "nodes": out.info["nodes"],
        "seconds": sec,
        "us_per_step": 1e6 * sec / n,
        "traced_peak_MB": peak / 1e6,
        "io_MB": io_bytes / 1e6,
        "beyond_io_MB": (peak - io_bytes) / 1e6,
        "rss_peak_MB": rss1 / 1024,
        "rss_growth_MB": (rss1 - rss0) / 1024,
        "energy_residual": out.info.get("energy_residual_J_m2"),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--months", type=float, nargs="+", default=[1, 3, 12])
    ap.add_argument("--paths", nargs="+", default=["modal", "general"])
    ap.add_argument("--threads", type=int, help="NUMBA_NUM_THREADS for the runs")
    ap.add_argument("--child", nargs=2, metavar=("MONTHS", "PATH"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(float(args.child[0]), args.child[1])))
        return
    env = dict(os.environ)
    if args.threads:
        env["NUMBA_NUM_THREADS"] = str(args.threads)
    rows = []
    for path in args.paths:
        for m in args.months:
            r = subprocess.run(
                [sys.executable, __file__, "--child", str(m), path], capture_output=True, text=True, env=env, check=True
            )
            rows.append(json.loads(r.stdout.strip().splitlines()[-1]))
    print(
        f"{'path':8s} {'months':>6s} {'steps':>8s} {'nodes':>5s} {'time s':>7s} {'us/step':>7s} "
        f"{'traced MB':>9s} {'in+out MB':>9s} {'beyond MB':>9s} {'RSS MB':>7s} {'RSS +MB':>7s}"
    )
    for r in rows:
        print(
            f"{r['path']:8s} {r['months']:6g} {r['steps']:8d} {r['nodes']:5d} {r['seconds']:7.3f} "
            f"{r['us_per_step']:7.3f} {r['traced_peak_MB']:9.1f} {r['io_MB']:9.1f} {r['beyond_io_MB']:9.1f} "
            f"{r['rss_peak_MB']:7.0f} {r['rss_growth_MB']:7.0f}"
        )
    # a full temperature field would be n_nodes * steps * 8 bytes:
    r = rows[-1]
    print(f"\n(a full temperature field of the last run would take {8 * r['nodes'] * r['steps'] / 1e6:.0f} MB)")


if __name__ == "__main__":
    main()
