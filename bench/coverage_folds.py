"""The posterior predictive band on the real walls, judged on every part of their record in turn (blocked
cross-validation; docs/identifiability.md, "Judged on every part of the record").

    PYTHONPATH=src python bench/coverage_folds.py [trh passys passys0] [--folds 3] [--steps 300]

The record of each study (``start`` to the end of its held-out window) is cut into ``--folds`` equal blocks. Each
block in turn is held out: ``wallcal diagnose`` chooses the structure on the rest (it scores its candidates on the
block), ``wallcal posterior`` samples it from diagnose's optimum (``--steps`` ensemble steps, the default walkers,
seed 1) and predicts the block. Printed per block and target: coverage_95 (band_width_95) of the posterior's band
(out of sample) and of the same chain's band from its in-sample errors alone, and the held-out RMSE of the model;
then the means over the blocks. The last block is each study's own window.

``trh``: the bundled TRH-1 example (fd-cn); ``passys``: examples/passys/study_moisture.toml (the ham engine; data
read in place from ../shared); ``passys0``: examples/passys/study.toml with its face offset set to 0 (heat only, as
measured). About 1 min (trh), 15 s (passys0) and 5 min (passys) with the default 300 steps on two cores.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from wallcal.analysis.diagnose import diagnose
from wallcal.analysis.posterior import posterior
from wallcal.analysis.posterior_predictive import predictive
from wallcal.calibration.objective import Evaluator
from wallcal.calibration.space import space_of
from wallcal.simulation import BATCH_NEEDS, prepare
from wallcal.study import load_study

BENCH = Path(__file__).resolve().parent
sys.path.insert(0, str(BENCH))

from validation_arms import study_of  # noqa: E402  (TRH-1 and PASSYS as measured, as validation_arms.py builds them)

ROOT = BENCH.parent
STUDIES = {
    "trh": lambda: study_of("trh"),
    "passys": lambda: load_study(ROOT / "examples" / "passys" / "study_moisture.toml"),
    "passys0": lambda: study_of("passys0"),
}


def folds(study, k: int) -> list[tuple[pd.Timestamp, pd.Timestamp]]:
    """``k`` equal blocks of the record from ``start`` to the end of the held-out window (or ``end``), each ending
    one sampling step before the next begins (the last ends where the record does)."""
    p = study.period
    start = pd.Timestamp(p.start)
    stop = pd.Timestamp(p.validation_end or p.end)
    edges = [start + (stop - start) * i / k for i in range(k + 1)]
    step = pd.Timedelta(seconds=study.simulation.time_step)
    return [(edges[i].ceil("5min"), (edges[i + 1].ceil("5min") - step) if i < k - 1 else stop) for i in range(k)]


def held_out(study, window):
    """The study with ``window`` held out and the rest of the record fitted."""
    p = study.period
    stop = p.validation_end or p.end
    period = dataclasses.replace(
        p, end=stop, validation_start=window[0].to_pydatetime(), validation_end=window[1].to_pydatetime()
    )
    return study.replace(period=period)


def run(name: str, k: int, steps: int) -> pd.DataFrame:
    study = STUDIES[name]()
    rows = []
    for i, window in enumerate(folds(study, k)):
        t0 = time.perf_counter()
        st = held_out(study, window)
        d = diagnose(st, progress=False)
        space = space_of(d.study)
        x0 = np.array([d.x[n] for n in space.names])
        r = posterior(d.study, x_start=x0, steps=steps, progress=False, nonunique_candidates=64)
        adopted = " + ".join(d.adopted) or "nothing"
        # the same chain's band from its in-sample errors alone (the rule before the out-of-fold widening)
        ev = Evaluator(prepare(d.study, needs=BATCH_NEEDS), space)
        plain = predictive(d.study, space, r.samples, ev, out_of_sample=False).table.set_index("sensor")
        for q in r.predictive.table.itertuples():
            rows.append(
                {
                    "wall": name,
                    "block": i + 1,
                    "window": f"{window[0]:%m-%d %H:%M} .. {window[1]:%m-%d %H:%M}",
                    "adopted": adopted,
                    "sensor": q.sensor,
                    "coverage_95": q.coverage_95,
                    "band_width_95": q.band_width_95,
                    "in-sample coverage_95": plain.loc[q.sensor, "coverage_95"],
                    "in-sample band_width_95": plain.loc[q.sensor, "band_width_95"],
                    "rmse": q.rmse,
                    "rejected": r.structure["rejected"],
                }
            )
        print(
            f"{name} block {i + 1}/{k} {window[0]} .. {window[1]}: adopted {adopted}; "
            + "; ".join(
                f"{q.sensor} {q.coverage_95:.3f} ({q.band_width_95:.3g}) in-sample "
                f"{plain.loc[q.sensor, 'coverage_95']:.3f} ({plain.loc[q.sensor, 'band_width_95']:.3g}), "
                f"RMSE {q.rmse:.3g}"
                for q in r.predictive.table.itertuples()
            )
            + f"; structure {'rejected' if r.structure['rejected'] else 'accepted'} ({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("walls", nargs="*", default=["trh", "passys", "passys0"], choices=sorted(STUDIES))
    ap.add_argument("--folds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=300)
    args = ap.parse_args(argv)
    tables = [run(w, args.folds, args.steps) for w in args.walls]
    t = pd.concat(tables)
    cols = ["coverage_95", "band_width_95", "in-sample coverage_95", "in-sample band_width_95", "rmse"]
    mean = t.groupby(["wall", "sensor"], sort=False)[cols].mean()
    print("\nmean over the blocks: the band (out-of-fold widening), the in-sample band, the held-out RMSE")
    print(mean.to_string(float_format=lambda v: f"{v:.3f}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
