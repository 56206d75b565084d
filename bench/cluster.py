"""EnergyPlus runs on the dask executor: runs per minute against the number of workers, and the scheduling
overhead per task.

Run:  .venv/bin/python bench/cluster.py [--runs N] [--days D] [--workers 1,2] [--tasks N]

- EnergyPlus: ``--runs`` runs of the bundled example's wall (different conductivities, so no two runs are
  alike) over ``--days`` days from 30 May at the study's 60 s step (two EnergyPlus passes each, as the engine
  runs them), first in this process one after the other, then on a local cluster of 1 and 2 worker processes
  (`wallcal.cluster.Executor`); the cluster is started and each process has made one short EnergyPlus run
  (imports, compiled kernels) before the clock starts. Prints runs per minute.
- Overhead: ``--tasks`` trivial tasks through the executor on 2 workers: wall time per task, and the same
  tasks through the executor with the cache (each result written to disk).
- A projection: what a Sobol study with EnergyPlus (28,000 runs) would take on 100 workers, from the
  measured seconds per run and overhead per task (``--project-runs``, ``--project-workers``).

These are figures, not tests. The host's load average is printed: on a shared machine it changes the
absolute figures a lot.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"


def noop(x):
    return x


def wait(seconds):
    """A task that takes ``seconds`` of wall time and no CPU (what the executor's parallelism alone gives)."""
    time.sleep(seconds)
    return seconds


def inputs(n_runs: int, days: int):
    from wallcal.simulation import prepare
    from wallcal.study import PeriodSpec, load_study

    study = load_study(EXAMPLE)
    start = dt.datetime(2025, 5, 30)
    study = study.replace(period=PeriodSpec(start - dt.timedelta(days=1), start, start + dt.timedelta(days=days)))
    prep = prepare(study, "energyplus")
    layer = study.wall.layers[0]
    out = []
    for k in range(n_runs):
        wall = study.wall.replace_layer(layer.id, conductivity=layer.conductivity * (1.0 + 0.01 * (k + 1)))
        out.append(prep.inp.replace(wall=wall))
    return prep.engine, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=4, help="EnergyPlus runs per configuration (default 4)")
    ap.add_argument("--days", type=int, default=2, help="days simulated per run (default 2)")
    ap.add_argument("--workers", default="1,2", help="worker counts to measure (default 1,2)")
    ap.add_argument("--tasks", type=int, default=400, help="trivial tasks for the overhead (default 400)")
    ap.add_argument("--no-energyplus", action="store_true", help="only the overhead and the waiting tasks")
    ap.add_argument("--project-runs", type=int, default=28_000)
    ap.add_argument("--project-workers", type=int, default=100)
    args = ap.parse_args(argv)

    from wallcal.cluster import Executor
    from wallcal.engines.energyplus import run_task

    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; python {sys.version.split()[0]}")
    workers = [int(x) for x in args.workers.split(",") if x.strip()]
    for n in workers:
        with Executor("local", workers=n, progress=False) as ex:
            ex.map(noop, range(n))
            t = time.perf_counter()
            ex.map(wait, [2.0] * 4)
            el = time.perf_counter() - t
            print(f"4 tasks of 2 s without CPU (sleep) on {n} worker{'s' if n > 1 else ''}: {el:.1f} s")
    if args.no_energyplus:
        with Executor("local", workers=2, progress=False) as ex:
            ex.map(noop, range(2))
            t = time.perf_counter()
            ex.map(noop, range(args.tasks))
            print(
                f"overhead per task ({args.tasks} trivial tasks, 2 workers): "
                f"{(time.perf_counter() - t) / args.tasks * 1e3:.1f} ms"
            )
        return 0
    engine, inps = inputs(args.runs, args.days)
    _, warm = inputs(2, 1)  # one short run per process before the clock: imports and compiled kernels loaded
    print(f"EnergyPlus: {args.runs} runs of {args.days} days at {inps[0].time_step:g} s (two passes each)")
    rows = []
    engine.run_inputs(warm[:1])
    t = time.perf_counter()
    seq = engine.run_inputs(inps)  # no executor active: in this process, one after the other
    el = time.perf_counter() - t
    per_run = [o.info["seconds"] for o in seq]
    rows.append(("in-process, one after the other", el, args.runs / el * 60.0))
    for n in workers:
        with Executor("local", workers=n, progress=False, label="EnergyPlus runs") as ex:
            ex.map(run_task, [(engine.settings, i, 3600 // int(i.time_step)) for i in warm[:n]])  # warm workers
            t = time.perf_counter()
            outs = ex.map(run_task, [(engine.settings, i, 3600 // int(i.time_step)) for i in inps])
            el = time.perf_counter() - t
        assert all(a.temperatures.keys() == b.temperatures.keys() for a, b in zip(outs, seq, strict=True))
        rows.append((f"local cluster, {n} worker{'s' if n > 1 else ''}", el, args.runs / el * 60.0))
    width = max(len(r[0]) for r in rows)
    print(f"{'configuration':<{width}}  {'wall s':>7}  {'runs/min':>8}  {'speed-up':>8}")
    for name, el, rpm in rows:
        print(f"{name:<{width}}  {el:7.1f}  {rpm:8.2f}  {rpm / rows[0][2]:8.2f}")
    print(f"seconds per run inside the runs (EnergyPlus itself, in-process): {sum(per_run) / len(per_run):.1f}")

    with Executor("local", workers=2, progress=False) as ex:
        ex.map(noop, range(2))
        t = time.perf_counter()
        ex.map(noop, range(args.tasks))
        plain = (time.perf_counter() - t) / args.tasks
        with tempfile.TemporaryDirectory() as d:
            ex.cache_dir = Path(d)
            t = time.perf_counter()
            ex.map(noop, range(args.tasks))
            cached = (time.perf_counter() - t) / args.tasks
    print(
        f"overhead per task ({args.tasks} trivial tasks, 2 workers): {plain * 1e3:.1f} ms; "
        f"with the cache written: {cached * 1e3:.1f} ms"
    )

    sec_run = sum(per_run) / len(per_run)
    full = sec_run  # seconds of one run at these settings on one core of this host
    n, w = args.project_runs, args.project_workers
    hours = (n / w) * full / 3600.0
    print(
        f"projection: {n} runs of {args.days} days on {w} workers at {full:.1f} s per run: "
        f"{hours:.2f} h of runs + {n * plain / 60:.1f} min of scheduling (if the scheduler handled the tasks "
        f"one at a time); one worker: {n * full / 3600:.0f} h"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
