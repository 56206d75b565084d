"""What the heat-only PASSYS model misses: the interior humidity step of 2014-01-08 (docs/identifiability.md,
"Real walls").

    PYTHONPATH=src python bench/passys_moisture_event.py [--figure docs/passys_moisture_event.png]

``wallcal diagnose`` of the two PASSYS studies, each as measured (no offset declared) with its last 4 days held
out: the heat-only ``examples/passys/study.toml`` (its face offset set to 0) and the heat-and-moisture
``examples/passys/study_moisture.toml``. Each adopted structure at its recalibrated optimum is then run over the
whole record, window included. Printed: the adopted extensions and values, the held-out RMSE of T_4, T_8, T_12,
and the mean residual (model - measured) of each probe over the day before the interior humidity (HR_0) crosses
0.55 and over the two days after it; and how fast the in-wall HR follows the step, measured and as diffusion
through the catalogue's and the calibrated board would give it (:func:`arrival`). The figure shows HR_0 and the
in-wall HR, and both models' temperature residuals, with the held-out window shaded. About 25 s.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from wallcal.analysis.diagnose import diagnose
from wallcal.calibration.objective import Evaluator
from wallcal.calibration.space import space_of
from wallcal.simulation import BATCH_NEEDS, prepare
from wallcal.study import PeriodSpec, load_study

BENCH = Path(__file__).resolve().parent
sys.path.insert(0, str(BENCH))

from validation_arms import study_of  # noqa: E402  (the PASSYS studies as validation_arms.py builds them)

ROOT = BENCH.parent
MOISTURE = ROOT / "examples" / "passys" / "study_moisture.toml"
PROBES = ("T_4", "T_8", "T_12")


def whole_record(d) -> pd.DataFrame:
    """Residuals (model - measured, the adopted offsets applied) of every target of a diagnosis' adopted structure
    over the whole record, held-out window included; indexed by time."""
    st = d.study
    p = st.period
    full = st.replace(period=PeriodSpec(warmup_start=p.warmup_start, start=p.start, end=p.validation_end))
    space = space_of(st)
    ev = Evaluator(prepare(full, needs=BATCH_NEEDS), space)
    x = np.array([d.x[n] for n in space.names])
    e = ev.errors(x[None])[0]
    e = np.where(ev.mask, e, np.nan)
    return pd.DataFrame(e.T, index=ev.prepared.times, columns=list(space.targets))


def rise(s: pd.Series, at: pd.Timestamp, hours: float) -> float:
    """Change of ``s`` from the hour before ``at`` to the hour ending ``hours`` after it."""
    h = pd.Timedelta("1h")
    return s[at + (hours - 1) * h : at + hours * h].mean() - s[at - h : at].mean()


def arrival(rh: pd.DataFrame, hr0: pd.Series, step: pd.Timestamp, board_c: float, layer, fitted: dict) -> None:
    """How fast the in-wall HR follows the interior step, measured and as diffusion would give it.

    Each probe's rise ``hours`` after the step, less its rise at the same time of day over the five days before
    (its daily pattern), divided by the interior face's rise: the measured fraction. A step at the face of a
    half-space under moisture diffusion of diffusivity ``D_phi`` gives ``erfc(x / (2 sqrt(D_phi t)))`` at depth
    ``x``; ``D_phi`` fitted to the measured fractions (least squares on a log grid) is the board's apparent
    moisture diffusivity, set beside ``delta_p p_sat / xi`` of the catalogue's board and of the calibrated one
    (``xi = dw/dphi`` at the board's RH, ``delta_p`` from the vapour resistance factor). Then the air flow that
    would carry the step to 8 cm in 4 h: the sorbed water holds the front back, so it moves at
    ``q rho_v,sat / xi`` for an air flux ``q`` [m3/(m2 s)] through the board."""
    from scipy.special import erfc

    from wallcal.moisture.materials import D_AIR, R_V, saturation_pressure

    depths = {"HR_4": 0.04, "HR_8": 0.08}  # m from the interior face (HR_12 follows the exterior's daily swing)
    hours = (2.0, 4.0, 8.0)
    day = pd.Timedelta("1D")
    measured = []
    print("rise of the in-wall HR after the interior step, as a fraction of HR_0's (less the daily pattern):")
    for n, x in depths.items():
        for hrs in hours:
            pattern = [rise(rh[n], step - k * day, hrs) for k in range(1, 6)]
            frac = (rise(rh[n], step, hrs) - np.mean(pattern)) / rise(hr0, step, hrs)
            measured.append((x, hrs * 3600.0, frac, np.std(pattern) / rise(hr0, step, hrs)))
            print(f"  {n} after {hrs:.0f} h: {frac:.2f} (daily pattern's sd {measured[-1][3]:.2f})")
    x, t, f = (np.array([m[i] for m in measured]) for i in range(3))
    grid = np.logspace(-10, -6, 801)
    sse = [np.sum((erfc(x / (2.0 * np.sqrt(d * t))) - f) ** 2) for d in grid]
    d_fit = grid[int(np.argmin(sse))]
    phi = float(np.mean([rh[n][step - day : step].mean() for n in depths]))
    p_sat = float(saturation_pressure(board_c))
    material = layer.hygric_material()

    def xi(scale: float) -> float:
        return scale * float(np.diff(material.water_content_from_rh([phi - 0.01, phi + 0.01]))[0]) / 0.02

    def d_phi(mu: float, scale: float) -> float:
        return D_AIR / (R_V * (board_c + 273.15)) / mu * p_sat / xi(scale)

    cat = d_phi(layer.vapour_resistance_factor, 1.0)
    fit = d_phi(fitted["vapour_resistance_factor[wood_fibre]"], fitted["sorption_scale[wood_fibre]"])
    print(
        f"apparent moisture diffusivity from the rises: {d_fit:.2g} m2/s (erfc fractions "
        + ", ".join(f"{erfc(a / (2 * np.sqrt(d_fit * b))):.2f}" for a, b in zip(x, t, strict=True))
        + f"); the catalogue's board (mu {layer.vapour_resistance_factor:g}, xi {xi(1.0):.1f} kg/m3 at RH {phi:.2f}, "
        f"{board_c:.1f} degC): {cat:.2g} m2/s, {d_fit / cat:.0f} x slower; the calibrated board (mu "
        f"{fitted['vapour_resistance_factor[wood_fibre]']:.2f}, {fitted['sorption_scale[wood_fibre]']:.2f} x the "
        f"storage): {fit:.2g} m2/s"
    )
    rho_sat = p_sat / (R_V * (board_c + 273.15))
    q = 0.08 * xi(1.0) / (rho_sat * 4 * 3600.0)
    print(
        f"air flow that would carry the step to 8 cm in 4 h through the catalogue's board: {q:.1g} m3/(m2 s) "
        f"({q * 3600:.0f} m3/(m2 h))"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figure", type=Path, help="write the figure here (PNG)")
    args = ap.parse_args(argv)
    humid = load_study(MOISTURE)
    hp = humid.period
    data = prepare(humid.replace(period=PeriodSpec(warmup_start=hp.start, start=hp.start, end=hp.validation_end)))
    rh = data.measured  # the in-wall HR as measured
    inside = data.inp.interior.relative_humidity
    at = np.asarray(data.inp.output_positions).astype(int)  # the engine's steps of the measured times
    hr0 = pd.Series(np.asarray(inside, dtype=float)[at], index=data.times)
    step = hr0[hr0 > 0.55].index[0]
    day, two = pd.Timedelta("1D"), pd.Timedelta("2D")
    print(
        f"interior RH (HR_0) crosses 0.55 at {step}: mean {hr0[step - day : step].mean():.2f} over the day before, "
        f"{hr0[step : step + two].mean():.2f} over the two days after"
    )
    rows, resid, fitted = {}, {}, {}
    for label, study in (("heat only (fd-cn)", study_of("passys0")), ("heat and moisture (ham)", humid)):
        t0 = time.perf_counter()
        d = diagnose(study, progress=False)
        fitted = d.x
        v = d.validation.set_index("sensor")["rmse"]
        e = whole_record(d)
        resid[label] = e
        before = e.loc[step - day : step, list(PROBES)].mean()
        after = e.loc[step : step + two, list(PROBES)].mean()
        rows[label] = {
            **{f"held-out {t}": v[t] for t in PROBES},
            **{f"shift {t}": after[t] - before[t] for t in PROBES},
        }
        vals = ", ".join(f"{n} = {d.x[n]:.4g}" for n in d.adopted) or "nothing"
        print(f"{label}: adopted {vals} ({time.perf_counter() - t0:.0f} s)")
    board = float(data.measured.loc[step - day : step, list(PROBES)].mean().mean())  # degC
    arrival(rh, hr0, step, board, humid.wall.layers[0], fitted)
    t = pd.DataFrame(rows).T
    print("held-out RMSE [K] and the step in the mean residual (model - measured) [K], the two days after the")
    print("interior humidity step against the day before:")
    print(t.to_string(float_format=lambda v: f"{v:+.2f}" if abs(v) < 10 else f"{v:.0f}"))
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(3, 1, figsize=(10, 8), sharex=True, constrained_layout=True)
        ax[2].sharey(ax[1])  # the two models' residuals on one scale
        ax[0].plot(hr0.index, hr0, color="k", label="HR_0 (interior face)")
        for n in ("HR_4", "HR_8", "HR_12"):
            ax[0].plot(rh.index, rh[n], label=n)
        ax[0].set_ylabel("relative humidity [-]")
        ax[0].legend(ncol=4, fontsize=8)
        for a, (label, e) in zip(ax[1:], resid.items(), strict=True):
            for n in PROBES:
                a.plot(e.index, e[n], label=n, lw=0.8)
            a.axhline(0, color="grey", lw=0.5)
            a.set_ylabel("model - measured [K]")
            a.set_title(label, fontsize=9)
            a.legend(ncol=3, fontsize=8)
        p = humid.period
        for a in ax:
            a.axvspan(p.validation_start, p.validation_end, color="0.9", zorder=0)
            a.axvline(step, color="k", ls=":", lw=0.8)
        ax[0].set_title("PASSYS as measured, each study's diagnosed structure; shaded: held out", fontsize=9)
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.figure, dpi=110)
        print(f"wrote {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
