"""First run after installing: `wallcal calibrate` on the bundled example with an empty kernel cache
(cold: every numba kernel compiled) against the same command once the cache is filled (warm).

Run:  .venv/bin/python bench/first_run.py [--repeat N]

Each run is a fresh process; the cold runs each get a new, empty NUMBA_CACHE_DIR (numba then neither
reads nor writes the __pycache__ next to the sources), the warm runs reuse the cache the first cold
run filled. Outputs go to a temporary directory. Prints the medians and the ratio (target: <= 3).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"


def calibrate(cache_dir: str, out_dir: str) -> float:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir}
    cmd = [sys.executable, "-m", "wallcal.cli", "calibrate", str(EXAMPLE), "--out", out_dir, "--quiet"]
    t = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, capture_output=True, text=True)
    return time.perf_counter() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args(argv)
    cold, warm = [], []
    with tempfile.TemporaryDirectory() as tmp:
        shared = os.path.join(tmp, "cache")
        for r in range(args.repeat):  # interleaved: cold, warm, cold, warm ...
            cache = shared if r == 0 else os.path.join(tmp, f"cache{r}")
            cold.append(calibrate(cache, os.path.join(tmp, f"cold{r}")))
            warm.append(calibrate(shared, os.path.join(tmp, f"warm{r}")))
    c, w = float(np.median(cold)), float(np.median(warm))
    print(f"wallcal calibrate {EXAMPLE.relative_to(REPO)}, fresh process each, {os.cpu_count()} cores")
    print(f"cold (empty kernel cache): median {c:7.2f} s  ({', '.join(f'{x:.2f}' for x in cold)})")
    print(f"warm (cached kernels):     median {w:7.2f} s  ({', '.join(f'{x:.2f}' for x in warm)})")
    print(f"cold / warm: {c / w:.2f} (target <= 3)")


if __name__ == "__main__":
    main()
