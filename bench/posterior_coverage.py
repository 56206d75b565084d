"""Coverage of the posterior's intervals, measured on synthetic campaigns whose true wall is known (issue 19).

For each campaign the study's parameter space (18 parameters: lambda, rho, c of six layer groups) is
calibrated and sampled; the identifiable combinations of the posterior (``posterior_combinations``:
diffusivities, resistances, conductivity ratios, rho*c, R_total; those with a verdict "identified" or
"weakly identified") are compared with the true wall's. The figures: the fraction of true values inside the
50 % and 95 % intervals, per campaign and over all, without and with ``wallcal diagnose`` (the study's structure
extended by the extensions the data support, then calibrated and sampled again), and what the posterior's
self-check said about the structure.

Campaigns (their walls and errors are printed):

- ``visible``: the EnergyPlus-made campaign of ../shared/data/campaign_visible (truth.json; no structure
  error, but EnergyPlus CondFD against wallcal's grid);
- ``offset``, ``contact``, ``lambdaT``, ``all``: made here with the fd engine on a fine grid (time step 20 s,
  grid constant 0.5; the calibration runs at the study's 60 s and C = 2) from the true wall of campaign A with
  a probe 6 mm off its nominal depth, a contact resistance between layers 3 and 4, lambda(T) in the mineral
  wool, or all three, under three kinds of boundary weather, and the campaign's sensor error model
  (thermocouples bias U(-0.3, 0.3) degC + N(0, 0.1); PT100 U(-0.15, 0.15) + N(0, 0.05); heat-flux meters
  gain U(-3 %, 3 %) + N(0, 0.3) W/m2; rounded to 0.01).

    nice .venv/bin/python bench/posterior_coverage.py                  # all campaigns, both arms
    nice .venv/bin/python bench/posterior_coverage.py --campaigns visible offset --steps 600 --no-diagnose
    nice .venv/bin/python bench/posterior_coverage.py --steps 1000 --no-without     # only the 'with diagnose' arm
    nice .venv/bin/python bench/posterior_coverage.py --hold-out 2 --no-diagnose --tempering sandwich  # + bands

Also timed: the posterior of a 22-parameter space on the ``all`` campaign, ``--speed`` (target: under 2 minutes on
2 cores): ``--speed-space lambdaT`` (the study's 18 plus a probe depth, a contact resistance and two lambda(T)
coefficients) or ``linear`` (18 plus a probe depth, two contact resistances and a sensor offset).
"""

from __future__ import annotations

import argparse
import json
import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

import wallcal
from wallcal.analysis.posterior import posterior
from wallcal.calibration import calibrate
from wallcal.simulation import BATCH_NEEDS, prepare
from wallcal.wallfile import dump_wall, load_wall

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "src" / "wallcal" / "examples" / "campaign_a"
VISIBLE = ROOT.parent / "shared" / "data" / "campaign_visible"

# the campaign's sensor error model (truth.json of campaign A): (bias half-width or gain half-width, noise sd)
ERRORS = {
    "TSe": ("bias", 0.15, 0.05),
    "TSi": ("bias", 0.15, 0.05),
    "T3A": ("bias", 0.3, 0.1),
    "T2A": ("bias", 0.3, 0.1),
    "T1A": ("bias", 0.3, 0.1),
    "qe": ("gain", 0.03, 0.3),
    "qi": ("gain", 0.03, 0.3),
}
MINERAL_WOOL = ("3", "5", "7", "8")


@dataclass(frozen=True)
class Campaign:
    name: str
    weather: str
    probe_offset: float = 0.0  # T3A's true depth minus its nominal one [m]
    contact_34: float = 0.0  # true contact resistance between layers 3 and 4 [m2K/W]
    lambda_coefficient: float = 0.0  # true f [1/K] of the mineral wool layers (lambda(T), ISO 10456 law)
    seed: int = 0


CAMPAIGNS = {
    "offset": Campaign("offset", "recorded", probe_offset=-0.006, seed=11),
    "contact": Campaign("contact", "winter", contact_34=0.12, seed=12),
    "lambdaT": Campaign("lambdaT", "overcast", lambda_coefficient=0.006, seed=13),
    "all": Campaign("all", "winter", probe_offset=-0.005, contact_34=0.08, lambda_coefficient=0.005, seed=14),
}


