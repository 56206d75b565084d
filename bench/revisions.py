"""The engine's speed lines against an earlier revision's, side by side on the same host.

Run:  .venv/bin/python bench/revisions.py [--rev de315da] [--pairs 100] [--lines LINE ...]

The shared host's speed drifts by up to 2x from one minute to the next, and so does the ratio of a
line to the reference loop of ``bench/engine.py`` (throughput-bound and latency-bound code slow down
differently when a neighbour is busy): the same revision's lambda(T) run has measured 1.35x and
1.62x the loop on different days. Whether a speed target that an earlier revision met is still met
is therefore measured against that revision's own code: its tree (``git archive``) and this one each
get a warm process (own kernel cache), and the runs of a line alternate between the two, pair after
pair, so that both see the same moments of the host. Printed per line: each tree's median and the
median of the per-pair ratios this tree / revision (below 1: this tree is faster). Lines: one
simulation (modal path), the batch of 256 candidate walls, one lambda(T) run, the lambda(T) batch of
16, and the reference loop (the same code in both processes: its ratio shows what the pairing leaves
of the host's drift). A figure, not a test.
"""

from __future__ import annotations

import argparse
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

# A server in a fresh process with the tree's src on the path (only the API that both trees have): reads
# a line's name per input line, runs it once and prints its time in seconds.
CHILD = r"""
import sys, time
import numpy as np
sys.path.insert(0, sys.argv[2])
from engine import candidate_walls, lambda_wall, plain_cn_loop
import wallcal
from wallcal.engines.fd import FDEngine
from wallcal.grid import PropertyArrays
from wallcal.simulation import prepare

study = wallcal.load_study(sys.argv[1])
data = prepare(study)
eng = FDEngine("cn")
prep = eng.prepare(data.inp)
one = PropertyArrays.from_walls([study.wall])
batch = PropertyArrays.from_walls(candidate_walls(study.wall))
nl_wall = lambda_wall(study.wall)
nl_prep = eng.prepare(data.with_wall(nl_wall).inp)
nl_one = PropertyArrays.from_walls([nl_wall])
nl_batch = PropertyArrays.from_walls([nl_wall] * 16)
plain = plain_cn_loop()
cases = {
    "modal one run": lambda: prep.run_batch(one),
    "batch of 256": lambda: prep.run_batch(batch),
    "lambda(T) one run": lambda: nl_prep.run_batch(nl_one),
    "lambda(T) batch of 16": lambda: nl_prep.run_batch(nl_batch),
    "reference loop": plain,
}
for fn in cases.values():  # compilation or cache load, and a first call
    fn()
    fn()
print("ready", flush=True)
for line in sys.stdin:
    fn = cases[line.strip()]
    t = time.perf_counter()
    fn()
    print(time.perf_counter() - t, flush=True)
"""


def tree_of(rev: str, into: Path) -> Path:
    """The source tree of ``rev`` (``git archive``), extracted under ``into``."""
    tar = into / "tree.tar"
    done = subprocess.run(
        ["git", "-C", str(REPO), "archive", "--format=tar", "-o", str(tar), rev], capture_output=True, text=True
    )
    if done.returncode != 0:
        raise SystemExit(f"bench/revisions.py: --rev {rev!r}: git archive failed: {done.stderr.strip()}")
    root = into / "tree"
    with tarfile.open(tar) as t:
        t.extractall(root, filter="data")
    return root


class Server:
    """A tree's measuring process (:data:`CHILD`), warm, timing one run of a line per request."""

    def __init__(self, root: Path, cache: Path):
        env = {**os.environ, "PYTHONPATH": str(root / "src"), "NUMBA_CACHE_DIR": str(cache)}
        example = root / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"
        bench = str(Path(__file__).resolve().parent)
        self.proc = subprocess.Popen(
            [sys.executable, "-c", CHILD, str(example), bench],
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        if self.proc.stdout.readline().strip() != "ready":
            raise RuntimeError(f"the measuring process of {root} did not start")

    def time(self, line: str) -> float:
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        return float(self.proc.stdout.readline())

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rev", default="de315da", help="the earlier revision (default: de315da, which resolved issue 3)")
    ap.add_argument("--pairs", type=int, default=100, help="alternated pairs of runs per line (batches: a fifth)")
    ap.add_argument("--lines", nargs="+", default=list(LINES), choices=LINES, metavar="LINE")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        servers = {
            "revision": Server(tree_of(args.rev, tmp), tmp / "cache-revision"),
            "this tree": Server(REPO, tmp / "cache-this"),
        }
        loads = [os.getloadavg()[0]]
        res = {}
        for line in args.lines:
            n = max(5, args.pairs // 5) if "batch" in line else args.pairs
            a, b = [], []
            for i in range(n):
                first, second = ("revision", "this tree") if i % 2 == 0 else ("this tree", "revision")
                t = {first: servers[first].time(line), second: servers[second].time(line)}
                a.append(t["revision"])
                b.append(t["this tree"])
            res[line] = (np.array(a), np.array(b))
            loads.append(os.getloadavg()[0])
        for s in servers.values():
            s.close()
    print(
        f"revision {args.rev} against this tree: per line, runs alternated between the two trees' warm "
        f"processes ({args.pairs} pairs, batches {max(5, args.pairs // 5)}); "
        f"host load {min(loads):.2f}-{max(loads):.2f}"
    )
    print(f"{'line':24s} {args.rev + ' (ms)':>14s} {'this tree (ms)':>15s}   this / rev: median of pairs (p10-p90)")
    for line, (a, b) in res.items():
        q = b / a
        print(
            f"{line:24s} {np.median(a) * 1e3:14.3f} {np.median(b) * 1e3:15.3f}   "
            f"{np.median(q):.3f} ({np.percentile(q, 10):.3f}-{np.percentile(q, 90):.3f})"
        )


if __name__ == "__main__":
    main()
