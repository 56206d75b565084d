"""Sensitivity of the results to the numerical grid (the paper's Fig. 4).

For every time step dt and grid constant C = dx^2 / (alpha dt) the study's wall is
simulated against the measurements; the RMSE of each target is tabulated against
dt for each C. The finest setting (smallest dt, smallest C) is the reference; a
setting is *converged* when, for every target, its RMSE differs from the finest
one's by at most ``tolerance`` (in the target's unit: degC or W/m2). The
recommended setting is the cheapest converged one (cost ~ nodes x steps).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

DEFAULT_TIME_STEPS = (60.0, 120.0, 300.0, 600.0, 900.0, 1800.0)
DEFAULT_GRID_CONSTANTS = (1.0, 2.0, 3.0)
#: default tolerance on |RMSE - RMSE_finest| [target unit: degC or W/m2]
DEFAULT_TOLERANCE = 0.01


@dataclass
class GridStudyResult:
    """Outcome of :func:`grid_study`.

    Attributes
    ----------
    table : DataFrame
        Long format: ``time_step`` [s], ``grid_constant``, ``target``, ``rmse`` [unit], ``deviation`` (RMS of the
        simulated series minus the finest setting's [unit]), ``nodes``, ``seconds``.
    targets : list of str
    tolerance : float
    finest : (dt, C)
    recommended : (dt, C) or None
        Cheapest setting within tolerance of the finest for every target.
    engine : str
        The engine that ran.
    note : str
        Why it is not the engine asked for (empty when it is).
    """

    study: object
    table: pd.DataFrame
    targets: list
    tolerance: float
    finest: tuple
    recommended: tuple | None
    units: dict
    engine: str = "fd-cn"
    note: str = ""

    def rmse_table(self) -> pd.DataFrame:
        """RMSE with one row per time step and one column per (target, C) (Fig. 4 as numbers)."""
        w = self.table.pivot_table(index="time_step", columns=["target", "grid_constant"], values="rmse")
        w.columns = [f"{t} C={c:g}" for t, c in w.columns]
        return w[[f"{t} C={c:g}" for t in self.targets for c in sorted(self.table["grid_constant"].unique())]]

    def convergence(self) -> pd.DataFrame:
        """Per setting: largest |RMSE - finest| over the targets, spread over C at that dt, cost, within tolerance."""
        t = self.table.copy()
        fin = t[(t.time_step == self.finest[0]) & (t.grid_constant == self.finest[1])].set_index("target")["rmse"]
        t["diff"] = (t["rmse"] - t["target"].map(fin)).abs()
        g = t.groupby(["time_step", "grid_constant"])
        out = pd.DataFrame(
            {
                "max |dRMSE|": g["diff"].max(),
                "max deviation": g["deviation"].max(),
                "nodes": g["nodes"].first(),
                "seconds": g["seconds"].first(),
            }
        )
        spread = t.groupby(["time_step", "target"])["rmse"].agg(lambda s: s.max() - s.min()).groupby("time_step").max()
        out["spread over C"] = out.index.get_level_values("time_step").map(spread)
        out["within tolerance"] = out["max |dRMSE|"] <= self.tolerance
        return out

    def summary(self) -> str:
        conv = self.convergence()
        spread = conv.groupby(level="time_step")["spread over C"].first()
        lines = [
            f"finest setting dt = {self.finest[0]:g} s, C = {self.finest[1]:g}; tolerance {self.tolerance:g} "
            "(|RMSE - finest RMSE|, target units)"
        ]
        if self.recommended:
            lines.append(
                f"coarsest (cheapest) setting within tolerance for every target: dt = "
                f"{self.recommended[0]:g} s, C = {self.recommended[1]:g}"
            )
        else:
            lines.append("no setting other than the finest is within tolerance")
        if self.note:
            lines.append(self.note)
        dts = spread.index.to_numpy()
        lines.append(
            "spread of the RMSE over C at each time step (largest over targets): "
            + ", ".join(f"{dt:g} s: {v:.3g}" for dt, v in zip(dts, spread.to_numpy(), strict=True))
        )
        if len(dts) > 1:
            trend = "converge" if spread.iloc[0] < spread.iloc[-1] else "do not converge"
            lines.append(
                f"the curves for the different C {trend} as the time step goes to "
                f"{dts[0]:g} s (the paper's Fig. 4 finding)"
            )
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "targets": self.targets,
            "tolerance": self.tolerance,
            "finest": list(self.finest),
            "recommended": list(self.recommended) if self.recommended else None,
            "units": self.units,
            "engine": self.engine,
            "summary": self.summary(),
        }

    def write_into(self, d: Path) -> None:
        d = Path(d)
        self.table.to_csv(d / "grid_study.csv", index=False, float_format="%.6g")
        self.rmse_table().to_csv(d / "rmse_vs_time_step.csv", float_format="%.6g")
        self.convergence().to_csv(d / "convergence.csv", float_format="%.6g")
        (d / "grid_study.json").write_text(json.dumps(self.to_json(), indent=2, default=float))
        from .plots import plot_grid_study

        plot_grid_study(self, d / "grid_study.png")


def grid_study(
    study,
    time_steps=DEFAULT_TIME_STEPS,
    grid_constants=DEFAULT_GRID_CONSTANTS,
    *,
    targets=None,
    tolerance: float = DEFAULT_TOLERANCE,
    engine: str | None = None,
    wall=None,
    progress: bool = True,
) -> GridStudyResult:
    """RMSE of each target against the time step for each grid constant.

    Parameters
    ----------
    study : Study
    time_steps : sequence of float
        [s]
    grid_constants : sequence of float
        C = dx^2 / (alpha dt) [-]
    targets : list of str, optional
        Sensors to report; default every sensor of the study.
    tolerance : float
        Allowed |RMSE - RMSE of the finest setting| [target unit].
    engine : str, optional
        Default the study's; an engine that refuses some of the time steps (EnergyPlus: 60, 120 and
        180 s only) is replaced by its substitute (``fd-cn``), and the result's ``note`` says so.
    wall : Wall, optional
        Simulate this wall instead of the study's.
    progress : bool

    Returns
    -------
    GridStudyResult
    """
    from ..calibration.algorithms import Progress
    from ..data import load_measurements
    from ..errors import StudyError
    from ..simulation import prepare, result_from_output, simulate

    time_steps = sorted({float(x) for x in time_steps})
    grid_constants = sorted({float(x) for x in grid_constants})
    bad = [f"time step {x:g} must be > 0" for x in time_steps if not x > 0]
    bad += [f"grid constant {x:g} must be > 0" for x in grid_constants if not x > 0]
    if bad or not time_steps or not grid_constants:
        raise StudyError(bad or ["give at least one time step and one grid constant"])
    from ..engines import engine_class, engine_for

    choice = engine_for(engine or study.simulation.engine, time_steps=time_steps, purpose="the grid study")
    engine = choice.name
    names = [s.name for s in study.sensors]
    targets = list(targets or names)
    unknown = [t for t in targets if t not in names]
    if unknown:
        from ..errors import closest

        raise StudyError([f"--targets: {t!r} is not a sensor; {closest(t, names)}" for t in unknown])
    meas = load_measurements(study)
    prog = Progress("grid-study", enabled=progress)
    rows, series = [], {}
    settings = [(dt, C) for C in grid_constants for dt in time_steps]
    batch = {}
    if not engine_class(engine).capabilities.batches:
        # one run per setting, seconds each (EnergyPlus): every setting at once on the executor
        preps = [prepare(study, engine, time_step=dt, grid_constant=C, measurements=meas) for dt, C in settings]
        preps = [p.with_wall(wall) if wall is not None else p for p in preps]
        outs = preps[0].engine.run_inputs([p.inp for p in preps])
        batch = {s: (p, o) for s, p, o in zip(settings, preps, outs, strict=True)}
    for i, (dt, C) in enumerate(settings):
        prog.update(f"dt {dt:g} s, C {C:g} ({i + 1}/{len(settings)})")
        if (dt, C) in batch:
            prep, out = batch[(dt, C)]
            res = result_from_output(prep, out, engine)
            sec = float(out.info.get("seconds", float("nan")))
        else:
            prep = prepare(study, engine, time_step=dt, grid_constant=C, measurements=meas)
            t0 = time.perf_counter()
            res = simulate(study, engine, prepared=prep, wall=wall)
            sec = time.perf_counter() - t0
        met = res.metrics.set_index("signal")
        series[(dt, C)] = res.simulated
        for t in targets:
            rows.append(
                {
                    "time_step": dt,
                    "grid_constant": C,
                    "target": t,
                    "rmse": float(met.loc[t, "rmse"]),
                    "nodes": int(res.info.get("nodes", 0) or 0),
                    "seconds": sec,
                }
            )
    prog.close(f"{len(settings)} settings simulated")
    finest = (time_steps[0], grid_constants[0])
    ref = series[finest]
    table = pd.DataFrame(rows)
    table["deviation"] = [
        float(np.sqrt(np.nanmean((series[(r.time_step, r.grid_constant)][r.target] - ref[r.target]) ** 2)))
        for r in table.itertuples()
    ]
    units = {t: ("W/m2" if study.sensor(t).quantity == "heat_flux" else "degC") for t in targets}
    out = GridStudyResult(
        study=study,
        table=table,
        targets=targets,
        tolerance=float(tolerance),
        finest=finest,
        recommended=None,
        units=units,
        engine=engine,
        note=choice.note,
    )
    conv = out.convergence()
    ok = conv[conv["within tolerance"]].copy()
    if len(ok):
        # cost ~ nodes x number of steps
        ok["cost"] = ok["nodes"].clip(lower=1) / ok.index.get_level_values("time_step")
        best = ok["cost"].idxmin()
        out.recommended = (float(best[0]), float(best[1]))
    return out