def weather(frame: pd.DataFrame, kind: str) -> pd.DataFrame:
    """The true surface temperatures TSe, TSi [degC] of a campaign from campaign A's record.

    ``recorded``: as recorded (late May, SSE facade, Chicago TMY3); ``winter``: the exterior surface 15 K colder
    with 1.3 times its swings about the mean, the interior held near 20 degC (half its swings); ``overcast``: the
    exterior surface averaged over 6 h (slower, weaker forcing), 3 K warmer.
    """
    f = frame.copy()
    te, ti = f["TSe"].astype(float), f["TSi"].astype(float)
    if kind == "winter":
        f["TSe"] = te.mean() - 15.0 + 1.3 * (te - te.mean())
        f["TSi"] = 20.0 + 0.5 * (ti - ti.mean())
    elif kind == "overcast":
        f["TSe"] = te.rolling(72, center=True, min_periods=1).mean() + 3.0
    elif kind != "recorded":
        raise ValueError(kind)
    return f


def true_wall(c: Campaign):
    """Campaign A's true wall with the campaign's structure errors (layers 3..9, probes at their true depths)."""
    base = wallcal.load_study(EXAMPLE / "study.toml").wall
    ref = load_wall(EXAMPLE / "true_wall.toml")
    wall = base.replace(layers=ref.layers)
    if c.contact_34:
        wall = wall.replace_layer("3", contact_resistance=c.contact_34)
    if c.lambda_coefficient:
        for lid in MINERAL_WOOL:
            wall = wall.replace_layer(lid, conductivity_temperature_coefficient=c.lambda_coefficient)
    if c.probe_offset:
        wall = wall.replace_probe("T3A", depth=wall.probe("T3A").depth + c.probe_offset)
    return wall


def study_text(data_file: str, reference_wall: str) -> str:
    """The bundled example's study (base-case wall, 18-parameter space) on another data file and reference wall."""
    text = (EXAMPLE / "study.toml").read_text()
    text = re.sub(r'(?m)^file = "measured.csv"', f'file = "{data_file}"', text)
    text = re.sub(r'(?m)^reference_wall = "true_wall.toml"', f'reference_wall = "{reference_wall}"', text)
    return text.split("\n[retrofit]")[0]


def make_campaign(c: Campaign, folder: Path) -> Path:
    """Write a synthetic campaign (measured.csv, true_wall.toml, study.toml) into ``folder``; returns the study."""
    folder.mkdir(parents=True, exist_ok=True)
    frame = pd.read_csv(EXAMPLE / "measured.csv")
    truth = weather(frame, c.weather)
    truth.to_csv(folder / "measured.csv", index=False, float_format="%.4f")
    wall = true_wall(c)
    (folder / "true_wall.toml").write_text(dump_wall(wall, f"true wall of the synthetic campaign {c.name}"))
    (folder / "study.toml").write_text(study_text("measured.csv", "true_wall.toml"))
    study = wallcal.load_study(folder / "study.toml")
    sim = wallcal.simulate(study, "fd-cn", time_step=20.0, grid_constant=0.5, wall=wall).simulated
    rng = np.random.default_rng(c.seed)
    out = truth.copy()
    ts = pd.to_datetime(out["timestamp"])
    for name, (kind, size, sd) in ERRORS.items():
        x = out[name].to_numpy(dtype=float) if name in ("TSe", "TSi") else _at(sim, name, ts)
        draw = rng.uniform(-size, size)
        x = x + draw if kind == "bias" else x * (1.0 + draw)
        out[name] = np.round(x + rng.normal(0.0, sd, len(x)), 2)
    # the warm-up days carry no simulated targets (the engine starts there): keep the truth's boundary only
    out.to_csv(folder / "measured.csv", index=False, float_format="%.2f")
    return folder / "study.toml"


def _at(sim: pd.DataFrame, name: str, ts: pd.Series) -> np.ndarray:
    s = sim[name].reindex(pd.DatetimeIndex(ts))
    return s.to_numpy(dtype=float)


# the two extensions both 22-parameter spaces add to the study's 18 parameters
_PROBE_AND_CONTACT = """
[[calibration.parameters]]
probe = "T3A"
property = "depth"
bounds = [0.085, 0.115]

[[calibration.parameters]]
layers = ["3"]
property = "contact_resistance"
bounds = [0.0, 0.3]
bounds_kind = "absolute"
"""

EXTENSIONS_22 = (
    _PROBE_AND_CONTACT
    + """
[[calibration.parameters]]
layers = ["3"]
property = "conductivity_temperature_coefficient"
bounds = [-0.01, 0.02]
bounds_kind = "absolute"

[[calibration.parameters]]
layers = ["5", "8"]
property = "conductivity_temperature_coefficient"
bounds = [-0.01, 0.02]
bounds_kind = "absolute"
"""
)

