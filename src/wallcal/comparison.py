"""Several engines on one study: the paper's Table IV (engine x sensor) and engine-to-engine differences.

:func:`compare_engines` runs the study once per engine with the same time step, grid
constant C and node rule (each may be overridden), on the same prepared data, and gathers

- the long table engine x sensor x metrics (:mod:`wallcal.metrics`: RMSE, RN_RMSE,
  CV_RMSE over the effective value, and the ASHRAE Guideline-14 MBE, NMBE and CV(RMSE));
- the RMS (and maximum absolute) difference between every pair of engines, per sensor,
  over the comparison timestamps [degC or W/m2];
- the :class:`~wallcal.simulation.SimulationResult` of each engine.

Engine names: every engine of the registry (:func:`wallcal.engines.engine_names`): ``fd-cn``,
``fd-implicit``, ``fd-reference``, ``energyplus`` (Crank-Nicolson, as in a study's
``simulation.engine = "energyplus"``), and ``energyplus-cn`` / ``energyplus-implicit`` to pick
EnergyPlus' CondFD scheme explicitly. What this module needs to know about an engine (its scheme, which
engine object runs it, the node rule it always uses) comes from its registry entry; it tests no name.

The node rule applies to the engines that take the input's (``fd-*``): EnergyPlus always places
``int(L / sqrt(C alpha dt))`` intervals per layer (the ``"energyplus"`` rule of
:mod:`wallcal.grid`). With the study's defaults (``node_rule = "wallcal"``, C = 2) the fd
engines therefore run a finer grid than EnergyPlus; ``node_rule="energyplus"`` makes the grids
identical node for node.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import OptionalDependencyError, StudyError, closest
from .metrics import METRIC_COLUMNS
from .study import QUANTITY_UNITS, Study

#: Metrics shown in Table IV (rows per sensor), in this order.
TABLE_IV_METRICS = ("rmse", "rn_rmse", "cv_rmse_eff", "mbe", "nmbe", "cv_rmse_g14")
#: Long-table metric columns (``comparison.csv``): engine, signal, unit, then every metric.
LONG_COLUMNS = ("engine", "signal", "unit") + tuple(METRIC_COLUMNS[1:])


@dataclass
class Comparison:
    """Results of :func:`compare_engines`.

    Attributes
    ----------
    study : Study
    engines : tuple of str
        Engines that ran, in the requested order.
    results : dict[str, SimulationResult]
        One result per engine that ran.
    table : DataFrame
        Long form, one row per (engine, signal): columns :data:`LONG_COLUMNS`. Errors in the
        signal's unit (degC, W/m2, fraction of RH or kg/m3); rn_rmse, cv_rmse_eff, nmbe and cv_rmse_g14 are fractions.
    differences : DataFrame
        One row per (signal, engine_a, engine_b): ``rms_difference`` and ``max_abs_difference``
        of ``simulated_a - simulated_b`` over the comparison timestamps [unit of the signal],
        ``mean_difference`` likewise, and ``n``.
    skipped : dict[str, str]
        Requested engines that could not run (not installed) -> reason.
    settings : dict
        time_step [s], grid_constant [-], node_rule and the per-engine run times [s].
    """

    study: Study
    engines: tuple[str, ...]
    results: dict
    table: pd.DataFrame
    differences: pd.DataFrame
    skipped: dict[str, str] = field(default_factory=dict)
    settings: dict = field(default_factory=dict)

    def table_iv(self, metrics: tuple[str, ...] = TABLE_IV_METRICS) -> pd.DataFrame:
        """The paper's Table IV: rows (signal, metric), one column per engine.

        Parameters
        ----------
        metrics : tuple of str
            Metric columns of :attr:`table` to show.

        Returns
        -------
        DataFrame
            MultiIndex (signal, metric) in the study's sensor order.
        """
        long = self.table.melt(id_vars=["engine", "signal"], value_vars=list(metrics), var_name="metric")
        wide = long.pivot_table(
            index=["signal", "metric"], columns="engine", values="value", aggfunc="first", dropna=False
        )
        order = [(s, m) for s in self.table["signal"].drop_duplicates() for m in metrics]
        return wide.reindex(
            index=pd.MultiIndex.from_tuples(order, names=["signal", "metric"]), columns=list(self.engines)
        )

    def difference_matrix(self, value: str = "rms_difference") -> pd.DataFrame:
        """Engine-to-engine differences per sensor: rows signals, one column per engine pair.

        Parameters
        ----------
        value : str
            ``"rms_difference"``, ``"max_abs_difference"`` or ``"mean_difference"``.

        Returns
        -------
        DataFrame
            Columns ``"a - b"`` [unit of the signal].
        """
        d = self.differences.assign(pair=self.differences["engine_a"] + " - " + self.differences["engine_b"])
        wide = d.pivot(index="signal", columns="pair", values=value)
        pairs = list(dict.fromkeys(d["pair"]))
        return wide.reindex(index=list(dict.fromkeys(d["signal"])), columns=pairs)

    def pair(self, a: str, b: str) -> pd.DataFrame:
        """Rows of :attr:`differences` for engines ``a`` and ``b`` (either order), indexed by signal."""
        d = self.differences
        sel = ((d["engine_a"] == a) & (d["engine_b"] == b)) | ((d["engine_a"] == b) & (d["engine_b"] == a))
        return d[sel].set_index("signal")

    def write_into(self, d: str | Path, plot: bool = True) -> list[str]:
        """Write ``comparison.csv``, ``differences.csv``, ``table_iv.csv``, ``simulated_<engine>.csv``
        and (``plot``) ``comparison.png`` into the existing directory ``d``; return the file names."""
        d = Path(d)
        files = []
        self.table.to_csv(d / "comparison.csv", index=False, float_format="%.6g")
        self.differences.to_csv(d / "differences.csv", index=False, float_format="%.6g")
        self.table_iv().to_csv(d / "table_iv.csv", float_format="%.6g")
        files += ["comparison.csv", "differences.csv", "table_iv.csv"]
        for name, res in self.results.items():
            sim = res.simulated.copy()
            sim.index = sim.index.strftime("%Y-%m-%dT%H:%M:%S")
            sim.to_csv(d / f"simulated_{name}.csv", float_format="%.6g")
            files.append(f"simulated_{name}.csv")
        if plot:
            plot_comparison(self, d / "comparison.png")
            files.append("comparison.png")
        return files


def __getattr__(attr: str):
    if attr == "COMPARE_ENGINES":  # engine names compare_engines accepts: every registered engine
        from .engines import engine_names

        return engine_names()
    raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")


def compare_engines(
    study: Study,
    engines,
    *,
    node_rule: str | None = None,
    grid_constant: float | None = None,
    time_step: float | None = None,
    skip_missing: bool = True,
) -> Comparison:
    """Run ``study`` with several engines and compare them with the measurements and with each other.

    Parameters
    ----------
    study : Study
        From :func:`wallcal.load_study`.
    engines : sequence of str
        Registered engine names (:func:`wallcal.engines.engine_names`; at least one).
    node_rule : str, optional
        ``"wallcal"`` or ``"energyplus"`` for the fd engines; default the study's. EnergyPlus
        always uses its own rule (the ``"energyplus"`` one).
    grid_constant : float, optional
        C = dx^2 / (alpha dt) [-] for every engine; default the study's.
    time_step : float, optional
        Time step [s] for every engine; default the study's (EnergyPlus accepts 60, 120, 180 s).
    skip_missing : bool
        Skip an engine whose optional dependency is not installed (recorded in
        :attr:`Comparison.skipped`) as long as another engine runs; False: raise.

    Returns
    -------
    Comparison

    Raises
    ------
    StudyError
        Unknown or repeated engine names, or none given.
    OptionalDependencyError
        An engine is not installed and ``skip_missing`` is False or no engine could run.
    EngineError
        An engine cannot run the study.
    """
    return compare_many(
        [study],
        engines,
        node_rule=node_rule,
        grid_constant=grid_constant,
        time_step=time_step,
        skip_missing=skip_missing,
    )[0]


def compare_many(
    studies,
    engines,
    *,
    node_rule: str | None = None,
    grid_constant: float | None = None,
    time_step: float | None = None,
    skip_missing: bool = True,
) -> list[Comparison]:
    """:func:`compare_engines` for several studies (e.g. one study with several walls: ``wallcal crosscheck``),
    the EnergyPlus runs of every study and engine sent at once to the executor (:mod:`wallcal.cluster`), so
    they run in parallel. Same arguments and errors as :func:`compare_engines`; one :class:`Comparison` per study.
    """
    from .data import load_measurements
    from .engines import engine_names, entry, get_engine
    from .simulation import prepare, result_from_output

    known = engine_names()
    names = [str(e).strip() for e in engines if str(e).strip()]
    if not names:
        raise StudyError([f"engines: give at least one of {', '.join(known)}"])
    problems = [f"engines: unknown engine {n!r}; {closest(n, known)}" for n in names if n not in known]
    dup = [n for n in dict.fromkeys(names) if names.count(n) > 1]
    if dup:
        problems.append(f"engines: {', '.join(map(repr, dup))} given more than once")
    if problems:
        raise StudyError(problems)
    entries = {n: entry(n) for n in names}
    runners = {e.runner: get_engine(e.runner) for e in entries.values()}  # one engine object per runner

    plans = []  # per study: (study, preps, {engine name: prepared data}, skipped)
    jobs: dict[str, list] = {}  # runner -> [(study index, engine name, input)]: an engine's runs, sent at once
    for k, study in enumerate(studies):
        meas = load_measurements(study)
        preps: dict[str, object] = {}
        use, skipped = {}, {}
        for name in names:
            scheme = entries[name].scheme
            if scheme not in preps:  # the same data for every engine of a scheme
                preps[scheme] = prepare(
                    study,
                    name,
                    time_step=time_step,
                    grid_constant=grid_constant,
                    node_rule=node_rule,
                    measurements=meas,
                )
            why = runners[entries[name].runner].unavailable()
            if why:
                if not skip_missing:
                    raise OptionalDependencyError(why)
                skipped[name] = why
                continue
            use[name] = preps[scheme]
            jobs.setdefault(entries[name].runner, []).append((k, name, preps[scheme].inp))
        if not use:
            raise OptionalDependencyError("no engine could run: " + "; ".join(f"{a}: {b}" for a, b in skipped.items()))
        plans.append((study, preps, use, skipped))
    outputs = {}
    for runner, todo in jobs.items():
        outs = runners[runner].run_inputs([inp for _, _, inp in todo])
        outputs.update({(k, name): out for (k, name, _), out in zip(todo, outs, strict=True)})

    comparisons = []
    for k, (study, preps, use, skipped) in enumerate(plans):
        results, seconds = {}, {}
        for name, prep in use.items():
            out = outputs[(k, name)]
            seconds[name] = float(out.info.get("seconds", float("nan")))
            res = result_from_output(prep, out, name)
            res.info["node_rule"] = entries[name].node_rule or prep.inp.node_rule
            results[name] = res
        comparisons.append(_assemble(study, preps, results, skipped, seconds))
    return comparisons


def _assemble(study, preps, results, skipped, seconds) -> Comparison:
    units = {s.name: QUANTITY_UNITS[s.quantity] for s in study.sensors}  # the units after conversion
    rows = []
    for name, res in results.items():
        m = res.metrics.copy()
        m.insert(0, "engine", name)
        m.insert(2, "unit", m["signal"].map(units))
        rows.append(m)
    table = pd.concat(rows, ignore_index=True)[list(LONG_COLUMNS)]

    diff_rows = []
    ran = list(results)
    for sig in [s.name for s in study.sensors]:
        ok = results[ran[0]].measured[sig].notna()
        for a, b in itertools.combinations(ran, 2):
            e = (results[a].simulated[sig] - results[b].simulated[sig])[ok].to_numpy(dtype=float)
            e = e[np.isfinite(e)]
            nan = float("nan")
            diff_rows.append(
                {
                    "signal": sig,
                    "unit": units[sig],
                    "engine_a": a,
                    "engine_b": b,
                    "n": int(e.size),
                    "rms_difference": float(np.sqrt(np.mean(e**2))) if e.size else nan,
                    "max_abs_difference": float(np.max(np.abs(e))) if e.size else nan,
                    "mean_difference": float(np.mean(e)) if e.size else nan,
                }
            )
    differences = pd.DataFrame(
        diff_rows,
        columns=[
            "signal",
            "unit",
            "engine_a",
            "engine_b",
            "n",
            "rms_difference",
            "max_abs_difference",
            "mean_difference",
        ],
    )
    any_prep = next(iter(preps.values()))
    settings = {
        "time_step_s": any_prep.inp.time_step,
        "grid_constant": any_prep.inp.grid_constant,
        "node_rule_fd": any_prep.inp.node_rule,
        "seconds": seconds,
        "nodes": {n: r.info.get("nodes", r.info.get("n_nodes")) for n, r in results.items()},
    }
    return Comparison(
        study=study,
        engines=tuple(ran),
        results=results,
        table=table,
        differences=differences,
        skipped=skipped,
        settings=settings,
    )


def _unit_label(unit: str) -> str:
    return {"degC": "°C", "W/m2": "W/m²"}.get(unit, unit)


def plot_comparison(comparison: Comparison, path: str | Path) -> Path:
    """Figure of measured vs each engine, one row per sensor.

    Each row has two panels sharing the time axis: the measured series and each engine's
    simulated series (left) and each engine minus measured (right), in the signal's unit
    (degC for temperatures, W/m2 for heat flux densities, positive towards the interior).

    Parameters
    ----------
    comparison : Comparison
    path : str or Path
        PNG file to write.

    Returns
    -------
    Path
        The file written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    signals = list(comparison.table["signal"].drop_duplicates())
    units = dict(zip(comparison.table["signal"], comparison.table["unit"], strict=False))
    first = comparison.results[comparison.engines[0]]
    fig, axes = plt.subplots(len(signals), 2, figsize=(13, 2.6 * len(signals) + 0.8), sharex=True, squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, sig in enumerate(signals):
        ax, axr = axes[i]
        unit = _unit_label(units.get(sig, ""))
        meas = first.measured[sig]
        ax.plot(meas.index, meas.to_numpy(), color="black", lw=1.2, label="measured")
        for j, name in enumerate(comparison.engines):
            sim = comparison.results[name].simulated[sig]
            style = ("-", "--", ":", "-.")[j % 4]
            c = colors[j % len(colors)]
            ax.plot(sim.index, sim.to_numpy(), ls=style, color=c, lw=1.0, label=name)
            axr.plot(sim.index, (sim - meas).to_numpy(), ls=style, color=c, lw=0.9, label=name)
        axr.axhline(0.0, color="black", lw=0.6)
        ax.set_ylabel(f"{sig} [{unit}]")
        axr.set_ylabel(f"{sig} simulated - measured [{unit}]", fontsize=8)
        ax.grid(alpha=0.3)
        axr.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=8, ncol=len(comparison.engines) + 1, loc="best")
            axr.legend(fontsize=8, ncol=len(comparison.engines), loc="best")
    for ax in axes[-1]:
        ax.set_xlabel("time (local standard time)")
    fig.autofmt_xdate()
    s = comparison.settings
    title = comparison.study.name or "study"
    fig.suptitle(
        f"{title}: measured vs engines (dt = {s['time_step_s']:g} s, C = {s['grid_constant']:g}, "
        f"fd node rule {s['node_rule_fd']})",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
