"""Interleaved A/B of the engine's optimisations against the simpler code, on the user-felt lines.

Run:  PYTHONPATH=src .venv/bin/python bench/ab_engine.py [--rounds N]

Each round times every variant of a line once, in alternating order, in one process (the host is
shared and its speed drifts); the table gives per-variant medians and the median of the per-round
ratios variant / baseline. A trick stays when it buys >= 15 % on a line a user feels.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"


def interleaved(fns: dict, rounds: int) -> dict:
    for fn in fns.values():
        fn()  # compile / warm up
    ts = {k: [] for k in fns}
    keys = list(fns)
    for r in range(rounds):
        order = keys if r % 2 == 0 else keys[::-1]
        for k in order:
            t = time.perf_counter()
            fns[k]()
            ts[k].append(time.perf_counter() - t)
    return {k: np.array(v) for k, v in ts.items()}


def report(line: str, ts: dict, base: str) -> None:
    print(f"\n{line}")
    for k, v in ts.items():
        ratio = np.median(v / ts[base])
        print(f"  {k:44s} median {np.median(v) * 1e3:9.3f} ms   per-round ratio to {base!r}: {ratio:5.2f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rounds", type=int, default=40)
    args = ap.parse_args(argv)

    import wallcal
    from wallcal.engines.fd import FDEngine
    from wallcal.grid import PropertyArrays
    from wallcal.simulation import prepare

    study = wallcal.load_study(EXAMPLE)
    data = prepare(study)
    eng = FDEngine("cn")
    prep = eng.prepare(data.inp)
    one = PropertyArrays.from_walls([study.wall])
    rng = np.random.default_rng(1)
    walls = []
    for _ in range(256):
        w = study.wall
        for layer in w.layers:
            f = 1 + 0.2 * rng.uniform(-1, 1, 3)
            w = w.replace_layer(
                layer.id,
                conductivity=layer.conductivity * f[0],
                density=layer.density * f[1],
                specific_heat=layer.specific_heat * f[2],
            )
        walls.append(w)
    batch = PropertyArrays.from_walls(walls)
    targets = np.zeros(len(prep.probe_names) + 2, dtype=bool)
    targets[: len(prep.probe_names)] = True
    nl_wall = study.wall
    for lid in ("3", "5", "7", "8"):
        nl_wall = nl_wall.replace_layer(lid, conductivity_temperature_coefficient=0.0046)
    nl_prep = eng.prepare(data.with_wall(nl_wall).inp)
    nl_one = PropertyArrays.from_walls([nl_wall])

    def with_variant(p, v, fn):
        def call():
            p._variant = v
            fn()

        return call

    solves = {"reduction (pcr.py)": 0, "twisted LU": 1, "plain LU, pivots folded": 3}
    ts = interleaved(
        {k: with_variant(nl_prep, v, lambda: nl_prep.run_batch(nl_one)) for k, v in solves.items()}, args.rounds
    )
    report("lambda(T) run (general path): tridiagonal solve", ts, "plain LU, pivots folded")
    ts = interleaved(
        {k: with_variant(prep, v, lambda: prep.run_batch(one, path="general")) for k, v in solves.items()},
        args.rounds,
    )
    report("one simulation, general path (constant lambda): tridiagonal solve", ts, "plain LU, pivots folded")
    ts = interleaved(
        {
            "short polynomials while in range": with_variant(nl_prep, 0, lambda: nl_prep.run_batch(nl_one)),
            "long polynomials only": with_variant(nl_prep, 4, lambda: nl_prep.run_batch(nl_one)),
        },
        args.rounds,
    )
    report("lambda(T) run: short polynomials of a step", ts, "long polynomials only")
    ts = interleaved(
        {
            "three-row fused pass": with_variant(prep, 0, lambda: prep.run_batch(batch, rows=targets)),
            "five-row fused pass only": with_variant(prep, 1, lambda: prep.run_batch(batch, rows=targets)),
        },
        max(5, args.rounds // 4),
    )
    report("calibration batch of 256 (3 target rows, modal): fused pass", ts, "five-row fused pass only")
    ts = interleaved(
        {
            "three-row fused pass": with_variant(prep, 0, lambda: prep.run_batch(one, rows=targets)),
            "five-row fused pass only": with_variant(prep, 1, lambda: prep.run_batch(one, rows=targets)),
        },
        args.rounds,
    )
    report("one calibration candidate (3 target rows, modal): fused pass", ts, "five-row fused pass only")


if __name__ == "__main__":
    main()