LINEAR_22 = (
    _PROBE_AND_CONTACT
    + """
[[calibration.parameters]]
layers = ["5"]
property = "contact_resistance"
bounds = [0.0, 0.3]
bounds_kind = "absolute"

[[calibration.parameters]]
sensor = "T1A"
property = "offset"
bounds = [-1.0, 1.0]
"""
)


def study_of(name: str, workdir: Path) -> Path:
    """The study file of campaign ``name`` (made in ``workdir`` for the synthetic ones)."""
    if name == "visible":
        folder = workdir / "visible"
        folder.mkdir(parents=True, exist_ok=True)
        truth = json.loads((VISIBLE / "truth.json").read_text())["true_wall"]
        base = wallcal.load_study(EXAMPLE / "study.toml").wall
        layers = tuple(
            layer.replace(conductivity=t["lambda"], density=t["rho"], specific_heat=t["c"])
            for layer, t in zip(base.layers, truth["layers"], strict=True)
        )
        (folder / "true_wall.toml").write_text(dump_wall(base.replace(layers=layers), "truth.json of campaign_visible"))
        data = (VISIBLE / "measured.csv").resolve()
        (folder / "study.toml").write_text(study_text(str(data), "true_wall.toml"))
        return folder / "study.toml"
    return make_campaign(CAMPAIGNS[name], workdir / name)


def hold_out(path: Path, days: float) -> None:
    """Give the study file at ``path`` a held-out validation window: the last ``days`` of its period (the posterior
    then predicts it: ``predictive`` in the rows, coverage and width of the 95 % band per sensor)."""
    text = path.read_text()
    end = pd.Timestamp(re.search(r"(?m)^end = (\S+)", text).group(1))
    start = (end - pd.Timedelta(days=days)).isoformat()
    text = re.sub(
        r"(?m)^(end = \S+)",
        lambda m: f"{m.group(1)}\nvalidation_start = {start}\nvalidation_end = {end.isoformat()}",
        text,
        count=1,
    )
    path.write_text(text)


def diagnose_or_none():
    """``wallcal.analysis.diagnose.diagnose`` when this wallcal has it, else None."""
    try:
        from wallcal.analysis.diagnose import diagnose
    except ImportError:
        return None
    return diagnose


def sample(study, temperings, steps, walkers, missing=(), label="", start=None):
    """Calibrate ``study`` (unless a ``start`` {name: value} is given) and sample its posterior with each
    tempering; one row per tempering."""
    prep = prepare(study, needs=BATCH_NEEDS)
    t = time.perf_counter()
    names = [p.name for p in study.calibration.parameters]
    if start is None or any(n not in start for n in names):
        x0 = calibrate(study, progress=False, prepared=prep).x_opt
    else:
        x0 = np.array([start[n] for n in names])
    t_cal = time.perf_counter() - t
    rows = []
    for temp in temperings:
        t = time.perf_counter()
        r = posterior(
            study,
            x_start=x0,
            prepared=prep,
            walkers=walkers,
            steps=steps,
            progress=False,
            tempering=temp,
            missing_extensions=missing,
            nonunique_candidates=64,
        )
        c = r.combination_coverage()
        rows.append(
            {
                "arm": label,
                "tempering": temp,
                "parameters": r.space.n,
                "n": c["n"],
                "inside 50%": c["inside 50%"],
                "inside 95%": c["inside 95%"],
                "w": r.tempering["weight"],
                "rejected": r.structure["rejected"],
                "reasons": len(r.structure["reasons"]),
                "calibration s": t_cal,
                "posterior s": time.perf_counter() - t,
                "acceptance": r.acceptance,
                "tau max": float(np.nanmax(r.tau)),
                "effective samples": effective_samples(r),
                "steps": r.chain.shape[0],
                "adequate": r.adequate,
                "missed": ", ".join(
                    r.combinations.index[
                        ~r.combinations["verdict"].str.startswith("not") & ~r.combinations["inside 95%"].astype(bool)
                    ]
                ),
                "structure": r.structure["statement"],
                "predictive": "" if r.predictive is None else bands(study, prep, r),
            }
        )
    return rows


