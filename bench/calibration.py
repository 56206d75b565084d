"""Calibration benchmarks on the bundled example.

Run:  .venv/bin/python bench/calibration.py [--algorithms pso-hj,least-squares,...] [--skip-15]

For each algorithm: final objective, simulations and wall time, and the simulations / seconds
needed to come within 1 %, 0.1 % and 0.01 % of the best objective found by any run (the "best
attainable"). Two parameter spaces:

- the study's 18 parameters (the example's [calibration] table: +-20 %, layer 7 -50/+200 %, 5 and 8 tied);
- the reference 15-parameter space (layers 4 and 6 also tied), whose optimum a many-restart
  least-squares search puts at a CSE of about 222.57 degC^2.

These are figures, not tests.
"""

from __future__ import annotations

import argparse
import copy
import time
from pathlib import Path

import wallcal
from wallcal.calibration import calibrate, convergence_table, parse_space
from wallcal.simulation import prepare

EXAMPLE = Path(__file__).resolve().parents[1] / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"
ALGOS = {
    "pso-hj": {},
    "least-squares": {"max_nfev": 300},
    "nelder-mead": {"maxfev": 4000},
    "differential-evolution": {"maxiter": 60},
    "cma-es": {"maxfevals": 4000},
}


def tied_15(study):
    cal = copy.deepcopy(study.raw["calibration"])
    params = [p for p in cal["parameters"] if p["layers"] != ["6"]]
    for p in params:
        if p["layers"] == ["4"]:
            p["layers"] = ["4", "6"]
    cal["parameters"] = params
    return cal


def run_space(study, space, algos, prepared):
    rows = []
    for name in algos:
        try:
            t = time.perf_counter()
            res = calibrate(study, algorithm=name, settings=ALGOS[name], progress=False, prepared=prepared, space=space)
            rows.append((name, res, time.perf_counter() - t))
        except Exception as exc:  # report and go on (e.g. cma not installed)
            print(f"  {name}: not run ({exc})")
    return rows


def report(title, rows, reference=None):
    best = min([r.f_opt for _, r, _ in rows] + ([reference] if reference else []))
    print(f"\n{title}\nbest attainable (min over runs{' and the reference' if reference else ''}): {best:.6g}")
    head = (
        f"{'algorithm':24s} {'objective':>11s} {'sims':>7s} {'seconds':>8s} | {'1 %':>14s} "
        f"{'0.1 %':>14s} {'0.01 %':>14s}"
    )
    print(head)
    print("-" * len(head))
    for name, res, wall in rows:
        cells = []
        for _lev, ev, sec in convergence_table(res.history, best):
            cells.append(f"{ev:6d} /{sec:5.2f}s" if ev is not None else f"{'not reached':>14s}")
        line = f"{name:24s} {res.f_opt:11.6g} {res.evaluations:7d} {wall:8.2f} | "
        print(line + " ".join(f"{c:>14s}" for c in cells))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--algorithms", default=",".join(ALGOS))
    ap.add_argument("--skip-15", action="store_true")
    args = ap.parse_args(argv)
    algos = [a.strip() for a in args.algorithms.split(",") if a.strip()]
    study = wallcal.load_study(EXAMPLE)
    prepared = prepare(study)
    # warm the kernels (compilation or cache load) outside the timings
    calibrate(
        study,
        settings={"particles": 4, "generations": 2, "step_reductions": 0, "polish": False},
        progress=False,
        prepared=prepared,
    )
    space18 = parse_space(study)
    rows = run_space(study, space18, algos, prepared)
    report(f"18 parameters (the example's [calibration]); base case objective {rows[0][1].f_base:.6g}", rows)
    pso = [r for n, r, _ in rows if n == "pso-hj"]
    if pso:
        r = pso[0]
        rm = r.metrics[r.metrics.case == "calibrated"].set_index("signal")["rmse"]
        print(
            "pso-hj RMSE after: "
            + ", ".join(f"{t} {rm[t]:.3f}" for t in r.space.targets)
            + "; noise floors: "
            + ", ".join(f"{k} {v:.3f}" for k, v in r.floors.items() if k in r.space.targets)
        )
    if not args.skip_15:
        space15 = parse_space(study, tied_15(study))
        rows15 = run_space(study, space15, algos, prepared)
        report("15 parameters (layers 4 and 6 also tied); reference optimum 222.57", rows15, reference=222.57)
        best = [r for n, r, _ in rows15 if n == "pso-hj"]
        if best:
            r = best[0]
            rm = r.metrics[r.metrics.case == "calibrated"].set_index("signal")["rmse"]
            print(
                f"pso-hj: CSE {r.f_opt:.4f} (reference 222.57); RMSE "
                + ", ".join(f"{t} {rm[t]:.3f}" for t in r.space.targets)
                + " (reference 0.136 / 0.157 / 0.231)"
            )
    print(
        f"\nnumba threads: {__import__('numba').get_num_threads()}; seed "
        f"{study.calibration.seed} (the same seed gives the same result)"
    )


if __name__ == "__main__":
    main()
