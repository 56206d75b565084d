"""Synthetic monitoring campaigns with a known wall and known structure errors (tests of ``wallcal diagnose``).

The "true" wall runs in the fd engine on a finer grid (30 s, C = 0.5) than the study's (60 s, C = 2), driven by
the measured surface temperatures of the bundled example; its probe temperatures plus white sensor noise are the
measured probes. The study written next to them declares the nominal wall (probes at their nominal depths, no
contact resistance, constant conductivities) and a small calibration space.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from conftest import EXAMPLE

STUDY = """
[study]
name = "synthetic campaign"

[wall]
name = "nominal wall"
{layers}
[[wall.probes]]
name = "T3A"
depth = 0.10
[[wall.probes]]
name = "T2A"
depth = 0.1525
[[wall.probes]]
name = "T1A"
depth = 0.26

[data]
file = "measured.csv"
time_column = "timestamp"

[boundary.exterior]
type = "surface_temperature"
column = "TSe"

[boundary.interior]
type = "surface_temperature"
column = "TSi"

[[sensors]]
name = "T3A"
column = "T3A"
accuracy = 0.5
[[sensors]]
name = "T2A"
column = "T2A"
accuracy = 0.5
[[sensors]]
name = "T1A"
column = "T1A"
accuracy = 0.5

[period]
warmup_start = {warmup}
start = {start}
end = {end}

[simulation]
engine = "fd-cn"
time_step = 60
grid_constant = 2.0

[calibration]
targets = ["T3A", "T2A", "T1A"]
seed = 1
[calibration.settings]
particles = 8
generations = 4
{parameters}
"""

PARAMETERS = """
[[calibration.parameters]]
layers = ["3"]
property = "conductivity"
bounds = [-0.2, 0.2]
[[calibration.parameters]]
layers = ["5", "8"]
property = "conductivity"
bounds = [-0.2, 0.2]
[[calibration.parameters]]
layers = ["7"]
property = "conductivity"
bounds = [-0.5, 1.0]
"""


def _layers_toml(wall) -> str:
    out = []
    for layer in wall.layers:
        out.append(
            f'[[wall.layers]]\nid = "{layer.id}"\nthickness = {layer.thickness!r}\n'
            f"conductivity = {layer.conductivity!r}\ndensity = {layer.density!r}\n"
            f"specific_heat = {layer.specific_heat!r}\n"
        )
    return "\n".join(out)


def make_campaign(
    folder: Path,
    *,
    probe_depths: dict | None = None,
    contact: dict | None = None,
    conductivity: dict | None = None,
    coefficient: dict | None = None,
    bias: dict | None = None,
    noise: float = 0.05,
    days: float = 3.0,
    warmup_days: float = 2.0,
    seed: int = 7,
) -> Path:
    """Write ``measured.csv`` and ``study.toml`` into ``folder``; return the study's path.

    Parameters
    ----------
    probe_depths : dict, optional
        Probe name -> true depth [m] (the study declares the nominal one).
    contact : dict, optional
        Layer id -> true contact resistance to the next layer [m2K/W].
    conductivity : dict, optional
        Layer id -> true conductivity [W/(m K)] (within the study's bounds).
    coefficient : dict, optional
        Layer id -> true conductivity temperature coefficient f [1/K] (lambda(T); the study's is 0).
    bias : dict, optional
        Probe name -> constant sensor bias added to its measured series [K].
    noise : float
        Standard deviation of the white sensor noise [K].
    """
    import wallcal

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    base = wallcal.load_study(EXAMPLE)
    nominal = base.wall
    truth = nominal
    for lid, lam in (conductivity or {}).items():
        truth = truth.replace_layer(lid, conductivity=lam)
    for lid, f in (coefficient or {}).items():
        truth = truth.replace_layer(lid, conductivity_temperature_coefficient=f)
    for lid, r in (contact or {}).items():
        truth = truth.replace_layer(lid, contact_resistance=r)
    for name, d in (probe_depths or {}).items():
        truth = truth.replace_probe(name, depth=d)
    t0 = pd.Timestamp(base.period.warmup_start)
    start = t0 + pd.Timedelta(days=warmup_days)
    end = start + pd.Timedelta(days=days)
    # the truth runs over the whole record (its own warm-up is the first 2 days of the example's)
    run = base.replace(
        period=base.period.__class__(warmup_start=t0 - pd.Timedelta(days=0), start=t0, end=end),
        sensors=tuple(s for s in base.sensors if s.quantity == "temperature"),
    )
    res = wallcal.simulate(run, wall=truth, time_step=30.0, grid_constant=0.5)
    meas = pd.read_csv(Path(EXAMPLE).parent / "measured.csv", parse_dates=["timestamp"]).set_index("timestamp")
    meas = meas.loc[t0:end, ["TSe", "TSi"]]
    rng = np.random.default_rng(seed)
    for name in ("T3A", "T2A", "T1A"):
        sim = res.simulated[name].reindex(meas.index)
        meas[name] = sim.to_numpy() + (bias or {}).get(name, 0.0) + noise * rng.standard_normal(len(meas))
    meas.index.name = "timestamp"
    meas.reset_index().to_csv(
        folder / "measured.csv", index=False, float_format="%.4f", date_format="%Y-%m-%dT%H:%M:%S"
    )
    text = STUDY.format(
        layers=_layers_toml(nominal),
        warmup=(start - pd.Timedelta(days=warmup_days)).isoformat(),
        start=start.isoformat(),
        end=end.isoformat(),
        parameters=PARAMETERS,
    )
    path = folder / "study.toml"
    path.write_text(text)
    return path
