"""Benchmark of ``wallcal diagnose`` on the bundled example (prints figures); target under 60 s on 2 cores.

Three figures, each the median of ``--repeat`` runs:

- the command in a fresh process, ``wallcal diagnose EXAMPLE --out DIR`` (calibrates first, then scores every
  candidate: what a user waits for; numba's cache warm);
- the library call ``diagnose(study)`` in a warm process (calibration included);
- the library call from a saved calibration (``start=DIR``, the ``--from`` route): the diagnosis alone.

The host's load average is printed with each figure: the machine may be shared.

Usage: python bench/diagnose.py [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"
TARGET = 60.0


def _load() -> str:
    return "load average {:.1f} / {:.1f} / {:.1f}".format(*os.getloadavg())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    from wallcal import load_study
    from wallcal.analysis.diagnose import diagnose
    from wallcal.calibration import calibrate

    study = load_study(EXAMPLE)
    with tempfile.TemporaryDirectory() as tmp:
        # warm-up: numba's cache and every engine path the candidates use
        cal = calibrate(study, progress=False)
        cal.write(Path(tmp) / "cal")
        diagnose(study, start=Path(tmp) / "cal")
        rows = []
        times = []
        for k in range(args.repeat):
            t = time.perf_counter()
            subprocess.run(
                [sys.executable, "-m", "wallcal.cli", "diagnose", str(EXAMPLE), "--out", f"{tmp}/cli{k}", "--quiet"],
                check=True,
                stdout=subprocess.DEVNULL,
            )
            times.append(time.perf_counter() - t)
        rows.append(("wallcal diagnose EXAMPLE --out DIR (fresh process, calibrates first)", times, _load()))
        times, d = [], None
        for _ in range(args.repeat):
            t = time.perf_counter()
            d = diagnose(study)
            times.append(time.perf_counter() - t)
        rows.append(("diagnose(study), warm process, calibration included", times, _load()))
        times = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            d2 = diagnose(study, start=Path(tmp) / "cal")
            times.append(time.perf_counter() - t)
        rows.append(("diagnose(study, start=calibration dir) (--from)", times, _load()))
    for label, ts, load in rows:
        med = statistics.median(ts)
        print(
            f"{label}: {med:.1f} s (runs: {', '.join(f'{x:.1f}' for x in ts)}) -> "
            f"{'OK' if med <= TARGET else 'SLOW'} (target {TARGET:g} s); {load}"
        )
    print(
        f"{os.cpu_count()} CPUs; adopted: {', '.join(d.adopted) or 'none'} (calibrated first), "
        f"{', '.join(d2.adopted) or 'none'} (from the saved calibration); {len(d2.candidates)} candidates and "
        f"combinations scored, {d2.evaluations} simulations"
    )


if __name__ == "__main__":
    main()
