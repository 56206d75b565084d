"""A/B of the general (lambda(T)) kernel: this tree's kernels.py against another revision's, in one process.

Run:  .venv/bin/python bench/lambda_ab.py [--baseline REV] [--repeat N]

The baseline's ``src/wallcal/engines/kernels.py`` (``git show REV:...``) is loaded as a second module
of the package, and the bench wall of ``bench/engine.py`` (the bundled example with lambda(T) on its
mineral-wool layers 3, 5, 7 and 8) runs through ``PreparedFD.run_batch`` with either module, interleaved
with the plain numba reference loop of ``bench/engine.py``: per round the baseline, this tree and the
reference loop, in a rotating order. Prints the medians of the per-round ratios (baseline / reference,
this tree / reference, this tree / baseline) and the largest temperature difference between the two.
A figure, not a test.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from engine import EXAMPLE, REPO, lambda_wall, plain_cn_loop  # noqa: E402


def load_baseline(rev: str):
    """The kernels module of revision ``rev`` as ``wallcal.engines.kernels_baseline``."""
    src = subprocess.run(
        ["git", "-C", str(REPO), "show", f"{rev}:src/wallcal/engines/kernels.py"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    sha = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", rev], capture_output=True, text=True, check=True
    ).stdout.strip()
    path = Path(tempfile.gettempdir()) / f"wallcal-ab-{sha[:12]}" / "kernels_baseline.py"
    path.parent.mkdir(exist_ok=True)
    if not path.exists() or path.read_text() != src:  # (an unchanged file keeps numba's cache valid)
        path.write_text(src)
    spec = importlib.util.spec_from_file_location("wallcal.engines.kernels_baseline", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--baseline", default="main", help="git revision of the simpler code (default: main)")
    ap.add_argument("--repeat", type=int, default=30)
    args = ap.parse_args(argv)

    import wallcal
    from wallcal.engines import fd, kernels
    from wallcal.engines.fd import FDEngine
    from wallcal.grid import PropertyArrays
    from wallcal.simulation import prepare

    base = load_baseline(args.baseline)
    study = wallcal.load_study(EXAMPLE)
    nl_wall = lambda_wall(study.wall)
    prep = FDEngine("cn").prepare(prepare(study).with_wall(nl_wall).inp)
    one = PropertyArrays.from_walls([nl_wall])

    def run_with(mod):
        fd.kernels = mod
        try:
            return prep.run_batch(one)
        finally:
            fd.kernels = kernels

    ra, rb = run_with(base), run_with(kernels)  # compilation
    diff = float(np.nanmax(np.abs(ra.out[0, : len(prep.probe_names)] - rb.out[0, : len(prep.probe_names)])))
    plain = plain_cn_loop()
    plain()
    cases = {"A": lambda: run_with(base), "B": lambda: run_with(kernels), "ref": plain}
    order = ["A", "B", "ref"]
    ts: dict[str, list[float]] = {c: [] for c in order}
    for r in range(args.repeat):
        for c in order[r % 3 :] + order[: r % 3]:
            t = time.perf_counter()
            cases[c]()
            ts[c].append(time.perf_counter() - t)
    a, b, ref = (np.array(ts[c]) for c in order)
    load = os.getloadavg()[0]
    print(f"baseline A = {args.baseline}, B = this tree; {args.repeat} rounds, host load {load:.2f}")
    for name, x in (("A (baseline)", a), ("B (this tree)", b), ("reference loop", ref)):
        print(f"{name:16s} median {np.median(x) * 1e3:7.3f} ms, min {x.min() * 1e3:7.3f} ms")
    print(
        f"A / reference: median {np.median(a / ref):.3f}; B / reference: median {np.median(b / ref):.3f} "
        f"(p10 {np.percentile(b / ref, 10):.3f}, p90 {np.percentile(b / ref, 90):.3f}); "
        f"B / A: median {np.median(b / a):.3f} (min-based {b.min() / a.min():.3f})"
    )
    print(f"largest probe temperature difference B - A: {diff:.2e} K")


if __name__ == "__main__":
    main()