def bands(study, prep, r) -> str:
    """The held-out window's coverage_95 (band_width_95) per sensor: the posterior's band, then the same chain's
    band from its in-sample errors alone (``out_of_sample=False``)."""
    from wallcal.analysis.posterior_predictive import predictive
    from wallcal.calibration.objective import Evaluator
    from wallcal.calibration.space import space_of

    plain = predictive(study, r.space, r.samples, Evaluator(prep, space_of(study)), out_of_sample=False)
    p = plain.table.set_index("sensor")
    return "; ".join(
        f"{q.sensor} {q.coverage_95:.3f} ({q.band_width_95:.3g}), in-sample {p.loc[q.sensor, 'coverage_95']:.3f} "
        f"({p.loc[q.sensor, 'band_width_95']:.3g})"
        for q in r.predictive.table.itertuples()
    )


def effective_samples(r) -> float:
    """Effective posterior samples of a chain: walkers x steps after burn-in / the largest autocorrelation time."""
    return r.effective_samples


def coverage(
    names,
    temperings,
    steps,
    walkers,
    with_diagnose: bool,
    workdir: Path,
    start_at: str = "diagnose",
    without_diagnose: bool = True,
    hold_out_days: float | None = None,
) -> pd.DataFrame:
    diagnose = diagnose_or_none() if with_diagnose else None
    if with_diagnose and diagnose is None:
        print("wallcal.analysis.diagnose is not available in this wallcal: the 'with diagnose' arm is skipped")
    rows = []
    for name in names:
        path = study_of(name, workdir)
        if hold_out_days:
            hold_out(path, hold_out_days)
        study = wallcal.load_study(path)
        adopted = []
        d = None
        if diagnose is not None:
            t = time.perf_counter()
            d = diagnose(study)
            adopted = list(d.adopted)
            print(f"{name}: diagnose adopted {adopted or 'nothing'} in {time.perf_counter() - t:.0f} s", flush=True)
        if without_diagnose or d is None:
            for row in sample(study, temperings, steps, walkers, missing=adopted, label="without diagnose"):
                rows.append({"campaign": name, **row})
                _show(rows[-1])
        if d is not None:
            start = d.x if start_at == "diagnose" else None
            for row in sample(d.study, temperings, steps, walkers, label="with diagnose", start=start):
                rows.append({"campaign": name, "adopted": ", ".join(adopted), **row})
                _show(rows[-1])
    return pd.DataFrame(rows)


def _show(r: dict) -> None:
    print(
        f"{r['campaign']:8s} {r['arm']:17s} tempering {r['tempering']:8s} ({r['parameters']} parameters, "
        f"w {r['w']:.3f}): 50 % {r['inside 50%']}/{r['n']}, 95 % {r['inside 95%']}/{r['n']}; "
        f"structure {'REJECTED' if r['rejected'] else 'not rejected'} ({r['reasons']} reasons); "
        f"calibration {r['calibration s']:.0f} s, posterior {r['posterior s']:.0f} s (acceptance "
        f"{r['acceptance']:.2f}, {r['steps']} steps, autocorrelation time {r['tau max']:.0f} steps, "
        f"{r['effective samples']:.0f} effective samples, chain {'adequate' if r['adequate'] else 'NOT adequate'})",
        flush=True,
    )
    if r["missed"]:
        print(f"         missed at 95 %: {r['missed']}", flush=True)
    if r["predictive"]:
        print(f"         held-out window, coverage of the 95 % band (its width): {r['predictive']}", flush=True)


def totals(df: pd.DataFrame) -> pd.DataFrame:
    g = df.groupby(["arm", "tempering"])[["n", "inside 50%", "inside 95%"]].sum()
    g["fraction in 50%"] = g["inside 50%"] / g["n"]
    g["fraction in 95%"] = g["inside 95%"] / g["n"]
    rej = df.groupby(["arm", "tempering"])["rejected"].sum()
    g["structure rejected (campaigns)"] = rej
    return g


