"""Sensitivity of the calibration objective (and each target's RMSE) to the calibration parameters.

Methods, all over the calibration parameter space and evaluated through the batched engine:

- ``oat``: one at a time, the study's manual route: each parameter to its lower and
  upper bound, the others at the base case (or at ``x0``); change of the objective
  and of each target's RMSE (2n + 1 simulations);
- ``morris``: elementary effects (mu*, sigma) on ``r`` trajectories (r (n + 1) simulations), SALib;
- ``sobol``: Saltelli/Sobol' first-order S1 and total ST indices with bootstrap
  confidence intervals (N (n + 2) simulations), SALib.

The ranking measure is |d objective| (oat), mu* (morris) or ST (sobol). Parameters
are also grouped per layer, and the share of the insulation layers
(conductivity below 0.1 W/(m K)) is reported.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

METHODS = ("oat", "morris", "sobol")
#: layers with a conductivity below this are called insulation [W/(m K)]
INSULATION_LAMBDA = 0.1


@dataclass
class SensitivityResult:
    """Outcome of :func:`sensitivity`.

    Attributes
    ----------
    method : str
    ranking : DataFrame
        One row per parameter, sorted by ``measure`` (descending), with the layer group.
    measure : str
        The ranking column.
    per_target : DataFrame
        The ranking measure for each target's RMSE (columns: targets).
    by_layer : DataFrame
        The measure summed per layer group.
    evaluations : int
    seconds : float
    """

    method: str
    ranking: pd.DataFrame
    measure: str
    per_target: pd.DataFrame
    by_layer: pd.DataFrame
    evaluations: int
    seconds: float
    objective: str
    notes: list = field(default_factory=list)

    def summary(self) -> str:
        lines = [
            f"{self.method}: {self.evaluations} simulations in {self.seconds:.1f} s "
            f"({self.evaluations / max(self.seconds, 1e-9):.0f}/s); ranking by {self.measure} of the "
            f"objective ({self.objective})"
        ]
        lines += self.notes
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "method": self.method,
            "measure": self.measure,
            "objective": self.objective,
            "evaluations": self.evaluations,
            "seconds": self.seconds,
            "notes": self.notes,
            "ranking": self.ranking.reset_index().to_dict(orient="records"),
            "by_layer": self.by_layer.reset_index().to_dict(orient="records"),
        }

    def write_into(self, d: Path) -> None:
        d = Path(d)
        self.ranking.to_csv(d / f"sensitivity_{self.method}.csv", float_format="%.6g")
        self.per_target.to_csv(d / f"sensitivity_{self.method}_per_target.csv", float_format="%.6g")
        self.by_layer.to_csv(d / f"sensitivity_{self.method}_by_layer.csv", float_format="%.6g")
        (d / "sensitivity.json").write_text(json.dumps(self.to_json(), indent=2, default=float))
        from .plots import plot_sensitivity

        plot_sensitivity(self, d / f"sensitivity_{self.method}.png")


# ---------------------------------------------------------------------------- the estimators (arrays in, indices out)
# ``problem`` is SALib's dict: {"num_vars": n, "names": [...], "bounds": [[lower, upper], ...]}.
def morris_sample(problem: dict, r: int, levels: int, seed: int) -> np.ndarray:
    """Morris design: ``r`` trajectories of ``n + 1`` points on a ``levels``-level grid, shape (r (n + 1), n)."""
    from SALib.sample import morris as ms

    return ms.sample(problem, r, num_levels=levels, seed=seed)


def morris_indices(problem: dict, X: np.ndarray, Y: np.ndarray, levels: int, seed: int) -> pd.DataFrame:
    """Elementary-effect statistics of the outputs ``Y`` of the design ``X``: mu* (mean |EE|), sigma (sd of
    EE), mu (mean EE), each in units of Y per unit of the normalised parameter range, and a bootstrap 95 %
    half-width of mu*; one row per parameter."""
    from SALib.analyze import morris as ma

    a = ma.analyze(problem, X, np.asarray(Y, dtype=float), num_levels=levels, seed=seed, print_to_console=False)
    return pd.DataFrame(
        {"mu_star": a["mu_star"], "sigma": a["sigma"], "mu": a["mu"], "mu_star_conf": a["mu_star_conf"]},
        index=pd.Index(problem["names"], name="parameter"),
    )


def sobol_sample(problem: dict, N: int, seed: int, second_order: bool = False) -> np.ndarray:
    """Saltelli's design for Sobol' indices: N (n + 2) points (N (2 n + 2) with second order)."""
    from SALib.sample import sobol as ss

    return ss.sample(problem, N, calc_second_order=second_order, seed=seed)


def sobol_indices(problem: dict, Y: np.ndarray, seed: int, second_order: bool = False) -> pd.DataFrame:
    """First-order S1 and total ST Sobol' indices of the outputs ``Y`` of :func:`sobol_sample`'s design, with
    bootstrap 95 % half-widths (S1_conf, ST_conf); one row per parameter."""
    from SALib.analyze import sobol as sa

    a = sa.analyze(
        problem, np.asarray(Y, dtype=float), calc_second_order=second_order, seed=seed, print_to_console=False
    )
    return pd.DataFrame(
        {"ST": a["ST"], "ST_conf": a["ST_conf"], "S1": a["S1"], "S1_conf": a["S1_conf"]},
        index=pd.Index(problem["names"], name="parameter"),
    )


def _evaluate(ev, X, prog, chunk=1024):
    """Objective and per-target RMSE of many candidates, in engine batches of ``chunk``."""
    objs, rmses = [], []
    for i in range(0, len(X), chunk):
        cse, rmse = ev.per_target(X[i : i + chunk])
        objs.append(ev.objective_from(cse))
        rmses.append(rmse)
        prog.update(f"{min(i + chunk, len(X))}/{len(X)} simulations")
    return np.concatenate(objs), np.concatenate(rmses)


def _layer_of(space, wall, j) -> str:
    p = space.parameters[j]
    if p.sensor is not None:
        return f"sensor {p.sensor}"
    if p.probe is not None:
        return f"probe {p.probe}"
    return ",".join(wall.layers[i].id for i in p.layers)


def sensitivity(
    study,
    method: str = "oat",
    *,
    space=None,
    x0=None,
    n: int | None = None,
    levels: int = 4,
    seed: int = 1,
    second_order: bool = False,
    prepared=None,
    progress: bool = True,
    chunk: int = 1024,
) -> SensitivityResult:
    """Rank the calibration parameters by their influence on the objective.

    Parameters
    ----------
    study : Study
    method : {"oat", "morris", "sobol"}
    space : ParameterSpace, optional
        Default the study's ``[calibration]`` space (a subset may be passed).
    x0 : ndarray, optional
        Centre of the one-at-a-time analysis [SI]; default the base case.
    n : int, optional
        Morris: trajectories (default 32); Sobol: base sample N (default 256; a power of 2).
    levels : int
        Morris grid levels.
    seed : int
    second_order : bool
        Sobol: also second-order indices (N (2n + 2) simulations).
    prepared : Prepared, optional
    progress : bool
    chunk : int
        Candidates per engine batch.

    Returns
    -------
    SensitivityResult
    """
    import time

    from ..calibration.algorithms import Progress
    from ..calibration.objective import Evaluator
    from ..calibration.space import parse_space
    from ..errors import StudyError, closest, require
    from ..simulation import BATCH_NEEDS, prepare

    if method not in METHODS:
        raise StudyError([f"--method: unknown method {method!r}; {closest(method, METHODS)}"])
    space = space or parse_space(study)
    prepared = prepared or prepare(study, needs=BATCH_NEEDS, purpose="the sensitivity analysis")
    ev = Evaluator(prepared, space)
    prog = Progress(f"sensitivity ({method})", enabled=progress)
    names = space.names
    targets = list(space.targets)
    t0 = time.perf_counter()
    if method == "oat":
        x0 = space.base if x0 is None else np.asarray(x0, dtype=float)
        X = np.repeat(x0[None], 2 * space.n + 1, axis=0)
        for j in range(space.n):
            X[1 + 2 * j, j] = space.lower[j]
            X[2 + 2 * j, j] = space.upper[j]
        obj, rmse = _evaluate(ev, X, prog, chunk)
        rows = []
        for j in range(space.n):
            lo, hi = 1 + 2 * j, 2 + 2 * j
            row = {"parameter": names[j], "d_objective_lower": obj[lo] - obj[0], "d_objective_upper": obj[hi] - obj[0]}
            row["|d objective|"] = max(abs(row["d_objective_lower"]), abs(row["d_objective_upper"]))
            row["relative"] = row["|d objective|"] / obj[0] if obj[0] else np.nan
            for k, t in enumerate(targets):
                row[f"dRMSE_{t}_lower"] = rmse[lo, k] - rmse[0, k]
                row[f"dRMSE_{t}_upper"] = rmse[hi, k] - rmse[0, k]
            rows.append(row)
        ranking = pd.DataFrame(rows).set_index("parameter")
        measure = "|d objective|"
        per_target = pd.DataFrame(
            {t: np.maximum(np.abs(ranking[f"dRMSE_{t}_lower"]), np.abs(ranking[f"dRMSE_{t}_upper"])) for t in targets}
        )
        notes = [f"objective at the centre: {obj[0]:.6g}"]
    else:
        require("SALib", "analysis")
        problem = {"num_vars": space.n, "names": names, "bounds": [[p.lower, p.upper] for p in space.parameters]}
        if method == "morris":
            X = morris_sample(problem, int(n or 32), levels, seed)
            obj, rmse = _evaluate(ev, X, prog, chunk)

            def analyze(Y):
                return morris_indices(problem, X, Y, levels, seed)

            measure = "mu_star"
        else:
            N = int(n or 256)
            if N & (N - 1):
                raise StudyError([f"--samples: the Sobol base sample must be a power of 2, got {N}"])
            X = sobol_sample(problem, N, seed, second_order)
            obj, rmse = _evaluate(ev, X, prog, chunk)

            def analyze(Y):
                return sobol_indices(problem, Y, seed, second_order)

            measure = "ST"
        ok = np.isfinite(obj)
        if not ok.all():
            raise StudyError([f"{(~ok).sum()} of {len(obj)} simulations failed (non-finite objective)"])
        ranking = analyze(obj)
        per_target = pd.DataFrame({t: analyze(rmse[:, k])[measure] for k, t in enumerate(targets)})
        notes = [f"objective over the sample: mean {obj.mean():.6g}, min {obj.min():.6g}, max {obj.max():.6g}"]
    seconds = time.perf_counter() - t0
    prog.close(f"{ev.evaluations} simulations, {seconds:.1f} s")
    wall = study.wall
    ranking.insert(0, "layer", [_layer_of(space, wall, j) for j in range(space.n)])
    ranking = ranking.sort_values(measure, ascending=False)
    per_target = per_target.loc[ranking.index]
    by_layer = ranking.groupby("layer")[measure].sum().sort_values(ascending=False).to_frame()
    total = by_layer[measure].clip(lower=0).sum()
    by_layer["share"] = by_layer[measure].clip(lower=0) / total if total > 0 else np.nan
    ins = [
        lab
        for lab in by_layer.index
        if not lab.startswith("probe")
        and all(
            (wall.layers[[L.id for L in wall.layers].index(i)].conductivity or 1.0) < INSULATION_LAMBDA
            for i in lab.split(",")
        )
    ]
    by_layer["insulation"] = [lab in ins for lab in by_layer.index]
    share = float(by_layer.loc[ins, "share"].sum()) if ins else 0.0
    top = ranking.index[:3].tolist()
    notes.append(f"most influential parameters: {', '.join(top)}")
    notes.append(
        f"insulation layers (lambda < {INSULATION_LAMBDA:g} W/(m K): {'; '.join(ins) or 'none'}) carry "
        f"{100 * share:.0f} % of the summed {measure}"
        + (
            " - the insulation layers are the most influential, as the study found"
            if share > 0.5
            else " - not the majority: the thin massive layers' heat capacity matters here"
        )
    )
    if method == "sobol":
        s1 = float(ranking["S1"].clip(lower=0).sum())
        notes.append(
            f"sum of S1 = {s1:.2f} (1 - sum S1 = {1 - s1:.2f} is the share of the variance due to "
            "interactions, e.g. the rho*c products and the lambda ratios)"
        )
    return SensitivityResult(
        method=method,
        ranking=ranking,
        measure=measure,
        per_target=per_target,
        by_layer=by_layer,
        evaluations=ev.evaluations,
        seconds=seconds,
        objective=space.objective,
        notes=([prepared.note] if prepared.note else []) + notes,
    )
