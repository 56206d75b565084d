"""The Python between ``PreparedFD.run_batch`` and the numba kernel for ONE candidate (bundled example).

Run:  .venv/bin/python bench/overhead.py [--repeat N]

The kernel (``kernels.run_batch`` for the lambda(T) wall of bench/engine.py, ``modal.modal_batch`` for the
example's wall) is replaced by a stub that returns its saved result, so that what is timed is the Python
around it; the numba dispatch of the kernel's own arguments is timed apart, with a no-op jitted function of
the same argument types. "cold": each call right after the plain reference loop of bench/engine.py (caches
cold, as in its lambda(T) line); "warm": the call repeated back to back. Figures, not tests.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

sys.path.insert(0, str(Path(__file__).resolve().parent))
import engine as bench_engine  # noqa: E402


def _stubbed(module, name, call):
    """Run ``call`` once with ``module.name`` recorded; return a stub returning its result, and its arguments."""
    saved = {}
    original = getattr(module, name)

    def spy(*args):
        saved["args"], saved["result"] = args, original(*args)
        return saved["result"]

    setattr(module, name, spy)
    try:
        call()
    finally:
        setattr(module, name, original)
    result = saved["result"]
    return (lambda *args: result), saved["args"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=200)
    args = ap.parse_args(argv)

    import wallcal
    from wallcal.engines import kernels, modal
    from wallcal.engines.fd import FDEngine
    from wallcal.grid import PropertyArrays
    from wallcal.simulation import prepare

    study = wallcal.load_study(bench_engine.EXAMPLE)
    data = prepare(study)
    eng = FDEngine("cn")
    nl_wall = bench_engine.lambda_wall(study.wall)
    nl_prep, nl_one = eng.prepare(data.with_wall(nl_wall).inp), PropertyArrays.from_walls([nl_wall])
    prep, one = eng.prepare(data.inp), PropertyArrays.from_walls([study.wall])
    plain = bench_engine.plain_cn_loop()
    nl_prep.run_batch(nl_one), prep.run_batch(one), plain()

    general_stub, general_args = _stubbed(kernels, "run_batch", lambda: nl_prep.run_batch(nl_one))
    modal_stub, modal_args = _stubbed(modal, "modal_batch", lambda: prep.run_batch(one))
    noop_general = njit(lambda *a: 0)
    noop_modal = njit(lambda *a: 0)
    noop_general(*general_args), noop_modal(*modal_args)
    cases = {
        "lambda(T) wall: Python around the kernel": lambda: nl_prep.run_batch(nl_one),
        "lambda(T) wall: dispatch of the kernel's arguments": lambda: noop_general(*general_args),
        "modal path: Python around the kernel": lambda: prep.run_batch(one),
        "modal path: dispatch of the kernel's arguments": lambda: noop_modal(*modal_args),
    }
    cold = {k: [] for k in cases}
    warm = {k: [] for k in cases}
    originals = kernels.run_batch, modal.modal_batch
    kernels.run_batch, modal.modal_batch = general_stub, modal_stub
    try:
        for _ in range(args.repeat):
            for key, fn in cases.items():
                plain()
                t = time.perf_counter()
                fn()
                cold[key].append(time.perf_counter() - t)
                fn()
                t = time.perf_counter()
                fn()
                warm[key].append(time.perf_counter() - t)
    finally:
        kernels.run_batch, modal.modal_batch = originals
    print(f"one candidate, {args.repeat} rounds (host load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores), us:")
    for label, runs in (("cold", cold), ("warm", warm)):
        for key, ts in runs.items():
            ts = np.array(ts) * 1e6
            print(
                f"{label} {key:52s} median {np.median(ts):7.1f}  p10 {np.percentile(ts, 10):7.1f}  min {ts.min():7.1f}"
            )


if __name__ == "__main__":
    main()