def speed(
    workdir: Path, walkers: int | None, steps: int | None, space: str, campaign: str = "all", seed: int = 1
) -> None:
    """Time the posterior of a 22-parameter space on a campaign (default ``all``; starting at its calibrated optimum):
    ``lambdaT`` (the study's 18 + a probe depth, a contact resistance, two lambda(T) coefficients: every
    candidate wall is nonlinear, the engine's general path) or ``linear`` (18 + a probe depth, two contact
    resistances, a sensor offset: the modal fast path)."""
    folder = f"speed-{space}" if campaign == "all" else f"speed-{campaign}-{space}"
    path = make_campaign(CAMPAIGNS[campaign], workdir / folder)
    text = path.read_text() + (EXTENSIONS_22 if space == "lambdaT" else LINEAR_22)
    path.write_text(text)
    study = wallcal.load_study(path)
    prep = prepare(study, needs=BATCH_NEEDS)
    cal = calibrate(study, progress=False, prepared=prep)
    posterior(study, x_start=cal.x_opt, prepared=prep, walkers=walkers, steps=4, progress=False, tempering="none")
    t = time.perf_counter()
    r = posterior(study, x_start=cal.x_opt, prepared=prep, walkers=walkers, steps=steps, progress=False, seed=seed)
    dt = time.perf_counter() - t
    kind = "lambda(T) walls: the engine's general path" if space == "lambdaT" else "linear walls: the modal path"
    ess = effective_samples(r)
    ok = "OK" if dt <= 120 and r.adequate else "SLOW" if r.adequate else "NOT ADEQUATE"
    print(
        f"posterior of a {r.space.n}-parameter space ({kind}; campaign {campaign}): "
        f"{r.chain.shape[1]} walkers x {r.chain.shape[0]} steps = {r.evaluations} proposals, {r.simulations} "
        f"simulated (the rest outside the prior box) in {dt:.1f} s ({r.evaluations / dt:.0f} proposals/s, "
        f"{r.simulations / dt:.0f} simulations/s) -> {ok} (target: adequate in 120 s); seed {seed}, acceptance "
        f"{r.acceptance:.2f}, autocorrelation time {np.nanmax(r.tau):.0f} steps, burn-in {r.burn}, {ess:.0f} "
        f"effective samples ({ess / dt:.1f}/s), chain {'adequate' if r.adequate else 'NOT adequate'}"
    )
    print(r.report())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaigns", nargs="+", default=["visible", *CAMPAIGNS])
    ap.add_argument("--tempering", nargs="+", default=["none", "sandwich"], choices=("none", "sandwich"))
    ap.add_argument(
        "--steps", type=int, help="steps per posterior (default the posterior's: until the chain is adequate)"
    )
    ap.add_argument("--walkers", type=int, help="default the posterior's (4 per sampled coordinate)")
    ap.add_argument("--no-diagnose", action="store_true")
    ap.add_argument(
        "--no-without", action="store_true", help="skip the 'without diagnose' arm (only the study diagnose writes)"
    )
    ap.add_argument(
        "--start",
        choices=("diagnose", "calibrate"),
        default="diagnose",
        help="start the 'with diagnose' posterior at diagnose's recalibrated optimum, or calibrate its study afresh",
    )
    ap.add_argument("--speed", action="store_true", help="only time the 22-parameter posterior")
    ap.add_argument("--speed-steps", type=int, help="default the posterior's (until the chain is adequate)")
    ap.add_argument("--speed-walkers", type=int, help="default the posterior's (4 per sampled coordinate)")
    ap.add_argument("--speed-seed", type=int, default=1, help="the timed posterior's seed")
    ap.add_argument("--speed-space", choices=("lambdaT", "linear"), default="lambdaT")
    ap.add_argument(
        "--speed-campaign",
        choices=tuple(CAMPAIGNS),
        default="all",
        help="the campaign whose posterior --speed times (all: its structure is not the space's)",
    )
    ap.add_argument(
        "--hold-out",
        type=float,
        metavar="DAYS",
        help="hold out the last DAYS of each campaign's period (fitted on the rest) and report the posterior "
        "predictive band's coverage there",
    )
    ap.add_argument("--workdir", help="keep the synthetic campaigns here (default: a temporary folder)")
    ap.add_argument("--csv", help="write the per-campaign rows here")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(args.workdir or tmp)
        if args.speed:
            args_ = (args.speed_walkers, args.speed_steps, args.speed_space, args.speed_campaign, args.speed_seed)
            speed(workdir, *args_)
            return
        print(
            f"settings: {args.walkers or '4 per sampled coordinate'} walkers x "
            f"{args.steps or 'until adequate'} steps per posterior, "
            f"temperings {args.tempering}, "
            f"campaigns {args.campaigns}, calibration: the study's pso-hj; the 'with diagnose' arm starts at "
            f"{'diagnose' + chr(39) + 's recalibrated optimum' if args.start == 'diagnose' else 'a fresh calibration'}"
        )
        df = coverage(
            args.campaigns,
            args.tempering,
            args.steps,
            args.walkers,
            not args.no_diagnose,
            workdir,
            args.start,
            without_diagnose=not args.no_without,
            hold_out_days=args.hold_out,
        )
        if args.csv:
            df.to_csv(args.csv, index=False)
        print()
        print(totals(df).to_string(float_format=lambda v: f"{v:.2f}"))


if __name__ == "__main__":
    main()
