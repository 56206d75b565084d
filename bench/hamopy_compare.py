"""HAMSTAD 5 (60 days) in wallcal and in the Python HAM code hamopy 0.4.0: CPU times, ratio, profiles.

Run: ``NUMBA_NUM_THREADS=1 PYTHONPATH=src python bench/hamopy_compare.py`` (hamopy from the ``bench`` extra:
``pip install -e .[bench]``). hamopy is GPL: a benchmark-only dependency, imported here and nowhere in src/.

Both codes get the same definition: brick 365 mm, mortar 15 mm, insulation 40 mm (hamopy's
``materials.hamstad.BM5_*``, wallcal's :func:`wallcal.moisture.cases.hamstad5_materials`), exterior air
0 degC / 80 % (h 25 W/(m2 K), beta 1.8382e-7 s/m), interior air 20 degC / 60 % (h 8, beta 5.8823e-8),
initially 25 degC / 60 %. Each code with its own discretisation: hamopy as in its own HAMSTAD 5 example
(``hamopy/examples/BM5_simul.py``: 100 + 20 + 20 finite elements, variable step of at most 900 s), wallcal as
in ``wallcal verify hamstad5`` (176 cells, steps of at most 1 h). Prints the CPU time of each (wallcal warm,
median of five runs; hamopy one run), the ratio, and the largest differences of the 60-day profiles of
temperature, relative humidity and water content.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from wallcal.moisture.cases import _hamstad5_run

T_END = 60 * 86400.0
SIZES = (0.365, 0.015, 0.040)


def run_wallcal(repeats: int = 5):
    _hamstad5_run()  # compile / load the kernels
    cpu = []
    for _ in range(repeats):
        start = time.process_time()
        res, grid, _ = _hamstad5_run()
        cpu.append(time.process_time() - start)
    return float(np.median(cpu)), res, grid


def run_hamopy():
    from hamopy import ham_library as ham
    from hamopy.algorithm import calcul
    from hamopy.classes import Boundary, Mesh, Time
    from hamopy.materials.hamstad import BM5_brick, BM5_insulation, BM5_mortar
    from hamopy.postpro import distribution

    mesh = Mesh(materials=[BM5_brick, BM5_mortar, BM5_insulation], sizes=list(SIZES), nbr_elements=[100, 20, 20])
    clim = [
        Boundary("Fourier", T=273.15, HR=0.8, h_t=25.0, h_m=1.8382e-7),
        Boundary("Fourier", T=293.15, HR=0.6, h_t=8.0, h_m=5.8823e-8),
    ]
    init = {"T": 298.15, "HR": 0.6}
    steps = Time("variable", delta_t=900, t_max=T_END, iter_max=12, delta_min=1e-3, delta_max=900)
    start = time.process_time()
    result = calcul(mesh, clim, init, steps)
    cpu = time.process_time() - start

    def profile(x):
        t = distribution(result, "T", x, T_END)
        rh = distribution(result, "HR", x, T_END)
        w = np.empty_like(x)
        edges = np.cumsum((0.0, *SIZES))
        for k, m in enumerate(mesh.materials):
            sel = (x >= edges[k]) & (x <= edges[k + 1])
            w[sel] = m.w(ham.p_c(rh[sel], t[sel]), t[sel])
        return t - 273.15, rh, w

    return cpu, profile, len(result["t"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5, help="wallcal's warm runs (median)")
    args = ap.parse_args()
    cpu_w, res, grid = run_wallcal(args.repeats)
    print(
        f"wallcal: {cpu_w:.3f} s CPU (median of {args.repeats} warm runs), {grid.dx.size} cells, "
        f"{res.stats['steps']} steps, {res.stats['newton_iterations']} Newton iterations"
    )
    try:
        cpu_h, profile, n_steps = run_hamopy()
    except Exception as exc:  # report why hamopy cannot run here, with its error
        print(f"hamopy: could not run: {type(exc).__name__}: {exc}")
        return
    print(f"hamopy 0.4.0: {cpu_h:.1f} s CPU, {n_steps} steps")
    print(f"ratio hamopy / wallcal: {cpu_h / cpu_w:.0f}x (target at least 20x)")
    # profiles at 60 days at wallcal's cell centres (each code's own interpolation)
    x = grid.x
    t_h, rh_h, w_h = profile(x)
    k = -1  # the 60-day state
    for label, mine, theirs, unit in (
        ("temperature", res.temperature[k], t_h, "K"),
        ("relative humidity", 100 * res.relative_humidity[k], 100 * rh_h, "% RH"),
        ("water content", res.water_content[k], w_h, "kg/m3"),
    ):
        d = np.abs(mine - theirs)
        i = int(np.argmax(d))
        print(f"60 days, largest difference in {label}: {d[i]:.3g} {unit} at x = {1000 * x[i]:.1f} mm")
    brick = x < SIZES[0]
    print(
        f"60 days, brick: largest relative humidity difference "
        f"{100 * np.abs(res.relative_humidity[k][brick] - rh_h[brick]).max():.2f} % RH"
    )


if __name__ == "__main__":
    main()
