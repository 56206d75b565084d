"""The engine's speed lines against an earlier revision's, side by side on the same host.

Run:  .venv/bin/python bench/revisions.py [--rev de315da] [--rounds 6] [--repeat 20]

The shared host's speed drifts by up to 2x from one minute to the next, and so does the ratio of a
line to the reference loop of ``bench/engine.py`` (throughput-bound and latency-bound code slow down
differently when a neighbour is busy): the same revision's lambda(T) run has measured 1.35x and
1.62x the loop on different days. Whether a speed target that an earlier revision met is still met
is therefore measured against that revision's own code: its tree (``git archive``) and this one run
the same lines in fresh processes that alternate, round after round, each tree with its own kernel
cache (warmed before the first round). Printed per line: each tree's median over the rounds and the
median of the per-round ratios this tree / revision (below 1: this tree is faster). Lines: one
simulation (modal path), the batch of 256 candidate walls, one lambda(T) run, the lambda(T) batch of
16, and the reference loop (which both trees run with the same code: a check on the host's drift).
A figure, not a test.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from engine import REPO  # noqa: E402

LINES = ("modal one run", "batch of 256", "lambda(T) one run", "lambda(T) batch of 16", "reference loop")

# Runs in a fresh process with the tree's src on the path; uses only the API that both trees have.
CHILD = r"""
import json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[2])
from engine import plain_cn_loop
import wallcal
from wallcal.engines.fd import FDEngine
from wallcal.grid import PropertyArrays
from wallcal.simulation import prepare

repeat = int(sys.argv[3])
study = wallcal.load_study(sys.argv[1])
data = prepare(study)
eng = FDEngine("cn")
prep = eng.prepare(data.inp)
one = PropertyArrays.from_walls([study.wall])
rng = np.random.default_rng(1)
walls = []
for _ in range(256):  # as bench/engine.py
    w = study.wall
    for layer in w.layers:
        f = 1 + 0.2 * rng.uniform(-1, 1, 3)
        w = w.replace_layer(layer.id, conductivity=layer.conductivity * f[0], density=layer.density * f[1],
                            specific_heat=layer.specific_heat * f[2])
    walls.append(w)
batch = PropertyArrays.from_walls(walls)
nl_wall = study.wall
for lid in ("3", "5", "7", "8"):
    nl_wall = nl_wall.replace_layer(lid, conductivity_temperature_coefficient=0.0046)
nl_prep = eng.prepare(data.with_wall(nl_wall).inp)
nl_one = PropertyArrays.from_walls([nl_wall])
nl_batch = PropertyArrays.from_walls([nl_wall] * 16)
plain = plain_cn_loop()

def med(fn, n):
    fn()
    ts = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts))

print(json.dumps({
    "modal one run": med(lambda: prep.run_batch(one), repeat),
    "batch of 256": med(lambda: prep.run_batch(batch), max(3, repeat // 5)),
    "lambda(T) one run": med(lambda: nl_prep.run_batch(nl_one), repeat),
    "lambda(T) batch of 16": med(lambda: nl_prep.run_batch(nl_batch), max(3, repeat // 5)),
    "reference loop": med(plain, repeat),
}))
"""


def tree_of(rev: str, into: Path) -> Path:
    """The source tree of ``rev`` (``git archive``), extracted under ``into``."""
    tar = into / "tree.tar"
    subprocess.run(["git", "-C", str(REPO), "archive", "--format=tar", "-o", str(tar), rev], check=True)
    root = into / "tree"
    with tarfile.open(tar) as t:
        t.extractall(root, filter="data")
    return root


def measure(root: Path, cache: Path, repeat: int) -> dict[str, float]:
    env = {**os.environ, "PYTHONPATH": str(root / "src"), "NUMBA_CACHE_DIR": str(cache)}
    example = root / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"
    bench = str(Path(__file__).resolve().parent)
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(example), bench, str(repeat)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rev", default="de315da", help="the earlier revision (default: de315da, which resolved issue 3)")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        trees = {"revision": tree_of(args.rev, tmp), "this tree": REPO}
        caches = {name: tmp / f"cache-{i}" for i, name in enumerate(trees)}
        for name, root in trees.items():  # compile into each tree's cache
            measure(root, caches[name], 1)
        runs: dict[str, list[dict[str, float]]] = {name: [] for name in trees}
        loads = []
        for r in range(args.rounds):
            order = list(trees) if r % 2 == 0 else list(trees)[::-1]
            for name in order:
                runs[name].append(measure(trees[name], caches[name], args.repeat))
            loads.append(os.getloadavg()[0])
            print(f"round {r + 1}/{args.rounds} done (load {loads[-1]:.2f})", file=sys.stderr)
    print(
        f"revision {args.rev} against this tree, {args.rounds} rounds of alternating fresh processes, "
        f"{args.repeat} repeats each (batches {max(3, args.repeat // 5)}); host load {min(loads):.2f}-{max(loads):.2f}"
    )
    print(f"{'line':24s} {args.rev + ' (ms)':>14s} {'this tree (ms)':>15s} {'this / rev: median (range)':>30s}")
    for line in LINES:
        a = np.array([x[line] for x in runs["revision"]])
        b = np.array([x[line] for x in runs["this tree"]])
        q = b / a
        print(
            f"{line:24s} {np.median(a) * 1e3:14.3f} {np.median(b) * 1e3:15.3f} "
            f"{np.median(q):12.3f} ({q.min():.3f}-{q.max():.3f})"
        )


if __name__ == "__main__":
    main()
